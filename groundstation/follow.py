"""Tension following and tug-to-land, as a pure state machine (paper sec. Tension following).

The paper: "The goal position of the quadcopter changes if the estimated tension is
greater than a pre-defined threshold. When this occurs, the goal position of the
quadcopter is successively updated to its current position, making it to follow the
pull's direction. When the tension ... is no longer greater than the threshold, the
goal position stops being updated and the quadcopter remains hovering at its last
position." And for landing: "after the first tug, a flag is activated ... if the
quadcopter flies under a certain height, the motors are turned off."

This module is that logic and nothing else: :func:`follow_step` takes the previous
:class:`FollowState` and this step's inputs and returns the next state with what to
publish (a setpoint, a Stop, or nothing). No clock, no I/O: time is ``stamp_s``.

Behaviour, in the order :func:`follow_step` applies it:

1. **Stale input.** More than ``stale_after_s`` since the previous step, or a stamp
   that goes backwards: following disengages (``enabled`` and ``active`` False, with
   the reason); the operator must enable it again. :func:`mark_stale` does the same
   when the caller knows the input is stale (a silent drone).
2. **Off.** Not enabled, or stopped after a tug-to-land: nothing is published.
3. **No position.** A missing or non-finite position never yields a setpoint; the
   follower releases (``active`` False) and the goal stays frozen.
4. **Pull, with hysteresis.** Engage when the *pull* exceeds ``threshold_n``; release
   when it falls below ``threshold_n * (1 - hysteresis_ratio)``; in between keep the
   previous mode, so noise around the threshold does not chatter the goal. A missing
   tension estimate, or the drone on the ground, releases; on the ground landing is
   disarmed too (a landed drone's next spool-up is never stopped).
   The pull is the tension beyond the tether's own: ``T - T_own``, with ``T_own`` the
   tension the tether exerts in quiet hover at the reference position (step 4a), so the
   threshold means "a hand pulls with 0.10 N" at any reach. The paper compares |T| with
   the threshold; near taut the tether alone exceeds the 0.10 N default (0.104 N at 97 %
   of L = 1.6 m, 0.119 N at 90 % of L = 3 m, omega = 0.05 N/m), so every hover there would
   engage following and arm tug-to-land with nobody pulling.
4a. **The tether's own tension.** ``T_own = F_cat(p_ref) + b``: ``F_cat`` the catenary's
   force (:func:`groundstation.catenary.tether_force`) at the reference position, ``b``
   the estimate's offset from it: 0 at the first step after enabling with motion capture
   (the catenary at the measured position is independent of the estimate), the whole
   difference without it (nobody is taken to pull while following is switched on); then
   tracked over ``REFERENCE_TIME_CONSTANT_S`` while
   not following and the pull is within the quiet band (``QUIET_BAND_RATIO``), so a
   steady model or sensor error (length, thrust scale, mocap offset) is absorbed and a
   tug is not. The reference position is the motion-capture position
   when there is one; without motion capture the tether-based position is itself derived
   from the tension (F_cat there *is* the estimate, so nothing would ever read as pull):
   the quiet-hover position before the pull (averaged, frozen while following), and the
   goal while following (the drone tracks it). Within ``OWN_TAUT_MARGIN_M`` (5 cm) of
   taut ``F_cat`` is taken at that margin (a few cm of position or length error there is
   tens to hundreds of mN of catenary force). Where the catenary has no answer (an end
   below the floor) the last ``F_cat`` is kept. Without ``weight_n_per_m``
   ``F_cat`` is 0 and ``b`` alone is the reference (the slowly tracked quiet tension).
5. **Tug-to-land.** The first activation with ``land_below_m`` set arms landing. Once
   armed, a position below ``land_below_m`` issues exactly one Stop, and the machine
   stays ``stopped`` (no setpoints, no more Stops) until enabled again.
6. **Setpoint while active** = the current position, made safe: projected onto the
   reachable set (the ball of radius ``length_m - reach_margin_m`` around the base,
   above ``floor_z_m + floor_margin_m``), then moved from the previous setpoint by at
   most ``max_speed_mps`` times the time since that setpoint. If the reachable set
   changed under it (the reel took tether in) the result is projected again: reach
   wins over the rate limit.
6b. **Without motion capture** (``position_is_external=False``) the "current position"
   is the tether-based estimate, which a hand's pull corrupts: the pull is not the
   catenary's, so localization reads it as a drone elsewhere (a downward tug as a drone
   higher up). Following it would lead the drone away from the hand, and tug-to-land
   would never fire (measured in docs/RESULTS.md before this rule). The paper itself
   says tension following needs an external position. So the goal starts at the
   position before the tug (averaged while quiet) and moves along the pull,
   ``v = admittance_mps_per_n (T - T_own)`` (step 4a, with the catenary at the goal),
   capped at ``max_speed_mps`` and kept within reach; tug-to-land then watches the
   goal's height, which the drone tracks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from groundstation import catenary
from groundstation.frozen import evolve

__all__ = [
    "OWN_TAUT_MARGIN_M",
    "QUIET_BAND_RATIO",
    "REFERENCE_TIME_CONSTANT_S",
    "FollowDecision",
    "FollowParams",
    "FollowState",
    "clamp_to_reach",
    "follow_step",
    "mark_stale",
    "set_enabled",
]

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]

QUIET_TIME_CONSTANT_S = 0.5
"""Averaging time of the pre-tug position (without motion capture), s."""

REFERENCE_TIME_CONSTANT_S = 2.0
"""Tracking time of the offset ``b`` between the estimate and the catenary's tension while
not following, s (step 4a): quick beside drift (thrust scale, battery), slow beside a tug."""

OWN_TAUT_MARGIN_M = 0.05
"""Step 4a takes the catenary's force no closer to taut than this (chord at most
``length_m`` minus it), m. Near taut that force is no model of the tether's own tension:
at 97 % of L = 1.6 m (omega = 0.05 N/m; 4.8 cm from taut) it is 0.105 N, and 2, 3, 4 cm
further out it is 29, 60, 136 mN more, beyond that there is no catenary at all. The
position (a motion-capture marker off the tether's attachment, a base measured by hand)
and the length (stretch, the reel's count) are known to a few cm, and the motion capture
jitters by a mm, which there moves the force by up to tens of mN: with the force taken at
the measured position, 3-5 cm of error switched following on with nobody pulling
(tests/test_follow.py). Pulled back to 5 cm from taut the force saturates (at 0.103 N
there), and ``b`` covers what is left. The price: a drone that moves deeper toward taut
after switch-on sees the tether's own rise there as pull; following it takes the drone
back from taut."""

QUIET_BAND_RATIO = 0.5
"""``b`` tracks only while the pull is below this fraction of the release level (0.04 N by
default). A tug rising to 0.10 N within 0.3 s spends ~0.1 s in that band and loses about
``(1 / 2 s) * (0.04 N * 0.1 s / 2)`` = 1 mN of itself to the tracking."""


@dataclass(frozen=True)
class FollowParams:
    """Tuning of tension following.

    Attributes:
        threshold_n: Pull (the tension beyond the tether's own) above which following
            engages, N, > 0.
        hysteresis_ratio: Following releases below ``threshold_n * (1 - ratio)``,
            dimensionless in [0, 1).
        land_below_m: Height (world z) below which an armed follower stops the motors,
            m; None disables tug-to-land.
        max_speed_mps: Largest setpoint speed, m/s, > 0.
        reach_margin_m: Setpoints stay within ``length_m - reach_margin_m`` of the base,
            m, >= 0.
        stale_after_s: Input older than this disengages following, s, > 0.
        floor_margin_m: Setpoints stay this far above the floor, m, >= 0.
        admittance_mps_per_n: Without motion capture, the goal moves along the pull at
            this speed per newton of pull (the tension beyond the one before the tug),
            m/s/N, > 0 (then capped at ``max_speed_mps``).
    """

    threshold_n: float = 0.10
    hysteresis_ratio: float = 0.2
    land_below_m: float | None = None
    max_speed_mps: float = 0.5
    reach_margin_m: float = 0.05
    stale_after_s: float = 0.5
    floor_margin_m: float = 0.05
    admittance_mps_per_n: float = 2.0

    def __post_init__(self) -> None:
        checks = [
            ("threshold_n", self.threshold_n, self.threshold_n > 0.0),
            ("hysteresis_ratio", self.hysteresis_ratio, 0.0 <= self.hysteresis_ratio < 1.0),
            ("max_speed_mps", self.max_speed_mps, self.max_speed_mps > 0.0),
            ("reach_margin_m", self.reach_margin_m, self.reach_margin_m >= 0.0),
            ("stale_after_s", self.stale_after_s, self.stale_after_s > 0.0),
            ("floor_margin_m", self.floor_margin_m, self.floor_margin_m >= 0.0),
            ("admittance_mps_per_n", self.admittance_mps_per_n, self.admittance_mps_per_n > 0),
        ]
        for name, value, ok in checks:
            if not (math.isfinite(value) and ok):
                raise ValueError(f"FollowParams.{name} out of range: {value!r}")
        if self.land_below_m is not None and not math.isfinite(self.land_below_m):
            raise ValueError(f"FollowParams.land_below_m must be finite, got {self.land_below_m!r}")

    @property
    def release_n(self) -> float:
        """Pull below which an active follower releases, N."""
        return self.threshold_n * (1.0 - self.hysteresis_ratio)


@dataclass(frozen=True)
class FollowState:
    """State of the follower between steps (immutable; each step returns a new one).

    Attributes:
        enabled: Following switched on by the operator.
        active: The pull is above the threshold: the goal follows the drone.
        landing_armed: A tug has happened with tug-to-land configured.
        stopped: A Stop was issued; terminal until enabled again.
        setpoint_world_m: The last published setpoint (the frozen goal), m, or None.
        setpoint_stamp_s: Stamp of that setpoint, s, or None.
        last_stamp_s: Stamp of the previous step, s, or None.
        reason: Why the follower is in this state (human-readable; "" when nothing to
            say).
        quiet_position_world_m: Without motion capture: the tether-based position
            before the pull (averaged while quiet), m, or None.
        own_offset_world_n: ``b`` of step 4a, the estimate minus the catenary's force at
            the reference position, tracked while not following, N, or None before the
            first step with a tension.
        catenary_world_n: The last finite catenary force at the reference position
            (``F_cat`` of step 4a), N, or None.
        pull_world_n: This step's pull ``T - T_own``, N, or None.
    """

    enabled: bool = False
    active: bool = False
    landing_armed: bool = False
    stopped: bool = False
    setpoint_world_m: Vec3 | None = None
    setpoint_stamp_s: float | None = None
    last_stamp_s: float | None = None
    reason: str = ""
    quiet_position_world_m: Vec3 | None = None
    own_offset_world_n: Vec3 | None = None
    catenary_world_n: Vec3 | None = None
    pull_world_n: Vec3 | None = None


@dataclass(frozen=True)
class FollowDecision:
    """Outcome of one :func:`follow_step`.

    Attributes:
        state: The next state.
        setpoint_world_m: Publish this Setpoint (world, m, shape (3,)), or None.
        stop_reason: Publish a Stop with this reason, or None.
    """

    state: FollowState
    setpoint_world_m: FloatArray | None = None
    stop_reason: str | None = None


def set_enabled(state: FollowState, enabled: bool) -> FollowState:
    """Applies an operator's FollowCommand.

    Enabling an already enabled (and not stopped) follower changes nothing, so a
    repeated command does not disarm landing. Enabling a disabled or stopped follower
    starts afresh: not active, landing disarmed, goal cleared. Disabling releases and
    disarms; a ``stopped`` flag stays visible until the next enable.

    Args:
        state: Current state.
        enabled: The requested mode.

    Returns:
        The next state.
    """
    if enabled:
        if state.enabled and not state.stopped:
            return state
        # A fresh start also forgets the last stamp: the gap before an enable is not a
        # stale input.
        return FollowState(enabled=True, reason="enabled")
    return replace(state, enabled=False, active=False, landing_armed=False, reason="disabled")


def mark_stale(state: FollowState, stamp_s: float | None = None) -> FollowState:
    """Disengages following because the input stopped or is known to be stale.

    Args:
        state: Current state.
        stamp_s: When the staleness was noticed, s (kept for the next step's gap
            check), or None to leave the previous stamp.

    Returns:
        The next state: not enabled, not active, landing disarmed, with the reason.
    """
    if not state.enabled and not state.active:
        return state
    return replace(
        state,
        enabled=False,
        active=False,
        landing_armed=False,
        last_stamp_s=state.last_stamp_s if stamp_s is None else stamp_s,
        reason="stale input: following disengaged",
    )


def clamp_to_reach(
    point_world_m: ArrayLike,
    base_world_m: ArrayLike,
    radius_m: float,
    min_z_m: float,
) -> FloatArray | None:
    """Closest point to ``point_world_m`` in the ball around the base above ``min_z_m``.

    The reachable set {|p - base| <= radius, z >= min_z} is convex; the Euclidean
    projection onto it is the projection onto the half-space if that lies in the ball,
    else onto the ball if that lies above ``min_z``, else onto the disc where the
    plane ``z = min_z`` cuts the ball.

    Args:
        point_world_m: Point, world, m, shape (3,).
        base_world_m: Centre of the ball (the tether's base exit), world, m, shape (3,).
        radius_m: Radius, m.
        min_z_m: Lowest allowed height, m (``-inf`` for none).

    Returns:
        The projected point, m, shape (3,), or None when the set is empty (radius < 0,
        or the plane lies above the ball) or an input is not finite.
    """
    p, b = _vec3(point_world_m), _vec3(base_world_m)
    if p is None or b is None:
        raise ValueError(f"points must have shape (3,), got {point_world_m!r}, {base_world_m!r}")
    q = _clamp(p, b, radius_m, min_z_m)
    return None if q is None else np.array(q)


def _clamp(p: Vec3, b: Vec3, radius_m: float, min_z_m: float) -> Vec3 | None:
    """:func:`clamp_to_reach` on three floats each (the per-message form)."""
    px, py, pz = p
    bx, by, bz = b
    if not (_finite(p) and _finite(b) and math.isfinite(radius_m)):
        return None
    if radius_m < 0.0 or math.isnan(min_z_m) or min_z_m > bz + radius_m:
        return None
    qz = max(pz, min_z_m)
    dx, dy, dz = px - bx, py - by, qz - bz
    if dx * dx + dy * dy + dz * dz <= radius_m * radius_m:
        return (px, py, qz)
    dz = pz - bz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    k = radius_m / dist  # dist > radius >= 0 here
    on_ball = (bx + dx * k, by + dy * k, bz + dz * k)
    if on_ball[2] >= min_z_m:
        return on_ball
    disc_r = math.sqrt(max(radius_m * radius_m - (min_z_m - bz) ** 2, 0.0))
    h_norm = math.hypot(dx, dy)
    if h_norm > disc_r:
        k = disc_r / h_norm
        dx, dy = dx * k, dy * k
    return (bx + dx, by + dy, min_z_m)


def _finite(v: Vec3) -> bool:
    return math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(v[2])


def _vec3(value: ArrayLike) -> Vec3 | None:
    """Three Python floats of a 3-array, list or tuple of numbers; None for another shape."""
    if type(value) is tuple and len(value) == 3:
        x, y, z = value
        if type(x) is float and type(y) is float and type(z) is float:
            return value
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,):
        return None
    x, y, z = arr.tolist()
    return (x, y, z)


def _finite_vec3(value: ArrayLike | None) -> Vec3 | None:
    """``value`` as three finite floats, or None (None, another shape, a non-finite entry)."""
    v = None if value is None else _vec3(value)
    return v if v is not None and _finite(v) else None


def _tether_own_force(
    reference_world_m: Vec3,
    base_world_m: Vec3,
    length_m: float,
    weight_n_per_m: float | None,
    floor_z_m: float,
) -> Vec3 | None:
    """The catenary's force on a drone at rest at ``reference_world_m`` (step 4a), or None.

    Within ``OWN_TAUT_MARGIN_M`` of taut the reference is first pulled back along the chord
    to that margin (:data:`OWN_TAUT_MARGIN_M`). None without ``weight_n_per_m``, or where
    the catenary has no finite answer (an end below the floor, bad inputs).
    """
    if weight_n_per_m is None:
        return None
    bx, by, bz = base_world_m
    cx, cy, cz = (
        reference_world_m[0] - bx,
        reference_world_m[1] - by,
        reference_world_m[2] - bz,
    )
    chord_m = math.sqrt(cx * cx + cy * cy + cz * cz)
    max_chord_m = length_m - OWN_TAUT_MARGIN_M
    if max_chord_m > 0.0 and chord_m > max_chord_m:
        k = max_chord_m / chord_m
        reference_world_m = (bx + cx * k, by + cy * k, bz + cz * k)
    try:
        force = catenary.tether_force_xyz(
            base_world_m, reference_world_m, length_m, weight_n_per_m, floor_z_m
        )
    except (catenary.CatenaryError, ValueError):
        return None
    return force if _finite(force) else None


def follow_step(
    state: FollowState,
    params: FollowParams,
    *,
    stamp_s: float,
    tension_norm_n: float | None,
    position_world_m: ArrayLike | None,
    base_world_m: ArrayLike,
    length_m: float,
    floor_z_m: float = -math.inf,
    stale: bool = False,
    tension_world_n: ArrayLike | None = None,
    position_is_external: bool = True,
    weight_n_per_m: float | None = None,
    on_ground: bool = False,
) -> FollowDecision:
    """One step of tension following and tug-to-land (see the module docstring).

    The vectors are Python floats throughout (three per vector; a handful of operations
    per message, for which numpy's per-call overhead cost more than the arithmetic):
    ``tests/test_follow_floats.py`` holds this step equal to the numpy one it replaced.

    Args:
        state: State after the previous step.
        params: Tuning.
        stamp_s: Stamp of this step's input, s (telemetry clock).
        tension_norm_n: Norm of the estimated tether tension, N, or None when there is
            no (converged) estimate. With ``tension_world_n`` given, only its presence
            counts (the pull is computed from the vector); without it, it is taken as
            the pull itself (a caller that has already removed the tether's own tension,
            e.g. a test of the state machine).
        position_world_m: Current drone position, world, m, shape (3,): motion capture
            when the telemetry has it, else the tether-based estimate; None if unknown.
        base_world_m: Tether base exit, world, m, shape (3,).
        length_m: Tether length paid out, m.
        floor_z_m: Floor height, m (``-inf`` for none).
        stale: The caller knows this input is stale: disengage.
        tension_world_n: The estimated tension vector, world, N, shape (3,): the pull is
            this minus the tether's own (step 4a). Needed when ``position_is_external``
            is False.
        position_is_external: True when ``position_world_m`` comes from motion capture
            (the paper's setting). False for the tether-based estimate, which a hand's
            pull corrupts: the goal then moves along the pull (admittance, step 6b).
        weight_n_per_m: Tether weight per length omega, N/m, for the catenary's own
            tension at the reference position (step 4a); None to use the slowly tracked
            quiet tension alone.
        on_ground: The drone is on the floor (the floor's push is no pull): no
            engagement, landing disarmed, the tether's own tension forgotten (it starts
            again at the first step in the air).

    Returns:
        The next state, and the setpoint and/or Stop to publish.

    Raises:
        ValueError: If ``stamp_s`` is not finite.
    """
    if not math.isfinite(stamp_s):
        raise ValueError(f"stamp_s must be finite, got {stamp_s!r}")
    prev = state.last_stamp_s
    state = evolve(state, last_stamp_s=stamp_s)

    # 1. Stale input disengages; the operator re-enables.
    if state.enabled or state.active:
        why = None
        if stale:
            why = "stale input: following disengaged"
        elif prev is not None and stamp_s - prev > params.stale_after_s:
            why = f"input gap {stamp_s - prev:.3f} s > {params.stale_after_s} s: disengaged"
        elif prev is not None and stamp_s < prev:
            why = f"stamp went backwards ({prev} -> {stamp_s}): disengaged"
        if why is not None:
            state = evolve(state, enabled=False, active=False, landing_armed=False, reason=why)
            return FollowDecision(state)

    # 2. Off, or stopped after tug-to-land.
    if not state.enabled or state.stopped:
        return FollowDecision(evolve(state, active=False))

    # 3. Never act on a missing position.
    position = _finite_vec3(position_world_m)
    if position is None:
        return FollowDecision(evolve(state, active=False, reason="no position: goal frozen"))
    base = _vec3(base_world_m)
    if base is None:
        raise ValueError(f"base_world_m must have shape (3,), got {base_world_m!r}")

    # 4. The pull beyond the tether's own tension, with hysteresis.
    dt_prev_s = max(stamp_s - prev, 0.0) if prev is not None else 0.0
    tension = _finite_vec3(tension_world_n)
    norm_n = tension_norm_n
    if norm_n is not None and not math.isfinite(norm_n):
        norm_n = None
    pull: Vec3 | None = None
    pull_n: float | None
    if tension is not None and norm_n is not None:
        # 4a. T_own = F_cat(p_ref) + b at the reference position.
        if position_is_external:
            reference = position
        elif state.active and state.setpoint_world_m is not None:
            reference = state.setpoint_world_m  # the goal the drone tracks
        else:
            quiet_p = _finite_vec3(state.quiet_position_world_m)
            reference = quiet_p if quiet_p is not None else position
        f_cat = _tether_own_force(reference, base, length_m, weight_n_per_m, floor_z_m)
        modelled = f_cat is not None
        if f_cat is None:  # keep the last answer where the catenary has none
            last_cat = _finite_vec3(state.catenary_world_n)
            f_cat = last_cat if last_cat is not None else _ZERO3
        tx, ty, tz = tension
        fx, fy, fz = f_cat
        offset = _finite_vec3(state.own_offset_world_n)
        if offset is None:
            # With motion capture the catenary at the measured position is the tether's own
            # tension, independently of the estimate: b starts at 0 (a hand already pulling
            # as following is switched on is a pull). Without it the reference position
            # comes from the tension itself: nobody is taken to pull at the switch-on.
            offset = _ZERO3 if (position_is_external and modelled) else (tx - fx, ty - fy, tz - fz)
        ox, oy, oz = offset
        pull = (tx - (fx + ox), ty - (fy + oy), tz - (fz + oz))  # T - (F_cat + b)
        pull_n = math.sqrt(pull[0] * pull[0] + pull[1] * pull[1] + pull[2] * pull[2])
        state = evolve(state, catenary_world_n=f_cat, own_offset_world_n=offset)
    else:
        pull_n = norm_n if tension_world_n is None and norm_n is not None else None
    if on_ground:
        active = False
        reason = "on the ground: goal frozen"
        state = evolve(
            state, own_offset_world_n=None, catenary_world_n=None, quiet_position_world_m=None
        )
    elif pull_n is None:
        active = False
        reason = "no tension estimate: goal frozen"
    else:
        active = bool(pull_n >= params.release_n if state.active else pull_n > params.threshold_n)
        reason = "following the pull" if active else "below threshold: goal frozen"
    # On the floor a tug-to-land has nothing left to do, and an arm kept from an earlier
    # flight must not stop the next take-off's spool-up: landing disarms.
    landing_armed = not on_ground and (
        state.landing_armed or (active and params.land_below_m is not None)
    )
    was_active = state.active
    state = evolve(
        state, active=active, landing_armed=landing_armed, reason=reason, pull_world_n=pull
    )
    admittance = not position_is_external and tension is not None and pull is not None
    if not active and not on_ground and tension is not None and pull is not None:
        # Not following: b tracks the estimate's offset from the catenary slowly, and
        # (without motion capture, where the tether-based position is valid while nobody
        # pulls) the quiet position is averaged over QUIET_TIME_CONSTANT_S, so the first
        # samples of a tug (the filter needs a few to see it) barely move it.
        assert state.catenary_world_n is not None and state.own_offset_world_n is not None
        fx, fy, fz = state.catenary_world_n
        ox, oy, oz = state.own_offset_world_n
        tx, ty, tz = tension
        # Only inside the quiet band: a tug's rise passes the band in a fraction of the
        # filter's ~0.3 s and is held out of b from there on.
        quiet = pull_n is not None and pull_n < QUIET_BAND_RATIO * params.release_n
        w_b = min(1.0, dt_prev_s / REFERENCE_TIME_CONSTANT_S) if quiet else 0.0
        offset_now = (  # b += w (T - F - b)
            ox + w_b * (tx - fx - ox),
            oy + w_b * (ty - fy - oy),
            oz + w_b * (tz - fz - oz),
        )
        state = evolve(state, own_offset_world_n=offset_now)
        if not position_is_external:
            prev_p = _finite_vec3(state.quiet_position_world_m)
            if prev_p is None:
                quiet_now = position
            else:
                w = min(1.0, dt_prev_s / QUIET_TIME_CONSTANT_S)
                qx, qy, qz = prev_p
                quiet_now = (
                    qx + w * (position[0] - qx),
                    qy + w * (position[1] - qy),
                    qz + w * (position[2] - qz),
                )
            state = evolve(state, quiet_position_world_m=quiet_now)

    # 6. While active, the goal: within reach and at a bounded speed.
    radius_m = length_m - params.reach_margin_m if math.isfinite(length_m) else math.nan
    min_z_m = floor_z_m + params.floor_margin_m if not math.isnan(floor_z_m) else math.nan
    target: Vec3 | None = None
    if active:
        last = _finite_vec3(state.setpoint_world_m)
        dt_s = (
            max(stamp_s - state.setpoint_stamp_s, 0.0)
            if last is not None and state.setpoint_stamp_s is not None
            else None
        )
        if admittance:
            # 6b. The tether-based position is wrong while a hand pulls (the pull is not
            # the catenary's), so the goal starts where the drone was before the tug and
            # moves along the pull: v = k (T - T_own), capped at max_speed_mps.
            assert pull is not None
            start = last if was_active else None
            if start is None:  # the tug begins: from the last position before it
                start = _finite_vec3(state.quiet_position_world_m)
                dt_s = 0.0
            if start is None:
                start = position
            k = params.admittance_mps_per_n
            vx, vy, vz = k * pull[0], k * pull[1], k * pull[2]
            speed = math.sqrt(vx * vx + vy * vy + vz * vz)
            if speed > params.max_speed_mps:
                k = params.max_speed_mps / speed
                vx, vy, vz = vx * k, vy * k, vz * k
            t = dt_s or 0.0
            goal = (start[0] + vx * t, start[1] + vy * t, start[2] + vz * t)
            target = _clamp(goal, base, radius_m, min_z_m)
        else:
            # 6a. The paper: the goal is the current position (motion capture).
            target = _clamp(position, base, radius_m, min_z_m)
            if target is not None and last is not None and dt_s is not None:
                max_step_m = params.max_speed_mps * dt_s
                sx, sy, sz = target[0] - last[0], target[1] - last[1], target[2] - last[2]
                dist = math.sqrt(sx * sx + sy * sy + sz * sz)
                if dist > max_step_m:
                    # Reach wins over the rate limit if the reachable set moved.
                    k = max_step_m / dist
                    goal = (last[0] + sx * k, last[1] + sy * k, last[2] + sz * k)
                    target = _clamp(goal, base, radius_m, min_z_m)
        if target is None:
            state = evolve(state, reason="position out of reach and no reachable goal")
            return FollowDecision(state)

    # 5. Tug-to-land: exactly one Stop, then terminal until enabled again. Without motion
    # capture the height during a pull is the goal's (the drone tracks it). On the
    # ground landing is disarmed (step 4), so nothing stops a spool-up.
    z_m = target[2] if (admittance and target is not None) else position[2]
    if state.landing_armed and params.land_below_m is not None and z_m < params.land_below_m:
        stop_reason = f"tug-to-land: z {z_m:.3f} m below land_below_m {params.land_below_m} m"
        state = evolve(state, enabled=False, active=False, stopped=True, reason=stop_reason)
        return FollowDecision(state, stop_reason=stop_reason)

    if target is None:
        return FollowDecision(state)
    state = evolve(state, setpoint_world_m=target, setpoint_stamp_s=stamp_s)
    out = np.array(target)
    out.setflags(write=False)
    return FollowDecision(state, setpoint_world_m=out)


_ZERO3: Vec3 = (0.0, 0.0, 0.0)
