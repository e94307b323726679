"""A tug under a hover: found in the filter's own innovations (the hover's thrust balance
enters through the velocity state, tension_kalman.HoverVelocity, so the accelerometer
model is the filter's observation throughout), and the hover ends (slow_accel.end_hover)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from groundstation.bus import Sample
from groundstation.pipeline import Pipeline
from groundstation.slow_accel import (
    HOVER_MEAN_S,
    SlowAccelParams,
    SlowAccelState,
    end_hover,
    slow_accel_step,
)
from groundstation.tension import TensionFilterParams
from groundstation.tension_change import exceedance_chi2
from tests.test_perf_equivalence import HOVER_N, _telemetry, pinned_settings

DT_S = 0.01
LEVEL = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


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
            hover_chi2=exceedance_chi2(TensionFilterParams().false_alarms_per_h, DT_S),
        )
        states.append(state)
    return states


def test_end_hover_ends_it_and_holds_the_hover_off_for_one_mean_window() -> None:
    rng = np.random.default_rng(4)
    state = _hovering(SlowAccelState(), rng, 600)[-1]
    assert state.quasi_static
    state = end_hover(state)
    assert not state.quasi_static
    flags = [s.quasi_static for s in _hovering(state, rng, 200, t0_s=6.0)]
    first = flags.index(True)
    assert first == pytest.approx(HOVER_MEAN_S / DT_S, abs=1)
    assert all(flags[first:])


def test_the_pipeline_answers_a_stamp_jump_under_a_hover() -> None:
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


def test_a_tug_under_a_hover_restarts_the_filter_and_ends_the_hover() -> None:
    """The pipeline hovers (the thrust balance fused through the velocity), then the
    tether pulls 40 mN more along x; the telemetry's thrust does not answer (the controller
    has not yet): the filter finds it in the accelerometer model and the hover ends."""
    rng = np.random.default_rng(5)
    pipe = Pipeline(pinned_settings())
    for k in range(600):
        pipe.handle(_telemetry(k, HOVER_N, rng), k * 0.004)
    drone = pipe.drones["cf1"]
    assert drone.slow.quasi_static
    before = drone.filter_control.change_detections
    pulled = HOVER_N + np.array([0.040, 0.0, 0.0])
    ended_at = None
    for k in range(600, 900):
        msg = _telemetry(k, HOVER_N, rng)
        body = json.loads(msg.payload)
        # The accelerometer feels the pull (f = (thrust + T) / m); the thrust is unchanged.
        body["accel_mps2"][0] += 0.040 / drone.params.drone.mass_kg
        pipe.handle(Sample(msg.key, json.dumps(body).encode()), k * 0.004)
        if drone.filter_control.change_detections > before:
            ended_at = k
            break
    assert ended_at is not None, "no detection within 1.2 s of the pull"
    assert not drone.slow.quasi_static and drone.slow.hover_hold_s > 0.0
    est = drone.filter.estimate
    assert est is not None
    assert abs(est.tension_world_n[0] - pulled[0]) < 0.015
