"""The calibration protocol rehearsed on the simulator, end to end, as a lab would run it.

``sim --scenario calibration --untethered --profile realistic`` recorded by the recorder
(in process, on the in-memory bus, many times faster than real time), then ``calibrate
--untethered`` on the file: the fit must find the simulator's own airframe; ``replay
--offline`` must learn the accelerometer's offsets while the drone sits disarmed on the floor,
and draw the flight over its own length.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from groundstation.bus import InMemoryBus
from groundstation.cli import main
from groundstation.config import load_settings
from groundstation.pipeline import Pipeline
from groundstation.recording import Recorder, iter_messages, replay_offline
from groundstation.recording.figures import figure_series
from groundstation.sim import SCENARIOS, Simulator

SEED = 1
SCENARIO = SCENARIOS["calibration"]
DURATION_S = SCENARIO.duration_s or 0.0


@dataclass(frozen=True)
class Flight:
    path: Path
    errors: dict[str, Any]
    """``Simulator.drawn_errors``: the truth the fit is judged against."""
    rotor_drag_n_s_per_m: float
    telemetry: list[dict[str, Any]]
    truth: list[dict[str, Any]]
    keys: dict[str, int]


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Flight:
    path = tmp_path_factory.mktemp("sim") / "cal1.mcap"
    sim_cfg = {
        "profile": "realistic",
        "scenario": "calibration",
        "untethered": True,
        "seed": SEED,
        "duration_s": DURATION_S,
        "speed": 1e6,  # as fast as it runs
    }
    settings = load_settings(None, {"sim": sim_cfg}, use_env=False)
    bus = InMemoryBus()
    try:
        recorder = Recorder(bus, path)
        sim = Simulator(settings, bus)
        sim.run()  # the simulator's own loop, on this thread, until duration_s
        assert bus.flush(60.0)
        stats = recorder.close()
    finally:
        bus.close()
    assert stats.dropped == 0
    keys: dict[str, int] = {}
    telemetry, truth = [], []
    for msg in iter_messages(path):
        keys[msg.key] = keys.get(msg.key, 0) + 1
        if msg.key.endswith("/telemetry"):
            telemetry.append(json.loads(msg.payload))
        elif msg.key.endswith("/truth"):
            truth.append(json.loads(msg.payload))
    return Flight(
        path,
        sim.drawn_errors("cf1") or {},
        settings.sim.realistic.rotor_drag_n_s_per_m,
        telemetry,
        truth,
        keys,
    )


def test_the_untethered_flight_has_no_tether_and_starts_at_rest_on_the_floor(
    flight: Flight,
) -> None:
    # Nothing a tether would publish: calibrate --untethered must find no reel to refuse.
    assert set(flight.keys) == {"tether/cf1/telemetry", "tether/cf1/truth"}
    assert all(t["tension_n"] == [0.0, 0.0, 0.0] for t in flight.truth)
    assert all(t["length_m"] == 0.0 and not t["taut"] for t in flight.truth)
    rest = [t for t in flight.telemetry if t["stamp_s"] < SCENARIO.arm_at_s]
    assert rest and all(not t["armed"] and t["thrust_n"] == 0.0 for t in rest)
    assert rest[-1]["stamp_s"] - rest[0]["stamp_s"] > 2.5
    still = [t for t in flight.truth if t["stamp_s"] < SCENARIO.arm_at_s]
    assert all(t["on_ground"] and t["velocity_mps"] == [0.0, 0.0, 0.0] for t in still)
    # Motion capture throughout the flight, as calibrate needs it.
    assert sum("position_m" in t for t in flight.telemetry) > 0.95 * len(flight.telemetry)
    assert flight.truth[-1]["position_m"][2] > 0.9


def test_calibrate_untethered_finds_the_simulated_airframe(flight: Flight, tmp_path: Path) -> None:
    out = tmp_path / "lab-cal.toml"
    assert main(["calibrate", str(flight.path), "--untethered", "--out", str(out)]) == 0
    cal = load_settings(out, use_env=False).for_drone("cf1").calibration
    truth = flight.errors["calibration"]
    # The slope is undetermined on one short flight (fixed at 0), so the scale holds at the
    # flight's voltage: the simulator's map there, to first order in V − V_ref.
    flying = [t["vbat_v"] for t in flight.telemetry if t["armed"]]
    v_med = float(np.median(flying))
    scale_truth = truth["thrust_scale"] + truth["thrust_vbat_slope_per_v"] * (
        v_med - truth["thrust_vbat_ref_v"]
    )
    assert abs(scale_truth - 1.0) > 0.05  # the nominal map is far off: the fit must move it
    assert cal.thrust_scale == pytest.approx(scale_truth, abs=0.01)
    assert cal.thrust_vbat_slope_per_v == 0.0
    np.testing.assert_allclose(cal.thrust_axis_rad, truth["thrust_axis_rad"], atol=0.003)
    assert 0.5 * flight.rotor_drag_n_s_per_m < cal.rotor_drag_n_s_per_m
    assert cal.rotor_drag_n_s_per_m < 1.5 * flight.rotor_drag_n_s_per_m
    assert cal.accel_bias_mps2 == (0.0, 0.0, 0.0)  # per power-on: learnt by the service


@pytest.fixture(scope="module")
def replayed(flight: Flight, tmp_path_factory: pytest.TempPathFactory) -> tuple[Pipeline, Path]:
    out = tmp_path_factory.mktemp("replay") / "rerun.mcap"
    pipeline = Pipeline(load_settings(None, {}, use_env=False))
    replay_offline(flight.path, out, pipeline)
    return pipeline, out


def test_the_service_learns_the_accelerometer_offsets_on_the_floor(
    flight: Flight, replayed: tuple[Pipeline, Path]
) -> None:
    pipeline, _ = replayed
    status = pipeline.status("cf1", flight.telemetry[-1]["stamp_s"])
    assert status is not None
    rest = status["rest_calibration"]
    assert rest["in_force"]
    assert rest["stamp_s"] < SCENARIO.arm_at_s  # learnt before take-off, disarmed and still
    # The drawn per-power-on error at level (bias, misalignment, scale): what a rest sees.
    level = flight.errors["calibration"]["accel_bias_level_mps2"]
    assert np.hypot(*level[:2]) > 0.1  # large enough to matter
    np.testing.assert_allclose(rest["offset_mps2"], level[:2], atol=0.03)


def test_the_figures_span_the_flight_on_the_drone_s_clock(
    flight: Flight, replayed: tuple[Pipeline, Path]
) -> None:
    _, out = replayed
    series = figure_series(out)["cf1"]
    stamps = [t["stamp_s"] for t in flight.telemetry]
    assert series.span_s == pytest.approx(max(stamps) - min(stamps), abs=1e-6)
    assert series.span_s > 0.97 * DURATION_S
    assert "mocap" in series.position and "truth" in series.position
    assert "smoothed" in series.tension
