"""The realistic envelope's plan (benchmarks/results_envelope.py), without flying it.

The results page's quick run (tests/test_results.py) flies it; these check what a reader
cannot see in the numbers: that every flight is the realistic profile with exactly one error
class on, that the sizes reach the simulator, and that 'nothing to calibrate' is true.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks import results_envelope as renv
from benchmarks.bench_realistic import ALL_CLASSES, DRONE, _NullBus, _settings
from benchmarks.results_sim import SimJob
from groundstation.config import CalibrationSection
from groundstation.sim import Simulator


def _flight_settings(job: renv.ClassJob) -> Any:
    classes = dict(job.realistic)
    noise = classes.pop("accel_noise_mps2")
    return _settings(noise, job.seed, classes, None)


@pytest.mark.parametrize("quick", [True, False])
def test_every_flight_is_the_realistic_profile_with_one_class_on(quick: bool) -> None:
    jobs = renv.jobs(renv.plan(quick))
    assert len({j.key for j in jobs}) == len(jobs)
    for job in jobs:
        if isinstance(job, SimJob):
            assert job.sim["profile"] == "realistic" and job.sim["mocap"] is False
            assert job.sim["realistic"] == renv.BASELINE
            continue
        sim = _flight_settings(job).sim
        assert sim.profile == "realistic" and sim.mocap is False
        on = {c for c in ALL_CLASSES if getattr(sim.realistic, c)}
        name = job.key.split("/")[1]
        if name == "all":
            assert on == set(ALL_CLASSES)
        elif name == "battery":  # the battery's drift acts through the thrust map
            assert on == {"vibration", "thrust_map", "battery"}
            assert sim.realistic.thrust_report_error == 0.0
        elif name == "vibration" and sim.realistic.vibration is False:
            assert on == set()
        else:
            assert on <= {"vibration", name} and "vibration" in on, (job.key, on)


def test_full_plan_sweeps_every_sensor_and_dynamics_class_over_its_range() -> None:
    classes = {c.name: c for c in renv.error_classes(quick=False)}
    assert set(ALL_CLASSES) - {"mocap_timing"} <= set(classes)
    for c in classes.values():
        assert c.real in c.values and c.baseline in c.values
        assert len(c.values) >= 2
    for name in ("misalignment", "accel_scale", "accel_bias", "thrust_axis", "thrust_map"):
        vals = classes[name].values
        assert len(vals) >= 4 and max(map(abs, vals)) >= 2 * abs(classes[name].real) * 0.99


def test_sizes_reach_the_simulator_and_the_draws_scale_with_them() -> None:
    """Same seed, twice the size: twice the drawn misalignment (the rows differ by the error
    and not by luck, as the section says)."""
    drawn = {}
    for size_deg in (3.0, 6.0):
        job = next(
            j
            for j in renv.jobs(renv.plan(False))
            if isinstance(j, renv.ClassJob) and j.key == f"envr/misalignment/{size_deg:g}/raw/0"
        )
        sim = Simulator(_flight_settings(job), _NullBus(), scenario="hover")  # type: ignore[arg-type]
        errors = sim.drawn_errors(DRONE)
        assert errors is not None
        drawn[size_deg] = renv.drawn_sizes(errors)["misalignment_deg"]
    assert 0.0 < drawn[3.0] <= 3.0
    assert drawn[6.0] == pytest.approx(2.0 * drawn[3.0], rel=1e-9)


@pytest.mark.slow
def test_nothing_to_calibrate_where_the_plan_flies_no_calibrated_run() -> None:
    """The truth of a class without calibrated flights is the calibration's defaults, and the
    truth of a calibratable class is not (else its calibrated column would mean nothing)."""
    defaults = CalibrationSection()
    for c in renv.error_classes(quick=False):
        if c.name in ("all", "battery"):
            continue
        value = c.real if c.real != c.baseline else c.values[-1]
        job = renv.ClassJob("t", 0, 1.0, 500, {**renv.BASELINE, **c.settings(value)}, False)
        sim = Simulator(_flight_settings(job), _NullBus(), scenario="hover")  # type: ignore[arg-type]
        truth = CalibrationSection(**sim.truth_calibration(DRONE))
        same = (
            truth.thrust_scale == pytest.approx(defaults.thrust_scale, abs=1e-12)
            and truth.thrust_axis_rad == pytest.approx(defaults.thrust_axis_rad, abs=1e-12)
            and truth.accel_bias_mps2 == pytest.approx(defaults.accel_bias_mps2, abs=1e-12)
            and truth.thrust_vbat_slope_per_v == pytest.approx(0.0, abs=1e-12)
        )
        assert same is not c.calibratable, (c.name, truth)


@pytest.mark.slow
def test_model_sweep_path_reproduces_the_baseline_flight() -> None:
    """The ω and L sweeps take their nominal from the baseline's flights (bench_realistic's
    ``fly``) and fly the rest as SimJobs (``closed_loop``): for the same settings both paths
    give the same errors, sample by sample."""
    from benchmarks.results_sim import _run_reduced, hover_scenario
    from groundstation.sim import PAPER_HOVER_SPOTS_M

    fly = renv.ClassJob("a", 0, 2.0, 500, dict(renv.BASELINE), False).run()
    job = SimJob(
        "b",
        hover_scenario("bench_hover_0", PAPER_HOVER_SPOTS_M[0]),
        2.0,
        sim={"profile": "realistic", "mocap": False, "seed": 500, "realistic": renv.BASELINE},
        reduce="error",
    )
    sim = _run_reduced(job)
    assert len(fly.t_s) == len(sim.t_s) > 100
    np.testing.assert_array_equal(fly.t_s, sim.t_s)
    np.testing.assert_array_equal(fly.pos_error_m, sim.pos_error_m)
    np.testing.assert_array_equal(fly.tension_error_n, sim.tension_error_n)
