"""The simulator's physics: equilibrium against the tether, sensors consistent with truth."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from groundstation.bus import Sample
from groundstation.evaluation import settings_for
from groundstation.sim import (
    SCENARIOS,
    DroneSim,
    Simulator,
    quat_wxyz_from_z_axis,
)
from groundstation.tension import observe_tension, rotation_world_body


class _Bus:
    def publish(self, key: str, payload: bytes) -> None:
        pass


def _sim(scenario: str, **sim: object) -> Simulator:
    return Simulator(settings_for(**sim), _Bus(), scenario=scenario)  # type: ignore[arg-type]


def _run(sim: Simulator, seconds: float) -> list[Sample]:
    out: list[Sample] = []
    for _ in range(round(seconds / sim.dt_s)):
        out.extend(sim.step())
    return out


@pytest.mark.parametrize("z_axis", [(0, 0, 1), (0.3, -0.2, 0.9), (-0.5, 0.5, 0.7)])
def test_quaternion_body_z(z_axis: tuple[float, float, float]) -> None:
    z = np.array(z_axis, float) / np.linalg.norm(z_axis)
    q = quat_wxyz_from_z_axis(z)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    np.testing.assert_allclose(rotation_world_body(q)[:, 2], z, atol=1e-12)


def test_hover_holds_position_against_the_tether() -> None:
    sim = _sim("hover", accel_noise_mps2=0.0, thrust_noise_n=0.0)
    _run(sim, 8.0)
    drone = sim.drones["cf1"]
    np.testing.assert_allclose(drone.position_world_m, (1.2, 0.0, 1.0), atol=2e-3)
    assert np.linalg.norm(drone.tension_world_n) > 0.01


def test_noise_free_sensors_reproduce_the_true_tension() -> None:
    sim = _sim("tug", accel_noise_mps2=0.0, thrust_noise_n=0.0)
    samples = _run(sim, 11.0)  # includes the onset of the 30 mN pull at 10 s
    tel = [json.loads(s.payload) for s in samples if s.key.endswith("/telemetry")]
    truth = [json.loads(s.payload) for s in samples if s.key.endswith("/truth")]
    for t, gt in list(zip(tel, truth, strict=True))[::50]:
        obs = observe_tension(t["accel_mps2"], t["quat_wxyz"], t["thrust_n"], 0.030)
        assert obs.tension_world_n is not None
        np.testing.assert_allclose(obs.tension_world_n, gt["tension_n"], atol=1e-9)


def test_takeoff_from_the_floor_above_the_base() -> None:
    sim = _sim("takeoff_1.3", accel_noise_mps2=0.0, thrust_noise_n=0.0)
    samples = _run(sim, 1.0)
    first = json.loads(next(s.payload for s in samples if s.key.endswith("/telemetry")))
    assert first["armed"] is False and first["thrust_n"] == 0.0
    np.testing.assert_allclose(first["accel_mps2"], (0.0, 0.0, 9.81), atol=1e-9)
    _run(sim, 14.0)
    drone = sim.drones["cf1"]
    assert drone.position_world_m[2] == pytest.approx(1.3, abs=0.01)
    # Straight above a base on the floor: T_v = ω z, no horizontal tension (paper, sec. 4.1).
    assert -drone.tension_world_n[2] == pytest.approx(0.05 * 1.3, rel=0.02)
    assert math.hypot(*drone.tension_world_n[:2]) < 1e-6


def test_coin_bench_horizontal_tension() -> None:
    sim = _sim("coin", accel_noise_mps2=0.0, thrust_noise_n=0.0)
    _run(sim, 10.0)
    drone = sim.drones["cf1"]
    arm = np.array(SCENARIOS["coin"].coin_arm_m)
    r = math.hypot(*(arm - drone.position_world_m)[:2])
    gamma = math.atan((drone.position_world_m[2] - arm[2]) / r)  # eq:exp_gamma
    h_truth = math.cos(gamma) * 0.0041 * 9.81  # eq:exp_HorGroundThruth
    assert math.hypot(*drone.tension_world_n[:2]) == pytest.approx(h_truth, rel=1e-6)


def test_stop_turns_the_motors_off_and_it_falls() -> None:
    sim = _sim("hover")
    _run(sim, 1.0)
    sim._on_command(Sample("tether/cf1/cmd/stop", b'{"stamp_s": 1.0, "reason": "test"}'))
    _run(sim, 2.0)
    drone = sim.drones["cf1"]
    assert not drone.armed and drone.thrust_n == 0.0
    assert drone.position_world_m[2] == pytest.approx(0.0, abs=1e-9)


def test_setpoint_moves_the_target_and_bad_commands_are_ignored() -> None:
    sim = _sim("hover")
    sim._on_command(Sample("tether/cf1/cmd/setpoint", b'{"stamp_s": 0, "position_m": [1,0.2,1]}'))
    sim._on_command(Sample("tether/cf1/cmd/setpoint", b'{"stamp_s": 0, "position_m": [1, 0]}'))
    _run(sim, 6.0)
    np.testing.assert_allclose(sim.drones["cf1"].position_world_m, (1.0, 0.2, 1.0), atol=0.01)


def test_taut_stop_keeps_the_drone_within_reach() -> None:
    drone = DroneSim(
        base_world_m=np.array([0.0, 0.0, 0.754]),
        length_m=1.0,
        weight_n_per_m=0.05,
        floor_z_m=0.0,
        position_world_m=np.array([0.5, 0.0, 1.0]),
        target_world_m=np.array([3.0, 0.0, 1.0]),  # far beyond reach
    )
    for _ in range(2000):
        drone.step(0.004, np.zeros(3))
        assert np.linalg.norm(drone.position_world_m - drone.base_world_m) <= 1.0
        assert np.all(np.isfinite(drone.tension_world_n))
    # It ends up hanging on a nearly straight tether that holds its full tilt thrust.
    assert np.linalg.norm(drone.position_world_m - drone.base_world_m) > 0.98
    assert math.hypot(*drone.tension_world_n[:2]) > 0.15


def test_reel_in_shortens_the_tether() -> None:
    sim = _sim("reel_in")
    samples = _run(sim, 15.0)
    reels = [json.loads(s.payload) for s in samples if s.key.endswith("/reel")]
    assert reels[0]["length_m"] == pytest.approx(1.6)
    assert reels[-1]["length_m"] == pytest.approx(1.3, abs=0.01)


def test_simulator_imports_none_of_the_estimator() -> None:
    """The simulator checks the estimator, so it must not run the estimator's code."""
    import subprocess
    import sys

    code = (
        "import sys, groundstation.sim, groundstation.sim.runner;"
        "bad = [m for m in ('groundstation.tension', 'groundstation.localization',"
        " 'groundstation.pipeline', 'groundstation.follow') if m in sys.modules];"
        "print(','.join(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"the simulator imports {out.stdout.strip()}"


def test_takeoff_ramp_spools_up_on_the_floor_then_climbs() -> None:
    """Thrust ramps 0 → weight over 2 s while the drone still sits on the floor."""
    sim = _sim("takeoff_ramp", accel_noise_mps2=0.0, thrust_noise_n=0.0)
    sc = SCENARIOS["takeoff_ramp"]
    weight_n = 0.030 * 9.81
    ramp: list[tuple[float, float]] = []
    for _ in range(round(15.0 / sim.dt_s)):
        samples = sim.step()
        tel = json.loads(next(s.payload for s in samples if s.key.endswith("/telemetry")))
        truth = json.loads(next(s.payload for s in samples if s.key.endswith("/truth")))
        t = tel["stamp_s"]
        if sc.arm_at_s + 0.05 <= t < sc.arm_at_s + sc.thrust_ramp_s - 0.05:
            assert tel["armed"] and truth["on_ground"], t
            assert truth["position_m"][2] == pytest.approx(0.0, abs=1e-9)
            np.testing.assert_allclose(tel["accel_mps2"], (0.0, 0.0, 9.81), atol=1e-9)
            ramp.append((t - sc.arm_at_s, tel["thrust_n"]))
    assert len(ramp) > 400
    t_ramp = np.array([r[0] for r in ramp])
    thrust = np.array([r[1] for r in ramp])
    # Linear in time from 0 to the weight over thrust_ramp_s.
    np.testing.assert_allclose(thrust, weight_n * t_ramp / sc.thrust_ramp_s, atol=2e-3)
    assert thrust.max() < weight_n
    drone = sim.drones["cf1"]
    np.testing.assert_allclose(drone.position_world_m, (1.0, 0.0, 1.0), atol=0.01)


@pytest.mark.parametrize("profile", ["ideal", "realistic"])
@pytest.mark.parametrize("scenario", ["takeoff_ramp", "tug"])
def test_every_message_the_simulator_publishes_parses_with_the_contracts_models(
    profile: str, scenario: str
) -> None:
    """The simulator writes its payloads as dicts (speed), so the contract's models check
    them here: one definition of each payload (groundstation/messages.py)."""
    from groundstation.messages import Reel, Telemetry, Truth

    sim = Simulator(
        settings_for(profile=profile, mocap=True, exit_angles=True),
        _Bus(),  # type: ignore[arg-type]
        scenario=scenario,
    )
    counts = {"telemetry": 0, "reel": 0, "truth": 0}
    for sample in _run(sim, 3.0):
        kind = sample.key.rsplit("/", 1)[1]
        if kind == "telemetry":
            Telemetry.parse(sample.payload)
        elif kind == "reel":
            Reel.parse(sample.payload)
        elif kind == "truth":
            Truth.read(sample.payload)
        else:
            continue
        counts[kind] += 1
    assert min(counts.values()) > 0, counts


def test_untethered_hover_has_no_tether_force_and_publishes_no_reel() -> None:
    sim = _sim("hover", untethered=True, accel_noise_mps2=0.0, thrust_noise_n=0.0)
    samples = _run(sim, 6.0)
    assert {s.key for s in samples} == {"tether/cf1/telemetry", "tether/cf1/truth"}
    truth = [json.loads(s.payload) for s in samples if s.key.endswith("/truth")]
    assert all(t["tension_n"] == [0.0, 0.0, 0.0] and t["length_m"] == 0.0 for t in truth)
    assert not any(t["taut"] or t["floor_contact"] for t in truth)
    drone = sim.drones["cf1"]
    np.testing.assert_allclose(drone.position_world_m, (1.2, 0.0, 1.0), atol=2e-3)
    # Nothing but the thrust holds the drone up: it carries the weight alone, level.
    tel = json.loads([s for s in samples if s.key.endswith("/telemetry")][-1].payload)
    assert tel["thrust_n"] == pytest.approx(drone.mass_kg * 9.81, rel=1e-3)
    np.testing.assert_allclose(tel["accel_mps2"], (0.0, 0.0, 9.81), atol=1e-3)
    # The same scenario on its tether leans on it (the tether is not switched off there).
    tethered = _sim("hover", accel_noise_mps2=0.0, thrust_noise_n=0.0)
    _run(tethered, 1.0)
    assert np.linalg.norm(tethered.drones["cf1"].tension_world_n) > 0.01


def test_untethered_flies_past_the_tether_s_reach() -> None:
    """No taut stop: a setpoint beyond the tether's length is reached."""
    sim = _sim("hover", untethered=True)
    far = (2.5, 0.0, 1.0)  # 2.5 m from a base with 1.6 m of tether
    sim.handle_command(
        Sample("tether/cf1/cmd/setpoint", json.dumps({"stamp_s": 0.0, "position_m": far}).encode())
    )
    _run(sim, 8.0)
    np.testing.assert_allclose(sim.drones["cf1"].position_world_m, far, atol=0.02)


def test_the_coin_bench_has_no_untethered_flight() -> None:
    from groundstation.config import ConfigError

    with pytest.raises(ConfigError, match="coin"):
        _sim("coin", untethered=True)


def test_the_calibration_scenario_rests_disarmed_on_the_floor_then_tours_the_spots() -> None:
    sim = _sim("calibration", untethered=True)
    sc = SCENARIOS["calibration"]
    samples = _run(sim, sc.duration_s or 0.0)
    truth = [json.loads(s.payload) for s in samples if s.key.endswith("/truth")]
    rest = [t for t in truth if t["stamp_s"] < sc.arm_at_s]
    assert len(rest) > 2.5 * sim.settings.sim.rate_hz  # ≥ 2.5 s still, disarmed, on the floor
    assert all(not t["armed"] and t["on_ground"] for t in rest)
    assert all(t["velocity_mps"] == [0.0, 0.0, 0.0] for t in rest)
    assert truth[-1]["armed"] and not truth[-1]["on_ground"]
    np.testing.assert_allclose(truth[-1]["position_m"], (0.9, 0.6, 1.0), atol=0.05)
    # Hovers at each spot and legs in between: some of the flight moves at ≥ 0.3 m/s.
    speed_h = [math.hypot(*t["velocity_mps"][:2]) for t in truth]
    assert float(np.percentile(speed_h, 90)) >= 0.3


def test_sim_once_stops_at_the_scenarios_end(capsys: pytest.CaptureFixture[str]) -> None:
    """``sim --once`` flies the scenario's natural length and returns (the calibration
    rehearsal ends by itself); a scenario without an end is refused before the bus opens."""
    import socket

    from groundstation.cli import main

    assert main(["sim", "--scenario", "hover", "--once"]) == 2
    assert "'hover' runs until stopped" in capsys.readouterr().err
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    argv = ["sim", "--scenario", "takeoff_ramp", "--once", "--speed", "20", "--mode", "peer"]
    # 16 simulated seconds at 20x: it returns by itself (without --once it runs until stopped).
    assert main([*argv, "--listen", f"tcp/127.0.0.1:{port}"]) == 0


def test_demo_once_stops_at_the_scenarios_end(monkeypatch: pytest.MonkeyPatch) -> None:
    """``demo --once`` ends with its scenario (it ran until stopped: the flag set no end of
    the simulated run). The scenario is shortened to 1 s here: the demo runs in real time."""
    import dataclasses
    import os
    import signal
    import socket
    import threading

    from groundstation.cli import main
    from groundstation.sim.scenarios import SCENARIOS

    short = dataclasses.replace(SCENARIOS["takeoff_ramp"], duration_s=1.0)
    monkeypatch.setitem(SCENARIOS, "takeoff_ramp", short)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    argv = ["demo", "--headless", "--once", "--scenario", "takeoff_ramp"]
    # A demo that does not end by itself is stopped by SIGTERM after 30 s (and fails).
    hung = threading.Event()

    def stop_it() -> None:
        hung.set()
        os.kill(os.getpid(), signal.SIGTERM)

    guard = threading.Timer(30.0, stop_it)
    guard.start()
    try:
        assert main([*argv, "--listen", f"tcp/127.0.0.1:{port}"]) == 0
    finally:
        guard.cancel()
    assert not hung.is_set(), "demo --once did not end with its scenario"


def test_sim_untethered_flag_sets_sim_untethered() -> None:
    from groundstation.cli import _load, _sim_overrides, build_parser

    args = build_parser().parse_args(["sim", "--untethered", "--scenario", "calibration"])
    args.sim_overrides = _sim_overrides(args)
    settings = _load(args)
    assert settings.sim.untethered and settings.sim.scenario == "calibration"
    args = build_parser().parse_args(["sim"])
    args.sim_overrides = _sim_overrides(args)
    assert not _load(args).sim.untethered
