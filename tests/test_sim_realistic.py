"""The ``realistic`` simulator profile: its own tether against the catenary, each error class.

The tests may import the estimator's modules (catenary, tension) to check the simulator;
the simulator itself may not (the last test asserts it).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from groundstation import catenary
from groundstation.config import RealisticSection
from groundstation.evaluation import settings_for
from groundstation.sim import SCENARIOS, Simulator
from groundstation.sim.drone import AirframeParams, RigidDrone
from groundstation.sim.realistic import RealisticDrone
from groundstation.sim.rotation import rot_x, rot_y
from groundstation.sim.tether import LumpedTether, TetherParams
from groundstation.tension import rotation_world_body

BASE = np.array([0.0, 0.0, 0.754])
L_M = 1.6
OMEGA = 0.05
MASS = 0.030
CLASSES = (
    "vibration",
    "misalignment",
    "accel_scale",
    "accel_bias",
    "thrust_axis",
    "thrust_map",
    "battery",
    "motor_lag",
    "rotor_drag",
    "yaw_motion",
    "imu_timing",
    "mocap_timing",
)


class _Bus:
    def publish(self, key: str, payload: bytes) -> None:
        pass


def _only(*on: str, **sizes: Any) -> RealisticSection:
    """``[sim.realistic]`` with every error class off except ``on``."""
    flags = {name: name in on for name in CLASSES}
    return RealisticSection(**flags, **sizes)


def _drone(
    cfg: RealisticSection, start: tuple[float, float, float] = (1.2, 0.0, 1.0), seed: int = 1
) -> RealisticDrone:
    return RealisticDrone(
        cfg,
        base_world_m=BASE,
        start_world_m=np.array(start),
        length_m=L_M,
        weight_n_per_m=OMEGA,
        floor_z_m=0.0,
        mass_kg=MASS,
        seed=seed,
    )


def _fly(drone: RealisticDrone, seconds: float) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for _ in range(round(seconds / 0.004)):
        out.extend(drone.step(0.004, np.zeros(3)))
    return out


def _arrays(items: list[dict[str, Any]], part: str, key: str) -> np.ndarray:
    return np.array([it[part][key] for it in items], dtype=float)


# ---------------------------------------------------------------------- the tether


def _near_taut(ratio: float, elevation_rad: float = 0.1) -> tuple[float, float, float]:
    d = ratio * L_M
    return (d * math.cos(elevation_rad), 0.0, 0.754 + d * math.sin(elevation_rad))


@pytest.mark.parametrize(
    "drone_m",
    [
        (1.2, 0.0, 1.0),  # the paper's first spot
        (1.0, -0.3, 0.5),  # below the base
        _near_taut(0.95),
        _near_taut(0.97),  # the near-taut case
        (0.9, 0.0, 0.3),  # touchdown with a straight run on the floor
        (0.0, 0.0, 1.2),  # straight above the base: it hangs plumb
    ],
)
def test_lumped_tether_at_rest_agrees_with_the_catenary(
    drone_m: tuple[float, float, float],
) -> None:
    """Within 1 % of L in shape and 5 % in end force of catenary.solve's tether."""
    drone = np.array(drone_m)
    tether = LumpedTether(TetherParams(weight_n_per_m=OMEGA), BASE, drone, L_M, 0.0)
    tether.settle(5.0, extra_damping_per_s=3.0)
    tether.settle(5.0)  # undamped by the settling aid: it stays at rest
    ref = catenary.tether_force(BASE, drone, L_M, OMEGA, 0.0)
    curve = catenary.tether_points(BASE, drone, L_M, 0.0, n=4001)
    dist = np.min(np.linalg.norm(tether.x_world_m[:, None, :] - curve[None, :, :], axis=2), axis=1)
    assert dist.max() < 0.01 * L_M, f"shape off by {dist.max():.4f} m"
    force_ref = np.asarray(ref.force_world_n)
    err = np.linalg.norm(tether.force_on_drone_world_n - force_ref)
    assert err < 0.05 * np.linalg.norm(force_ref), (tether.force_on_drone_world_n, force_ref)
    assert tether.floor_contact == ref.floor_contact
    if drone_m == (1.2, 0.0, 1.0):
        # the free catenary itself, from solve (2D, in the plane of base and drone)
        r = math.hypot(drone[0], drone[1])
        cat = catenary.solve(0.0, BASE[2], r, drone[2], L_M)
        r_nodes = np.hypot(tether.x_world_m[:, 0], tether.x_world_m[:, 1])
        z_cat = np.asarray(cat.y(r_nodes))
        assert np.max(np.abs(z_cat - tether.x_world_m[:, 2])) < 0.01 * L_M


def test_lumped_tether_swings_and_settles() -> None:
    tether = LumpedTether(TetherParams(), BASE, np.array([1.2, 0.0, 1.0]), L_M, 0.0)
    tether.settle(5.0, extra_damping_per_s=3.0)
    e_rest = tether.energy_j()
    tether.v_world_mps[1:-1, 1] = 0.4 * np.sin(np.linspace(0, np.pi, 11))[1:-1]  # a sideways kick
    e_kick = tether.energy_j()
    mid_y, energy = [], []
    for _ in range(300):  # 30 s
        tether.settle(0.1)
        mid_y.append(float(tether.x_world_m[5, 1]))
        energy.append(tether.energy_j() - e_rest)
    crossings = np.count_nonzero(np.diff(np.sign(mid_y)) != 0)
    assert crossings >= 6, "it should swing back and forth"
    excess = np.array(energy)
    # energy decays: each 5 s window holds less than the one before, and little is left
    windows = excess.reshape(6, 50).max(axis=1)
    assert np.all(np.diff(windows) < 0.0), windows
    assert windows[-1] < 0.05 * (e_kick - e_rest)


# ---------------------------------------------------------------------- noise and timing


@pytest.mark.parametrize(("sigma", "lag1"), [(1.0, 0.2), (0.5, 0.3)])
def test_vibration_noise_has_the_configured_std_and_autocorrelation(
    sigma: float, lag1: float
) -> None:
    drone = _drone(_only("vibration", accel_noise_mps2=sigma, accel_noise_lag1=lag1))
    items = _fly(drone, 20.0)
    residual = _arrays(items, "telemetry", "accel_mps2") - _arrays(
        items, "truth", "specific_force_body_mps2"
    )
    assert len(items) > 1900
    std = residual.std(axis=0)
    np.testing.assert_allclose(std, sigma, rtol=0.06)
    r = residual - residual.mean(axis=0)
    rho = (r[1:] * r[:-1]).sum(axis=0) / (r * r).sum(axis=0)
    np.testing.assert_allclose(rho, lag1, atol=0.06)


def test_without_vibration_only_the_sensor_floor_remains() -> None:
    items = _fly(_drone(_only()), 5.0)
    residual = _arrays(items, "telemetry", "accel_mps2") - _arrays(
        items, "truth", "specific_force_body_mps2"
    )
    np.testing.assert_allclose(residual.std(axis=0), 0.02, rtol=0.15)


def test_imu_stamps_jitter_between_6_and_27_ms_or_tick_at_100_hz() -> None:
    stamps = _arrays(_fly(_drone(_only("imu_timing")), 15.0), "telemetry", "stamp_s")
    spacing = np.diff(stamps)
    assert spacing.min() >= 0.006 - 1e-9 and spacing.max() <= 0.027 + 1e-9
    assert spacing.min() <= 0.0075 and spacing.max() >= 0.018  # the jitter is there
    assert 85.0 < 1.0 / spacing.mean() < 100.0
    exact = np.diff(_arrays(_fly(_drone(_only()), 2.0), "telemetry", "stamp_s"))
    np.testing.assert_allclose(exact, 0.010, atol=1e-9)


def test_motion_capture_bursts_gaps_and_latency() -> None:
    drone = _drone(_only("mocap_timing"))
    items = _fly(drone, 30.0)
    arrivals = np.array(drone.mocap.arrivals_s)
    gaps = np.diff(arrivals)
    burst = np.mean(gaps < 0.001)
    assert 0.14 <= burst <= 0.21, burst  # real flights: 15–20 % of samples < 1 ms apart
    assert gaps.max() <= 0.150 + 0.0015
    assert gaps.max() > 0.05  # outages happen
    rate = len(arrivals) / 30.0
    assert 60.0 <= rate <= 116.0
    # the attached position is older than the sample: at least the latency
    assert "position_m" not in items[0]["telemetry"]  # nothing has arrived at t = 0
    items = [it for it in items if "position_m" in it["telemetry"]]
    pos = _arrays(items, "telemetry", "position_m")
    truth = _arrays(items, "truth", "position_m")
    t = _arrays(items, "telemetry", "stamp_s")
    vel = np.gradient(truth[:, 0], t)
    moving = np.abs(vel) > 0.002
    if moving.any():
        lag_s = (truth[moving, 0] - pos[moving, 0]) / vel[moving]
        assert np.median(lag_s) >= 0.009
    off = _fly(_drone(_only()), 2.0)
    np.testing.assert_allclose(
        _arrays(off, "telemetry", "position_m"), _arrays(off, "truth", "position_m"), atol=2e-3
    )


def test_mocap_attach_new_publishes_each_frame_once() -> None:
    drone = _drone(_only("mocap_timing", mocap_attach="new"))
    items = _fly(drone, 5.0)
    with_pos = sum(1 for it in items if "position_m" in it["telemetry"])
    assert 0.5 * len(items) < with_pos < len(items)
    assert with_pos <= len(drone.mocap.arrivals_s)


# ---------------------------------------------------------------------- DC errors


@pytest.mark.parametrize("name", ["misalignment", "accel_scale", "accel_bias"])
def test_accelerometer_errors_and_their_equivalent_bias(name: str) -> None:
    drone = _drone(_only(name))
    items = _fly(drone, 2.0)
    accel = _arrays(items, "telemetry", "accel_mps2")
    f_body = _arrays(items, "truth", "specific_force_body_mps2")
    # on: the accelerometer no longer reads the specific force (noise floor: 0.02 m/s²)
    assert np.linalg.norm((accel - f_body).mean(axis=0)) > 0.01
    # accel − (equivalent bias at f) = f, sample by sample
    errors = drone.errors
    corrected = np.array([a - errors.accel_bias_at(f) for a, f in zip(accel, f_body, strict=True)])
    np.testing.assert_allclose(corrected.mean(axis=0), f_body.mean(axis=0), atol=0.003)
    off = _fly(_drone(_only()), 2.0)
    f_off = _arrays(off, "truth", "specific_force_body_mps2")
    res = _arrays(off, "telemetry", "accel_mps2") - f_off
    assert np.linalg.norm(res.mean(axis=0)) < 0.003


def _thrust_direction_body(items: list[dict[str, Any]]) -> np.ndarray:
    """Mean direction of m·f_B − R'·T (the rotor force in B), from the truth."""
    dirs = []
    for it in items:
        R = rotation_world_body(it["telemetry"]["quat_wxyz"])
        rotor = MASS * np.array(it["truth"]["specific_force_body_mps2"]) - R.T @ np.array(
            it["truth"]["tension_n"]
        )
        dirs.append(rotor / np.linalg.norm(rotor))
    d = np.mean(dirs, axis=0)
    return np.asarray(d / np.linalg.norm(d))


def test_thrust_axis_offset() -> None:
    drone = _drone(_only("thrust_axis"))
    axis = _thrust_direction_body(_fly(drone, 3.0))
    ax, ay = drone.errors.thrust_axis_rad
    assert (ax, ay) == (-0.037, -0.016)
    np.testing.assert_allclose(axis, rot_x(ax) @ rot_y(ay) @ np.array([0, 0, 1.0]), atol=2e-4)
    off = _thrust_direction_body(_fly(_drone(_only()), 3.0))
    np.testing.assert_allclose(off, (0.0, 0.0, 1.0), atol=2e-4)


def test_thrust_map_reads_off_by_the_drawn_factor() -> None:
    drone = _drone(_only("thrust_map"))
    items = _fly(drone, 3.0)
    ratio = _arrays(items, "telemetry", "thrust_n") / _arrays(items, "truth", "motor_thrust_n")
    e = drone.errors.thrust_report_error
    assert -0.0909 - 0.04 < e < -0.0909 + 0.04  # the default draw: 1.10 too low, ± spread
    np.testing.assert_allclose(ratio, 1.0 + e, rtol=1e-9)
    assert drone.drawn_errors()["calibration"]["thrust_scale"] == pytest.approx(1.0 / (1.0 + e))
    off = _fly(_drone(_only()), 1.0)
    ratio_off = _arrays(off, "telemetry", "thrust_n") / _arrays(off, "truth", "motor_thrust_n")
    np.testing.assert_allclose(ratio_off, 1.0, rtol=1e-9)


def test_battery_sags_and_the_thrust_map_drifts_with_it() -> None:
    drone = _drone(_only("thrust_map", "battery"))
    items = _fly(drone, 10.0)
    vbat = _arrays(items, "telemetry", "vbat_v")
    assert 3.9 < vbat.min() < vbat.max() < 4.1
    assert vbat[-50:].mean() < vbat[:50].mean() - 0.005  # it drains
    ratio = _arrays(items, "telemetry", "thrust_n") / _arrays(items, "truth", "motor_thrust_n")
    expected = [drone.errors.report_factor(v) for v in vbat]
    np.testing.assert_allclose(ratio, expected, rtol=1e-9)
    assert ratio[-50:].mean() > ratio[:50].mean()  # reads higher as the battery sags
    off = _fly(_drone(_only("thrust_map")), 1.0)
    assert all("vbat_v" not in it["telemetry"] for it in off)


def test_motor_voltage_equivalent_is_the_battery_law_at_every_voltage() -> None:
    """The estimator's motor-voltage model (groundstation.tension's, read from the
    configuration as the service reads it) given the simulator's equivalent returns the true
    motor thrust from Telemetry's thrust and battery, to rounding, as the battery sags; the
    straight line (the first-order equivalent) drifts from it as the voltage leaves V_ref."""
    from groundstation.config import CalibrationSection
    from groundstation.estimator.drone import calibration_from_config

    drone = _drone(_only("thrust_map", "battery"))
    items = _fly(drone, 10.0)
    thrust = _arrays(items, "telemetry", "thrust_n")
    vbat = _arrays(items, "telemetry", "vbat_v")
    truth = _arrays(items, "truth", "motor_thrust_n")
    motor = drone.errors.airframe_equivalent(False, "motor_voltage")
    assert motor["thrust_model"] == "motor_voltage"
    cal, _ = calibration_from_config(CalibrationSection(**motor))
    assert cal.motor_model_in_force
    got = np.array([cal.thrust_n(float(t), float(v)) for t, v in zip(thrust, vbat, strict=True)])
    np.testing.assert_allclose(got, truth, rtol=1e-9)
    # Far below V_ref the line and the law part: F ∝ (V/V_ref)² against its tangent.
    line = drone.errors.airframe_equivalent(False)
    lin, _ = calibration_from_config(CalibrationSection(**line))
    v_low = 3.3
    f_law = cal.thrust_n(0.3, v_low)
    assert f_law == pytest.approx(
        0.3 * (v_low / 4.05) ** 2 / (1 + drone.errors.thrust_report_error)
    )
    assert abs(lin.thrust_n(0.3, v_low) - f_law) > 1e-3  # over 1 mN of 0.3 N
    with pytest.raises(ValueError, match="exponent of 2"):
        _drone(_only("thrust_map", "battery", thrust_vbat_exponent=1.5)).errors.airframe_equivalent(
            False, "motor_voltage"
        )


def test_motor_lag_delays_the_thrust_by_its_time_constant() -> None:
    def step_response(tau_s: float) -> float:
        body = RigidDrone(
            AirframeParams(motor_tau_s=tau_s, rotor_drag_n_s_per_m=0.0),
            np.array([0.0, 0.0, 1.0]),
            floor_z_m=-10.0,
        )
        body.preload_integral(np.zeros(3))
        for _ in range(200):
            body.step(0.001, np.zeros(3))
        body.target_world_m = np.array([0.0, 0.0, 1.3])
        body.step(0.001, np.zeros(3))
        c0, f0 = body.command_thrust_n, body.thrust_n
        for k in range(1, 200):
            body.step(0.001, np.zeros(3))
            if body.thrust_n - f0 >= 0.632 * (c0 - f0):
                return k * 0.001
        return math.inf

    assert step_response(0.030) == pytest.approx(0.030, abs=0.006)
    body = RigidDrone(AirframeParams(motor_tau_s=0.0), np.array([0.0, 0.0, 1.0]), floor_z_m=-10.0)
    body.target_world_m = np.array([0.0, 0.0, 1.3])
    for _ in range(20):
        body.step(0.001, np.zeros(3))
        assert body.thrust_n == pytest.approx(body.command_thrust_n, abs=1e-12)


def test_rotor_drag_opposes_horizontal_body_velocity() -> None:
    def rotor_residual(on: bool) -> tuple[float, float]:
        drone = _drone(_only("rotor_drag") if on else _only())
        drone.target_world_m = np.array([0.9, 0.0, 1.0])  # fly 0.3 m toward the base
        items = _fly(drone, 1.5)
        res, vel = [], []
        for it in items:
            R = rotation_world_body(it["telemetry"]["quat_wxyz"])
            f = np.array(it["truth"]["specific_force_body_mps2"])
            rotor = MASS * f - R.T @ np.array(it["truth"]["tension_n"])
            res.append(rotor[0] / rotor[2])  # body x force per unit thrust
            vel.append((R.T @ np.array(it["truth"]["velocity_mps"]))[0])
        v, r = np.array(vel), np.array(res)
        slope = float(np.polyfit(v, r, 1)[0])
        return slope, float(np.abs(v).max())

    slope_on, vmax = rotor_residual(True)
    slope_off, _ = rotor_residual(False)
    assert vmax > 0.1
    # per unit thrust: −D/W, W the weight (drag ∝ thrust)
    assert slope_on == pytest.approx(-0.0073 / (MASS * 9.81), rel=0.1)
    # off: what is left is the attitude's change within a step (R at its start vs its end)
    assert abs(slope_off) < 0.02 * abs(slope_on)


def test_yaw_motion() -> None:
    def yaw_range(cfg: RealisticSection) -> tuple[float, float]:
        q = _arrays(_fly(_drone(cfg), 4.0), "telemetry", "quat_wxyz")
        R = [rotation_world_body(qq) for qq in q]
        yaw = np.unwrap([math.atan2(r[1, 0], r[0, 0]) for r in R])
        return float(yaw.max() - yaw.min()), float(abs(yaw[0]))

    span, _ = yaw_range(_only("yaw_motion", yaw_period_s=4.0))
    assert span == pytest.approx(0.6, abs=0.1)
    span_off, yaw0_off = yaw_range(_only(yaw_period_s=4.0))
    assert span_off < 0.01 and yaw0_off < 0.01


# ---------------------------------------------------------------------- calibration = truth


def _observed_tension(tel: dict[str, Any], cal: dict[str, Any] | None) -> np.ndarray:
    """The estimator's calibration model (config.CalibrationSection), written here anew."""
    R = rotation_world_body(tel["quat_wxyz"])
    accel = np.array(tel["accel_mps2"])
    thrust = tel["thrust_n"]
    axis = np.array([0.0, 0.0, 1.0])
    if cal is not None:
        accel = accel - np.array(cal["accel_bias_mps2"])
        scale = cal["thrust_scale"] + cal["thrust_vbat_slope_per_v"] * (
            tel["vbat_v"] - cal["thrust_vbat_ref_v"]
        )
        thrust = thrust * scale
        ax, ay = cal["thrust_axis_rad"]
        axis = rot_x(ax) @ rot_y(ay) @ axis
    # eq:NE_tether: T = R (m f − F n_B)
    return np.asarray(R @ (MASS * accel - thrust * axis))


def test_equivalent_calibration_makes_the_tension_observation_exact_at_hover() -> None:
    dc = ("misalignment", "accel_scale", "accel_bias", "thrust_axis", "thrust_map", "battery")
    drone = _drone(_only(*dc, "motor_lag", "yaw_motion", "imu_timing"))
    items = _fly(drone, 5.0)
    cal = drone.drawn_errors()["calibration"]
    truth = _arrays(items, "truth", "tension_n")
    calibrated = np.array([_observed_tension(it["telemetry"], cal) for it in items])
    raw = np.array([_observed_tension(it["telemetry"], None) for it in items])
    err_cal = np.linalg.norm(calibrated - truth, axis=1)
    err_raw = np.linalg.norm(raw - truth, axis=1)
    assert np.median(err_cal) < 0.001  # 1 mN (noise floor 0.02 m/s² ≈ 0.6 mN)
    assert np.median(err_raw) > 0.01  # uncalibrated: tens of mN


# ---------------------------------------------------------------------- the simulator


def _realistic_sim(scenario: str, **sim: Any) -> Simulator:
    return Simulator(settings_for(profile="realistic", **sim), _Bus(), scenario=scenario)  # type: ignore[arg-type]


def _payloads(sim: Simulator, seconds: float) -> list[tuple[str, bytes]]:
    out: list[tuple[str, bytes]] = []
    for _ in range(round(seconds / sim.dt_s)):
        out.extend((s.key, s.payload) for s in sim.step())
    return out


def test_same_seed_same_flight_and_another_seed_another() -> None:
    a = _payloads(_realistic_sim("hover", seed=7), 2.0)
    b = _payloads(_realistic_sim("hover", seed=7), 2.0)
    c = _payloads(_realistic_sim("hover", seed=8), 2.0)
    assert a == b
    assert a != c
    assert len({k for k, _ in a}) == 3  # telemetry, truth, reel


def test_truth_carries_the_profile_and_the_drawn_errors() -> None:
    sim = _realistic_sim("hover")
    truths = [json.loads(p) for k, p in _payloads(sim, 2.1) if k.endswith("/truth")]
    assert all(t["profile"] == "realistic" for t in truths)
    with_errors = [t for t in truths if "errors" in t]
    assert len(with_errors) == 3  # at 0, 1 and 2 s
    assert with_errors[0]["errors"] == json.loads(json.dumps(sim.drawn_errors("cf1")))
    cal = with_errors[0]["errors"]["calibration"]
    assert set(cal) >= {"thrust_scale", "thrust_axis_rad", "accel_bias_mps2"}
    ideal = Simulator(settings_for(), _Bus(), scenario="hover")  # type: ignore[arg-type]
    assert ideal.drawn_errors("cf1") is None
    first = json.loads(next(s.payload for s in ideal.step() if s.key.endswith("/truth")))
    assert "errors" not in first and "profile" not in first


def test_realistic_takeoff_ramp_stays_on_the_floor_then_climbs() -> None:
    sim = _realistic_sim("takeoff_ramp")
    sc = SCENARIOS["takeoff_ramp"]
    on_floor = []
    for _ in range(round(14.0 / sim.dt_s)):
        for s in sim.step():
            if s.key.endswith("/truth"):
                t = json.loads(s.payload)
                if sc.arm_at_s + 0.1 < t["stamp_s"] < sc.arm_at_s + sc.thrust_ramp_s - 0.1:
                    on_floor.append(t["on_ground"] and t["position_m"][2] == 0.0)
    assert on_floor and all(on_floor)
    np.testing.assert_allclose(sim.drones["cf1"].position_world_m, (1.0, 0.0, 1.0), atol=0.03)


@pytest.mark.parametrize("name", ["tug", "follow", "reel_in", "coin", "hover_spots"])
def test_realistic_scenarios_fly(name: str) -> None:
    sim = _realistic_sim(name)
    for _ in range(round(6.0 / sim.dt_s)):
        sim.step()
    drone = sim.drones["cf1"]
    assert drone.armed and not drone.on_ground
    assert np.all(np.isfinite(drone.position_world_m))
    assert np.linalg.norm(drone.tension_world_n) < MASS * 9.81


def test_realistic_profile_imports_no_estimator_and_no_catenary() -> None:
    code = (
        "import sys\n"
        "from groundstation.config import load_settings\n"
        "from groundstation.sim import Simulator\n"
        "class B:\n"
        "    def publish(self, k, p): pass\n"
        "s = load_settings(None, {'sim': {'profile': 'realistic'}}, use_env=False)\n"
        "sim = Simulator(s, B(), scenario='hover')\n"
        "for _ in range(50): sim.step()\n"
        "bad = [m for m in ('groundstation.tension', 'groundstation.localization',"
        " 'groundstation.pipeline', 'groundstation.follow', 'groundstation.catenary')"
        " if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"the realistic profile imports {out.stdout.strip()}"


def test_no_mocap_drops_position_on_the_realistic_profile_too() -> None:
    sim = _realistic_sim("hover", mocap=False)
    tel = [json.loads(p) for k, p in _payloads(sim, 1.0) if k.endswith("/telemetry")]
    assert len(tel) > 80 and all("position_m" not in t for t in tel)


def test_the_service_pipeline_runs_in_lock_step_on_the_realistic_profile() -> None:
    """The benchmarks' closed loop: one estimate per jittered Telemetry, truth at its stamp."""
    from groundstation.evaluation import closed_loop

    run, _, _ = closed_loop(settings_for(profile="realistic"), "hover", 3.0)
    assert run.telemetry > 250 and len(run.estimates) == run.telemetry
    for e in run.estimates[::25]:
        truth = run.truth_at(e["stamp_s"])
        assert truth["profile"] == "realistic"
        assert all(math.isfinite(v) for v in e["tension_n"])


def test_sim_realistic_table_from_a_file_and_its_errors(tmp_path: Any) -> None:
    from groundstation.config import ConfigError, load_settings

    cfg = tmp_path / "sim.toml"
    cfg.write_text('[sim]\nprofile = "realistic"\n\n[sim.realistic]\naccel_noise_mps2 = 0.5\n')
    settings = load_settings(cfg, use_env=False)
    assert settings.sim.profile == "realistic"
    assert settings.sim.realistic.accel_noise_mps2 == 0.5
    assert load_settings(None, use_env=False).sim.profile == "ideal"  # today's default
    for body, key in (
        ("accel_noise_lag1 = 0.7", "accel_noise_ar 0.6 must be >= accel_noise_lag1 0.7"),
        ("imu_spacing_max_s = 0.005", "imu_spacing_max_s 0.005 must hold"),
        ("mocap_rate_max_hz = 50.0", "mocap_rate_max_hz 50.0 must be >= mocap_rate_min_hz"),
        ("no_such_key = 1", "sim.realistic.no_such_key"),
    ):
        cfg.write_text(f"[sim.realistic]\n{body}\n")
        with pytest.raises(ConfigError, match=re.escape(key)):
            load_settings(cfg, use_env=False)


def test_truth_calibration_is_a_valid_calibration_table() -> None:
    from groundstation.config import CalibrationSection

    sim = _realistic_sim("hover")
    cal = CalibrationSection(**sim.truth_calibration("cf1"))
    errors = sim.drawn_errors("cf1")
    assert errors is not None
    assert cal.thrust_scale == pytest.approx(errors["calibration"]["thrust_scale"])
    assert cal.thrust_axis_rad == (-0.037, -0.016)
    flat = CalibrationSection(**sim.truth_calibration("cf1", use_vbat=False))
    assert flat.thrust_vbat_slope_per_v == 0.0
    assert flat.thrust_scale == pytest.approx(errors["calibration"]["thrust_scale_hover_start"])
    ideal = Simulator(settings_for(thrust_bias_ratio=0.1), _Bus(), scenario="hover")  # type: ignore[arg-type]
    assert CalibrationSection(**ideal.truth_calibration("cf1")).thrust_scale == pytest.approx(
        1.0 / 1.1
    )


def test_draw_levels_draws_noise_lag1_and_charge_per_flight_within_their_ranges() -> None:
    """``draw_levels``: a seeded per-flight draw in the ranges; the other draws do not move."""
    fixed = RealisticSection()
    drawn = RealisticSection(draw_levels=True)
    levels = []
    for seed in range(8):
        a, b = _drone(fixed, seed=seed), _drone(drawn, seed=seed)
        ea, eb = a.drawn_errors(), b.drawn_errors()
        assert (ea["accel_noise_mps2"], ea["accel_noise_lag1"]) == (1.0, 0.2)
        assert ea["battery_soc_start"] == 1.0
        assert 0.7 <= eb["accel_noise_mps2"] <= 2.0
        assert 0.0 <= eb["accel_noise_lag1"] <= 0.3
        assert 0.6 <= eb["battery_soc_start"] <= 1.0
        # misalignment, scale, bias, thrust map, mocap rate, yaw: the same stream as before
        for key in ("misalignment_rad", "accel_bias_mps2", "thrust_report_error", "yaw0_rad"):
            assert ea[key] == eb[key], key
        assert b.sensors.accel_noise_mps2 == eb["accel_noise_mps2"]
        assert b.battery.soc == eb["battery_soc_start"]
        levels.append(eb["accel_noise_mps2"])
        again = _drone(drawn, seed=seed).drawn_errors()
        assert again["accel_noise_mps2"] == eb["accel_noise_mps2"]  # seeded
    assert len(set(levels)) == 8


def test_draw_ranges_are_checked() -> None:
    with pytest.raises(ValueError, match="accel_noise_lag1_range"):
        RealisticSection(accel_noise_lag1_range=(0.1, 0.7))  # above accel_noise_ar 0.6
    with pytest.raises(ValueError, match="battery_soc_range"):
        RealisticSection(battery_soc_range=(0.9, 0.5))
