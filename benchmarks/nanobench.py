"""The NanoBench Crazyflie 2.1 flights (untethered, Vicon) as calibration samples.

Reads the excerpts under tests/data/nanobench/ (``scripts/nanobench_excerpt.py``; the full
files are in ../shared/data/nanobench/, README there) and fits the calibration against the
true tension, zero: the real-data check of the fit (tests/test_calibration_nanobench.py, and
the numbers of docs/calibration.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from groundstation.calibration import (
    GRAVITY_MPS2,
    CalibrationData,
    CalibrationFit,
    HoverCriteria,
    fit_calibration,
    hover_mask,
)

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "nanobench"
FILES = ("B6_linear_ramp_rep1.csv", "B3_figure8_fast_rep1.csv")
MASS_KG = 0.030
"""Assumed (the files do not say; a stock Crazyflie 2.1 with markers is 27–32 g)."""
MOVING = HoverCriteria(max_speed_mps=2.0, max_accel_mps2=3.0, max_gyro_rps=3.0, settle_s=0.5)
"""Not hover only: untethered, the observation holds in motion too (the accelerometer sees
the manoeuvre); take-off, landing and hard manoeuvres are still left out."""


def nominal_thrust_n(pwm: np.ndarray) -> np.ndarray:
    """The nominal per-motor map of the data README, summed over the four motors, N."""
    per_motor = 2.130295e-11 * pwm**2 + 1.032633e-6 * pwm + 5.484560e-4
    return np.where(pwm > 0, per_motor, 0.0).sum(axis=1)


def load(name: str, data_dir: Path = DATA) -> CalibrationData:
    """One flight as samples (an excerpt by default; ``data_dir`` the full files'
    directory): accelerometer g → m/s², the attitude the drone reports."""
    a = np.genfromtxt(data_dir / name, delimiter=",", names=True)
    pwm = np.stack([a[f"motor_motor_m{i}"] for i in range(1, 5)], axis=1)
    return CalibrationData.from_arrays(
        a["t"],
        np.stack([a[f"imu_acc_{k}"] for k in "xyz"], 1) * GRAVITY_MPS2,
        np.stack([a[f"att_stateEstimate_q{k}"] for k in "wxyz"], 1),
        nominal_thrust_n(pwm),
        armed=pwm.max(axis=1) > 0,
        position_world_m=np.stack([a["px"], a["py"], a["pz"]], 1),
        gyro_rps=np.stack([a[f"imu_gyro_{k}"] for k in "xyz"], 1),
        vbat_v=a["pwr_pm_vbat"],
    )


def fit(name: str) -> tuple[CalibrationData, CalibrationFit, np.ndarray]:
    """(samples, fit against zero tension, the samples used)."""
    data = load(name)
    mask = hover_mask(data, MASS_KG, MOVING)
    return data, fit_calibration(data, MASS_KG, weight_n_per_m=None, hover=mask), mask


def reading_over_weight(data: CalibrationData, f: CalibrationFit, mask: np.ndarray) -> float:
    """How much the nominal map over-reads at the flight's median voltage: 1/scale."""
    v = float(np.nanmedian(data.vbat_v[mask]))
    scale = f.values["thrust_scale"] + f.values["vbat_slope_per_v"] * (v - f.vbat_ref_v)
    return 1.0 / scale
