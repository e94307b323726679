"""Ground or air: whether the floor carries the drone, with hysteresis (pure state machine).

Pure: the standard library's maths only; time enters as ``dt_s``.

Why it matters (NOTES "Tension observation"): on the floor, the balance of ``eq:NE_tether``
reads the floor's push as tether tension, ``T_z = m g - F`` upward, up to the whole weight
(~0.3 N). Below ``[filter] ground_thrust_ratio`` of the weight (0.5) the drone is surely on
the floor; between that and the weight it may still rest there while the propellers spin
up: at 0.51 of the weight the floor pushes with 144 mN, above the follow threshold. So
while the thrust is at or above the ratio, lift-off must be *seen* before the tension is
trusted, and a touch-down is noticed where it can be:

* **On the ground, seen at rest** (any state): disarmed, or thrust below
  ``ground_thrust_ratio`` of the weight *while the accelerometer shows the floor holding the
  drone still*. A low thrust alone is no evidence (the demo's controller cuts the
  thrust to 7 % of the weight for 60 ms at a jump from 1.2 m to 0.5 m, and the rule "below
  the ratio is the ground" learnt a resting height of 1.2 m in mid-air and stayed on the
  ground for good). Physics tells the two apart: on the floor the specific force is about
  g upward whatever the thrust (the floor pushes with ``m g - F``), so the world vertical
  acceleration is ~0; in the air the drone falls at ``(F + T_z) / m - g``, below
  ``-(1 - ratio) g`` plus what the tether holds (-4.9 m/s^2 at the ratio; -10.4 m/s^2 in
  that dip). So the vertical acceleration, smoothed over ``floor_time_s`` (0.1 s, the
  stage's one time scale; it was a time constant of its own, 50 ms, which no benchmark
  flight told from 0.1 s)
  and less the bias learnt at rest, must stay within half of ``(1 - ratio) g`` (derived:
  2.45 m/s^2 at the ratio 0.5, halfway between a rest and the slowest fall) for
  ``rest_hold_s`` (0.2 s: longer than a motor's spin-down, during which the thrust reads
  low before the drone falls; 30-40 ms in the realistic simulator). Then the vertical
  accelerometer bias is learnt (the drone does not move) and the resting motion-capture
  height is remembered (a marker sits above the floor).
  Disarmed is the ground at once (no estimate is made without the motors), but what is
  learnt there also waits for that evidence: a drone stopped in mid-air falls, |f| ~ 0.
  Until the evidence is in, a low-thrust sample keeps the state it found; in the air the
  service then coasts the tension filter (the floor may be carrying part of the weight),
  it does not publish "on the ground".
* **Falling** (on the ground, without motion capture, armed): the smoothed vertical
  acceleration below minus that for ``rest_hold_s`` says the floor holds nothing:
  in the air (``reason = "falling"``). The floor cannot accelerate the drone downward, so
  no ground state outlives this; on the floor the 50 ms mean of 2 m/s^2 of vibration
  wanders by ~1 m/s^2 and would have to stay 2.5 sigma low for 0.2 s.
* **Lift-off with motion capture:** the height stands out of the motion capture's noise
  above the resting height (or the floor when no rest was seen): more than
  ``sample_sigmas`` of ``height_std_m`` (σ_p, ``[localization] mocap_std_m``) above it, the
  estimator's one false-alarm rate as a per-sample threshold (5.55 σ_p at 100 Hz: 1.1 cm
  at 2 mm); touch-down within that band again. One band, no hysteresis of its own: a
  resting marker leaves it by chance once per 1/``false_alarms_per_h`` hours, and a
  descent crosses it in a sample or two.
* **Lift-off without motion capture**, either of:

  - *the floor carries nothing*: the floor's load ``m g - F`` (what the observation of
    ``eq:NE_tether`` reads vertically for a drone at rest, from the same calibrated thrust
    ``F``), smoothed over ``floor_time_s``, stays below ``push_free_weight_ratio`` of the weight
    (10 mN at 30 g) for ``floor_time_s`` too (one time scale of the floor's judgement). Whatever
    rests on the floor then, what is published as tension is below that, which is the point; in
    the air the tether pulls down (or a hand pulls), so a hovering drone whose service restarts
    is found in the air in 0.1 s. A thrust reading low by more than the tether's downward pull
    (e.g. 15 % at 10 mN of pull) defeats this rule; a take-off is then found by its thrust surge
    (the climb's acceleration takes some 20 % of the weight) or by the climb;
  - *climbing*: the vertical acceleration (IMU specific force rotated to the world, minus
    gravity, minus the bias learnt at rest) integrated with a leak of
    ``speed_time_constant_s`` stands out of its uncertainty by the estimator's one
    false-alarm rate (below), while the smoothed load is below
    ``climb_push_max_weight_ratio`` of the weight (50 mN at 30 g: the floor carries about a
    sixth of the drone or less).

  Why the load and not the observation itself: on the floor the accelerometer adds only
  its noise to ``m g - F``, and that noise is the propellers' vibration, 1-2 m/s^2 on real
  flights, i.e. 30-60 mN per sample on a 30 g drone. Averaged over 0.1 s it still wandered
  by ~20 mN, so at 2 m/s^2 (the realistic simulator, ``takeoff_ramp``: 2 s of spool-up,
  ~3 s on the floor at hover thrust, then a climb at ~0.75 m/s; 10 seeds with and without
  calibration) the rule "below 10 mN for 0.1 s" fired on noise in 9 of 20 take-offs at a
  load (as read) of up to 30 mN. The thrust reading has no such noise.

  Why the climb's bound is learnt: the leaky speed's noise is the vibration's too. On the
  floor at or above the thrust ratio the drone does not move, so its vertical acceleration
  is noise, and the tension filter measures it there (``TensionFilter.learn_noise``: the
  observation's vertical long-run variance r, i.e. its level from successive differences,
  blind to a thrust ramp, times its shape kappa, measured; over the mass squared, an
  acceleration's) with its allowance for a young or scattered estimate
  (``TensionFilter.vertical_noise_var_n2``); the speed's variance is ``r / m^2 * sum
  dt_k^2 (1 - dt/tau)^(2 j)``. (This stage had a measure of its own, over 1 s, with kappa
  set to 3 by hand: one measure of the vibration now.) At 2 m/s^2 and ~100 Hz that is
  0.12-0.14 m/s with the 0.25 s leak. Beside the noise, the bias: the one learnt at rest
  may have moved by the time the propellers spin at flying thrust (the vibration, the
  warming), by ``[calibration] flight_bias_std_mps2`` (σ_δ, which ``calibrate`` fits: how
  far the bias in the air strays from the rest's), and a bias error ε holds the leaky
  speed at ε·τ (0.05 m/s^2, the default, at 0.25 s: 0.0125 m/s). The speed's uncertainty
  is the two in quadrature, and the climb must exceed it by the standard deviations at
  which a per-sample test fires by chance ``false_alarms_per_h`` (the change test's one
  knob, 0.005 per hour: 5.55 at 100 Hz, 5.72 at 250 Hz;
  ``tension_change.exceedance_sigmas``): a climb counts above ~0.7 m/s at 2 m/s^2, ~0.1
  m/s at the ideal profile's 0.3 m/s^2. Both were hand-set before, 4 standard deviations
  of the noise and a floor of 0.1 m/s for what the noise did not cover. The fixed 0.1 m/s
  before the bound was learnt was about one standard deviation and fired on the floor in
  10 of the 20 take-offs. On the floor at hover thrust the leaky speed reached 0.27 m/s at
  most; in 40 x 59 s at hover thrust on the floor with that vibration (synthetic, measured
  with the stage's own measure) no climb was seen at 4 sigma (5 at 3.5), nor in 6 x 58 s of
  the realistic simulator; none in tests/test_contact.py's 3 x 60 s. The price: a climb
  alone stands out late under 2 m/s^2 (at 0.25 g, 10-100 cm up); the take-offs above were
  found by their thrust surge at 1.3-1.7 cm. The load bound keeps a large bias (vibration
  at spool-up) from lifting a drone that the floor still visibly carries.

  With both, on those 20 take-offs: calibrated, the floor is found to carry nothing at
  hover thrust, 1.5 s before the drone leaves it (the tether on the floor pulls it down
  with 4 mN), and what is published there is 7-15 mN (before: 28-63 mN); uncalibrated
  (the thrust map reads ~15 % low) the drone stays on the ground until it is 1.3-1.7 cm
  up, found by the thrust surge or the climb (before: up to 27-56 mN published on the
  floor in 9 of 10). The 7-15 mN are mostly the floor's friction
  holding the sideways push of the airframe's thrust axis (2.3 deg off the body's z:
  12 mN at hover thrust) plus the filter's noise; the simulator's floor holds any
  sideways force, a real one lets the drone slide.

  What the rules cannot tell apart: a drone held on the floor at hover thrust from one
  hovering, when neither climbs. A thrust map reading *high* by ``e`` makes the load read
  ``e F`` low: the push rule fires on the floor that much below hover thrust, and what is
  published there is ``-e F``, the thrust map's error, as in the air (calibrate it).

  In the air, without motion capture, only the rest seen above (or a disarm) brings the
  drone back to the ground (a hand holding the drone still pushes up like the floor would).

With motion capture the height decides between the rests: on the ground within the band
above the resting height, but not more than the band *below* it (a drone flying below the
surface it last rested on, beside a table, is not on it).

The state starts on the ground, but until the drone has once been *certainly* on the
ground (disarmed or below the ratio) the push rule is looser: a load below
``climb_push_max_weight_ratio`` (50 mN at 30 g) instead of ``push_free_weight_ratio`` for
``floor_time_s`` says the drone is
flying (``reason = "flying_at_start"``: the service (re)started while it was in the air).
With the strict bound a hover under a tether that pulls *up* (a base above the drone, the
paper's coin bench: 12.7 mN up) would be held on the ground forever. The price: a service
started in the last part of a spool-up on the floor (thrust above 0.83 of the weight,
without motion capture) publishes up to 50 mN of floor push as tension until it sees the
drone; below the follow threshold, and no tug-to-land can be armed without a tug.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from groundstation.attitude import GRAVITY_MPS2, STILL_WINDOW_S, Rows, rows_from_quat_wxyz
from groundstation.frozen import evolve

__all__ = [
    "ContactParams",
    "ContactState",
    "contact_step",
    "vertical_accel_from_rows_mps2",
    "vertical_accel_mps2",
]


Reason = Literal[
    "start",
    "disarmed",
    "low_thrust",
    "resting",
    "mocap_height",
    "climbing",
    "push_free",
    "air",
    "flying_at_start",
    "falling",
]


@dataclass(frozen=True)
class ContactParams:
    """Thresholds of :func:`contact_step` (see the module docstring).

    Attributes:
        ground_thrust_ratio: Below this fraction of the weight the drone is on the ground,
            in (0, 1) (``[filter] ground_thrust_ratio``).
        speed_time_constant_s: No motion capture: lift-off when the leaky vertical speed
            from the IMU, with this leak (s), stands out of its noise and of what the
            accelerometer's bias can hold it at (:func:`contact_step`'s ``sample_sigmas``
            and ``bias_step_std_mps2``).
        climb_push_max_weight_ratio: No motion capture: a climb counts only while the
            smoothed floor load is below this fraction of the weight ``m·g`` (a floor load
            scales with the weight), dimensionless.
        push_free_weight_ratio: No motion capture: lift-off when the smoothed floor load
            stays below this fraction of the weight, dimensionless ...
        floor_time_s: ... for this long, s; also the floor load's smoothing time constant,
            and the vertical acceleration's (rest against fall): the one time scale over
            which the stage judges the floor (``push_hold_s``, ``push_time_constant_s`` and
            ``accel_time_constant_s`` were three values, 0.1, 0.1 and 0.05 s).
        rest_hold_s: At rest the smoothed vertical acceleration, less the bias, stays within
            half of ``(1 - ground_thrust_ratio) g`` of 0 (below minus that the drone
            falls) for this long, s (a rest, or a fall, is seen only then).
    """

    ground_thrust_ratio: float = 0.5
    speed_time_constant_s: float = 0.25
    climb_push_max_weight_ratio: float = 0.17
    push_free_weight_ratio: float = 0.034
    floor_time_s: float = 0.1
    rest_hold_s: float = 0.2

    def __post_init__(self) -> None:
        if not (0.0 < self.ground_thrust_ratio < 1.0):
            raise ValueError(
                f"ContactParams.ground_thrust_ratio must be in (0, 1), "
                f"got {self.ground_thrust_ratio!r}"
            )
        for name in (
            "speed_time_constant_s",
            "climb_push_max_weight_ratio",
            "push_free_weight_ratio",
            "floor_time_s",
            "rest_hold_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"ContactParams.{name} must be finite and > 0, got {value!r}")


@dataclass(frozen=True)
class ContactState:
    """Ground/air state between samples (immutable; each step returns a new one).

    Attributes:
        on_ground: The floor carries (part of) the drone: its push is no tension.
        reason: What decided the last step (see :data:`Reason`).
        accel_bias_z_mps2: Vertical accelerometer bias learnt at rest, m/s^2, or None
            before the first rest.
        climb_speed_mps: Leaky vertical speed from the IMU while on the ground, m/s.
        speed_gain_s2: Its variance per unit of per-sample acceleration variance
            (``sum_k dt_k^2 (1 - leak)^(2 j)``), s^2.
        push_n: Smoothed floor load ``m g - F`` while on the ground, N, or None.
        push_free_s: How long ``push_n`` has been below the push limit, s.
        rest_height_m: Motion-capture height while resting, m, or None.
        rest_seen: The drone has once been disarmed or seen at rest on the ground (below
            the thrust ratio, held still); before that an armed drone at hover thrust is
            taken to be flying.
        accel_smooth_mps2: Vertical acceleration smoothed over ``floor_time_s``,
            m/s^2, or None before the first finite one.
        still_s: How long the smoothed acceleration (less the bias) has been within
            half of ``(1 - ground_thrust_ratio) g`` of 0, s.
        falling_s: How long it has been below minus that, s.
    """

    on_ground: bool = True
    reason: Reason = "start"
    accel_bias_z_mps2: float | None = None
    climb_speed_mps: float = 0.0
    speed_gain_s2: float = 0.0
    push_n: float | None = None
    push_free_s: float = 0.0
    rest_height_m: float | None = None
    rest_seen: bool = False
    accel_smooth_mps2: float | None = None
    still_s: float = 0.0
    falling_s: float = 0.0


_START = ContactState()
"""The state before any sample (what a rest on the ground is built from)."""


def vertical_accel_mps2(
    accel_body_mps2: tuple[float, float, float] | list[float],
    quat_wxyz: tuple[float, float, float, float] | list[float],
    gravity_mps2: float = GRAVITY_MPS2,
) -> float:
    """World vertical acceleration from the IMU: ``p''_z = (R_world_body f)_z - g``.

    Args:
        accel_body_mps2: Specific force in the body frame, m/s^2, 3 floats.
        quat_wxyz: Attitude body->world ``[w, x, y, z]`` (normalised here), 4 floats.
        gravity_mps2: Magnitude of gravity, m/s^2.

    Returns:
        The vertical acceleration, m/s^2 (0 at rest); NaN for a degenerate quaternion.
    """
    w, x, y, z = quat_wxyz
    n2 = w * w + x * x + y * y + z * z
    if not (math.isfinite(n2) and n2 > 1e-12):
        return math.nan
    return vertical_accel_from_rows_mps2(
        accel_body_mps2, rows_from_quat_wxyz(quat_wxyz), gravity_mps2
    )


def vertical_accel_from_rows_mps2(
    accel_body_mps2: tuple[float, float, float] | list[float],
    rotation_rows_world_body: Rows,
    gravity_mps2: float = GRAVITY_MPS2,
) -> float:
    """:func:`vertical_accel_mps2` on an attitude already turned into ``R_world_body`` rows
    (:func:`groundstation.attitude.rows_from_quat_wxyz`): ``(R f)_z − g``, m/s^2."""
    fx, fy, fz = accel_body_mps2
    r20, r21, r22 = rotation_rows_world_body[2]
    return r20 * fx + r21 * fy + r22 * fz - gravity_mps2


def contact_step(
    state: ContactState,
    params: ContactParams,
    *,
    dt_s: float,
    armed: bool,
    thrust_n: float,
    mass_kg: float,
    vertical_accel_mps2: float,
    height_m: float | None,
    floor_z_m: float = -math.inf,
    gravity_mps2: float = GRAVITY_MPS2,
    vertical_noise_var_mps4: float | None = None,
    sample_sigmas: float,
    bias_step_std_mps2: float,
    height_std_m: float,
) -> ContactState:
    """One sample of the ground/air state machine (module docstring).

    Args:
        state: State after the previous sample.
        params: Thresholds.
        dt_s: Time since the previous sample, s (0 for the first or after a gap).
        armed: Motors armed.
        thrust_n: Collective thrust (calibrated), N.
        mass_kg: Drone mass, kg.
        vertical_accel_mps2: World vertical acceleration from the IMU, m/s^2
            (:func:`vertical_accel_mps2`); NaN when unknown.
        height_m: Motion-capture height (world z) of the drone, m, or None.
        floor_z_m: Floor height, m (``-inf``: no floor, the resting height alone counts).
        gravity_mps2: Magnitude of gravity, m/s^2.
        vertical_noise_var_mps4: The vertical acceleration's noise, its long-run variance
            with the allowance for its estimate's error, (m/s^2)^2: the tension filter's
            (``TensionFilter.vertical_noise_var_n2`` over the mass squared). None: not
            measured yet, no climb is judged.
        sample_sigmas: Standard deviations a per-sample statistic must exceed: the
            estimator's one false-alarm rate at the sample spacing
            (``TensionFilter.sigmas_at``; infinite: nothing is judged). The climb test's
            (the leaky speed against its uncertainty) and the motion-capture height's
            (against ``height_std_m``).
        bias_step_std_mps2: How far the accelerometer's bias may have moved since the rest
            it was learnt at, m/s^2: ``[calibration] flight_bias_std_mps2`` (σ_δ, fitted by
            ``calibrate``; ``BiasKalmanParams.flight_bias_std_mps2``). A bias error ε holds
            the leaky speed at ε·``speed_time_constant_s``.
        height_std_m: σ_p, the motion-capture height's noise, m (``[localization]
            mocap_std_m``; the rest height it is compared with is a 1 s mean, its own
            error a tenth of σ_p at 100 Hz, not counted). Used only with ``height_m``.

    Returns:
        The next state; ``on_ground`` says whether the floor carries the drone.
    """
    dt = dt_s if math.isfinite(dt_s) and dt_s > 0.0 else 0.0
    height = height_m if height_m is not None and math.isfinite(height_m) else None
    accel = vertical_accel_mps2
    weight_n = mass_kg * gravity_mps2

    # The evidence of a rest: with the propellers carrying less than the ratio of the
    # weight (or nothing), the floor holds the drone still (vertical acceleration ~0), where
    # in the air it falls at (F + T_z) / m - g. (At hover thrust "still" says nothing: a
    # hovering drone is still too.)
    low_thrust = not armed or not (thrust_n >= params.ground_thrust_ratio * weight_n)
    # Halfway between a rest (mean 0) and the slowest fall, at the ratio (mean -(1 - ratio)
    # g): the likelihood-ratio boundary of the two under the same vibration.
    rest_accel = 0.5 * (1.0 - params.ground_thrust_ratio) * gravity_mps2
    smooth = state.accel_smooth_mps2
    still_s, falling_s = 0.0, 0.0
    if math.isfinite(accel):
        w = min(1.0, dt / params.floor_time_s) if smooth is not None else 1.0
        smooth = accel if smooth is None else smooth + w * (accel - smooth)
        rel = smooth - (state.accel_bias_z_mps2 or 0.0)
        if low_thrust and abs(rel) < rest_accel:
            still_s = state.still_s + dt
        elif rel < -rest_accel:
            falling_s = state.falling_s + dt
    at_rest = still_s >= params.rest_hold_s

    # On the ground: disarmed, or low thrust seen at rest. Learn the resting accelerometer
    # bias and height only at rest (a drone stopped in mid-air falls), averaged over the one
    # window of stillness (attitude.STILL_WINDOW_S, the rest detector's).
    if not armed or at_rest:
        bias = state.accel_bias_z_mps2
        rest = state.rest_height_m
        if at_rest:
            if math.isfinite(accel):
                w = min(1.0, dt / STILL_WINDOW_S) if bias is not None else 1.0
                bias = accel if bias is None else bias + w * (accel - bias)
            if height is not None:
                w = min(1.0, dt / STILL_WINDOW_S) if rest is not None else 1.0
                rest = height if rest is None else rest + w * (height - rest)
        return evolve(
            _START,
            on_ground=True,
            reason="disarmed" if not armed else "low_thrust",
            accel_bias_z_mps2=bias,
            rest_height_m=rest,
            rest_seen=state.rest_seen or at_rest or not armed,
            accel_smooth_mps2=smooth,
            still_s=still_s,
            falling_s=falling_s,
        )
    # Low thrust not (yet) seen at rest: a dip, a hard descent, or a touch-down being
    # confirmed. The state it found holds (in the air the service coasts the filter).
    state = evolve(state, accel_smooth_mps2=smooth, still_s=still_s, falling_s=falling_s)

    if height is not None:
        ground_m = state.rest_height_m if state.rest_height_m is not None else floor_z_m
        if math.isfinite(ground_m):
            above_m = height - ground_m
            # The band a resting marker leaves by chance at the one false-alarm rate.
            band_m = sample_sigmas * height_std_m
            if band_m < math.inf:  # False for NaN: no spacing yet, the state holds
                on_ground = not above_m > band_m
                if state.rest_height_m is not None and above_m < -band_m:
                    on_ground = False  # below the surface it rested on: not on it
            else:
                on_ground = state.on_ground
            return evolve(
                state,
                on_ground=on_ground,
                reason="resting" if on_ground else "mocap_height",
                climb_speed_mps=0.0,
                speed_gain_s2=0.0,
                push_n=None,
                push_free_s=0.0,
            )

    if not state.on_ground:
        # In the air and staying there.
        return state if state.reason == "air" else evolve(state, reason="air")

    # On the ground with the propellers carrying part of the weight: look for lift-off.
    if falling_s >= params.rest_hold_s:
        # The floor cannot pull the drone down: whatever said "ground" no longer holds.
        return evolve(state, on_ground=False, reason="falling", climb_speed_mps=0.0)
    finite_accel = math.isfinite(accel)
    speed, speed_gain = state.climb_speed_mps, state.speed_gain_s2
    if finite_accel and dt > 0.0:
        a = accel - (state.accel_bias_z_mps2 or 0.0)
        keep = 1.0 - min(1.0, dt / params.speed_time_constant_s)  # the leak
        speed = keep * speed + a * dt  # v_k = (1 - dt/tau) v_(k-1) + a_k dt
        speed_gain = keep * keep * speed_gain + dt * dt  # Var(v) / Var(a), white a
    climb_limit = math.inf  # no climb is judged before the vibration is known
    var_a = vertical_noise_var_mps4
    if var_a is not None and math.isfinite(var_a):
        # The floor's vibration as the tension filter measures it (the drone does not
        # move, its vertical acceleration is noise): the long-run variance, allowed for;
        # and the bias's step since the rest, which the leak holds at ε·τ (the steady
        # state of v ← (1 − dt/τ)·v + ε·dt), independent of the noise.
        held = bias_step_std_mps2 * params.speed_time_constant_s
        climb_limit = sample_sigmas * math.sqrt(var_a * speed_gain + held * held)
    # The floor's load, were the drone at rest: m g - F. It is what the observation of
    # eq:NE_tether reads there (the accelerometer adds only its noise), from the same thrust.
    load = weight_n - thrust_n
    push = state.push_n
    w = min(1.0, dt / params.floor_time_s) if push is not None else 1.0
    push = load if push is None else push + w * (load - push)
    # Before any rest was seen the drone is most likely flying (the service started
    # mid-flight), perhaps under a tether that pulls up: a looser bound on the load.
    climb_push_max_n = params.climb_push_max_weight_ratio * weight_n
    push_limit_n = params.push_free_weight_ratio * weight_n if state.rest_seen else climb_push_max_n
    free_s = state.push_free_s + dt if push < push_limit_n else 0.0
    if speed > climb_limit and push < climb_push_max_n:
        return evolve(state, on_ground=False, reason="climbing", climb_speed_mps=0.0)
    if push < push_limit_n and free_s >= params.floor_time_s:
        reason: Reason = "push_free" if state.rest_seen else "flying_at_start"
        return evolve(state, on_ground=False, reason=reason, climb_speed_mps=0.0)
    return evolve(
        state,
        on_ground=True,
        reason="resting",
        climb_speed_mps=speed,
        speed_gain_s2=speed_gain,
        push_n=push,
        push_free_s=free_s,
    )
