"""The realistic profile's targets, guarded in CI with loose bounds (realistic profile).

Short versions of ``benchmarks.bench_realistic`` (docs/realistic_benchmark.md has the full
ones): hover with calibration = the simulator's truth against the oracle Kalman filter told
the true noise in the same run, no false tug on a minute of coloured vibration noise, and a
30 mN tug detected. Loose on purpose (1.5x where the benchmark's target is 1.2x): a
regression, not a seed's scatter, should fail them.
"""

from __future__ import annotations

from benchmarks import bench_realistic as br


def test_hover_at_1_mps2_is_within_1_5x_of_the_oracle_in_the_same_run() -> None:
    h = br.hover(1.0, [0, 4], 14.0, [900])
    assert h["ours_median_m"] <= 1.5 * h["oracle_median_m"], h
    assert h["ours_p95_m"] <= 1.5 * h["oracle_p95_m"], h
    assert h["ours_tension_rms_n"] <= 1.5 * h["oracle_tension_rms_n"], h
    assert h["changes"] == 0, h


def test_no_false_tug_in_a_minute_of_coloured_hover_noise() -> None:
    f = br.false_tugs(2.0, 60.0, 901)
    assert f["hover_s"] > 55.0
    assert f["detections"] == 0, f


def test_a_30_mN_tug_at_0_5_mps2_is_detected_within_a_second() -> None:
    t = br.tug(0.5, [902])
    first = t["first_detection_s"][0]
    assert first is not None and first < 1.0, t
    assert t["t90_s"] is not None and t["t90_s"] < 1.0, t


def test_a_tug_under_a_hover_reaches_the_estimate_within_0_6_s() -> None:
    """The estimator issue's target at 0.5 m/s^2: the filter observes the accelerometer model
    while the drone hovers too (the thrust balance enters through the velocity state), so a
    tug shows in its innovations at once and the estimate does not wait for the drone's
    controller to tilt (t90 0.88 s when the hover model replaced the observation's low
    band, on the benchmark's seeds)."""
    t = br.tug(0.5, [902, 903])
    assert t["t90_s"] is not None and t["t90_s"] <= 0.6, t
    assert all(d is not None and d < 0.5 for d in t["first_detection_s"]), t
