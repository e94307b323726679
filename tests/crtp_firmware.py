"""A minimal stand-in for Crazyflie firmware over UDP (cflib's ``udp://`` driver), for tests.

It answers just enough CRTP for cflib 0.1.34 to connect (link-service sink, protocol version,
log and parameter TOCs (v2), memory count), create and start log blocks, and it streams log
data for the started blocks from its own clock. Every packet it receives is kept, so a test
can check what the bridge sent (setpoints, emergency stop). Not a simulator: values are
constant (level, 1 g up, motors at ``motor_pwm``).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from collections.abc import Mapping, Set
from dataclasses import dataclass

# CRTP ports (cflib.crtp.crtpstack.CRTPPort)
PARAM, MEM, LOGGING, PLATFORM, LINKCTRL = 0x02, 0x04, 0x05, 0x0D, 0x0F
TYPE_IDS = {
    "uint8_t": 1,
    "uint16_t": 2,
    "uint32_t": 3,
    "int8_t": 4,
    "int16_t": 5,
    "int32_t": 6,
    "float": 7,
    "FP16": 8,
}
PACK = {1: "B", 2: "H", 3: "I", 4: "b", 5: "h", 6: "i", 7: "f", 8: "e"}


def _header(port: int, channel: int) -> int:
    return ((port & 0x0F) << 4) | 0x0C | (channel & 0x03)


@dataclass
class _Block:
    ident: int
    variables: list[tuple[str, int]]  # (name, fetch type id)
    period_ms: int = 0
    started: bool = False
    next_ms: int = 0


class CrtpFirmware:
    """Serve ``toc`` (``{"group.name": C type}``) on ``udp://127.0.0.1:{port}``.

    A log block holding a variable of ``refuse`` is refused at creation with ``ENOMEM``, as
    firmware out of log memory answers.
    """

    def __init__(
        self, toc: Mapping[str, str], motor_pwm: float = 40000.0, refuse: Set[str] = frozenset()
    ) -> None:
        self.toc = list(toc.items())
        self.motor_pwm = motor_pwm
        self.refuse = refuse
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.01)
        self.port = int(self.sock.getsockname()[1])
        self.received: list[tuple[int, int, bytes]] = []
        self._peer: tuple[str, int] | None = None
        self._blocks: dict[int, _Block] = {}
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="crtp-firmware", daemon=True)
        self._thread.start()

    @property
    def uri(self) -> str:
        return f"udp://127.0.0.1:{self.port}"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()

    def packets(self, port: int) -> list[tuple[int, bytes]]:
        with self._lock:
            return [(ch, data) for p, ch, data in self.received if p == port]

    # ------------------------------------------------------------------ loop

    def _send(self, port: int, channel: int, data: bytes) -> None:
        if self._peer is not None:
            self.sock.sendto(bytes([_header(port, channel)]) + data, self._peer)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                raw, peer = self.sock.recvfrom(1024)
            except TimeoutError:
                raw = b""
            except OSError:
                return
            if raw:
                self._peer = peer
                header, data = raw[0], raw[1:]
                port, channel = (header >> 4) & 0x0F, header & 0x03
                with self._lock:
                    self.received.append((port, channel, data))
                self._handle(port, channel, data)
            self._stream()

    def _handle(self, port: int, ch: int, data: bytes) -> None:
        if port == LINKCTRL and ch == 1:
            self._send(LINKCTRL, 1, b"Bitcraze Crazyflie")
        elif port == LINKCTRL and ch == 0:
            self._send(LINKCTRL, 0, data)  # echo (cflib's latency pings)
        elif port == PLATFORM and ch == 1 and data[:1] == b"\x00":
            self._send(PLATFORM, 1, bytes([0, 12]))  # CRTP protocol version 12
        elif port == MEM and ch == 0 and data[:1] == b"\x01":
            self._send(MEM, 0, bytes([1, 0]))  # no memories
        elif port == PARAM and ch == 0 and data[:1] == b"\x03":
            self._send(PARAM, 0, struct.pack("<BHI", 3, 0, 0x5EED))  # an empty param TOC
        elif port == LOGGING and ch == 0:
            self._log_toc(data)
        elif port == LOGGING and ch == 1:
            self._log_settings(data)

    def _log_toc(self, data: bytes) -> None:
        if data[0] == 3:  # CMD_TOC_INFO_V2
            self._send(LOGGING, 0, struct.pack("<BHI", 3, len(self.toc), 0xC0FFEE))
        elif data[0] == 2:  # CMD_TOC_ITEM_V2
            ident = data[1] | data[2] << 8
            name, ctype = self.toc[ident]
            group, var = name.split(".")
            body = bytes([TYPE_IDS[ctype]]) + group.encode() + b"\0" + var.encode() + b"\0"
            self._send(LOGGING, 0, struct.pack("<BH", 2, ident) + body)

    def _log_settings(self, data: bytes) -> None:
        cmd = data[0]
        if cmd == 5:  # reset
            self._blocks.clear()
            self._send(LOGGING, 1, bytes([5, 0, 0]))
        elif cmd in (6, 7):  # create / append block (v2): (type, id_lo, id_hi)*
            ident = data[1]
            block = self._blocks.setdefault(ident, _Block(ident, []))
            if cmd == 6:
                block.variables.clear()
            for i in range(2, len(data), 3):
                fetch = data[i] & 0x0F
                toc_id = data[i + 1] | data[i + 2] << 8
                block.variables.append((self.toc[toc_id][0], fetch))
            size = sum(struct.calcsize("<" + PACK[f]) for _, f in block.variables)
            error = 0 if size <= 26 else 7  # E2BIG
            if any(name in self.refuse for name, _ in block.variables):
                error = 12  # ENOMEM
                del self._blocks[ident]
            self._send(LOGGING, 1, bytes([cmd, ident, error]))
        elif cmd == 3:  # start
            ident, period = data[1], data[2]
            block = self._blocks[ident]
            block.period_ms, block.started = 10 * period, True
            block.next_ms = self._now_ms() + 10 * period
            self._send(LOGGING, 1, bytes([3, ident, 0]))
        elif cmd in (2, 4):  # delete, stop
            block = self._blocks.get(data[1])
            if block is not None:
                block.started = False
            self._send(LOGGING, 1, bytes([cmd, data[1], 0]))

    def _now_ms(self) -> int:
        return int((time.monotonic() - self._t0) * 1000.0)

    def _value(self, name: str) -> float:
        if name.startswith(("motor.", "pwm.")):
            return self.motor_pwm
        return {
            "acc.z": 1.0,
            "stateEstimate.qw": 1.0,
            "pm.vbat": 3.9,
            "supervisor.info": 0b1011,
        }.get(name, 0.0)

    def _stream(self) -> None:
        now = self._now_ms()
        for block in list(self._blocks.values()):
            if not block.started or now < block.next_ms:
                continue
            stamp = block.next_ms
            block.next_ms += block.period_ms
            body = b"".join(
                struct.pack("<" + PACK[f], int(self._value(n)) if f != 7 else self._value(n))
                for n, f in block.variables
            )
            self._send(LOGGING, 2, bytes([block.ident]) + struct.pack("<I", stamp)[:3] + body)
