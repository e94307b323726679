"""Tension following stepped on Python floats is the numpy step it replaced.

``groundstation/follow.py`` writes :func:`follow_step` (and :func:`clamp_to_reach`, and the
tether's own force of step 4a) on three Python floats per vector: with follow on, the numpy
version cost ~100 µs of a message's ~240 µs (its 3-vectors, ``np.all(np.isfinite(...))``,
and ``dataclasses.replace`` of a 12-field state up to eight times a step). Below,
:func:`reference_follow_step` is the numpy version it replaced (as it was at
221e68a), kept as the reference, as numpy's tether step is for the simulator's
(tests/test_sim_tether_floats.py). Both are stepped through the same randomized sequences —
quiet hover, tugs, reel-ins that move the reachable set, a floor under the goal, taut
tethers, stale gaps, stamps going backwards, missing and non-finite positions and
tensions, on the ground, with and without motion capture, tug-to-land — and must make the
same decisions and the same floats: to the bit where this machine's numpy sums a 3-vector
dot product left to right (probed at test time), else to 1e-12.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

from groundstation import catenary
from groundstation.follow import (
    OWN_TAUT_MARGIN_M,
    QUIET_BAND_RATIO,
    QUIET_TIME_CONSTANT_S,
    REFERENCE_TIME_CONSTANT_S,
    FollowDecision,
    FollowParams,
    FollowState,
    clamp_to_reach,
    follow_step,
    set_enabled,
)

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]

# ---------------------------------------------------------------- the reference (numpy)


def _ref_clamp_to_reach(
    point_world_m: ArrayLike,
    base_world_m: ArrayLike,
    radius_m: float,
    min_z_m: float,
) -> FloatArray | None:
    """:func:`groundstation.follow.clamp_to_reach` as it was at 221e68a."""
    p = np.asarray(point_world_m, dtype=np.float64)
    b = np.asarray(base_world_m, dtype=np.float64)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(b)) and math.isfinite(radius_m)):
        return None
    if radius_m < 0.0 or math.isnan(min_z_m) or min_z_m > b[2] + radius_m:
        return None
    q = p.copy()
    q[2] = max(q[2], min_z_m)
    d = q - b
    if float(d @ d) <= radius_m * radius_m:
        return q
    d = p - b
    dist = math.sqrt(float(d @ d))
    on_ball = b + d * (radius_m / dist)  # dist > radius > = 0 here
    if on_ball[2] >= min_z_m:
        return on_ball
    disc_r = math.sqrt(max(radius_m * radius_m - (min_z_m - b[2]) ** 2, 0.0))
    h = p[:2] - b[:2]
    h_norm = math.hypot(float(h[0]), float(h[1]))
    if h_norm > disc_r:
        h = h * (disc_r / h_norm)
    return np.array([b[0] + h[0], b[1] + h[1], min_z_m])


def _ref_finite_vec3(value: ArrayLike | None) -> FloatArray | None:
    if value is None:
        return None
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        return None
    return arr


def _ref_tether_own_force(
    reference_world_m: FloatArray,
    base_world_m: ArrayLike,
    length_m: float,
    weight_n_per_m: float | None,
    floor_z_m: float,
) -> FloatArray | None:
    """The tether's own force of step 4a, on arrays, as it was at 221e68a."""
    if weight_n_per_m is None:
        return None
    base = np.asarray(base_world_m, dtype=np.float64)
    chord = reference_world_m - base
    chord_m = math.sqrt(float(chord @ chord))
    max_chord_m = length_m - OWN_TAUT_MARGIN_M
    if max_chord_m > 0.0 and chord_m > max_chord_m:
        reference_world_m = base + chord * (max_chord_m / chord_m)
    try:
        force = catenary.tether_force(
            base_world_m, reference_world_m, length_m, weight_n_per_m, floor_z_m
        ).force_world_n
    except (catenary.CatenaryError, ValueError):
        return None
    return force if bool(np.all(np.isfinite(force))) else None


def reference_follow_step(
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
    """:func:`groundstation.follow.follow_step` on numpy arrays, as it was at 221e68a."""
    if not math.isfinite(stamp_s):
        raise ValueError(f"stamp_s must be finite, got {stamp_s!r}")
    prev = state.last_stamp_s
    state = replace(state, last_stamp_s=stamp_s)

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
            state = replace(state, enabled=False, active=False, landing_armed=False, reason=why)
            return FollowDecision(state)

    # 2. Off, or stopped after tug-to-land.
    if not state.enabled or state.stopped:
        return FollowDecision(replace(state, active=False))

    # 3. Never act on a missing position.
    position = _ref_finite_vec3(position_world_m)
    if position is None:
        return FollowDecision(replace(state, active=False, reason="no position: goal frozen"))

    # 4. The pull beyond the tether's own tension, with hysteresis.
    dt_prev_s = max(stamp_s - prev, 0.0) if prev is not None else 0.0
    tension = _ref_finite_vec3(tension_world_n)
    norm_n = tension_norm_n
    if norm_n is not None and not math.isfinite(norm_n):
        norm_n = None
    pull: FloatArray | None = None
    pull_n: float | None
    if tension is not None and norm_n is not None:
        # 4a. T_own = F_cat(p_ref) + b at the reference position.
        if position_is_external:
            reference = position
        elif state.active and state.setpoint_world_m is not None:
            reference = np.array(state.setpoint_world_m)  # the goal the drone tracks
        else:
            quiet_p = _ref_finite_vec3(state.quiet_position_world_m)
            reference = quiet_p if quiet_p is not None else position
        f_cat = _ref_tether_own_force(reference, base_world_m, length_m, weight_n_per_m, floor_z_m)
        modelled = f_cat is not None
        if f_cat is None:  # keep the last answer where the catenary has none
            last_cat = _ref_finite_vec3(state.catenary_world_n)
            f_cat = last_cat if last_cat is not None else np.zeros(3)
        offset = _ref_finite_vec3(state.own_offset_world_n)
        if offset is None:
            # With motion capture the catenary at the measured position is the tether's own
            # tension, independently of the estimate: b starts at 0 (a hand already pulling
            # as following is switched on is a pull). Without it the reference position
            # comes from the tension itself: nobody is taken to pull at the switch-on.
            offset = np.zeros(3) if (position_is_external and modelled) else tension - f_cat
        pull = tension - (f_cat + offset)
        pull_n = math.sqrt(float(pull @ pull))
        state = replace(
            state, catenary_world_n=_ref_vec3(f_cat), own_offset_world_n=_ref_vec3(offset)
        )
    else:
        pull_n = norm_n if tension_world_n is None and norm_n is not None else None
    if on_ground:
        active = False
        reason = "on the ground: goal frozen"
        state = replace(
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
    state = replace(
        state,
        active=active,
        landing_armed=landing_armed,
        reason=reason,
        pull_world_n=_ref_vec3(pull) if pull is not None else None,
    )
    admittance = not position_is_external and tension is not None and pull is not None
    if not active and not on_ground and tension is not None and pull is not None:
        # Not following: b tracks the estimate's offset from the catenary slowly, and
        # (without motion capture, where the tether-based position is valid while nobody
        # pulls) the quiet position is averaged over QUIET_TIME_CONSTANT_S, so the first
        # samples of a tug (the filter needs a few to see it) barely move it.
        f_cat_now = np.array(state.catenary_world_n)
        offset_now = np.array(state.own_offset_world_n)
        # Only inside the quiet band: a tug's rise passes the band in a fraction of the
        # filter's ~0.3 s and is held out of b from there on.
        quiet = pull_n is not None and pull_n < QUIET_BAND_RATIO * params.release_n
        w_b = min(1.0, dt_prev_s / REFERENCE_TIME_CONSTANT_S) if quiet else 0.0
        offset_now = offset_now + w_b * (tension - f_cat_now - offset_now)  # b += w (T - F - b)
        state = replace(state, own_offset_world_n=_ref_vec3(offset_now))
        if not position_is_external:
            prev_p = _ref_finite_vec3(state.quiet_position_world_m)
            w = 1.0 if prev_p is None else min(1.0, dt_prev_s / QUIET_TIME_CONSTANT_S)
            state = replace(
                state,
                quiet_position_world_m=_ref_vec3(
                    position if prev_p is None else prev_p + w * (position - prev_p)
                ),
            )

    # 6. While active, the goal: within reach and at a bounded speed.
    radius_m = length_m - params.reach_margin_m if math.isfinite(length_m) else math.nan
    min_z_m = floor_z_m + params.floor_margin_m if not math.isnan(floor_z_m) else math.nan
    target: FloatArray | None = None
    if active:
        last = _ref_finite_vec3(state.setpoint_world_m)
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
                start = _ref_finite_vec3(state.quiet_position_world_m)
                dt_s = 0.0
            if start is None:
                start = position
            velocity = params.admittance_mps_per_n * pull
            speed = math.sqrt(float(velocity @ velocity))
            if speed > params.max_speed_mps:
                velocity = velocity * (params.max_speed_mps / speed)
            target = _ref_clamp_to_reach(
                start + velocity * (dt_s or 0.0), base_world_m, radius_m, min_z_m
            )
        else:
            # 6a. The paper: the goal is the current position (motion capture).
            target = _ref_clamp_to_reach(position, base_world_m, radius_m, min_z_m)
            if target is not None and last is not None and dt_s is not None:
                max_step_m = params.max_speed_mps * dt_s
                step = target - last
                dist = math.sqrt(float(step @ step))
                if dist > max_step_m:
                    # Reach wins over the rate limit if the reachable set moved.
                    target = _ref_clamp_to_reach(
                        last + step * (max_step_m / dist), base_world_m, radius_m, min_z_m
                    )
        if target is None:
            state = replace(state, reason="position out of reach and no reachable goal")
            return FollowDecision(state)

    # 5. Tug-to-land: exactly one Stop, then terminal until enabled again. Without motion
    # capture the height during a pull is the goal's (the drone tracks it). On the
    # ground landing is disarmed (step 4), so nothing stops a spool-up.
    z_m = float(target[2]) if (admittance and target is not None) else float(position[2])
    if state.landing_armed and params.land_below_m is not None and z_m < params.land_below_m:
        stop_reason = f"tug-to-land: z {z_m:.3f} m below land_below_m {params.land_below_m} m"
        state = replace(state, enabled=False, active=False, stopped=True, reason=stop_reason)
        return FollowDecision(state, stop_reason=stop_reason)

    if target is None:
        return FollowDecision(state)
    setpoint = _ref_vec3(target)
    state = replace(state, setpoint_world_m=setpoint, setpoint_stamp_s=stamp_s)
    out = np.array(setpoint)
    out.setflags(write=False)
    return FollowDecision(state, setpoint_world_m=out)


def _ref_vec3(a: FloatArray) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))


# ---------------------------------------------------------------- the comparison

BASE = (0.0, 0.0, 0.754)


def _dot_is_left_to_right() -> bool:
    """Whether numpy's ``a @ b`` of 3-vectors is ``(a0 b0 + a1 b1) + a2 b2`` here."""
    rng = np.random.default_rng(0)
    for _ in range(2000):
        a, b = rng.normal(size=3) * rng.uniform(0.01, 10.0), rng.normal(size=3)
        x0, x1, x2 = a.tolist()
        y0, y1, y2 = b.tolist()
        if float(a @ b) != (x0 * y0 + x1 * y1) + x2 * y2:
            return False
    return True


EXACT = _dot_is_left_to_right()


def _same_float(a: float, b: float) -> bool:
    if EXACT or not (math.isfinite(a) and math.isfinite(b)):
        return a == b or (math.isnan(a) and math.isnan(b))
    return math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-15)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
            return False
        return a.shape == b.shape and all(map(_same_float, a.tolist(), b.tolist()))
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return _same_float(a, b)
    if isinstance(a, str) and isinstance(b, str) and not EXACT:
        return a.split(":")[0] == b.split(":")[0]  # a Stop's height, printed to 1 mm
    return type(a) is type(b) and a == b


def _assert_same(new: FollowDecision, ref: FollowDecision, where: str) -> None:
    for name in FollowState.__dataclass_fields__:
        a, b = getattr(new.state, name), getattr(ref.state, name)
        assert _same(a, b), f"{where}: state.{name} {a!r} != reference {b!r}"
        if a is not None and name.endswith(("_m", "_n")) and name != "reason":
            assert type(a) is tuple and all(type(x) is float for x in a), (where, name, a)
    assert _same(new.setpoint_world_m, ref.setpoint_world_m), (
        f"{where}: setpoint {new.setpoint_world_m!r} != {ref.setpoint_world_m!r}"
    )
    if new.setpoint_world_m is not None:
        assert not new.setpoint_world_m.flags.writeable
    assert new.stop_reason == ref.stop_reason or (
        not EXACT and _same(new.stop_reason, ref.stop_reason)
    ), where


def _as_given(v: Vec3 | None, rng: np.random.Generator) -> Any:
    """A vector as a caller may pass it: tuple, list or array."""
    if v is None:
        return None
    kind = rng.integers(3)
    return tuple(v) if kind == 0 else (list(v) if kind == 1 else np.array(v))


def _sequence(seed: int) -> tuple[int, dict[str, int]]:
    """Step both followers through one randomized flight; return steps and branches seen."""
    rng = np.random.default_rng(seed)
    external = bool(rng.integers(2))
    weight = 0.05 if rng.random() < 0.85 else None
    floor_z = 0.0 if rng.random() < 0.8 else -math.inf
    params = FollowParams(
        threshold_n=float(rng.choice([0.05, 0.10])),
        land_below_m=float(rng.choice([0.3, 0.6])) if rng.random() < 0.5 else None,
        max_speed_mps=float(rng.choice([0.05, 0.5])),
        hysteresis_ratio=0.2,
    )
    length = float(rng.choice([1.0, 1.6]))
    low = rng.random() < 0.3
    # Where the drone hovers: anywhere from near plumb to a few cm from taut.
    r = float(rng.uniform(0.05, 0.97)) * length
    elev = float(rng.uniform(-0.3, 1.2))
    p = np.array([r * math.cos(elev), 0.0, BASE[2] + r * math.sin(elev)])
    p[2] = max(p[2], 0.02)
    p = np.array(BASE) + (p - np.array(BASE)) * min(1.0, 0.99 * length / np.linalg.norm(p - BASE))
    new = ref = set_enabled(FollowState(), True)
    stamp = 0.0
    tug = np.zeros(3)
    seen: dict[str, int] = {}
    steps = 600
    for k in range(steps):
        u = rng.random()
        dt = 0.004
        if u < 0.004:
            dt = 0.7  # a gap: stale
        elif u < 0.008:
            dt = -0.01  # a stamp going backwards
        stamp += dt
        if rng.random() < 0.01:
            tug = np.zeros(3) if tug.any() else rng.normal(size=3) * float(rng.choice([0.05, 0.2]))
        if rng.random() < 0.02:
            length = max(0.3, length - float(rng.uniform(0.0, 0.4)))  # the reel takes in
        p = p + rng.normal(size=3) * 0.002 + tug * 0.02
        p[2] = max(p[2], floor_z if math.isfinite(floor_z) else -1.0)
        z = float(p[2])
        if low and 300 <= k < 360:
            # Skimming the floor (a motion-capture marker may read below it): the goal is
            # clamped onto the floor's margin, the catenary has no answer below the floor.
            z = float(rng.uniform(-0.01, 0.04))
        position: Vec3 | None = (float(p[0]), float(p[1]), z)
        if rng.random() < 0.01:
            position = None
        elif rng.random() < 0.005:
            position = (math.nan, 0.0, 1.0)
        try:
            own = catenary.tether_force(BASE, p, length, 0.05, floor_z).force_world_n
        except catenary.CatenaryError:
            own = np.array([0.0, 0.0, -0.05])
        t = own + tug + rng.normal(size=3) * 0.003
        tension: Vec3 = (float(t[0]), float(t[1]), float(t[2]))
        converged = rng.random() > 0.01
        if rng.random() < 0.003:
            tension = (0.0, math.inf, 0.0)
        on_ground = 200 <= k < 215 or rng.random() < 0.003
        kwargs: dict[str, Any] = dict(
            stamp_s=stamp,
            tension_norm_n=math.hypot(*tension) if converged else None,
            position_world_m=_as_given(position, rng),
            base_world_m=_as_given(BASE, rng),
            length_m=length if rng.random() > 0.003 else math.nan,
            floor_z_m=floor_z,
            stale=bool(rng.random() < 0.002),
            tension_world_n=_as_given(tension, rng) if converged else None,
            position_is_external=external,
            weight_n_per_m=weight,
            on_ground=on_ground,
        )
        d_new = follow_step(new, params, **kwargs)
        d_ref = reference_follow_step(ref, params, **kwargs)
        _assert_same(d_new, d_ref, f"seed {seed} step {k}")
        new, ref = d_new.state, d_ref.state
        for key, hit in (
            ("active", new.active),
            ("setpoint", d_new.setpoint_world_m is not None),
            ("stop", d_new.stop_reason is not None),
            ("stale", "disengaged" in new.reason),
            ("out of reach", "out of reach" in new.reason),
        ):
            seen[key] = seen.get(key, 0) + int(hit)
        if not new.enabled and rng.random() < 0.05:  # the operator enables it again
            new = set_enabled(new, True)
            ref = set_enabled(ref, True)
    return steps, seen


def test_float_step_is_the_numpy_step() -> None:
    seen: dict[str, int] = {}
    for seed in range(60):
        _, hits = _sequence(seed)
        for key, n in hits.items():
            seen[key] = seen.get(key, 0) + n
    # The sequences reached every branch that makes a decision.
    for key in ("active", "setpoint", "stop", "stale"):
        assert seen.get(key, 0) > 0, (key, seen)


@pytest.mark.parametrize(
    ("point", "base", "radius", "min_z"),
    [
        ((0.1, 0.2, 0.3), (0.0, 0.0, 0.5), 1.0, -1.0),  # inside
        ((0.1, 0.2, -0.3), (0.0, 0.0, 0.5), 1.0, 0.0),  # below the floor, inside
        ((3.0, 1.0, 0.9), (0.0, 0.0, 0.5), 1.0, 0.0),  # onto the ball
        ((3.0, 1.0, -2.0), (0.0, 0.0, 0.5), 1.0, 0.6),  # onto the disc
        ((0.0, 0.0, -2.0), (0.0, 0.0, 0.5), 1.0, 0.6),  # straight below: the disc's centre
        ((0.0, 0.0, 5.0), (0.0, 0.0, 0.5), 1.0, 1.5),  # plane above the ball
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.5), -0.1, -math.inf),  # no ball
        ((0.0, math.nan, 0.0), (0.0, 0.0, 0.5), 1.0, -math.inf),
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.5), 1.0, math.nan),
    ],
)
def test_clamp_is_the_numpy_clamp(point: Vec3, base: Vec3, radius: float, min_z: float) -> None:
    a = clamp_to_reach(point, base, radius, min_z)
    b = _ref_clamp_to_reach(point, base, radius, min_z)
    assert (a is None) == (b is None)
    if a is not None:
        assert _same(a, b), (a, b)


def test_a_different_step_is_caught() -> None:
    """The comparison can fail: a reference with a 1 % slower rate limit differs."""
    params = FollowParams(threshold_n=0.05, max_speed_mps=0.05)
    state = set_enabled(FollowState(), True)
    kwargs: dict[str, Any] = dict(
        tension_norm_n=0.3,
        base_world_m=BASE,
        length_m=1.6,
        floor_z_m=0.0,
        tension_world_n=(-0.25, 0.0, -0.1),
        weight_n_per_m=0.05,
    )
    a = b = state
    differs = False
    for k in range(50):
        pos = (0.5 + 0.01 * k, 0.0, 1.0)
        da = follow_step(a, params, stamp_s=0.004 * k, position_world_m=pos, **kwargs)
        db = reference_follow_step(
            b,
            replace(params, max_speed_mps=0.0495),
            stamp_s=0.004 * k,
            position_world_m=pos,
            **kwargs,
        )
        a, b = da.state, db.state
        if da.setpoint_world_m is not None and db.setpoint_world_m is not None:
            differs |= not _same(da.setpoint_world_m, db.setpoint_world_m)
    assert differs
