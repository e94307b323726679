"""Tests of groundstation.contact: the ground/air state machine with hysteresis."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from groundstation.bias_kalman import BiasKalmanParams
from groundstation.contact import (
    ContactParams,
    ContactState,
    contact_step,
    vertical_accel_mps2,
)
from groundstation.tension import TensionFilter, TensionFilterParams
from groundstation.tension_change import exceedance_sigmas

MASS_KG = 0.030
G = 9.81
WEIGHT_N = MASS_KG * G
DT_S = 0.004
DEFAULT = ContactParams()
BIAS_STEP_STD_MPS2 = BiasKalmanParams().flight_bias_std_mps2  # σ_δ's default, as served
HEIGHT_STD_M = BiasKalmanParams().mocap_std_m  # σ_p's default, as served
# The per-sample tests' threshold at this spacing and the one false-alarm rate (5.6).
SAMPLE_SIGMAS = exceedance_sigmas(TensionFilterParams().false_alarms_per_h, DT_S)


def test_import_does_not_pull_io_libraries() -> None:
    code = (
        "import sys, groundstation.contact\n"
        "bad = [m for m in ('zenoh', 'viser', 'pydantic', 'logging') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


class _Vibration:
    """The floor's vibration as the pipeline hands it to ``contact_step``: the tension
    filter's measure (``TensionFilter.learn_noise`` on the observation's vertical axis,
    ``m (a + g) - F``, while on the ground, armed, at or above the thrust ratio), read on
    the ground (``vertical_noise_var_n2`` over the mass squared)."""

    def __init__(self) -> None:
        self.filt = TensionFilter(TensionFilterParams(mass_kg=MASS_KG))

    def var(self, state: ContactState) -> float | None:
        v = self.filt.vertical_noise_var_n2() if state.on_ground else None
        return None if v is None else v / (MASS_KG * MASS_KG)

    def sigmas(self, dt_s: float) -> float:
        """The climb test's standard deviations at the sample spacing (the one
        false-alarm rate; ``TensionFilter.sigmas_at``)."""
        return self.filt.sigmas_at(dt_s)

    def learn(
        self, state: ContactState, *, armed: bool, thrust_n: float, accel_z: float, dt_s: float
    ) -> None:
        ratio = DEFAULT.ground_thrust_ratio
        if state.on_ground and armed and thrust_n >= ratio * WEIGHT_N and math.isfinite(accel_z):
            # The filter pools the noise's shape over the three axes: this 1-D drone's
            # vertical observation stands for each (a real drone's vibrates on all three).
            y = MASS_KG * (accel_z + G) - thrust_n
            self.filt.learn_noise((y, y, y), dt_s)


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
        sample_sigmas=SAMPLE_SIGMAS,
        bias_step_std_mps2=BIAS_STEP_STD_MPS2,
        height_std_m=HEIGHT_STD_M,
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


def _hold(state: ContactState, seconds: float, **kw: object) -> ContactState:
    for _ in range(round(seconds / DT_S)):
        state = _step(state, **kw)  # type: ignore[arg-type]
    return state


def test_disarmed_is_ground_and_low_thrust_is_ground_only_when_seen_at_rest() -> None:
    s = _step(ContactState(on_ground=False), thrust_ratio=1.0, armed=False)
    assert s.on_ground and s.reason == "disarmed"
    params = ContactParams(ground_thrust_ratio=0.7)
    # Below the ratio with the floor holding the drone still (vertical acceleration 0):
    # the ground once that has lasted rest_hold_s, not before.
    s = _step(ContactState(on_ground=False), params, thrust_ratio=0.65)
    assert not s.on_ground, "one low-thrust sample is no evidence"
    s = _hold(
        ContactState(on_ground=False),
        DEFAULT.rest_hold_s + 2 * DT_S,
        params=params,
        thrust_ratio=0.65,
    )
    assert s.on_ground and s.reason == "low_thrust"
    s = _step(ContactState(), ContactParams(ground_thrust_ratio=0.3), thrust_ratio=0.4)
    assert s.on_ground and s.reason == "resting", "above the ratio: still on the floor"


def test_mocap_height_band_is_the_noise_at_the_one_false_alarm_rate() -> None:
    """The marker sits 4 cm above the floor at rest; lift-off once the height stands out of
    σ_p by the per-sample threshold of the one false-alarm rate (5.6 σ_p at 250 Hz: 1.1 cm
    at 2 mm), touch-down within that band again; the band follows σ_p."""
    s = ContactState()
    for _ in range(300):
        s = _step(s, thrust_ratio=0.0, height_m=0.04)
    assert s.rest_height_m == pytest.approx(0.04)
    band_m = SAMPLE_SIGMAS * HEIGHT_STD_M
    assert 0.010 < band_m < 0.012
    expected = [
        (0.04 + 0.9 * band_m, True),
        (0.04 + 1.1 * band_m, False),
        (0.04 + 2.0 * band_m, False),
        (0.04 + 0.9 * band_m, True),
        (0.04 - 0.9 * band_m, True),
    ]
    for height, ground in expected:
        s = _step(s, thrust_ratio=0.9, height_m=height)
        assert s.on_ground is ground, (height, s)
    # A noisier motion capture widens the band: 2 cm up is still the floor at σ_p = 5 mm.
    wide = contact_step(
        s, DEFAULT, dt_s=DT_S, armed=True, thrust_n=0.9 * WEIGHT_N, mass_kg=MASS_KG,
        vertical_accel_mps2=0.0, height_m=0.06, floor_z_m=0.0, sample_sigmas=SAMPLE_SIGMAS,
        bias_step_std_mps2=BIAS_STEP_STD_MPS2, height_std_m=0.005,
    )  # fmt: skip
    assert wide.on_ground
    # No spacing yet (an infinite threshold): the height decides nothing, the state holds.
    for before in (s, replace(s, on_ground=False, reason="air")):
        held = contact_step(
            before, DEFAULT, dt_s=DT_S, armed=True, thrust_n=0.9 * WEIGHT_N,
            mass_kg=MASS_KG, vertical_accel_mps2=0.0, height_m=0.3, floor_z_m=0.0,
            sample_sigmas=math.inf, bias_step_std_mps2=BIAS_STEP_STD_MPS2,
            height_std_m=HEIGHT_STD_M,
        )  # fmt: skip
        assert held.on_ground is before.on_ground


def test_a_resting_marker_stays_on_the_floor_through_its_noise() -> None:
    """Two minutes of a resting marker with Gaussian noise σ_p at 250 Hz, armed at 0.9 of
    the weight (the height alone decides): at the one false-alarm rate (0.005 per hour) the
    expected number of samples out of the band is 2e-4, so none."""
    rng = np.random.default_rng(7)
    s = ContactState()
    for _ in range(300):
        s = _step(s, thrust_ratio=0.0, height_m=0.04)
    heights = 0.04 + rng.normal(0.0, HEIGHT_STD_M, int(120.0 / DT_S))
    lifted = 0
    for h in heights.tolist():
        s = _step(s, thrust_ratio=0.9, height_m=h)
        lifted += not s.on_ground
    assert lifted == 0
    # The same marker with a noise 3x the configured σ_p does leave it: the band is σ_p's.
    noisy = 0
    for h in (0.04 + rng.normal(0.0, 3 * HEIGHT_STD_M, 5000)).tolist():
        noisy += not _step(s, thrust_ratio=0.9, height_m=h).on_ground
    assert noisy > 0


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
    vib = _Vibration()
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
            vertical_noise_var_mps4=vib.var(state),
            sample_sigmas=vib.sigmas(DT_S),
            bias_step_std_mps2=BIAS_STEP_STD_MPS2,
            height_std_m=HEIGHT_STD_M,
        )
        vib.learn(state, armed=armed, thrust_n=read, accel_z=f_z - G, dt_s=DT_S)
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
    # In the air without mocap only a rest seen brings it back: a thrust dip is no rest;
    # the drone falls at (F - m g) / m ...
    s = _step(s, thrust_ratio=0.9)
    assert not s.on_ground
    s = _hold(s, 1.0, thrust_ratio=0.3, accel_z=-0.7 * G)
    assert not s.on_ground
    # ... while the floor holds it still (once the smoothed fall has died out, 50 ms).
    s = _hold(s, DEFAULT.rest_hold_s + 0.1, thrust_ratio=0.3)
    assert s.on_ground and s.reason == "low_thrust"


def test_params_are_checked() -> None:
    with pytest.raises(ValueError, match="ground_thrust_ratio"):
        ContactParams(ground_thrust_ratio=1.0)
    with pytest.raises(ValueError, match="floor_time_s"):
        ContactParams(floor_time_s=0.0)


def _vibrating(
    thrust_of_t: object,
    seconds: float,
    *,
    noise_mps2: float,
    thrust_read_ratio: float,
    seed: int,
    params: ContactParams = DEFAULT,
    sample_sigmas: float | None = None,
) -> list[tuple[float, float, bool, str]]:
    """A 1-D drone at the realistic profile's vibration: rest disarmed 1 s, then the true
    thrust profile (N, of time since arming). IMU samples 8-12 ms apart; accelerometer noise
    ``noise_mps2`` times the thrust ratio, white plus AR(0.6) with lag-1 0.2 (the realistic
    simulator's mix); the thrust read ``thrust_read_ratio`` of the true one. Returns
    (t, z m, on_ground, reason) per sample."""
    rng = np.random.default_rng(seed)
    state = ContactState()
    vib = _Vibration()
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
            vertical_noise_var_mps4=vib.var(state),
            sample_sigmas=vib.sigmas(dt) if sample_sigmas is None else sample_sigmas,
            bias_step_std_mps2=BIAS_STEP_STD_MPS2,
            height_std_m=HEIGHT_STD_M,
        )
        read = thrust * thrust_read_ratio
        vib.learn(state, armed=armed, thrust_n=read, accel_z=a + noise, dt_s=dt)
        out.append((t, z, state.on_ground, state.reason))
    return out


def _ramp_then_hover(t: float) -> float:
    return WEIGHT_N * min(1.0, t / 2.0)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_vibration_at_hover_thrust_on_the_floor_is_no_climb(seed: int) -> None:
    """60 s on the floor at hover thrust with 2 m/s^2 of vibration and a thrust
    map reading 15 % low (the floor's load reads 44 mN: only a climb could lift the drone).
    The climb is judged against the vibration learnt on the floor and the bias's step,
    at the estimator's one false-alarm rate (5.55 deviations at ~100 Hz): no lift-off.
    With a bound of about one standard deviation of the leaky speed (the fixed 0.1 m/s
    of before) it fired."""
    samples = _vibrating(_ramp_then_hover, 60.0, noise_mps2=2.0, thrust_read_ratio=0.85, seed=seed)
    assert all(z == 0.0 for _, z, _, _ in samples), "the premise: it never leaves the floor"
    assert all(g for _, _, g, _ in samples)
    loose = replace(DEFAULT, speed_time_constant_s=0.5)
    before = _vibrating(
        _ramp_then_hover,
        60.0,
        noise_mps2=2.0,
        thrust_read_ratio=0.85,
        seed=seed,
        params=loose,
        sample_sigmas=1.0,
    )
    assert not all(g for _, _, g, _ in before), "a bound of one deviation lifts it on noise"


@pytest.mark.parametrize(
    ("thrust_read_ratio", "noise_mps2", "seen_by_m"),
    [(1.0, 2.0, 0.0), (0.85, 2.0, 0.05), (0.75, 1.0, 0.1), (0.75, 2.0, 1.0)],
)
def test_take_off_under_vibration_is_seen(
    thrust_read_ratio: float, noise_mps2: float, seen_by_m: float
) -> None:
    """3 s on the floor at hover thrust, then a climb at 0.25 g. Never in the air on the
    floor while the floor's load (as read) is above ``push_free_n``; the take-off is seen:
    calibrated at hover thrust (the floor carries nothing), with the thrust reading 15 %
    low by the thrust surge by 5 cm up; 25 % low (no surge shows) by the climb alone, by
    10 cm up at 1 m/s^2 of vibration (6.0 cm in this flight: the climb must stand out by
    5.55 deviations, the one false-alarm rate's, where 4 set by hand read 2.4 cm), later
    at 2 m/s^2 (the leaky speed's noise is ~0.12 m/s there: 17.8 cm in this flight, 8.9
    with the 4 by hand)."""

    def thrust(t: float) -> float:
        return WEIGHT_N * (min(1.0, t / 2.0) if t < 5.0 else 1.25)

    samples = _vibrating(
        thrust, 7.0, noise_mps2=noise_mps2, thrust_read_ratio=thrust_read_ratio, seed=7
    )
    for t, z, on_ground, _ in samples:
        if z == 0.0 and not on_ground:
            load = WEIGHT_N - thrust(t - 1.0) * thrust_read_ratio
            assert load < DEFAULT.push_free_weight_ratio * WEIGHT_N, (t, load)
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


# -- No ground without the evidence of a rest ---------------------------------------------


def _fly_1d(
    thrust_cmd_of_t: object,
    seconds: float,
    *,
    z0_m: float,
    noise_mps2: float,
    seed: int,
    motor_tau_s: float = 0.03,
    tether_down_n: float = 0.05,
    height: bool = False,
    state: ContactState | None = None,
) -> list[tuple[float, float, float, bool, str]]:
    """A 1-D drone under a tether pulling down ``tether_down_n`` in the air: the thrust
    follows the command (N, of t s, z m, v m/s) with a first-order motor lag while the
    *command* is what is read (as the realistic simulator reports it: low before the drone
    falls); IMU samples 8-12 ms apart with white + coloured vibration of ``noise_mps2`` at
    hover. The floor at z = 0 holds it. Returns (t, z m, commanded thrust over weight,
    on_ground, reason)."""
    rng = np.random.default_rng(seed)
    s = state or ContactState()
    vib = _Vibration()
    z, v, t, thrust = z0_m, 0.0, 0.0, float(thrust_cmd_of_t(0.0, z0_m, 0.0))  # type: ignore[operator]
    coloured = 0.0
    out = []
    while t < seconds:
        dt = float(rng.uniform(0.008, 0.012))
        t += dt
        cmd = float(thrust_cmd_of_t(t, z, v))  # type: ignore[operator]
        thrust += (cmd - thrust) * min(1.0, dt / motor_tau_s)
        pull = tether_down_n if z > 0.0 else 0.0
        net = thrust - WEIGHT_N - pull
        if z <= 0.0 and net <= 0.0:
            a, v = 0.0, 0.0  # the floor holds it
        else:
            a = net / MASS_KG
            v += a * dt
        z = max(0.0, z + v * dt)
        if z == 0.0:
            v = max(0.0, v)
        coloured = 0.6 * coloured + 0.8 * float(rng.normal())
        sigma = noise_mps2 * min(1.0, thrust / WEIGHT_N)
        noise = sigma * (0.58 * coloured + 0.82 * float(rng.normal()))
        s = contact_step(
            s,
            DEFAULT,
            dt_s=dt,
            armed=True,
            thrust_n=cmd,
            mass_kg=MASS_KG,
            vertical_accel_mps2=a + noise,
            height_m=z + 0.04 if height else None,
            floor_z_m=0.0,
            vertical_noise_var_mps4=vib.var(s),
            sample_sigmas=vib.sigmas(dt),
            bias_step_std_mps2=BIAS_STEP_STD_MPS2,
            height_std_m=HEIGHT_STD_M,
        )
        vib.learn(s, armed=True, thrust_n=cmd, accel_z=a + noise, dt_s=dt)
        out.append((t, z, cmd / WEIGHT_N, s.on_ground, s.reason))
    return out


def _airborne() -> ContactState:
    return ContactState(on_ground=False, reason="air", rest_seen=True)


@pytest.mark.parametrize("noise_mps2", [0.3, 2.0])  # the ideal and the realistic profile's
@pytest.mark.parametrize("height", [False, True])
@pytest.mark.parametrize("seed", [1, 2])
def test_thrust_dips_and_hard_descents_in_the_air_are_no_ground(
    noise_mps2: float, height: bool, seed: int
) -> None:
    """The mid-air latch's trigger and its kin: a height controller hovering at 1.2 m is sent to
    0.5 m (as the demo's jump to its fourth spot: the command saturates at 0.02 N, below
    the ratio, then catches the drop), back to 1.2 m, then told to hold 0.3 of the weight
    for 0.25 s (a hard descent) before it recovers. Before, the first low-thrust sample
    said "on the ground" (and, with motion capture, learnt a resting height in mid-air)."""
    pull = 0.05

    def cmd(t: float, z: float, v: float) -> float:
        if 5.0 <= t < 5.25:
            return 0.3 * WEIGHT_N
        goal = 0.5 if 1.0 <= t < 3.0 else 1.2
        a = 25.0 * (goal - z) - 8.0 * v  # a PD controller, saturated
        return min(2.0 * WEIGHT_N, max(0.02, WEIGHT_N + pull + MASS_KG * a))

    samples = _fly_1d(
        cmd, 7.0, z0_m=1.2, noise_mps2=noise_mps2, seed=seed, height=height, state=_airborne()
    )
    assert min(z for _, z, _, _, _ in samples) > 0.2, "the premise: it never lands"
    assert sum(1 for t, _, r, _, _ in samples if r < 0.5 and t < 5.0) >= 3, "the premise: dips"
    assert not any(g for _, _, _, g, _ in samples), [x for x in samples if x[3]][:3]


@pytest.mark.parametrize("noise_mps2", [0.3, 2.0])
@pytest.mark.parametrize("height", [False, True])
def test_a_landing_at_idle_thrust_is_seen_at_rest_then_the_take_off(
    noise_mps2: float, height: bool
) -> None:
    """A descent from 0.5 m at 0.8 of the weight onto the floor, then idle thrust (20 %)
    there for 2 s, then a take-off at 1.3x: on the ground within 0.4 s of the idle on the
    floor (rest_hold_s, the smoothing, the motors' lag) and until the take-off; in the
    air again within 0.3 s of leaving the floor."""

    def cmd(t: float, z: float, v: float) -> float:
        if t < 2.0:
            return 0.8 * WEIGHT_N if t < 1.0 else 0.95 * WEIGHT_N
        if t < 4.0:
            return 0.2 * WEIGHT_N
        return 1.3 * WEIGHT_N

    samples = _fly_1d(
        cmd, 5.0, z0_m=0.5, noise_mps2=noise_mps2, seed=3, height=height, state=_airborne()
    )
    touch = next(t for t, z, _, _, _ in samples if z == 0.0)
    assert touch < 2.0, "the premise: it lands before the idle"
    for t, _, _, g, _ in samples:
        if 2.4 <= t < 4.0:
            assert g, t
    lift = next(t for t, z, _, _, _ in samples if t > 4.0 and z > 0.0)
    air = next(t for t, _, _, g, _ in samples if t > 4.0 and not g)
    assert air - lift < 0.3, (lift, air)


def test_no_ground_state_outlives_a_fall() -> None:
    """The initial guess (on the ground) for a drone found at 60 % of its weight in the air,
    without motion capture: the floor's load rule alone would hold "on the ground" (it
    carries 118 mN, as read), but the drone falls at 0.4 g: in the air within 0.3 s."""
    samples = _fly_1d(
        lambda t, z, v: 0.6 * WEIGHT_N, 0.6, z0_m=5.0, noise_mps2=2.0, seed=4, tether_down_n=0.0
    )
    air = next(t for t, _, _, g, _ in samples if not g)
    assert air < 0.3
    assert next(r for _, _, _, g, r in samples if not g) == "falling"


def test_mocap_below_the_resting_surface_is_not_on_it() -> None:
    """Rested on a 75 cm table (marker at 0.79 m), then flown beside it at 0.5 m: in the air
    (before: "resting" for as long as it stayed below the table top)."""
    s = _hold(ContactState(), 1.0, thrust_ratio=0.0, height_m=0.79)
    assert s.rest_height_m == pytest.approx(0.79)
    s = _step(s, thrust_ratio=1.1, height_m=0.9)
    assert not s.on_ground
    s = _step(s, thrust_ratio=1.0, height_m=0.5)
    assert not s.on_ground and s.reason == "mocap_height"
    s = _step(s, thrust_ratio=1.0, height_m=0.795)
    assert s.on_ground, "back on the table"


def test_a_drone_stopped_in_mid_air_learns_no_rest() -> None:
    """Disarmed is the ground at once, but a drone stopped in the air falls (|f| ~ 0): no
    resting height nor accelerometer bias is learnt from that."""
    s = ContactState(on_ground=False, reason="air")
    for k in range(100):  # 0.4 s of free fall from 1.2 m
        s = _step(
            s, thrust_ratio=0.0, armed=False, accel_z=-G, height_m=1.2 - 0.5 * G * (k * DT_S) ** 2
        )
        assert s.on_ground and s.reason == "disarmed"
    assert s.rest_height_m is None and s.accel_bias_z_mps2 is None


@pytest.mark.parametrize("name", ["B6_linear_ramp_rep1.csv", "B3_figure8_fast_rep1.csv"])
@pytest.mark.parametrize("mocap", [True, False])
def test_real_take_off_and_landing_nanobench(name: str, mocap: bool) -> None:
    """Real Crazyflie 2.1 flights (NanoBench excerpts, 25 Hz, untethered), thrust calibrated
    against zero tension: at rest on the floor before arming, the evidence is seen on real
    accelerometer data (rest height and bias learnt); on the ground until lift-off; never
    on the ground 10 cm above the resting height; on the ground after the landing. Then the
    same floor samples of the end, replayed armed at idle thrust (20 % of the weight): the
    real floor's accelerometer is seen at rest, the ground (low_thrust)."""
    from benchmarks.nanobench import MASS_KG, fit

    data, f, _ = fit(name)
    vbat = np.nan_to_num(data.vbat_v, nan=f.vbat_ref_v)
    scale = f.values["thrust_scale"] + f.values["vbat_slope_per_v"] * (vbat - f.vbat_ref_v)
    thrust = data.thrust_n * scale
    z = data.position_world_m[:, 2]
    accel = [
        vertical_accel_mps2(a, q) for a, q in zip(data.accel_body_mps2, data.quat_wxyz, strict=True)
    ]
    armed = data.armed.astype(bool)
    first_armed = int(np.argmax(armed))
    last_armed = len(armed) - 1 - int(np.argmax(armed[::-1]))
    s = ContactState()
    out = []
    rate = TensionFilterParams().false_alarms_per_h
    for k in range(len(z)):
        dt = 0.0 if k == 0 else float(data.stamp_s[k] - data.stamp_s[k - 1])
        s = contact_step(
            s,
            DEFAULT,
            dt_s=dt,
            armed=bool(armed[k]),
            thrust_n=float(thrust[k]),
            mass_kg=MASS_KG,
            vertical_accel_mps2=accel[k],
            height_m=float(z[k]) if mocap else None,
            floor_z_m=0.0,
            # The per-sample threshold at the sample's spacing (5.3 at 25 Hz), as the
            # pipeline hands it (TensionFilter.sigmas_at) where a height is given.
            sample_sigmas=exceedance_sigmas(rate, dt) if mocap else math.inf,
            bias_step_std_mps2=BIAS_STEP_STD_MPS2,
            height_std_m=HEIGHT_STD_M,
        )
        out.append(s)
        if k == first_armed - 1:
            assert s.rest_seen and s.accel_bias_z_mps2 is not None
            if mocap:
                assert s.rest_height_m == pytest.approx(z[0], abs=0.005)
    rest_z = float(z[0])
    lift = next(k for k in range(first_armed, len(z)) if z[k] > rest_z + 0.01)
    assert all(s.on_ground for s in out[: lift - 1])
    assert any(not s.on_ground for s in out[lift:last_armed])
    for k in range(lift, last_armed):
        if z[k] > rest_z + 0.10:
            assert not out[k].on_ground, (name, data.stamp_s[k], z[k], out[k].reason)
    assert all(s.on_ground for s in out[last_armed + 1 :])
    assert len(out) - last_armed > 25, "the premise: a second at rest after the landing"
    # The landing's floor samples, armed at idle: seen at rest on real data.
    s = replace(out[last_armed], on_ground=False, reason="air")
    for k in range(last_armed + 1, len(z)):
        s = contact_step(
            s,
            DEFAULT,
            dt_s=float(data.stamp_s[k] - data.stamp_s[k - 1]),
            armed=True,
            thrust_n=0.2 * MASS_KG * G,
            mass_kg=MASS_KG,
            vertical_accel_mps2=accel[k],
            height_m=None,
            floor_z_m=0.0,
            sample_sigmas=math.inf,
            bias_step_std_mps2=BIAS_STEP_STD_MPS2,
            height_std_m=HEIGHT_STD_M,
        )
    assert s.on_ground and s.reason == "low_thrust"


@pytest.mark.parametrize("factor", [0.9, 1.1])
def test_a_climb_must_stand_out_of_the_bias_step_the_leak_holds(factor: float) -> None:
    """On a quiet floor the climb's bound is the bias's step since the rest (σ_δ) as the leak
    holds it, σ_δ·τ, times the sigmas of the one false-alarm rate: a steady acceleration
    whose leaky speed settles just below it is no climb, just above it is one."""
    sigmas, step_std = 5.55, 0.05
    limit_mps = sigmas * step_std * DEFAULT.speed_time_constant_s
    accel = factor * limit_mps / DEFAULT.speed_time_constant_s  # the speed settles at a·τ
    s = ContactState(rest_seen=True)
    for _ in range(round(3.0 / DT_S)):
        s = contact_step(
            s,
            DEFAULT,
            dt_s=DT_S,
            armed=True,
            thrust_n=0.9 * WEIGHT_N,
            mass_kg=MASS_KG,
            vertical_accel_mps2=accel,
            height_m=None,
            floor_z_m=0.0,
            vertical_noise_var_mps4=1e-12,
            sample_sigmas=sigmas,
            bias_step_std_mps2=step_std,
            height_std_m=HEIGHT_STD_M,
        )
        if not s.on_ground:
            break
    assert s.on_ground is (factor < 1.0), s
    if factor > 1.0:
        assert s.reason == "climbing"
