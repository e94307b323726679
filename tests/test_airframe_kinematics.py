"""Motion-capture derivatives for the airframe fit: lost messages cut the filter's runs."""

from __future__ import annotations

import numpy as np

from groundstation.airframe import MOCAP_GAP_PERIODS, mocap_kinematics
from groundstation.calibration import CalibrationData

ACCEL_MPS2 = np.array([0.4, -0.2, 0.1])
VEL0_MPS = np.array([0.3, 0.0, -0.1])


def _flight(stamp_s: np.ndarray) -> CalibrationData:
    """A constant acceleration: p = v0·t + a·t²/2 (a cubic filter's derivatives are exact)."""
    t = stamp_s[:, None]
    pos = VEL0_MPS * t + 0.5 * ACCEL_MPS2 * t**2
    n = stamp_s.size
    return CalibrationData.from_arrays(
        stamp_s,
        np.tile([0.0, 0.0, 9.81], (n, 1)),
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        np.full(n, 0.3),
        position_world_m=pos,
    )


def test_derivatives_are_exact_across_a_gap_of_lost_messages() -> None:
    t = np.arange(0.0, 6.0, 0.01)
    kept = np.ones(t.size, bool)
    kept[250:300] = False  # half a second of telemetry lost
    data = _flight(t[kept])
    vel, acc = mocap_kinematics(data)
    ok = np.all(np.isfinite(acc), axis=1)
    assert ok.sum() > 0.9 * ok.size
    np.testing.assert_allclose(acc[ok], np.tile(ACCEL_MPS2, (ok.sum(), 1)), atol=1e-6)
    tk = data.stamp_s[ok][:, None]
    np.testing.assert_allclose(vel[ok], VEL0_MPS + ACCEL_MPS2 * tk, atol=1e-6)


def test_without_the_cut_the_gap_would_corrupt_them() -> None:
    """What the cut prevents: the same samples as if evenly spaced (one run across the gap)."""
    t = np.arange(0.0, 6.0, 0.01)
    kept = np.ones(t.size, bool)
    kept[250:300] = False
    even = _flight(t[kept])
    # the positions of the gapped flight on a clock with no gap: the filter sees a jump
    relabelled = CalibrationData.from_arrays(
        np.arange(kept.sum()) * 0.01,
        even.accel_body_mps2,
        even.quat_wxyz,
        even.thrust_n,
        position_world_m=even.position_world_m,
    )
    _, acc = mocap_kinematics(relabelled)
    near = np.abs(np.arange(kept.sum()) - 250) < 5
    assert np.max(np.abs(acc[near] - ACCEL_MPS2)) > 1.0  # metres per s² of nonsense
    assert MOCAP_GAP_PERIODS < 2.0  # one lost message already cuts
