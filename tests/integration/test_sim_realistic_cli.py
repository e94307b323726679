"""``groundstation sim --profile realistic`` as a subprocess, on a router over TCP."""

from __future__ import annotations

import signal
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from tests.integration.harness import Probe, Procs, free_port

pytestmark = [pytest.mark.integration]


def test_sim_realistic_runs_alone_and_ends_after_its_duration() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation",
            "sim",
            "--profile",
            "realistic",
            "--duration",
            "1",
            "--speed",
            "4",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert "realistic profile" in out.stdout


@pytest.mark.slow
def test_sim_realistic_publishes_jittered_telemetry_with_vbat_and_drawn_errors(
    procs: Procs, make_probe: Any
) -> None:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    for key in ("tether/*/telemetry", "tether/*/truth", "tether/*/reel"):
        probe.collect(key)
    sim = procs.groundstation(
        "sim",
        "sim",
        "--profile",
        "realistic",
        "--connect",
        f"tcp/127.0.0.1:{port}",
        "--duration",
        "600",
    )
    probe.wait_for(lambda: len(probe.got("tether/*/telemetry")) > 150, 60, "telemetry")
    telemetry = probe.json("tether/*/telemetry")
    assert all("vbat_v" in t for t in telemetry)
    spacing = np.diff([t["stamp_s"] for t in telemetry])
    assert spacing.min() >= 0.006 - 1e-9 and spacing.max() <= 0.027 + 1e-9
    truths = probe.json("tether/*/truth")
    assert all(t["profile"] == "realistic" for t in truths)
    probe.wait_for(lambda: any("errors" in t for t in probe.json("tether/*/truth")), 20, "errors")
    errors = next(t["errors"] for t in probe.json("tether/*/truth") if "errors" in t)
    assert set(errors["calibration"]) >= {"thrust_scale", "thrust_axis_rad", "accel_bias_mps2"}
    assert probe.got("tether/*/reel")
    assert sim.stop(signal.SIGINT) == 0
