"""The battery model below the calibration's range, on real flights through the command line.

NanoBench excerpts (tests/data/nanobench/, 25 Hz; real Crazyflie 2.1, untethered, true
tension zero): ``calibrate --untethered`` on the runs of two flights (two days) flown with
the battery at or above 3.5 V; served without motion capture (``replay --offline``), the
flight of a third day, whose battery reads 3.19–3.52 V in the air, must read within 1.5×
of what the calibration's own flights read in range (the issue's acceptance line). The
straight battery line, calibrated on the same runs, does not; the motor-voltage model does.
The full-rate figures on all six shared flights: benchmarks/battery_model.py
(docs/battery_model.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks import battery_model as bm
from benchmarks import nanobench_cli as nb

DATA = Path(__file__).resolve().parent / "data" / "nanobench"
TRAIN = ("B3_figure8_fast_rep1", "B5_helix_medium_rep3")
BELOW = "B6_linear_ramp_rep3"
RATIO = 1.5
"""The issue's acceptance: below the range within 1.5× of the in-range figure."""


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, bm.Parts]]:
    work = tmp_path_factory.mktemp("battery")
    flights = {n: nb.load(n, DATA) for n in (*TRAIN, BELOW)}
    vbat = {n: bm.vbat_of(f.without_mocap) for n, f in flights.items()}
    parts = []
    for n in TRAIN:
        dt_s = float(np.median(np.diff(flights[n].stamp_s)))
        runs = bm.runs_above(flights[n].with_mocap, vbat[n], bm.SPLIT_V, dt_s)
        parts += [(f"{n}-above{k}", run) for k, run in enumerate(runs)]
    out: dict[str, dict[str, bm.Parts]] = {}
    for variant in bm.VARIANTS[:2]:  # vbat_linear, motor_voltage (calibrate's defaults)
        cal, _ = bm.calibrate(parts, work, variant.model, variant)
        out[variant.model] = {
            n: bm.judge(flights[n], vbat[n], cal, work, bm.SPLIT_V) for n in flights
        }
    return out


def _ratio(parts: dict[str, bm.Parts]) -> float:
    """The held-out day's flight below the range over the worst in-range flight."""
    in_range = max(parts[n].above for n in TRAIN)
    assert np.isfinite(in_range) and np.isnan(parts[BELOW].above)  # BELOW never reads ≥ 3.5
    return parts[BELOW].below / in_range


def test_the_motor_voltage_model_holds_below_the_range(
    served: dict[str, dict[str, bm.Parts]],
) -> None:
    ratio = _ratio(served["motor_voltage"])
    assert ratio <= RATIO, served["motor_voltage"]  # 25 Hz excerpts: 9.5 / 7.1 mN


def test_the_straight_line_does_not(served: dict[str, dict[str, bm.Parts]]) -> None:
    """The same test fails the model it replaces: it can fail."""
    assert _ratio(served["vbat_linear"]) > RATIO, served["vbat_linear"]  # 16.9 / 7.3 mN
    assert served["motor_voltage"][BELOW].below < 0.7 * served["vbat_linear"][BELOW].below
