"""Simulator → service → estimates, each in its own process, through a router over TCP.

The router is a Python session in router mode (these machines have no zenohd binary);
service and simulator are its clients, as in the docker-compose deployment.
"""

from __future__ import annotations

import signal
from typing import Any

import numpy as np
import pytest

from tests.integration.harness import Probe, Procs, free_port

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def _by_stamp(rows: list[dict[str, Any]]) -> dict[float, dict[str, Any]]:
    return {round(r["stamp_s"], 6): r for r in rows}


def _start(procs: Procs, make_probe: Any, scenario: str, *sim_args: str) -> tuple[Probe, Any]:
    port = free_port()
    procs.router(port)
    probe: Probe = make_probe(port)
    for key in ("tether/*/estimate", "tether/*/truth", "tether/*/cmd/**"):
        probe.collect(key)
    ep = f"tcp/127.0.0.1:{port}"
    service = procs.groundstation("serve", "serve", "--connect", ep, "--headless")
    # The simulator starts once the service listens: on a loaded machine the service's
    # start-up can take longer than the simulator's, and the first second of telemetry
    # (which test_takeoff_reports_no_tension_on_the_ground reads) would go unheard.
    probe.wait_for(
        lambda: "serving drones" in service.output(), timeout_s=30, what="the service's start"
    )
    procs.groundstation(
        "sim", "sim", "--connect", ep, "--scenario", scenario, "--drones", "cf1", *sim_args
    )
    return probe, service


def test_hover_without_mocap_estimates_position_and_tension(procs: Procs, make_probe: Any) -> None:
    probe, service = _start(procs, make_probe, "hover", "--no-mocap", "--duration", "60")
    probe.wait_for(
        lambda: sum(1 for e in probe.json("tether/*/estimate") if e["position_m"]) > 250 * 8,
        timeout_s=40,
        what="8 s of estimates with a position",
    )
    estimates = probe.json("tether/*/estimate")
    truth = _by_stamp(probe.json("tether/*/truth"))
    seqs = [e["seq"] for e in estimates]
    assert seqs == sorted(seqs), "one estimate per telemetry, in order"
    pos_err, ten_err = [], []
    for e in estimates[-250 * 5 :]:  # the last 5 s
        t = truth.get(round(e["stamp_s"], 6))
        if t is None or e["position_m"] is None:
            continue
        pos_err.append(np.linalg.norm(np.subtract(e["position_m"], t["position_m"])))
        ten_err.append(np.subtract(e["tension_n"], t["tension_n"]))
        for v in (*e["tension_n"], *e["tension_std_n"], *e["position_m"]):
            assert np.isfinite(v)
    assert len(pos_err) > 500
    assert float(np.median(pos_err)) < 0.05, f"median position error {np.median(pos_err):.3f} m"
    assert float(np.percentile(pos_err, 95)) < 0.10
    rms = np.sqrt(np.mean(np.square(ten_err), axis=0))
    assert np.all(rms < 1.5e-3), f"tension RMS per axis {rms} N"
    assert not probe.got("tether/*/cmd/**"), "no command without follow mode"
    assert service.stop(signal.SIGTERM) == 0


def test_takeoff_reports_no_tension_on_the_ground(procs: Procs, make_probe: Any) -> None:
    probe, service = _start(procs, make_probe, "takeoff_0.3", "--duration", "40")
    probe.wait_for(
        lambda: any(
            e["position_m"] and e["stamp_s"] > 12.0 for e in probe.json("tether/*/estimate")
        ),
        timeout_s=40,
        what="estimates 10 s after arming",
    )
    estimates = probe.json("tether/*/estimate")
    on_ground = [e for e in estimates if e["stamp_s"] < 1.5]
    assert on_ground and all(e["on_ground"] for e in on_ground)
    assert all(e["position_m"] is None for e in on_ground)
    assert all(abs(e["vertical_n"]) < 1e-9 for e in on_ground), "floor reaction is no tension"
    truth = _by_stamp(probe.json("tether/*/truth"))
    late = [e for e in estimates if e["stamp_s"] > 10.0 and e["position_m"]]
    # The truth travels on its own key: at the snapshot the newest ones may still be in flight.
    judged = [e for e in late if round(e["stamp_s"], 6) in truth]
    assert len(judged) > 0.9 * len(late)
    z_err = [
        abs(e["position_m"][2] - truth[round(e["stamp_s"], 6)]["position_m"][2]) for e in judged
    ]
    assert float(np.median(z_err)) < 0.05
    assert max(e["horizontal_n"] for e in late) < 0.010
    assert service.stop(signal.SIGINT) == 0


def test_follow_scenario_moves_with_the_pull(procs: Procs, make_probe: Any) -> None:
    probe, service = _start(procs, make_probe, "follow", "--duration", "22")
    probe.wait_for(
        lambda: any(e["stamp_s"] > 17.0 for e in probe.json("tether/*/estimate")),
        timeout_s=50,
        what="the follow scenario to pass 17 s",
    )
    estimates = probe.json("tether/*/estimate")
    setpoints = probe.json("tether/cf1/cmd/setpoint") or [
        s for s in probe.json("tether/*/cmd/**") if "position_m" in s
    ]
    assert all(not e["follow"]["enabled"] for e in estimates if e["stamp_s"] < 2.9)
    assert any(e["follow"]["enabled"] for e in estimates if e["stamp_s"] > 3.5)
    assert any(e["follow"]["active"] for e in estimates if 6.0 < e["stamp_s"] < 8.5)
    assert setpoints, "setpoints while the pull is on"
    assert all(sp["stamp_s"] > 3.0 for sp in setpoints), "no setpoint before follow is enabled"
    truth = _by_stamp(probe.json("tether/*/truth"))
    x_before = truth[min(truth, key=lambda s: abs(s - 5.5))]["position_m"][0]
    x_after = truth[min(truth, key=lambda s: abs(s - 9.0))]["position_m"][0]
    assert x_after < x_before - 0.1, "the drone yields to a pull toward -x"
    for sp in setpoints:
        assert np.linalg.norm(np.subtract(sp["position_m"], [0.0, 0.0, 0.754])) <= 1.6
    assert service.stop() == 0


def test_tug_landing_issues_one_stop_below_land_height(procs: Procs, make_probe: Any) -> None:
    probe, service = _start(procs, make_probe, "tug_landing", "--duration", "16")
    probe.wait_for(
        lambda: any(s.key.endswith("/cmd/stop") for s in probe.got("tether/*/cmd/**")),
        timeout_s=40,
        what="a Stop",
    )
    probe.wait_for(
        lambda: (
            any(e["stamp_s"] > 14.0 for e in probe.json("tether/*/estimate"))
            or any(t["stamp_s"] > 14.0 for t in probe.json("tether/*/truth"))
        ),
        timeout_s=30,
        what="the scenario to run on after the Stop",
    )
    stops = [s for s in probe.got("tether/*/cmd/**") if s.key.endswith("/cmd/stop")]
    assert len(stops) == 1
    import json

    stop = json.loads(stops[0].payload)
    truth = _by_stamp(probe.json("tether/*/truth"))
    z_at_stop = truth[min(truth, key=lambda s: abs(s - stop["stamp_s"]))]["position_m"][2]
    assert z_at_stop < 0.25 + 0.02
    assert service.stop() == 0
