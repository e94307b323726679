"""``groundstation record`` / ``replay`` as separate processes on real zenoh sessions.

Topology: ``router.py`` (zenohd stand-in, tcp on 127.0.0.1, multicast scouting off), the
recorder CLI and a publisher process as clients of it. The acceptance check of the recorder
issue is :func:`test_record_three_drones_at_2000_hz_sigint`.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from groundstation.recording import is_complete, iter_messages, recover

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
ROUTER = Path(__file__).with_name("router.py")
DRONES = ("cf1", "cf2", "cf3")

# Publishes ``count`` telemetry samples round-robin over three drones at ``rate`` samples/s
# once the recorder's subscriber matches every key; prints "published N"; then holds its
# session open until stdin closes, so nothing it sent is cut off by its own exit.
PUBLISHER = r"""
import json, sys, time
import zenoh

endpoint, count, rate = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
drones = sys.argv[4].split(",")

def payload(i):
    return json.dumps({"seq": i // len(drones), "stamp_s": round(i / rate, 6),
                       "accel_mps2": [0.0, 0.1 * (i % 7), 9.81], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                       "thrust_n": 0.3, "i": i}, separators=(",", ":")).encode()

conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
try:
    pubs = [session.declare_publisher(f"tether/{d}/telemetry",
                                      encoding=zenoh.Encoding.APPLICATION_JSON,
                                      congestion_control=zenoh.CongestionControl.BLOCK)
            for d in drones]
    deadline = time.monotonic() + 20.0
    while not all(p.matching_status.matching for p in pubs):
        if time.monotonic() > deadline:
            print("no subscriber", flush=True)
            sys.exit(3)
        time.sleep(0.01)  # polling a status, not synchronising with a sleep
    print("matched", flush=True)
    start = time.monotonic()
    for i in range(count):
        due = start + i / rate
        delay = due - time.monotonic()
        if delay > 0.002:
            time.sleep(delay)  # pacing the publication rate
        pubs[i % len(drones)].put(payload(i))
    print(f"published {count} in {time.monotonic() - start:.2f}", flush=True)
    sys.stdin.read()
finally:
    session.close()
"""


def expected_payload(i: int, rate: float, drones: int = 3) -> bytes:
    return json.dumps(
        {
            "seq": i // drones,
            "stamp_s": round(i / rate, 6),
            "accel_mps2": [0.0, 0.1 * (i % 7), 9.81],
            "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "thrust_n": 0.3,
            "i": i,
        },
        separators=(",", ":"),
    ).encode()


def expected(count: int, rate: float) -> list[tuple[str, bytes]]:
    return [(f"tether/{DRONES[i % 3]}/telemetry", expected_payload(i, rate)) for i in range(count)]


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Proc:
    """A child process whose stdout lines can be awaited with a timeout."""

    def __init__(self, args: list[str], *, stdin: bool = False) -> None:
        env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
        self.args = args
        self.popen = subprocess.Popen(
            args,
            cwd=REPO,
            env=env,
            stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.stderr: list[str] = []
        self._pumps = [
            threading.Thread(target=self._pump_out, daemon=True),
            threading.Thread(target=self._pump_err, daemon=True),
        ]
        for pump in self._pumps:
            pump.start()

    def _pump_out(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.put(line.rstrip("\n"))

    def _pump_err(self) -> None:
        assert self.popen.stderr is not None
        for line in self.popen.stderr:
            self.stderr.append(line)

    def wait_line(self, prefix: str, timeout_s: float) -> str:
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(
                    f"{self.args[1:3]}: no line starting {prefix!r} within {timeout_s} s; "
                    f"exit={self.popen.poll()} stderr={''.join(self.stderr)[-2000:]}"
                )
            try:
                line = self.lines.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                continue
            if line.startswith(prefix):
                return line

    def close_stdin(self) -> None:
        if self.popen.stdin is not None and not self.popen.stdin.closed:
            self.popen.stdin.close()

    def wait(self, timeout_s: float) -> int:
        return self.popen.wait(timeout=timeout_s)

    def stop(self) -> None:
        """Terminate (then kill) if still running; reap it and close its pipes."""
        self.close_stdin()
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(timeout=10)
        for pump in self._pumps:
            pump.join(timeout=10)
        for pipe in (self.popen.stdout, self.popen.stderr):
            if pipe is not None:
                pipe.close()


def groundstation(*args: str, stdin: bool = False) -> Proc:
    return Proc([sys.executable, "-m", "groundstation", *args], stdin=stdin)


def wait_until(predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.05)


def readable_count(path: Path) -> int:
    if not path.exists():
        return 0
    return sum(1 for _ in iter_messages(path))


@pytest.fixture
def router() -> Iterator[str]:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    proc = Proc([sys.executable, str(ROUTER), "--listen", endpoint])
    try:
        proc.wait_line("ready", 20.0)
        yield endpoint
    finally:
        proc.stop()
        assert proc.popen.returncode == 0, "".join(proc.stderr)


def publisher(tmp_path: Path, endpoint: str, count: int, rate: float) -> Proc:
    script = tmp_path / "publisher.py"
    script.write_text(PUBLISHER)
    return Proc(
        [sys.executable, str(script), endpoint, str(count), str(rate), ",".join(DRONES)],
        stdin=True,
    )


def test_record_three_drones_at_2000_hz_sigint(router: str, tmp_path: Path) -> None:
    """Acceptance: ~2,000 samples/s from three drones, SIGINT right after the last one, then
    the reference reader sees every sample byte-equal and in order; exit status 0."""
    count, rate = 8000, 2000.0
    out = tmp_path / "rec.mcap"
    rec = groundstation("record", "--out", str(out), "--connect", router)
    pub = publisher(tmp_path, router, count, rate)
    try:
        pub.wait_line("matched", 30.0)
        pub.wait_line("published", 60.0)
        rec.popen.send_signal(signal.SIGINT)
        assert rec.wait(30.0) == 0, "".join(rec.stderr)
    finally:
        rec.stop()
        pub.stop()

    assert is_complete(out)
    with out.open("rb") as fh:
        reader = make_reader(fh)
        got = [
            (channel.topic, message.data, message.log_time)
            for _schema, channel, message in reader.iter_messages(log_time_order=True)
        ]
        summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == count
    want = expected(count, rate)
    assert len(got) == len(want)
    first_bad = next(
        (i for i, (g, w) in enumerate(zip(got, want, strict=True)) if g[:2] != w), None
    )
    assert first_bad is None, f"sample {first_bad}: got {got[first_bad][:2]!r}"
    times = [t for _, _, t in got]
    assert times == sorted(times)
    # About 4 s of publishing: the receive times span about that (generous bounds).
    assert 2.0 < (times[-1] - times[0]) / 1e9 < 30.0


def test_killed_recorder_leaves_a_readable_file(router: str, tmp_path: Path) -> None:
    count, rate = 40000, 2000.0  # 20 s: the kill comes long before the end
    out = tmp_path / "rec.mcap"
    rec = groundstation("record", "--out", str(out), "--connect", router)
    pub = publisher(tmp_path, router, count, rate)
    try:
        pub.wait_line("matched", 30.0)
        # Two flushes' worth is on disk (the recorder closes a chunk at least every second).
        wait_until(lambda: readable_count(out) >= 3000, 30.0, "3000 samples on disk")
        seen = readable_count(out)
        rec.popen.kill()
        assert rec.wait(10.0) == -signal.SIGKILL
    finally:
        rec.stop()
        pub.stop()

    assert not is_complete(out)
    got = [(m.key, m.payload) for m in iter_messages(out)]
    assert len(got) >= seen
    assert got == expected(count, rate)[: len(got)]
    # The reference reader needs the footer; recover() writes a finished copy it can read.
    fixed = tmp_path / "fixed.mcap"
    assert recover(out, fixed) == len(got)
    with fixed.open("rb") as fh:
        assert [(c.topic, m.data) for _s, c, m in make_reader(fh).iter_messages()] == got


def write_recording(path: Path, messages: list[tuple[str, bytes, int]]) -> None:
    with path.open("wb") as fh:
        writer = Writer(fh)
        writer.start()
        schema = writer.register_schema("json", "jsonschema", b'{"type":"object"}')
        channels: dict[str, int] = {}
        for key, payload, t_ns in messages:
            if key not in channels:
                channels[key] = writer.register_channel(key, "json", schema)
            writer.add_message(channels[key], t_ns, payload, t_ns)
        writer.finish()


def test_replay_republishes_with_timing(router: str, tmp_path: Path) -> None:
    """replay → router → recorder: same bytes, same order, timing scaled by 1/speed."""
    t0 = 1_700_000_000 * 10**9
    msgs = [
        (f"tether/{DRONES[i % 3]}/telemetry", expected_payload(i, 100.0), t0 + i * 10_000_000)
        for i in range(200)
    ]  # 2 s at 100 samples/s
    msgs.append(("tether/cf1/reel", b'{"stamp_s":3.0,"length_m":1.2}', t0 + 3_000_000_000))
    src = tmp_path / "src.mcap"
    write_recording(src, msgs)
    out = tmp_path / "out.mcap"
    rec = groundstation("record", "--out", str(out), "--connect", router)
    play = None
    try:
        # The replayer waits for a matching subscriber before its first message, but the
        # recorder must have declared its subscriber by then: wait for its session first.
        wait_until(lambda: out.exists() and out.stat().st_size > 0, 30.0, "recorder started")
        play = groundstation("replay", str(src), "--connect", router, "--speed", "2")
        assert play.wait(60.0) == 0, "".join(play.stderr)
        wait_until(lambda: readable_count(out) == len(msgs), 30.0, "all replayed samples")
        rec.popen.send_signal(signal.SIGINT)
        assert rec.wait(30.0) == 0, "".join(rec.stderr)
    finally:
        rec.stop()
        if play is not None:
            play.stop()

    got = list(iter_messages(out))
    assert [(m.key, m.payload) for m in got] == [(k, p) for k, p, _ in msgs]
    span_s = (got[-1].log_time_ns - got[0].log_time_ns) / 1e9
    assert 1.0 < span_s < 6.0  # 3 s of recording at speed 2 is 1.5 s
    gap_s = (got[-1].log_time_ns - got[-2].log_time_ns) / 1e9
    assert gap_s > 0.2  # the 1 s gap before the reel sample, halved, survives


def test_record_stops_on_sigterm_with_nothing_recorded(router: str, tmp_path: Path) -> None:
    out = tmp_path / "empty.mcap"
    rec = groundstation("record", "--out", str(out), "--connect", router, "--key", "nothing/**")
    try:
        wait_until(lambda: out.exists() and out.stat().st_size > 0, 30.0, "recorder started")
        rec.popen.send_signal(signal.SIGTERM)
        assert rec.wait(30.0) == 0, "".join(rec.stderr)
    finally:
        rec.stop()
    assert is_complete(out)
    assert list(iter_messages(out)) == []


def test_replay_offline_cli(tmp_path: Path) -> None:
    """``replay --offline`` runs the service's pipeline over the file, as fast as it can."""
    t0 = 1_700_000_000 * 10**9
    msgs = [
        (
            "tether/cf1/telemetry",
            json.dumps(
                {
                    "seq": i,
                    "stamp_s": i * 0.004,
                    "accel_mps2": [0.0, 0.0, 9.81],
                    "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                    "thrust_n": 0.35,
                }
            ).encode(),
            t0 + i * 4_000_000,
        )
        for i in range(250)
    ]
    src = tmp_path / "src.mcap"
    out = tmp_path / "out.mcap"
    write_recording(src, msgs)
    proc = groundstation("replay", str(src), "--offline", "--out", str(out))
    try:
        assert proc.wait(120.0) == 0, "".join(proc.stderr)
    finally:
        proc.stop()
    keys = [m.key for m in iter_messages(out)]
    assert keys.count("tether/cf1/telemetry") == 250
    assert keys.count("tether/cf1/estimate") == 250
