"""Tests of groundstation.follow: the tension-following / tug-to-land state machine."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import ArrayLike

from groundstation.follow import (
    FollowDecision,
    FollowParams,
    FollowState,
    clamp_to_reach,
    follow_step,
    mark_stale,
    set_enabled,
)

BASE_M = np.array([0.0, 0.0, 0.754])
LENGTH_M = 1.6
FLOOR_M = 0.0
DT_S = 0.004
PARAMS = FollowParams(threshold_n=0.15, hysteresis_ratio=0.2, max_speed_mps=0.5)


def step(
    state: FollowState,
    stamp_s: float,
    tension_n: float | None,
    position_m: ArrayLike | None,
    params: FollowParams = PARAMS,
    *,
    base_world_m: ArrayLike = BASE_M,
    length_m: float = LENGTH_M,
    floor_z_m: float = FLOOR_M,
    stale: bool = False,
) -> FollowDecision:
    return follow_step(
        state,
        params,
        stamp_s=stamp_s,
        tension_norm_n=tension_n,
        position_world_m=position_m,
        base_world_m=base_world_m,
        length_m=length_m,
        floor_z_m=floor_z_m,
        stale=stale,
    )


def test_import_does_not_pull_io_libraries() -> None:
    code = (
        "import sys, groundstation.follow\n"
        "bad = [m for m in ('zenoh', 'viser') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_disabled_publishes_nothing() -> None:
    state = FollowState()
    for k in range(10):
        d = step(state, k * DT_S, 1.0, [1.0, 0.0, 1.0])
        assert d.setpoint_world_m is None and d.stop_reason is None
        assert not d.state.active and not d.state.enabled
        state = d.state


def test_follow_engages_updates_and_freezes_with_hysteresis() -> None:
    state = set_enabled(FollowState(), True)
    t = 0.0
    # Below threshold: enabled but idle.
    d = step(state, t, 0.10, [1.0, 0.0, 1.0])
    assert d.state.enabled and not d.state.active and d.setpoint_world_m is None
    # Above threshold: the goal is the current position, every step.
    positions = [[1.0, 0.0, 1.0], [1.001, 0.0, 1.0], [1.002, 0.001, 1.0]]
    for p in positions:
        t += DT_S
        d = step(d.state, t, 0.20, p)
        assert d.state.active
        assert d.setpoint_world_m is not None
        np.testing.assert_allclose(d.setpoint_world_m, p, atol=1e-12)
    # Between release (0.12 N) and threshold (0.15 N): stays active.
    t += DT_S
    d = step(d.state, t, 0.13, [1.003, 0.001, 1.0])
    assert d.state.active and d.setpoint_world_m is not None
    frozen = d.state.setpoint_world_m
    # Below release: the goal freezes; no new setpoints.
    for p in ([1.1, 0.0, 1.0], [1.2, 0.0, 1.0]):
        t += DT_S
        d = step(d.state, t, 0.11, p)
        assert not d.state.active and d.setpoint_world_m is None
        assert d.state.setpoint_world_m == frozen
    # Between release and threshold while released: stays released.
    t += DT_S
    d = step(d.state, t, 0.14, [1.2, 0.0, 1.0])
    assert not d.state.active and d.setpoint_world_m is None
    assert PARAMS.release_n == pytest.approx(0.12)


def test_tug_to_land_issues_exactly_one_stop() -> None:
    params = replace(PARAMS, land_below_m=0.3, max_speed_mps=100.0)
    state = set_enabled(FollowState(), True)
    t = 0.0
    # Below the landing height before any tug: landing is not armed, no Stop.
    d = step(state, t, 0.05, [0.5, 0.0, 0.2], params)
    assert d.stop_reason is None and not d.state.landing_armed
    # The tug (first activation) arms landing; the drone is pulled down.
    stops = []
    z = 1.0
    for _ in range(400):
        t += DT_S
        d = step(d.state, t, 0.3, [0.5, 0.0, z], params)
        z -= 0.004
        stops.append(d.stop_reason)
    # The operator lets go while the drone is already below: nothing more happens.
    for _ in range(50):
        t += DT_S
        d = step(d.state, t, 0.0, [0.5, 0.0, 0.1], params)
        stops.append(d.stop_reason)
    issued = [s for s in stops if s is not None]
    assert len(issued) == 1 and "tug-to-land" in issued[0]
    assert d.state.stopped and not d.state.active and not d.state.enabled
    # Re-enabling starts afresh.
    fresh = set_enabled(d.state, True)
    assert fresh.enabled and not fresh.stopped and not fresh.landing_armed
    assert fresh.setpoint_world_m is None


def test_landing_armed_after_release_still_lands() -> None:
    params = replace(PARAMS, land_below_m=0.3)
    d = step(set_enabled(FollowState(), True), 0.0, 0.3, [0.5, 0.0, 1.0], params)
    assert d.state.landing_armed
    d = step(d.state, DT_S, 0.0, [0.5, 0.0, 0.6], params)
    assert not d.state.active and d.stop_reason is None
    d = step(d.state, 2 * DT_S, 0.0, [0.5, 0.0, 0.29], params)
    assert d.stop_reason is not None and d.state.stopped


def test_no_landing_without_land_below() -> None:
    d = step(set_enabled(FollowState(), True), 0.0, 0.3, [0.5, 0.0, 0.01])
    assert not d.state.landing_armed and d.stop_reason is None


def test_repeated_enable_keeps_landing_armed() -> None:
    params = replace(PARAMS, land_below_m=0.3)
    d = step(set_enabled(FollowState(), True), 0.0, 0.3, [0.5, 0.0, 1.0], params)
    again = set_enabled(d.state, True)
    assert again == d.state
    off = set_enabled(d.state, False)
    assert not off.enabled and not off.active and not off.landing_armed


def test_setpoint_clamped_within_reach_and_above_floor() -> None:
    state = set_enabled(FollowState(), True)
    radius = LENGTH_M - PARAMS.reach_margin_m
    # Far beyond reach (a bad tether-based estimate): projected onto the sphere.
    d = step(state, 0.0, 0.5, [5.0, 0.0, 0.754])
    assert d.setpoint_world_m is not None
    np.testing.assert_allclose(d.setpoint_world_m, [radius, 0.0, 0.754], atol=1e-12)
    # Below the floor: lifted to the floor margin.
    d = step(set_enabled(FollowState(), True), 0.0, 0.5, [0.5, 0.2, -0.3])
    assert d.setpoint_world_m is not None
    np.testing.assert_allclose(d.setpoint_world_m, [0.5, 0.2, PARAMS.floor_margin_m])


def test_clamp_to_reach_cases() -> None:
    b = np.array([0.0, 0.0, 0.0])
    # Inside: unchanged.
    np.testing.assert_array_equal(clamp_to_reach([0.1, 0.2, 0.3], b, 1.0, -1.0), [0.1, 0.2, 0.3])
    # Outside the ball and below the plane: on the disc.
    p = clamp_to_reach([3.0, 0.0, -2.0], b, 1.0, 0.6)
    assert p is not None
    np.testing.assert_allclose(p, [0.8, 0.0, 0.6], atol=1e-12)
    # Plane above the ball: no reachable point.
    assert clamp_to_reach([0.0, 0.0, 5.0], b, 1.0, 1.5) is None
    assert clamp_to_reach([0.0, 0.0, 0.0], b, -0.1, -math.inf) is None
    assert clamp_to_reach([0.0, math.nan, 0.0], b, 1.0, -math.inf) is None


def test_setpoints_rate_limited() -> None:
    params = replace(PARAMS, max_speed_mps=0.5)
    d = step(set_enabled(FollowState(), True), 0.0, 0.5, [0.5, 0.0, 1.0], params)
    previous = np.array(d.setpoint_world_m)
    # The position estimate jumps 20 cm in one step: the setpoint moves 2 mm.
    for k in range(1, 20):
        d = step(d.state, k * DT_S, 0.5, [0.7, 0.0, 1.0], params)
        assert d.setpoint_world_m is not None
        moved = float(np.linalg.norm(d.setpoint_world_m - previous))
        assert moved <= params.max_speed_mps * DT_S + 1e-12
        previous = np.array(d.setpoint_world_m)
    assert previous[0] == pytest.approx(0.5 + 19 * 0.5 * DT_S)


def test_stale_gap_disengages() -> None:
    params = replace(PARAMS, land_below_m=0.3)
    d = step(set_enabled(FollowState(), True), 0.0, 0.5, [0.5, 0.0, 1.0], params)
    assert d.state.active
    d = step(d.state, 0.0 + 0.6, 0.5, [0.5, 0.0, 1.0], params)
    assert not d.state.enabled and not d.state.active and not d.state.landing_armed
    assert d.setpoint_world_m is None and "gap" in d.state.reason
    # It stays off until enabled again.
    d = step(d.state, 0.604, 0.5, [0.5, 0.0, 1.0], params)
    assert d.setpoint_world_m is None
    d = step(set_enabled(d.state, True), 0.608, 0.5, [0.5, 0.0, 1.0], params)
    assert d.state.active and d.setpoint_world_m is not None


def test_enable_after_silence_is_not_stale() -> None:
    d = step(FollowState(), 0.0, 0.0, [0.5, 0.0, 1.0])
    d = step(set_enabled(d.state, True), 100.0, 0.5, [0.5, 0.0, 1.0])
    assert d.state.active


def test_stale_signal_and_mark_stale_and_backwards_stamp() -> None:
    d = step(set_enabled(FollowState(), True), 0.0, 0.5, [0.5, 0.0, 1.0])
    stale = step(d.state, DT_S, 0.5, [0.5, 0.0, 1.0], stale=True)
    assert not stale.state.enabled and stale.setpoint_world_m is None
    marked = mark_stale(d.state)
    assert not marked.enabled and not marked.active and "stale" in marked.reason
    assert mark_stale(d.state, 7.0).last_stamp_s == 7.0
    back = step(d.state, -1.0, 0.5, [0.5, 0.0, 1.0])
    assert not back.state.enabled and "backwards" in back.state.reason


def test_missing_position_never_acts() -> None:
    d = step(set_enabled(FollowState(), True), 0.0, 0.5, [0.5, 0.0, 1.0])
    for bad in (None, [math.nan, 0.0, 1.0], [1.0, 2.0]):
        out = step(d.state, DT_S, 0.5, bad)
        assert out.setpoint_world_m is None and not out.state.active
        assert out.state.enabled and out.state.setpoint_world_m == d.state.setpoint_world_m
    out = step(d.state, DT_S, None, [0.5, 0.0, 1.0])
    assert out.setpoint_world_m is None and not out.state.active


def test_invalid_stamp_and_params_raise() -> None:
    with pytest.raises(ValueError, match="stamp_s"):
        step(FollowState(), math.nan, 0.5, [0.5, 0.0, 1.0])
    with pytest.raises(ValueError, match="hysteresis_ratio"):
        FollowParams(hysteresis_ratio=1.0)
    with pytest.raises(ValueError, match="threshold_n"):
        FollowParams(threshold_n=0.0)
    with pytest.raises(ValueError, match="land_below_m"):
        FollowParams(land_below_m=math.inf)


finite = st.floats(-10.0, 10.0, allow_nan=False)
maybe_bad = st.one_of(finite, st.just(math.nan), st.just(math.inf))


@given(
    steps=st.lists(
        st.tuples(
            st.floats(0.0, 0.6),  # dt to the next step, s
            st.one_of(st.none(), st.floats(0.0, 1.0), st.just(math.nan)),  # |T|, N
            st.one_of(st.none(), st.tuples(maybe_bad, maybe_bad, maybe_bad)),  # position
            st.floats(0.0, 3.0),  # length paid out, m
            st.booleans(),  # an enable/disable command before this step
        ),
        min_size=1,
        max_size=40,
    ),
    base=st.tuples(finite, finite, st.floats(-1.0, 2.0)),
    floor=st.one_of(st.just(-math.inf), st.floats(-1.0, 1.0)),
    land=st.one_of(st.none(), st.floats(-1.0, 2.0)),
)
@settings(max_examples=200, deadline=None)
def test_property_setpoints_finite_within_reach_and_one_stop(
    steps: list[tuple[float, float | None, tuple[float, float, float] | None, float, bool]],
    base: tuple[float, float, float],
    floor: float,
    land: float | None,
) -> None:
    params = replace(PARAMS, land_below_m=land)
    state = set_enabled(FollowState(), True)
    t = 0.0
    stops_since_enable = 0
    for dt, tension, position, length, toggle in steps:
        if toggle:
            state = set_enabled(state, not state.enabled)
            if state.enabled:
                stops_since_enable = 0
        t += dt
        d = step(
            state, t, tension, position, params,
            base_world_m=np.array(base), length_m=length, floor_z_m=floor,
        )  # fmt: skip
        if d.setpoint_world_m is not None:
            sp = d.setpoint_world_m
            assert np.all(np.isfinite(sp))
            assert position is not None and np.all(np.isfinite(position))
            radius = length - params.reach_margin_m
            assert np.linalg.norm(sp - np.array(base)) <= radius + 1e-9
            assert sp[2] >= floor + params.floor_margin_m - 1e-9
            assert d.state.enabled and d.state.active
        if d.stop_reason is not None:
            stops_since_enable += 1
            assert stops_since_enable == 1
            assert d.state.stopped
        state = d.state


# ---------------------------------------------------------------- without motion capture


def _admit(
    state: FollowState,
    stamp_s: float,
    tension: tuple[float, float, float],
    position: tuple[float, float, float],
    params: FollowParams = PARAMS,
) -> FollowDecision:
    return follow_step(
        state,
        params,
        stamp_s=stamp_s,
        tension_norm_n=float(np.linalg.norm(tension)),
        position_world_m=position,
        base_world_m=(0.0, 0.0, 0.754),
        length_m=1.6,
        floor_z_m=0.0,
        tension_world_n=tension,
        position_is_external=False,
    )


def test_without_mocap_the_goal_moves_along_the_pull_from_the_pre_tug_position() -> None:
    hover_t = (-0.014, 0.0, -0.046)
    state = set_enabled(FollowState(), True)
    for k in range(250):  # 1 s of quiet hover at (1, 0, 1)
        state = _admit(state, k * 0.004, hover_t, (1.0, 0.0, 1.0)).state
    assert state.quiet_position_world_m == pytest.approx((1.0, 0.0, 1.0))
    pull = np.array([-0.2, 0.0, 0.0])
    wrong_position = (1.5, -0.3, 0.76)  # what the catenary makes of the hand's pull
    setpoints = []
    for k in range(250, 500):  # 1 s of pull toward -x
        d = _admit(state, k * 0.004, tuple(np.add(hover_t, pull)), wrong_position)
        state = d.state
        assert state.active
        assert d.setpoint_world_m is not None
        setpoints.append(d.setpoint_world_m)
    assert setpoints[0] == pytest.approx((1.0, 0.0, 1.0), abs=1e-9)
    # v = k * pull = 2 m/s/N * 0.2 N = 0.4 m/s for ~1 s, along -x only
    assert setpoints[-1][0] == pytest.approx(1.0 - 0.4 * 0.996, abs=1e-6)
    assert setpoints[-1][1:] == pytest.approx((0.0, 1.0), abs=1e-9)
    # released: the goal freezes where it is
    d = _admit(state, 2.0, hover_t, wrong_position)
    assert not d.state.active and d.setpoint_world_m is None


def test_without_mocap_tug_to_land_uses_the_goal_height() -> None:
    params = FollowParams(threshold_n=0.15, land_below_m=0.25, max_speed_mps=0.5)
    hover_t = (-0.014, 0.0, -0.046)
    state = set_enabled(FollowState(), True)
    for k in range(100):
        state = _admit(state, k * 0.004, hover_t, (0.6, 0.0, 0.5), params).state
    down = tuple(np.add(hover_t, (0.0, 0.0, -0.25)))
    stops = []
    for k in range(100, 1000):
        # the catenary reads the downward pull as a drone far below: never trusted here
        d = _admit(state, k * 0.004, down, (0.2, 0.0, 2.0), params)
        state = d.state
        if d.stop_reason is not None:
            stops.append((k * 0.004, d.stop_reason))
        elif d.setpoint_world_m is not None:
            assert d.setpoint_world_m[2] >= 0.25 - 1e-9
    assert len(stops) == 1
    # from z = 0.5 down at 0.5 m/s: below 0.25 after ~0.5 s
    assert stops[0][0] == pytest.approx(0.4 + 0.5, abs=0.02)


# ---------------------------------------------------------------- the tether's own tension

NEAR_TAUT = [  # (length, fraction of it, tether force there) with omega = 0.05 N/m
    pytest.param(1.6, 0.97, id="97%-of-1.6m"),
    pytest.param(3.0, 0.90, id="90%-of-3m"),
]


def _near_taut_spot(length_m: float, fraction: float) -> np.ndarray:
    """A drone 0.3 m above the base at ``fraction`` of the length from it."""
    chord = fraction * length_m
    return BASE_M + np.array([math.sqrt(chord**2 - 0.3**2), 0.0, 0.3])


@pytest.mark.parametrize("pull_n", [0.09, 0.105])
@pytest.mark.parametrize("external", [True, False], ids=["mocap", "no-mocap"])
@pytest.mark.parametrize(("length_m", "fraction"), NEAR_TAUT)
def test_near_taut_nobody_pulling_never_engages_and_a_pull_does(
    length_m: float, fraction: float, external: bool, pull_n: float
) -> None:
    """The threshold (0.10 N) means a hand's pull, near taut too: 6 s of hover with nobody
    pulling never engages, arms landing or moves the goal; then a pull rising in 0.3 s
    engages at 0.105 N (the tracking of b takes ~1 mN of its rise) and not at 0.09 N."""
    from groundstation.catenary import tether_force

    spot = _near_taut_spot(length_m, fraction)
    own = np.asarray(tether_force(BASE_M, spot, length_m, 0.05, FLOOR_M).force_world_n)
    params = FollowParams(threshold_n=0.10, land_below_m=0.9)
    assert np.linalg.norm(own) > params.threshold_n, "the premise: |T| alone exceeds it"
    rng = np.random.default_rng(7)
    state = set_enabled(FollowState(), True)
    engaged_at = None
    for k in range(2500):  # 6 s quiet, then the pull toward the base for 4 s
        t = k * DT_S
        hand = np.array([-pull_n * min(1.0, max(0.0, t - 6.0) / 0.3), 0.0, 0.0])
        # The filtered estimate (~0.5 mN per axis) and 1 mm of motion-capture noise; the
        # tether-based position without motion capture (what the catenary makes of T).
        tension = own + hand + rng.normal(0.0, 5e-4, 3)
        position = spot + rng.normal(0.0, 1e-3, 3)
        d = follow_step(
            state,
            params,
            stamp_s=t,
            tension_norm_n=float(np.linalg.norm(tension)),
            position_world_m=position,
            base_world_m=BASE_M,
            length_m=length_m,
            floor_z_m=FLOOR_M,
            tension_world_n=tension,
            position_is_external=external,
            weight_n_per_m=0.05,
        )
        state = d.state
        if t < 6.0:
            assert not state.active and not state.landing_armed, (t, state.pull_world_n)
            assert d.setpoint_world_m is None and d.stop_reason is None
        elif state.active and engaged_at is None:
            engaged_at = t
    if pull_n > params.threshold_n:
        assert engaged_at is not None and engaged_at - 6.0 < 0.5, engaged_at
        assert state.landing_armed
    else:
        assert engaged_at is None and not state.landing_armed


def test_pull_is_measured_from_the_catenary_at_the_motion_capture_position() -> None:
    """With motion capture the reference moves with the drone: flying slowly from a slack
    spot to near taut (|T| from 0.02 to 0.10 N) is no pull; a steady model error (here a
    5 mN thrust bias) is the pull at first and is absorbed into b over a few seconds."""
    from groundstation.catenary import tether_force

    params = FollowParams(threshold_n=0.10, hysteresis_ratio=0.2)
    state = set_enabled(FollowState(), True)
    start, end = BASE_M + np.array([0.8, 0.0, 0.3]), _near_taut_spot(1.6, 0.97)
    bias = np.array([0.0, 0.0, 0.005])
    n = 2500
    for k in range(n):
        p = start + (end - start) * k / (n - 1)  # 0.75 m in 10 s
        own = np.asarray(tether_force(BASE_M, p, 1.6, 0.05, FLOOR_M).force_world_n)
        d = follow_step(
            state,
            params,
            stamp_s=k * DT_S,
            tension_norm_n=float(np.linalg.norm(own + bias)),
            position_world_m=p,
            base_world_m=BASE_M,
            length_m=1.6,
            floor_z_m=FLOOR_M,
            tension_world_n=own + bias,
            weight_n_per_m=0.05,
        )
        state = d.state
        assert not state.active and d.setpoint_world_m is None
        assert state.pull_world_n is not None
        assert np.linalg.norm(state.pull_world_n) <= 0.005 + 1e-9
    assert state.own_offset_world_n == pytest.approx(tuple(bias), abs=1e-4)


def test_on_the_ground_nothing_engages_or_arms_and_the_reference_restarts() -> None:
    params = FollowParams(threshold_n=0.10, land_below_m=0.5)
    state = set_enabled(FollowState(), True)
    floor_push = (0.0, 0.0, 0.144)  # 0.51 of the weight on the floor, seen as "tension"
    for k in range(100):
        d = follow_step(
            state,
            params,
            stamp_s=k * DT_S,
            tension_norm_n=0.144,
            position_world_m=(0.3, 0.0, 0.0),
            base_world_m=BASE_M,
            length_m=1.6,
            floor_z_m=FLOOR_M,
            tension_world_n=floor_push if k > 10 else (0.0, 0.0, 0.0),
            weight_n_per_m=0.05,
            on_ground=True,
        )
        state = d.state
        assert not state.active and not state.landing_armed
        assert d.setpoint_world_m is None and d.stop_reason is None
    assert state.own_offset_world_n is None and "ground" in state.reason


def test_with_mocap_a_pull_already_acting_at_switch_on_engages() -> None:
    """Motion capture says where the drone is, so the catenary there is the tether's own
    tension: a hand already pulling with 0.2 N when following is switched on is a pull."""
    from groundstation.catenary import tether_force

    spot = BASE_M + np.array([0.3, 0.0, -0.25])
    own = np.asarray(tether_force(BASE_M, spot, 1.6, 0.05, FLOOR_M).force_world_n)
    tension = own + np.array([0.0, 0.0, -0.2])
    d = follow_step(
        set_enabled(FollowState(), True),
        FollowParams(threshold_n=0.1, land_below_m=0.6),
        stamp_s=0.0,
        tension_norm_n=float(np.linalg.norm(tension)),
        position_world_m=spot,
        base_world_m=BASE_M,
        length_m=1.6,
        floor_z_m=FLOOR_M,
        tension_world_n=tension,
        weight_n_per_m=0.05,
    )
    # The pull engages (and arms landing); z 0.504 m < 0.6 m: the one Stop of tug-to-land.
    assert d.state.landing_armed and d.state.stopped and d.stop_reason is not None


@pytest.mark.parametrize("error_m", [-0.05, -0.02, 0.02, 0.03, 0.04, 0.05])
@pytest.mark.parametrize("kind", ["position", "length"])
def test_near_taut_with_mocap_a_model_error_is_no_pull(kind: str, error_m: float) -> None:
    """At 97 % of L = 1.6 m the tether's own force changes by 12-70 mN per
    cm of reach, so 2-5 cm of error in the motion-capture position (a marker off the
    tether's attachment, a base measured by hand) or in the tether's length makes the
    catenary there differ from the tension by up to 0.14 N (+4 cm) with nobody pulling.
    Switched on in quiet hover, following neither engages nor arms landing nor moves the
    goal for 6 s; a 0.15 N pull then engages."""
    from groundstation.catenary import tether_force

    spot = _near_taut_spot(1.6, 0.97)
    own = np.asarray(tether_force(BASE_M, spot, 1.6, 0.05, FLOOR_M).force_world_n)
    radial = (spot - BASE_M) / np.linalg.norm(spot - BASE_M)
    seen = spot + error_m * radial if kind == "position" else spot
    length_m = 1.6 - error_m if kind == "length" else 1.6
    params = FollowParams(threshold_n=0.10, land_below_m=0.9)
    rng = np.random.default_rng(11)
    state = set_enabled(FollowState(), True)
    engaged_at = None
    for k in range(2000):  # 6 s quiet, then a pull toward the base
        t = k * DT_S
        hand = np.array([-0.15 * min(1.0, max(0.0, t - 6.0) / 0.3), 0.0, 0.0])
        tension = own + hand + rng.normal(0.0, 5e-4, 3)
        d = follow_step(
            state,
            params,
            stamp_s=t,
            tension_norm_n=float(np.linalg.norm(tension)),
            position_world_m=seen + rng.normal(0.0, 1e-3, 3),
            base_world_m=BASE_M,
            length_m=length_m,
            floor_z_m=FLOOR_M,
            tension_world_n=tension,
            position_is_external=True,
            weight_n_per_m=0.05,
        )
        state = d.state
        if t < 6.0:
            assert not state.active and not state.landing_armed, (t, state.pull_world_n)
            assert d.setpoint_world_m is None and d.stop_reason is None
        elif state.active and engaged_at is None:
            engaged_at = t
    assert engaged_at is not None and engaged_at - 6.0 < 0.5, engaged_at


def test_landing_armed_in_the_air_is_disarmed_when_found_on_the_ground() -> None:
    """A tug armed landing in the air (above land_below_m: no Stop yet); the drone is then
    found on the ground (an operator landed it, or it was set down): landing disarms at
    once and no Stop is sent, whatever the floor's push reads as, so the next spool-up is
    never stopped; in the air again nothing is armed until the next tug."""
    params = FollowParams(threshold_n=0.10, land_below_m=0.3)
    state = replace(set_enabled(FollowState(), True), landing_armed=True)
    d = follow_step(
        state,
        params,
        stamp_s=0.0,
        tension_norm_n=0.144,
        position_world_m=(0.5, 0.0, 0.0),  # below land_below_m
        base_world_m=BASE_M,
        length_m=1.6,
        floor_z_m=FLOOR_M,
        tension_world_n=(0.0, 0.0, 0.144),
        weight_n_per_m=0.05,
        on_ground=True,
    )
    assert not d.state.landing_armed and not d.state.active and not d.state.stopped
    assert d.stop_reason is None and d.setpoint_world_m is None
    assert d.state.enabled, "following stays switched on"
    for k in range(1, 50):  # lifted off again, hovering low, nobody pulling
        d = follow_step(
            d.state,
            params,
            stamp_s=k * DT_S,
            tension_norm_n=0.01,
            position_world_m=(0.5, 0.0, 0.2),
            base_world_m=BASE_M,
            length_m=1.6,
            floor_z_m=FLOOR_M,
            tension_world_n=(0.0, 0.0, -0.01),
            weight_n_per_m=0.05,
        )
        assert not d.state.landing_armed and d.stop_reason is None
