"""A tug under a hover, found on the accelerometer model (tension_change.HoverChangeTest),
and what the estimator does with it (the filter restarts, the hover ends)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.slow_accel import (
    HOVER_MEAN_S,
    SlowAccelParams,
    SlowAccelState,
    end_hover,
    slow_accel_step,
)
from groundstation.tension import TensionFilter, TensionFilterParams

DT_S = 0.01
SIGMA_N = 0.015
"""Per-sample noise of the accelerometer model, N: 0.5 m/s² of vibration on 30 g."""
LEVEL = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _run(
    test: object, ys: np.ndarray, hovering: bool = True
) -> list[tuple[int, tuple[list[float], tuple[float, ...], int]]]:
    found = []
    for i, y in enumerate(ys):
        out = test.push(  # type: ignore[attr-defined]
            (float(y[0]), float(y[1]), float(y[2])), DT_S, DT_S, hovering
        )
        if out is not None:
            found.append((i, out))
    return found


def _test() -> object:
    return TensionFilter(TensionFilterParams()).hover_change_test()


def test_white_noise_at_a_constant_tension_is_no_tug() -> None:
    """Ten minutes of hover at 100 Hz: no detection (the test's threshold is the filter's
    fast test's, 50 on a chi-square with 3 dof per window)."""
    rng = np.random.default_rng(7)
    level = np.array([-0.015, 0.0, -0.01])
    ys = level + rng.normal(0.0, SIGMA_N, (60_000, 3))
    assert _run(_test(), ys) == []


def test_a_step_is_found_within_its_information_limit_and_its_level_measured() -> None:
    """A 30 mN step along x, 2 σ per sample: found within the samples whose non-centrality
    n·(step/σ)² reaches the threshold times the noise shape's prior (κ = 1.5, so that n is
    about 19), and restarted at the level since the step."""
    rng = np.random.default_rng(3)
    level = np.array([-0.015, 0.0, -0.01])
    step = np.array([-0.030, 0.0, 0.0])
    ys = level + rng.normal(0.0, SIGMA_N, (1000, 3))
    ys[500:] += step
    found = _run(_test(), ys)
    assert len(found) >= 1
    i, (mean, var, window) = found[0]
    limit = math.ceil(50.0 * 1.5 * SIGMA_N**2 / 0.030**2)
    assert 500 <= i < 500 + 2 * limit
    assert abs(window - (i - 499)) <= 3 + 0.3 * (i - 499)
    truth = level + step
    assert np.all(np.abs(np.array(mean) - truth) < 4.0 * np.sqrt(var))
    assert np.all(np.array(var) > 0.0)


def test_out_of_the_hover_it_does_not_run() -> None:
    """Out of the hover the filter observes the accelerometer model itself and its own
    tests see a step: this one stays silent."""
    rng = np.random.default_rng(3)
    level = np.array([-0.015, 0.0, -0.01])
    ys = level + rng.normal(0.0, SIGMA_N, (1000, 3))
    ys[500:] += (-0.030, 0.0, 0.0)
    assert _run(_test(), ys, hovering=False) == []


def test_a_gap_breaks_the_windows() -> None:
    """A step across a gap longer than the filter's gap_s is no evidence: the windows start
    again after it (and fill before they can detect)."""
    test = _test()
    level = (-0.015, 0.0, -0.01)
    for _ in range(200):
        assert test.push(level, DT_S, DT_S, True) is None  # type: ignore[attr-defined]
    assert test.push((-0.2, 0.0, -0.01), 1.0, DT_S, True) is None  # type: ignore[attr-defined]


def _hovering(
    state: SlowAccelState, rng: np.random.Generator, n: int, t0_s: float = 0.0
) -> list[SlowAccelState]:
    """The slow stage's states over n samples of a level hover with 0.2 m/s² of vibration
    (and a 0.05 m/s² slow error along x)."""
    params = SlowAccelParams()
    states = []
    for i in range(n):
        v = rng.normal(0.0, 0.2, 3)
        state = slow_accel_step(
            state,
            params,
            dt_s=DT_S,
            stamp_s=t0_s + i * DT_S,
            accel_body_mps2=(0.05 + v[0], v[1], 9.81 + v[2]),
            R_world_body=LEVEL,
            phase="air",
            mocap_world_m=None,
        )
        states.append(state)
    return states


def test_end_hover_hands_the_band_back_and_holds_the_hover_off_for_one_mean_window() -> None:
    rng = np.random.default_rng(4)
    state = _hovering(SlowAccelState(), rng, 600)[-1]
    assert state.quasi_static and state.fast_body_mps2 != (0.0, 0.0, 0.0)
    state = end_hover(state)
    assert not state.quasi_static and state.fast_body_mps2 == (0.0, 0.0, 0.0)
    flags = [s.quasi_static for s in _hovering(state, rng, 200, t0_s=6.0)]
    first = flags.index(True)
    assert first == pytest.approx(HOVER_MEAN_S / DT_S, abs=1)
    assert all(flags[first:])


def test_the_filter_restarts_where_the_hover_test_says() -> None:
    filt = TensionFilter(TensionFilterParams())
    filt.update((0.0, 0.0, 0.0), DT_S)
    filt.restart_from([-0.04, 0.0, -0.01], [1e-5, 2e-5, 3e-5], (1e-4, 1e-4, 1e-4))
    est = filt.coast(0.0)
    assert est is not None
    assert est.tension_world_n.tolist() == [-0.04, 0.0, -0.01]
    assert np.allclose(est.std_n**2, [1e-5, 2e-5, 3e-5])
    fresh = TensionFilter(TensionFilterParams())
    fresh.restart_from([1.0, 1.0, 1.0], [1.0, 1.0, 1.0], (1.0, 1.0, 1.0))  # nothing to restart
    assert fresh.estimate is None


def test_a_stamp_jump_under_a_hover_is_no_error_and_no_tug() -> None:
    """Telemetry whose stamp jumps forward (a clock glitch) while the drone hovers: the
    test starts its level again after the gap instead of failing on it (a 12 s jump once
    divided by zero)."""
    test = _test()
    rng = np.random.default_rng(9)
    level = np.array([-0.015, 0.0, -0.01])
    for y in level + rng.normal(0.0, SIGMA_N, (300, 3)):
        test.push((float(y[0]), float(y[1]), float(y[2])), DT_S, DT_S, True)  # type: ignore[attr-defined]
    for jump_s in (12.0, 15.0, 1e6):
        y = (float(level[0]), float(level[1]), float(level[2]))
        assert test.push(y, jump_s, DT_S, True) is None  # type: ignore[attr-defined]
        assert test.push(y, DT_S, DT_S, True) is None  # type: ignore[attr-defined]


def test_the_pipeline_answers_a_stamp_jump_under_a_hover() -> None:
    import json

    from groundstation.bus import Sample
    from groundstation.pipeline import Pipeline
    from tests.test_perf_equivalence import HOVER_N, _telemetry, pinned_settings

    rng = np.random.default_rng(3)
    pipe = Pipeline(pinned_settings())
    for k in range(600):
        pipe.handle(_telemetry(k, HOVER_N, rng), k * 0.004)
    assert pipe.drones["cf1"].slow.quasi_static
    sample = _telemetry(600, HOVER_N, rng)
    body = json.loads(sample.payload)
    body["stamp_s"] += 15.0
    out = pipe.handle(Sample(sample.key, json.dumps(body).encode()), 600 * 0.004)
    assert [o.key for o in out] == ["tether/cf1/estimate"]
