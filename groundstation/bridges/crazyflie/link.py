"""The boundary to the drone: a small :class:`Link` interface and its cflib implementation.

Everything the bridge needs from a Crazyflie goes through :class:`Link`, so the bridge runs
the same against :class:`CflibLink` (radio, USB, TCP, or UDP to a software-in-the-loop
firmware) and against the test fake in :mod:`groundstation.bridges.crazyflie.fake`.

Callbacks (``on_data``, ``on_lost``) arrive on the link's own thread (cflib's incoming packet
thread); the bridge only queues them.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = [
    "CFLIB_SCHEMES",
    "SERIAL_REFUSED",
    "TYPE_SIZES",
    "CflibLink",
    "DataHandler",
    "Link",
    "LinkError",
    "LogBlock",
    "LogBlockRefused",
    "LostHandler",
    "scan_cflib",
]

_log = logging.getLogger(__name__)

TYPE_SIZES: Mapping[str, int] = {
    "uint8_t": 1,
    "int8_t": 1,
    "uint16_t": 2,
    "int16_t": 2,
    "FP16": 2,
    "uint32_t": 4,
    "int32_t": 4,
    "float": 4,
}
"""Bytes of each log type (cflib's ``LogTocElement.types``)."""

DataHandler = Callable[[str, int, Mapping[str, float]], None]
"""``(block name, firmware timestamp in ms (24 bits, wraps), {variable: value})``."""
LostHandler = Callable[[str], None]
"""Called once with the reason when an open link is lost."""


class LinkError(RuntimeError):
    """Connecting failed, or a log block was refused; the message says why."""


@dataclass(frozen=True, slots=True)
class LogBlock:
    """One log configuration: variables that fit one CRTP packet, sampled together."""

    name: str
    period_ms: int
    """A multiple of 10 ms (the firmware counts log periods in 10 ms units)."""
    variables: tuple[str, ...]
    fetch_as: tuple[str, ...]
    """The type each variable travels as (the firmware converts from its stored type)."""

    @property
    def size_bytes(self) -> int:
        return sum(TYPE_SIZES[t] for t in self.fetch_as)


class LogBlockRefused(LinkError):
    """The firmware answered a log block's creation or start with an error.

    Not worth retrying (the same blocks would be refused again): the bridge stops and says
    which block, which variables and the firmware's reason.
    """

    def __init__(self, uri: str, block: LogBlock, reason: str) -> None:
        self.block = block
        self.reason = reason
        super().__init__(
            f"{uri}: the firmware refused log block {block.name} "
            f"({', '.join(block.variables)}; {block.size_bytes} bytes every "
            f"{block.period_ms} ms): {reason}. Retrying would be refused again: check the "
            "firmware's log limits (blocks, variables, memory) and [crazyflie] rate_hz / "
            "slow_period_ms"
        )


class Link(Protocol):
    """What the bridge needs from a Crazyflie."""

    uri: str

    def open(self, on_lost: LostHandler, timeout_s: float) -> Mapping[str, str]:
        """Connect and download the log TOC.

        Returns:
            The log TOC: ``{"group.name": C type}`` (e.g. ``{"acc.x": "float"}``).

        Raises:
            LinkError: no answer within ``timeout_s``, or the link failed.
        """
        ...

    def start_logging(
        self, blocks: Sequence[LogBlock], on_data: DataHandler, timeout_s: float = 10.0
    ) -> None:
        """Create and start the log blocks; return once the firmware has started every one.

        Raises:
            LogBlockRefused: the firmware refused a block (the message names it and why).
            LinkError: no answer within ``timeout_s``, or the link failed.
        """
        ...

    def send_position_setpoint(self, x_m: float, y_m: float, z_m: float, yaw_deg: float) -> None:
        """Low-level position setpoint, world frame (``commander.send_position_setpoint``)."""
        ...

    def stop_motors(self) -> None:
        """Emergency stop: the supervisor's where the firmware has it, and a stop setpoint."""
        ...

    def send_stop_setpoint(self) -> None:
        """A stop setpoint only (``commander.send_stop_setpoint``)."""
        ...

    def arm(self) -> None:
        """Ask the supervisor to arm the motors (``supervisor.send_arming_request(True)``)."""
        ...

    def send_extpos(self, position_m: Sequence[float], quat_wxyz: Sequence[float] | None) -> None:
        """Forward a motion-capture pose to the drone's estimator."""
        ...

    def set_param(self, name: str, value: float) -> None:
        """Set a firmware parameter (``cf.param.set_value``), e.g. ``kalman.resetEstimation``.

        Raises:
            LinkError: the firmware has no such writable parameter, or the link failed.
        """
        ...

    def close(self) -> None:
        """Disconnect (idempotent)."""
        ...


CFLIB_SCHEMES = ("radio", "usb", "udp", "tcp", "prrt")
"""URI schemes of cflib 0.1.34's drivers (``cflib.crtp``) that the bridge opens."""
SERIAL_REFUSED = (
    "serial:// is not supported: cflib 0.1.34's serial driver calls itself 'an early serial "
    "link driver [that] could still be used (after some fixing)', needs pyserial (which cflib "
    "does not install) and a firmware speaking CPX over its UART, and waits for the UART's "
    "sync without a timeout, which would hang the bridge. Use radio:// (a Crazyradio) or "
    "usb:// (the Crazyflie's USB port)"
)
"""Why ``serial://`` is refused (a link that can hang the bridge is not offered)."""
PARAM_TIMEOUT_S = 10.0
"""Longest wait for the firmware's parameter values after connecting (cflib reads them all
once before it writes one)."""


def scan_cflib(address: int | None = None) -> list[str]:
    """URIs of the Crazyflies that answer cflib's scan (``cflib.crtp.scan_interfaces``).

    The radio scan pings ``address`` (default E7E7E7E7E7) on every channel at 250K, 1M and 2M;
    USB lists Crazyflies plugged in. Nothing is connected to, so nothing is commanded (a
    connection's close would send a zero setpoint). It needs the Crazyradio, which a running
    bridge holds.

    Args:
        address: the radio address to ping, as an int (``0xE7E7E7E701``).
    """
    import contextlib
    import io

    import cflib.crtp

    CflibLink._init_drivers()
    chatter = io.StringIO()  # cflib prints (e.g. "Cannot find a Crazyradio Dongle")
    with contextlib.redirect_stdout(chatter):
        found = cflib.crtp.scan_interfaces(address)
    for line in chatter.getvalue().splitlines():
        if line.strip():
            _log.info("cflib: %s", line.strip())
    return [str(entry[0]) for entry in found]


class CflibLink:
    """:class:`Link` on ``cflib.crazyflie.Crazyflie`` (cflib 0.1.34).

    Args:
        uri: a cflib URI, e.g. ``radio://0/80/2M/E7E7E7E7E7``, ``usb://0``,
            ``udp://127.0.0.1:19850`` (a software-in-the-loop firmware).
        cache_dir: where cflib caches the TOCs between connections (None: no cache).
    """

    _drivers_initialised = False
    _drivers_lock = threading.Lock()

    def __init__(self, uri: str, cache_dir: str | None = None) -> None:
        scheme = uri.split("://", 1)[0] if "://" in uri else ""
        if scheme == "serial":
            raise LinkError(f"--uri {uri!r}: {SERIAL_REFUSED}")
        if scheme not in CFLIB_SCHEMES:
            schemes = ", ".join(f"{s}://" for s in CFLIB_SCHEMES)
            raise LinkError(
                f"--uri {uri!r}: not a cflib URI ({schemes}; e.g. radio://0/80/2M/E7E7E7E7E7)"
            )
        self.uri = uri
        self._cache_dir = cache_dir
        self._cf: Any = None
        self._configs: list[Any] = []
        self._params_ready = threading.Event()

    @classmethod
    def _init_drivers(cls) -> None:
        import cflib.crtp

        with cls._drivers_lock:
            if not cls._drivers_initialised:
                cflib.crtp.init_drivers()
                cls._drivers_initialised = True

    def open(self, on_lost: LostHandler, timeout_s: float) -> Mapping[str, str]:
        from cflib.crazyflie import Crazyflie

        self._init_drivers()
        cf = Crazyflie(rw_cache=self._cache_dir)
        connected = threading.Event()
        failure: list[str] = []
        lost_once = threading.Event()

        def on_connected(uri: str) -> None:
            connected.set()

        def on_failed(uri: str, msg: str) -> None:
            failure.append(str(msg).strip().splitlines()[0] if msg else "connection failed")
            connected.set()

        def on_connection_lost(uri: str, msg: str) -> None:
            if not lost_once.is_set():
                lost_once.set()
                on_lost(str(msg).strip().splitlines()[0] if msg else "link lost")

        # `connected` fires once the log and parameter TOCs are downloaded; `fully_connected`
        # once every parameter's value has been read (cflib writes none before that).
        self._params_ready.clear()
        cf.fully_connected.add_callback(lambda uri: self._params_ready.set())
        cf.connected.add_callback(on_connected)
        cf.connection_failed.add_callback(on_failed)
        cf.connection_lost.add_callback(on_connection_lost)
        self._cf = cf
        cf.open_link(self.uri)
        if not connected.wait(timeout_s):
            self.close()
            raise LinkError(f"no answer from {self.uri} within {timeout_s:g} s")
        if failure:
            self.close()
            raise LinkError(f"cannot connect to {self.uri}: {failure[0]}")
        toc: dict[str, str] = {}
        for group, elements in cf.log.toc.toc.items():
            for name, element in elements.items():
                toc[f"{group}.{name}"] = str(element.ctype)
        return toc

    def start_logging(
        self, blocks: Sequence[LogBlock], on_data: DataHandler, timeout_s: float = 10.0
    ) -> None:
        from cflib.crazyflie.log import LogConfig

        cf = self._require()
        # cflib reports the firmware's answer to each block asynchronously: error_cb when the
        # creation is refused, started_cb(False) when the start is. Wait for every answer so a
        # refusal fails the connection with its reason instead of a silent data timeout.
        outcomes: dict[str, str | None] = {}
        answered = threading.Condition()

        def settle(name: str, refusal: str | None) -> bool:
            with answered:
                if name in outcomes:
                    return False
                outcomes[name] = refusal
                answered.notify_all()
                return True

        for block in blocks:
            conf = LogConfig(name=block.name, period_in_ms=block.period_ms)
            for var, fetch_as in zip(block.variables, block.fetch_as, strict=True):
                conf.add_variable(var, fetch_as)

            def data_cb(timestamp: int, data: dict[str, float], logconf: Any) -> None:
                on_data(logconf.name, int(timestamp), data)

            def error_cb(logconf: Any, msg: str, name: str = block.name) -> None:
                if not settle(name, str(msg)):  # after it started: only say so
                    _log.error("log block %s: error from the firmware: %s", name, msg)

            def started_cb(_: Any, started: bool, name: str = block.name, c: Any = conf) -> None:
                if started:
                    settle(name, None)
                else:
                    settle(name, f"start refused (error {c.err_no})")

            try:
                cf.log.add_config(conf)
            except (KeyError, AttributeError) as exc:
                raise LinkError(f"log block {block.name} {list(block.variables)}: {exc}") from None
            conf.data_received_cb.add_callback(data_cb)
            conf.error_cb.add_callback(error_cb)
            conf.started_cb.add_callback(started_cb)
            conf.start()
            self._configs.append(conf)
        by_name = {b.name: b for b in blocks}
        with answered:
            answered.wait_for(
                lambda: len(outcomes) == len(blocks) or any(outcomes.values()), timeout_s
            )
            done = dict(outcomes)
        for name, refusal in done.items():
            if refusal is not None:
                raise LogBlockRefused(self.uri, by_name[name], refusal)
        waiting = [b.name for b in blocks if b.name not in done]
        if waiting:
            raise LinkError(
                f"{self.uri}: the firmware did not start log block(s) {', '.join(waiting)} "
                f"within {timeout_s:g} s"
            )

    def send_position_setpoint(self, x_m: float, y_m: float, z_m: float, yaw_deg: float) -> None:
        self._require().commander.send_position_setpoint(x_m, y_m, z_m, yaw_deg)

    def stop_motors(self) -> None:
        cf = self._require()
        # cflib 0.1.34: the supervisor's emergency stop on CRTP protocol >= 12, else it falls
        # back to the legacy localization-port emergency stop itself. The stop setpoint as
        # well, for firmware that has neither.
        cf.supervisor.send_emergency_stop()
        cf.commander.send_stop_setpoint()

    def send_stop_setpoint(self) -> None:
        self._require().commander.send_stop_setpoint()

    def arm(self) -> None:
        # cflib 0.1.34 uses the legacy platform-port request on firmware before protocol 12.
        self._require().supervisor.send_arming_request(True)

    def send_extpos(self, position_m: Sequence[float], quat_wxyz: Sequence[float] | None) -> None:
        cf = self._require()
        x, y, z = (float(v) for v in position_m)
        if quat_wxyz is None:
            cf.extpos.send_extpos(x, y, z)
        else:
            w, qx, qy, qz = (float(v) for v in quat_wxyz)
            cf.extpos.send_extpose(x, y, z, qx, qy, qz, w)  # cflib takes x, y, z, w

    def set_param(self, name: str, value: float) -> None:
        cf = self._require()
        # cflib's set_value would wait up to 60 s for the values on this (the bridge's) thread.
        if not self._params_ready.wait(PARAM_TIMEOUT_S):
            raise LinkError(
                f"{self.uri}: the firmware's parameter values were not read within "
                f"{PARAM_TIMEOUT_S:g} s; {name} not set"
            )
        try:
            cf.param.set_value(name, value)
        except (KeyError, AttributeError) as exc:  # not in the TOC; read-only
            raise LinkError(f"{self.uri}: cannot set parameter {name}: {exc}") from None

    def close(self) -> None:
        cf, self._cf = self._cf, None
        self._configs.clear()
        if cf is not None:
            cf.close_link()

    def _require(self) -> Any:
        if self._cf is None:
            raise LinkError(f"{self.uri} is not open")
        return self._cf
