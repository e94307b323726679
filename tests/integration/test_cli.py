"""Each CLI subcommand as a subprocess: a short smoke run (zenoh-python examples_check style)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import pytest

from tests.integration.harness import Probe, Procs, free_port

pytestmark = [pytest.mark.integration]


def _gs(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "groundstation", *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def test_help_version_and_scenarios() -> None:
    out = _gs("--help")
    assert out.returncode == 0
    for cmd in ("serve", "sim", "demo", "record", "replay", "crazyflie"):
        assert cmd in out.stdout
    serve_help = _gs("serve", "--help").stdout
    for flag in ("--config", "--connect", "--listen", "--headless", "--web-host", "--web-port"):
        assert flag in serve_help
    assert _gs("--version").stdout.startswith("groundstation ")
    listing = _gs("sim", "--list")
    assert listing.returncode == 0
    for name in ("hover_spots", "takeoff_0.3", "takeoff_1.3", "coin", "follow", "tug_landing"):
        assert name in listing.stdout


def test_bad_config_fails_at_start_naming_key_and_value(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[tether]\nweight_n_per_m = -0.05\n")
    out = _gs("serve", "--config", str(cfg), "--headless")
    assert out.returncode == 2
    assert "tether.weight_n_per_m = -0.05" in out.stderr
    out = _gs("sim", "--scenario", "no_such_scenario", "--duration", "1")
    assert out.returncode != 0 and "no_such_scenario" in out.stderr


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("serve", "--headless", "--connect", "tcp/127.0.0.1:{port}"), "no router reachable at"),
        (("record", "--out", "x.mcap", "--connect", "tcp/127.0.0.1:{port}"), "no router reachable"),
        (("sim", "--connect", "tcp/127.0.0.1:{port}"), "no router reachable at tcp/127.0.0.1:"),
        (("serve", "--headless", "--connect", "bogus"), "zenoh.connect = ['bogus']"),
        (("sim", "--scenario", "nope"), "unknown scenario 'nope'"),
        (("demo", "--scenario", "nope", "--headless"), "unknown scenario 'nope'"),
        (("replay", "--offline", "x.mcap"), "replay --offline needs --out"),
        (("serve", "--headless", "--config", "{strings}"), "tether.length_m = '1.6'"),
    ],
)
def test_errors_are_one_line_and_exit_2(tmp_path: Path, args: tuple[str, ...], needle: str) -> None:
    # A port nothing listens on: a router that is down.
    strings = tmp_path / "strings.toml"
    strings.write_text('[tether]\nlength_m = "1.6"\n')
    port = free_port()
    argv = [a.format(port=port, strings=strings) for a in args]
    out = subprocess.run(
        [sys.executable, "-m", "groundstation", *argv],
        capture_output=True,
        text=True,
        timeout=60.0,
        cwd=tmp_path,
    )
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("groundstation: "), out.stderr
    assert needle in lines[0], lines[0]
    assert "Traceback" not in out.stderr


@pytest.mark.slow
def test_sim_alone_publishes_the_contract(procs: Procs, make_probe: Any) -> None:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    for key in ("tether/*/telemetry", "tether/*/reel", "tether/*/truth"):
        probe.collect(key)
    sim = procs.groundstation(
        "sim", "sim", "--connect", f"tcp/127.0.0.1:{port}", "--duration", "600"
    )
    probe.wait_for(lambda: len(probe.got("tether/*/telemetry")) > 100, 20, "telemetry")
    telemetry = probe.json("tether/*/telemetry")[-1]
    assert set(telemetry) >= {"seq", "stamp_s", "accel_mps2", "quat_wxyz", "thrust_n"}
    assert probe.got("tether/*/reel") and probe.got("tether/*/truth")
    assert sim.stop(signal.SIGINT) == 0


@pytest.mark.slow
def test_demo_prints_the_dashboard_url_and_stops_cleanly(procs: Procs) -> None:
    web_port = free_port()
    demo = procs.groundstation("demo", "demo", "--web-port", str(web_port))
    deadline = time.monotonic() + 40
    url = None
    while time.monotonic() < deadline and url is None:
        m = re.search(r"dashboard: (http://127\.0\.0\.1:\d+)", demo.output())
        url = m.group(1) if m else None
        assert demo.popen.poll() is None, demo.output()
        time.sleep(0.2)
    assert url == f"http://127.0.0.1:{web_port}", demo.output()
    with urllib.request.urlopen(url, timeout=10) as resp:
        assert resp.status == 200
    assert demo.stop(signal.SIGINT) == 0, demo.output()


@pytest.mark.slow
def test_demo_headless_runs_for_a_duration(procs: Procs) -> None:
    demo = procs.groundstation("demo", "demo", "--headless", "--duration", "4")
    assert demo.popen.wait(30) == 0, demo.output()
    assert "groundstation demo: scenario hover_spots" in demo.output()
