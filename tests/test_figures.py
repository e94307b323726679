"""Figures of ``replay --offline --figures``: drawn on the drone's clock, every series present."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from groundstation.recording.figures import figure_series, write_figures

STAMP0_S = 12.5
"""The drone's clock at the first sample: not zero, as after a power-on's boot."""
DT_S = 0.02
N = 100


def _write(path: Path, messages: list[tuple[str, dict[str, object], int]]) -> None:
    with path.open("wb") as fh:
        writer = Writer(fh)
        writer.start()
        schema = writer.register_schema("json", "jsonschema", b'{"type":"object"}')
        channels: dict[str, int] = {}
        for key, payload, t_ns in messages:
            if key not in channels:
                channels[key] = writer.register_channel(key, "json", schema)
            writer.add_message(channels[key], t_ns, json.dumps(payload).encode(), t_ns)
        writer.finish()


def _flight(log_dt_s: float) -> list[tuple[str, dict[str, object], int]]:
    """A replayed flight: Telemetry with motion capture, Estimate, smoothed Estimate, Truth
    every ``DT_S`` of drone clock, received every ``log_dt_s`` (``DT_S / 2``: recorded while
    it was replayed at speed 2)."""
    t0_ns = 1_700_000_000 * 10**9
    out: list[tuple[str, dict[str, object], int]] = []
    for i in range(N):
        t_ns = t0_ns + round(i * log_dt_s * 1e9)
        stamp = STAMP0_S + i * DT_S
        x = 1.0 + 0.1 * math.sin(i / 10)
        tele = {
            "seq": i,
            "stamp_s": stamp,
            "accel_mps2": [0.0, 0.0, 9.81],
            "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "thrust_n": 0.35,
            "position_m": [x + 0.001, 0.0, 1.0],
        }
        est = {
            "seq": i,
            "stamp_s": stamp,
            "tension_n": [-0.05, 0.0, -0.04],
            "tension_std_n": [0.01, 0.01, 0.01],
            "horizontal_n": 0.05,
            "vertical_n": 0.04,
            "position_m": [x + 0.05, 0.0, 1.0] if i >= 10 else None,
            "follow": {"enabled": False, "active": False, "threshold_n": 0.15},
        }
        smoothed = {
            "seq": i,
            "stamp_s": stamp,
            "tension_n": [-0.048, 0.0, -0.041],
            "tension_std_n": [0.005, 0.005, 0.005],
            "position_m": [x + 0.02, 0.0, 1.0],
        }
        truth = {
            "stamp_s": stamp,
            "position_m": [x, 0.0, 1.0],
            "velocity_mps": [0.0, 0.0, 0.0],
            "tension_n": [-0.05, 0.0, -0.04],
            "length_m": 1.6,
            "base_m": [0.0, 0.0, 0.754],
            "floor_contact": False,
            "taut": False,
            "armed": True,
            "on_ground": False,
        }
        out.append(("tether/cf1/telemetry", tele, t_ns))
        out.append(("tether/cf1/estimate", est, t_ns + 1000))
        out.append(("tether/cf1/estimate_smoothed", smoothed, t_ns + 2000))
        out.append(("tether/cf1/truth", truth, t_ns + 3000))
    out.append(("tether/cf1/estimate", {"seq": "bad"}, t0_ns))  # invalid: not drawn
    return out


def test_a_flight_replayed_at_speed_2_plots_over_its_own_length(tmp_path: Path) -> None:
    rec = tmp_path / "replayed.mcap"
    _write(rec, _flight(log_dt_s=DT_S / 2))
    series = figure_series(rec)
    assert list(series) == ["cf1"]
    s = series["cf1"]
    drone_span_s = (N - 1) * DT_S
    assert s.t0_s == STAMP0_S
    # The drone's clock, not the receive time (which spans half of it).
    assert math.isclose(s.span_s, drone_span_s, rel_tol=1e-9)
    for tr in (*s.tension.values(), *s.position.values()):
        assert math.isclose(float(tr.t_s[0]), 0.0, abs_tol=1e-9)
        assert math.isclose(float(tr.t_s[-1]), drone_span_s, rel_tol=1e-9)
    # Every series drawn: the motion capture beside the truth, the smoothed estimate.
    assert sorted(s.position) == ["estimate", "mocap", "smoothed", "truth"]
    assert sorted(s.tension) == ["estimate", "smoothed", "truth"]
    np.testing.assert_allclose(
        s.position["mocap"].values_m_or_n[:, 0] - s.position["truth"].values_m_or_n[:, 0],
        0.001,
        atol=1e-12,
    )
    np.testing.assert_allclose(s.tension["smoothed"].values_m_or_n[:, 2], -0.041)
    assert s.tension["estimate"].std is not None
    # An Estimate without a position is a gap in its line, not a point at zero.
    est_x = s.position["estimate"].values_m_or_n[:, 0]
    assert np.isnan(est_x[:10]).all() and np.isfinite(est_x[10:]).all()

    written = write_figures(rec, tmp_path / "fig")
    assert sorted(p.name for p in written) == ["cf1_position.png", "cf1_tension.png"]
    for png in written:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_same_flight_at_speed_1_gives_the_same_series(tmp_path: Path) -> None:
    a, b = tmp_path / "speed1.mcap", tmp_path / "speed2.mcap"
    _write(a, _flight(log_dt_s=DT_S))
    _write(b, _flight(log_dt_s=DT_S / 2))
    sa, sb = figure_series(a)["cf1"], figure_series(b)["cf1"]
    assert sa.span_s == sb.span_s
    for name in sa.position:
        np.testing.assert_array_equal(sa.position[name].t_s, sb.position[name].t_s)


def test_a_drone_without_estimates_or_truth_has_no_figures(tmp_path: Path) -> None:
    rec = tmp_path / "telemetry_only.mcap"
    _write(rec, [m for m in _flight(DT_S) if m[0].endswith("/telemetry")])
    assert figure_series(rec) == {}
    assert write_figures(rec, tmp_path / "fig") == []
