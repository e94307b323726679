"""The parts as separate processes on one machine, without Docker.

``groundstation router`` is the hub; ``sim``, ``serve``, ``record`` and ``dashboard`` are
clients of it, each its own process, over TCP on 127.0.0.1 with multicast scouting off (the
README's five-terminal recipe, on a free port instead of 7447 so that tests can run side by
side). And the fixed ports: a port in use is an error that says so, never a silent move.
"""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from groundstation.recording import is_complete, iter_messages
from tests.integration.harness import Probe, Procs, free_port, wait_for_port

pytestmark = [pytest.mark.integration]


def _wait_output(proc: Any, pattern: str, timeout_s: float) -> re.Match[str]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        m = re.search(pattern, proc.output())
        if m:
            return m
        assert proc.popen.poll() is None, f"{proc.name} exited:\n{proc.output()}"
        time.sleep(0.1)
    raise AssertionError(f"{proc.name}: no {pattern!r} after {timeout_s} s:\n{proc.output()}")


@pytest.fixture
def busy_port() -> Iterator[int]:
    """A TCP port on 127.0.0.1 that something listens on."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        yield int(s.getsockname()[1])


@pytest.mark.slow
def test_router_sim_serve_record_dashboard_as_five_processes(
    procs: Procs, make_probe: Any, tmp_path: Path
) -> None:
    port, web_port = free_port(), free_port()
    ep = f"tcp/127.0.0.1:{port}"
    router = procs.groundstation("router", "router", "--listen", ep)
    wait_for_port(port)
    _wait_output(router, rf"groundstation router: listening on {re.escape(ep)} ", 20)
    probe: Probe = make_probe(port)
    probe.collect("tether/cf1/estimate")
    serve = procs.groundstation("serve", "serve", "--headless", "--connect", ep)
    rec_path = tmp_path / "rec.mcap"
    record = procs.groundstation("record", "record", "--out", str(rec_path), "--connect", ep)
    dash = procs.groundstation(
        "dashboard", "dashboard", "--connect", ep, "--web-port", str(web_port)
    )
    sim = procs.groundstation("sim", "sim", "--connect", ep, "--scenario", "hover")
    # The service's estimates reach a client of the router: the bus goes through it.
    probe.wait_for(
        lambda: sum(not e["on_ground"] for e in probe.json("tether/cf1/estimate")) > 250,
        60,
        "airborne estimates from serve through the router",
    )
    # The recorder subscribed (it says so once its subscriptions are declared), and
    # estimates kept flowing after that: on a loaded machine it may start last.
    _wait_output(record, r"recording .* to ", 60)
    seen = len(probe.json("tether/cf1/estimate"))
    probe.wait_for(
        lambda: len(probe.json("tether/cf1/estimate")) > seen + 100,
        60,
        "estimates after the recorder subscribed",
    )
    url = _wait_output(dash, r"dashboard: (http://127\.0\.0\.1:\d+)", 30).group(1)
    assert url == f"http://127.0.0.1:{web_port}"
    with urllib.request.urlopen(url, timeout=10) as resp:
        assert resp.status == 200
    for proc in (sim, dash, record, serve, router):
        assert proc.stop(signal.SIGTERM, 15.0) == 0, proc.output()
        # One line per signal, not one per thread or child.
        assert proc.output().count("signal 15: stopping") <= 1, proc.output()
    assert is_complete(rec_path)
    keys = {m.key for m in iter_messages(rec_path)}
    assert {"tether/cf1/telemetry", "tether/cf1/estimate"} <= keys


def _run(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "groundstation", *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def test_a_router_on_a_port_in_use_says_so(busy_port: int) -> None:
    out = _run("router", "--listen", f"tcp/127.0.0.1:{busy_port}")
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip() == (
        f"groundstation router: tcp/127.0.0.1:{busy_port} is in use (another router, zenohd, "
        "or a demo?); stop it, or pass --listen tcp/127.0.0.1:N"
    )


@pytest.mark.parametrize(
    "command",
    [
        ("serve", "--connect", "tcp/127.0.0.1:1"),
        ("dashboard", "--connect", "tcp/127.0.0.1:1"),
        ("demo",),
    ],
)
def test_a_dashboard_port_in_use_fails_before_anything_starts(
    busy_port: int, command: tuple[str, ...]
) -> None:
    """8080 busy once moved the dashboard to 8081 silently (the operator opens the
    other one's page). The port is checked before zenoh opens (the router at port 1 is
    never tried)."""
    out = _run(*command, "--web-port", str(busy_port))
    assert out.returncode == 2, out.stderr
    line = out.stderr.strip().splitlines()[-1]
    assert line == (
        f"groundstation {command[0]}: the dashboard's port 127.0.0.1:{busy_port} is in use "
        "(another groundstation serve, demo or dashboard?): stop it, or pass --web-port N "
        "(0: any free port)"
    ), out.stderr


@pytest.mark.slow
def test_demo_with_the_separate_process_config_runs_its_own_bus(procs: Procs) -> None:
    """config/sim.toml is a client of a router on 7447: the demo used to connect to itself
    (CONNECTION_TO_SELF, then "no router reachable"). It runs its own bus and says why."""
    repo = Path(__file__).resolve().parents[2]
    demo = procs.groundstation(
        "demo",
        "demo",
        "--config",
        str(repo / "config" / "sim.toml"),
        "--headless",
        "--duration",
        "4",
    )
    assert demo.popen.wait(60) == 0, demo.output()
    text = demo.output()
    assert "groundstation demo: runs its own bus in this process" in text, text
    assert "drones cf1, cf2" in text, text
    assert "CONNECTION_TO_SELF" not in text and "no router reachable" not in text, text
    assert text.count("signal") == 0, text


@pytest.mark.slow
def test_serve_with_its_dashboard_says_stopping_once(procs: Procs) -> None:
    """Serve says "signal 15: stopping" once (it came 2-3 times: serve, then its dashboard)."""
    port, web_port = free_port(), free_port()
    ep = f"tcp/127.0.0.1:{port}"
    procs.groundstation("router", "router", "--listen", ep)
    wait_for_port(port)
    serve = procs.groundstation("serve", "serve", "--connect", ep, "--web-port", str(web_port))
    _wait_output(serve, r"dashboard: http://127\.0\.0\.1:\d+", 40)
    assert serve.stop(signal.SIGTERM, 15.0) == 0, serve.output()
    assert serve.output().count("stopping") == 1, serve.output()
