"""Tests of groundstation.contact: the ground/air state machine with hysteresis."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from groundstation.contact import (
    ContactParams,
    ContactState,
    contact_step,
    vertical_accel_mps2,
)

MASS_KG = 0.030
G = 9.81
WEIGHT_N = MASS_KG * G
DT_S = 0.004
DEFAULT = ContactParams()


def test_import_does_not_pull_io_libraries() -> None:
    code = (
        "import sys, groundstation.contact\n"
        "bad = [m for m in ('zenoh', 'viser', 'pydantic', 'logging') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def _step(
    state: ContactState,
    params: ContactParams = DEFAULT,
    *,
    thrust_ratio: float,
    armed: bool = True,
    accel_z: float = 0.0,
    height_m: float | None = None,
) -> ContactState:
    return contact_step(
        state,
        params,
        dt_s=DT_S,
        armed=armed,
        thrust_n=thrust_ratio * WEIGHT_N,
        mass_kg=MASS_KG,
        vertical_accel_mps2=accel_z,
        height_m=height_m,
        floor_z_m=0.0,
    )


def test_vertical_accel_level_and_tilted() -> None:
    assert vertical_accel_mps2([0.0, 0.0, G], [1.0, 0.0, 0.0, 0.0]) == pytest.approx(0.0)
    # Body tilted 30 deg about x, the specific force along body z: world z sees cos(30).
    half = math.radians(30.0) / 2
    q = [math.cos(half), math.sin(half), 0.0, 0.0]
    assert vertical_accel_mps2([0.0, 0.0, 10.0], q) == pytest.approx(10.0 * math.cos(2 * half) - G)
    # An unnormalised quaternion is normalised; a zero one gives NaN.
    assert vertical_accel_mps2([0.0, 0.0, G], [2.0, 0.0, 0.0, 0.0]) == pytest.approx(0.0)
    assert math.isnan(vertical_accel_mps2([0.0, 0.0, G], [0.0, 0.0, 0.0, 0.0]))


def test_disarmed_and_the_ratio_are_certain_ground() -> None:
    s = _step(ContactState(on_ground=False), thrust_ratio=1.0, armed=False)
    assert s.on_ground and s.reason == "disarmed"
    s = _step(
        ContactState(on_ground=False), ContactParams(ground_thrust_ratio=0.7), thrust_ratio=0.65
    )
    assert s.on_ground and s.reason == "low_thrust"
    s = _step(ContactState(), ContactParams(ground_thrust_ratio=0.3), thrust_ratio=0.4)
    assert s.on_ground and s.reason == "resting", "above the ratio: still on the floor"


def test_mocap_height_has_hysteresis_about_the_resting_height() -> None:
    # The marker sits 4 cm above the floor at rest.
    s = ContactState()
    for _ in range(300):
        s = _step(s, thrust_ratio=0.0, height_m=0.04)
    assert s.rest_height_m == pytest.approx(0.04)
    expected = [(0.06, True), (0.08, False), (0.06, False), (0.05, True), (0.065, True)]
    for height, ground in expected:
        s = _step(s, thrust_ratio=0.9, height_m=height)
        assert s.on_ground is ground, (height, s)


def _spool_up(
    thrust_of_t: object,
    seconds: float,
    *,
    bias_mps2: float = 0.0,
    thrust_read_ratio: float = 1.0,
    seed: int = 0,
) -> list[tuple[float, float, float, bool]]:
    """A 1-D drone on the floor: rest disarmed 1 s, then the thrust profile (true thrust,
    N, of time since arming). Returns (t, true floor push N, z m, on_ground) per sample;
    IMU noise 0.3 m/s², thrust noise 3 mN, a vertical accelerometer bias, and a thrust
    reading off by ``thrust_read_ratio``."""
    rng = np.random.default_rng(seed)
    state = ContactState()
    z = v = 0.0
    out = []
    for k in range(round(seconds / DT_S)):
        t = k * DT_S
        armed = t >= 1.0
        thrust = float(thrust_of_t(t - 1.0)) if armed else 0.0  # type: ignore[operator]
        net = thrust - WEIGHT_N
        push = max(0.0, -net) if z <= 0.0 else 0.0
        a = (net + push) / MASS_KG
        v += a * DT_S
        z = max(0.0, z + v * DT_S)
        f_z = a + G + bias_mps2 + rng.normal(0.0, 0.3)
        read = thrust * thrust_read_ratio + rng.normal(0.0, 0.003)
        state = contact_step(
            state,
            ContactParams(),
            dt_s=DT_S,
            armed=armed,
            thrust_n=read,
            mass_kg=MASS_KG,
            vertical_accel_mps2=f_z - G,
            height_m=None,
            floor_z_m=0.0,
        )
        out.append((t, push, z, state.on_ground))
    return out


@pytest.mark.parametrize(
    ("bias_mps2", "thrust_read_ratio"), [(0.0, 1.0), (0.2, 1.0), (-0.2, 1.0), (0.0, 0.9)]
)
def test_spool_up_ramp_without_mocap(bias_mps2: float, thrust_read_ratio: float) -> None:
    """2 s ramp to 1.2x the weight: on the ground while the floor carries more than 20 mN of
    what the observation would report; in the air within 0.25 s of leaving the floor."""
    samples = _spool_up(
        lambda t: 1.2 * WEIGHT_N * min(1.0, t / 2.0),
        4.0,
        bias_mps2=bias_mps2,
        thrust_read_ratio=thrust_read_ratio,
    )
    for t, push, z, on_ground in samples:
        if not on_ground and z <= 0.0:
            # What the observation reports (the true push, plus the thrust reading's error).
            reported = push + (1.0 - thrust_read_ratio) * 1.2 * WEIGHT_N * min(1.0, (t - 1) / 2)
            assert reported <= 0.020, (t, push)
    lift_s = next(t for t, _, z, _ in samples if z > 0.0)
    air_s = next(t for t, _, _, g in samples if t > 1.0 and not g)
    assert air_s - lift_s < 0.25, (lift_s, air_s)


@pytest.mark.parametrize("bias_mps2", [0.3, -0.3])
def test_half_weight_on_the_floor_stays_on_the_ground(bias_mps2: float) -> None:
    samples = _spool_up(lambda t: 0.51 * WEIGHT_N, 6.0, bias_mps2=bias_mps2, seed=4)
    assert all(g for _, _, _, g in samples)


def test_hovering_drone_found_in_the_air_at_start() -> None:
    """The service restarts during a hover without motion capture: 40 mN of tether pull."""
    s = ContactState()
    for k in range(40):
        s = _step(s, thrust_ratio=1.0 + 0.04 / WEIGHT_N)
        if k * DT_S >= 0.1 + DT_S:
            assert not s.on_ground and s.reason in ("push_free", "air")
    # In the air without mocap only a certain sign brings it back.
    s = _step(s, thrust_ratio=0.9)
    assert not s.on_ground
    s = _step(s, thrust_ratio=0.3)
    assert s.on_ground and s.reason == "low_thrust"


def test_params_are_checked() -> None:
    with pytest.raises(ValueError, match="ground_thrust_ratio"):
        ContactParams(ground_thrust_ratio=1.0)
    with pytest.raises(ValueError, match="touchdown_height_m"):
        ContactParams(touchdown_height_m=0.05, liftoff_height_m=0.03)
    with pytest.raises(ValueError, match="push_hold_s"):
        ContactParams(push_hold_s=0.0)


def _vibrating(
    thrust_of_t: object,
    seconds: float,
    *,
    noise_mps2: float,
    thrust_read_ratio: float,
    seed: int,
    params: ContactParams = DEFAULT,
) -> list[tuple[float, float, bool, str]]:
    """A 1-D drone at the realistic profile's vibration: rest disarmed 1 s, then the true
    thrust profile (N, of time since arming). IMU samples 8-12 ms apart; accelerometer noise
    ``noise_mps2`` times the thrust ratio, white plus AR(0.6) with lag-1 0.2 (the realistic
    simulator's mix); the thrust read ``thrust_read_ratio`` of the true one. Returns
    (t, z m, on_ground, reason) per sample."""
    rng = np.random.default_rng(seed)
    state = ContactState()
    z = v = t = 0.0
    coloured = np.zeros(1)
    beta = 0.2 / 0.6
    out = []
    while t < seconds:
        dt = float(rng.uniform(0.008, 0.012))
        t += dt
        armed = t >= 1.0
        thrust = float(thrust_of_t(t - 1.0)) if armed else 0.0  # type: ignore[operator]
        net = thrust - WEIGHT_N
        a = net / MASS_KG if (z > 0.0 or net > 0.0) else 0.0
        v = v + a * dt if (z > 0.0 or net > 0.0) else 0.0
        z = max(0.0, z + v * dt)
        coloured = 0.6 * coloured + math.sqrt(1.0 - 0.36) * rng.normal(size=1)
        sigma = noise_mps2 * min(1.0, thrust / WEIGHT_N)
        noise = sigma * (math.sqrt(beta) * coloured[0] + math.sqrt(1.0 - beta) * rng.normal())
        state = contact_step(
            state,
            params,
            dt_s=dt,
            armed=armed,
            thrust_n=thrust * thrust_read_ratio,
            mass_kg=MASS_KG,
            vertical_accel_mps2=a + noise,
            height_m=None,
            floor_z_m=0.0,
        )
        out.append((t, z, state.on_ground, state.reason))
    return out


def _ramp_then_hover(t: float) -> float:
    return WEIGHT_N * min(1.0, t / 2.0)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_vibration_at_hover_thrust_on_the_floor_is_no_climb(seed: int) -> None:
    """Issue 11: 60 s on the floor at hover thrust with 2 m/s^2 of vibration and a thrust
    map reading 15 % low (the floor's load reads 44 mN: only a climb could lift the drone).
    The climb is judged against the vibration learnt on the floor: no lift-off. With the
    fixed 0.1 m/s of before (about one standard deviation of the leaky speed) it fired."""
    samples = _vibrating(_ramp_then_hover, 60.0, noise_mps2=2.0, thrust_read_ratio=0.85, seed=seed)
    assert all(z == 0.0 for _, z, _, _ in samples), "the premise: it never leaves the floor"
    assert all(g for _, _, g, _ in samples)
    fixed = replace(DEFAULT, climb_sigmas=0.0, speed_time_constant_s=0.5)
    before = _vibrating(
        _ramp_then_hover, 60.0, noise_mps2=2.0, thrust_read_ratio=0.85, seed=seed, params=fixed
    )
    assert not all(g for _, _, g, _ in before), "the old fixed bound lifts it on noise"


@pytest.mark.parametrize(
    ("thrust_read_ratio", "noise_mps2", "seen_by_m"),
    [(1.0, 2.0, 0.0), (0.85, 2.0, 0.05), (0.75, 1.0, 0.05), (0.75, 2.0, 1.0)],
)
def test_take_off_under_vibration_is_seen(
    thrust_read_ratio: float, noise_mps2: float, seen_by_m: float
) -> None:
    """3 s on the floor at hover thrust, then a climb at 0.25 g. Never in the air on the
    floor while the floor's load (as read) is above ``push_free_n``; the take-off is seen:
    calibrated at hover thrust (the floor carries nothing), with the thrust reading 15 %
    low by the thrust surge by 5 cm up; 25 % low (no surge shows) by the climb alone, by
    5 cm up at 1 m/s^2 of vibration, later at 2 m/s^2 (the climb must stand out of a
    leaky speed whose noise is ~0.12 m/s: some 0.3-0.6 s, 10-50 cm)."""

    def thrust(t: float) -> float:
        return WEIGHT_N * (min(1.0, t / 2.0) if t < 5.0 else 1.25)

    samples = _vibrating(
        thrust, 7.0, noise_mps2=noise_mps2, thrust_read_ratio=thrust_read_ratio, seed=7
    )
    for t, z, on_ground, _ in samples:
        if z == 0.0 and not on_ground:
            load = WEIGHT_N - thrust(t - 1.0) * thrust_read_ratio
            assert load < DEFAULT.push_free_n, (t, load)
    seen = next((t, z, r) for t, z, g, r in samples if t > 1.0 and not g)
    assert seen[1] <= seen_by_m, seen
    if thrust_read_ratio < 1.0:
        assert seen[1] > 0.0, seen
    if thrust_read_ratio == 0.75:
        assert seen[2] == "climbing"


def test_floor_load_rule_ignores_the_vibration() -> None:
    """0.9 of the weight on the floor (the floor carries 29 mN), calibrated, 2 m/s^2 of
    vibration for 20 s: the load is read from the thrust, so no noise lets it through."""
    samples = _vibrating(
        lambda t: 0.9 * WEIGHT_N * min(1.0, t / 2.0),
        20.0,
        noise_mps2=2.0,
        thrust_read_ratio=1.0,
        seed=5,
    )
    assert all(g for _, _, g, _ in samples)
