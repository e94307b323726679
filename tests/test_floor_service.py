"""The contract floor of the load benchmarks (benchmarks/floor_service.py) does what it claims:
one valid Estimate per accepted Telemetry, from a real Kalman step, and nothing for bad input.

It is the lower bound that docs/service_bursts.md compares the service with, so a floor that
skipped a step (or answered from nothing) would flatter the service."""

from __future__ import annotations

import numpy as np

from benchmarks.floor_service import _new_filter, estimate_bytes
from benchmarks.service_rig import telemetry_payloads
from groundstation.messages import Estimate


def test_floor_answers_each_telemetry_with_an_estimate_that_tracks_the_tension() -> None:
    rows = telemetry_payloads(1, 1500, seed=3)
    kf = _new_filter()
    estimates = []
    for row in rows:
        out = estimate_bytes(kf, row[0])
        assert out is not None
        estimates.append(Estimate.model_validate_json(out))
    assert [e.seq for e in estimates] == list(range(len(rows)))
    # The rig's drone hovers against a tether pull of (-0.02, 0, -0.06) N with IMU noise:
    # after 6 s at 250 Hz the filter's mean sits within a few mN of it, and it moved there
    # (the first estimate is one noisy sample).
    truth = np.array([-0.02, 0.0, -0.06])
    last = np.array(estimates[-1].tension_n)
    assert np.linalg.norm(last - truth) < 0.005
    assert estimates[-1].tension_std_n[0] < estimates[0].tension_std_n[0]
    assert estimates[-1].horizontal_n == np.hypot(*estimates[-1].tension_n[:2])
    assert estimates[-1].position_m is None


def test_floor_drops_a_bad_payload_and_keeps_its_state() -> None:
    kf = _new_filter()
    rows = telemetry_payloads(1, 10, seed=4)
    for row in rows:
        estimate_bytes(kf, row[0])
    x0 = kf.x.copy()
    assert estimate_bytes(kf, b'{"seq": 1, "stamp_s": "soon"}') is None
    assert estimate_bytes(kf, b"not json") is None
    assert np.array_equal(kf.x, x0)
