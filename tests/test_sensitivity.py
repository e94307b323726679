"""benchmarks/sensitivity.py changes each hand-set value it names, and only for the run."""

from __future__ import annotations

import re
from pathlib import Path

import groundstation.estimator.localize_control  # noqa: F401 - an importer of PLUMB_K's module
from benchmarks import sensitivity as sens
from groundstation import calibration, localization, tension

CONSTANTS_MD = Path(__file__).resolve().parent.parent / "docs" / "constants.md"


def test_the_rows_are_the_tables_hand_set_rows() -> None:
    text = CONSTANTS_MD.read_text(encoding="utf-8")
    total = int(re.search(r"\*\*\d+ tunables: .*?, (\d+) hand-set;", text).group(1))  # type: ignore[union-attr]
    names = sens.hand_set_rows(CONSTANTS_MD)
    assert len(names) == total
    assert len(set(names)) == len(names)
    assert "TensionFilterParams.hover_time_constant_s" in names
    assert "TensionFilterParams.hover_wander_n2_per_s" not in names  # fitted by calibrate
    assert "TensionFilterParams.mass_kg" not in names  # physical


def test_a_field_is_scaled_in_new_instances_and_in_a_default_argument() -> None:
    before = calibration.RestCriteria().max_gyro_rps
    default = calibration.RestCalibrator.__init__.__defaults__[0]  # type: ignore[index]
    undo = sens.patch("RestCriteria.max_gyro_rps", 2.0)
    try:
        assert calibration.RestCriteria().max_gyro_rps == 2.0 * before
        patched = calibration.RestCalibrator.__init__.__defaults__[0]  # type: ignore[index]
        assert patched.max_gyro_rps == 2.0 * before  # scaled once, not twice
        assert tension.TensionFilterParams().hover_wander_n2_per_s > 0.0  # others untouched
    finally:
        for step in reversed(undo):
            step()
    assert calibration.RestCriteria().max_gyro_rps == before
    assert calibration.RestCalibrator.__init__.__defaults__[0] is default  # type: ignore[index]


def test_a_module_constant_is_rebound_in_every_importer_and_restored() -> None:
    before = localization.PLUMB_K
    importers = [
        m for m in sens._functions() if m.__defaults__ and any(d is before for d in m.__defaults__)
    ]
    undo = sens.patch("localization.PLUMB_K", 0.5)
    try:
        now = localization.PLUMB_K
        assert now == 0.5 * before
        for f in importers:
            assert any(d is now for d in f.__defaults__)  # `is`: a default may be an array
    finally:
        for step in reversed(undo):
            step()
    assert localization.PLUMB_K is before
    for f in importers:
        assert any(d is before for d in f.__defaults__)


def test_scaled_keeps_each_kind() -> None:
    assert sens.scaled(True, 0.5) is False
    assert sens.scaled(3, 0.5) == 2 and sens.scaled(1, 0.5) == 1
    assert sens.scaled((0.1, 0.2), 2.0) == (0.2, 0.4)


def test_jobs_start_with_the_baselines_and_flip_a_switch_once() -> None:
    names = sens.hand_set_rows(CONSTANTS_MD)
    jobs = sens.jobs(names)
    assert jobs[:2] == [("estimator", "baseline", 1.0), ("contact", "baseline", 1.0)]
    switch = [j for j in jobs if j[1] == "TensionFilterParams.estimate_noise"]
    assert [j[0] for j in switch] == ["estimator", "noisy"]
    assert len(jobs) == len(set(jobs))
