"""What a user does, end to end: a real recording made with ``sim`` + ``record`` over a router,
then the three ways a flight used to be lost, and the two ``demo`` flags that were ignored.

Every process is a real ``groundstation`` command on real zenoh sessions over TCP on
127.0.0.1 (multicast scouting off). The overwrites must leave the recording byte-identical;
the demo's listening is checked with sockets, not with its log line.
"""

from __future__ import annotations

import hashlib
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from groundstation.recording import is_complete, iter_messages
from tests.integration.harness import Probe, Procs, free_port, wait_for_port

pytestmark = pytest.mark.integration

DEFAULT_PORT = 7447
"""The demo's default bus port (cli.ROUTER_ENDPOINT)."""


def _run(*args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "groundstation", *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def _listening(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def recording(procs: Procs, tmp_path: Path) -> tuple[Path, str]:
    """A few seconds of the simulator recorded through a router; the router's endpoint."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    procs.groundstation("router", "router", "--listen", ep)
    wait_for_port(port)
    rec = tmp_path / "flight.mcap"
    record = procs.groundstation("record", "record", "--out", str(rec), "--connect", ep)
    sim = procs.groundstation("sim", "sim", "--connect", ep, "--scenario", "hover")
    deadline = time.monotonic() + 60
    while "recording " not in record.output():
        assert time.monotonic() < deadline, record.output()
        time.sleep(0.1)
    time.sleep(4.0)  # four seconds of flight on the bus after the recorder subscribed
    assert sim.stop(signal.SIGTERM, 15.0) == 0, sim.output()
    assert record.stop(signal.SIGTERM, 15.0) == 0, record.output()
    assert is_complete(rec)
    assert sum(m.key == "tether/cf1/telemetry" for m in iter_messages(rec)) > 200
    return rec, ep


def test_the_three_overwrites_leave_the_flight_byte_identical(
    recording: tuple[Path, str], tmp_path: Path
) -> None:
    rec, ep = recording
    digest, size = _sha(rec), rec.stat().st_size
    attempts = [
        ("replay", str(rec), "--offline", "--out", str(rec)),
        ("calibrate", str(rec), "--out", str(rec)),
        ("record", "--out", str(rec), "--connect", ep),
    ]
    for args in attempts:
        out = _run(*args)
        assert out.returncode == 2, (args, out.stdout, out.stderr)
        assert "Traceback" not in out.stderr, out.stderr
        assert "refusing" in out.stderr and "flight.mcap" in out.stderr, out.stderr
        assert _sha(rec) == digest and rec.stat().st_size == size, args
    # --force replaces an output, never the input.
    out = _run("replay", str(rec), "--offline", "--out", str(rec), "--force")
    assert out.returncode == 2 and "is also an input" in out.stderr
    assert _sha(rec) == digest
    # A new name works, and the tool's own output is protected in turn.
    new = tmp_path / "replayed.mcap"
    assert _run("replay", str(rec), "--offline", "--out", str(new)).returncode == 0
    replayed = _sha(new)
    out = _run("replay", str(rec), "--offline", "--out", str(new))
    assert out.returncode == 2 and _sha(new) == replayed
    assert not list(tmp_path.glob(".*.partial"))


def test_demo_listens_where_told_and_nowhere_else(procs: Procs, make_probe: Any) -> None:
    assert not _listening(DEFAULT_PORT), "port 7447 is taken on this machine: cannot judge"
    port = free_port()
    demo = procs.groundstation("demo", "demo", "--headless", "--listen", f"tcp/127.0.0.1:{port}")
    wait_for_port(port, timeout_s=60.0)
    probe: Probe = make_probe(port)  # a client of the demo's own bus, where it was told
    probe.collect("tether/cf1/estimate")
    probe.wait_for(lambda: len(probe.got("tether/cf1/estimate")) > 50, 60, "demo estimates")
    assert not _listening(DEFAULT_PORT), demo.output()
    assert demo.stop(signal.SIGTERM, 15.0) == 0, demo.output()


def test_demo_joins_a_router_without_listening(procs: Procs, make_probe: Any) -> None:
    assert not _listening(DEFAULT_PORT), "port 7447 is taken on this machine: cannot judge"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    procs.groundstation("router", "router", "--listen", ep)
    wait_for_port(port)
    probe: Probe = make_probe(port)
    probe.collect("tether/cf1/estimate")
    demo = procs.groundstation("demo", "demo", "--headless", "--connect", ep)
    probe.wait_for(
        lambda: len(probe.got("tether/cf1/estimate")) > 50, 60, "demo estimates via the router"
    )
    assert not _listening(DEFAULT_PORT), demo.output()  # it would block a router there
    assert demo.stop(signal.SIGTERM, 15.0) == 0, demo.output()


def test_demo_on_an_explicit_port_in_use_says_so() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = _run("demo", "--headless", "--listen", f"tcp/127.0.0.1:{port}", timeout_s=60)
    assert out.returncode == 2, out.stderr
    assert f"tcp/127.0.0.1:{port} is in use" in out.stderr and "Traceback" not in out.stderr
