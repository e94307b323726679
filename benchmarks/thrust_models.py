"""Which thrust model needs the smaller calibration on the NanoBench flights.

The NanoBench Crazyflie 2.1 (firmware 2025.12.1, untethered, README in
``../shared/data/nanobench/``) flies with no tether: its thrust along body z is the mass times
the accelerometer's specific force on z (rotor drag aside). For each flight and thrust model
(the nominal PWM map of ``[crazyflie] thrust_map`` and the firmware's own cubics in the motor
voltage, :data:`~groundstation.bridges.crazyflie.bridge.VMOTOR2THRUST`) this prints the model's
median thrust in the air and the calibration the service would need, ``scale = m·a_z / thrust``
(1 is none), with its change per volt of battery (what ``[calibration]
thrust_vbat_slope_per_v`` must absorb).

    python -m benchmarks.thrust_models [--mass-kg 0.030] [--data ../shared/data/nanobench]
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from groundstation.bridges.crazyflie.bridge import VMOTOR2THRUST, thrust_cubic_n, thrust_n

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nanobench"
NOMINAL_MAP = (2.130295e-11, 1.032633e-6, 5.484560e-4)
G_MPS2 = 9.81
AIRBORNE_Z_M = 0.3
"""Above this height only: out of ground effect (``B6_linear_ramp_rep1`` never is: left out)."""
MODELS = ("pwm_map", "cubic_21plus", "cubic_legacy")


def _rows(path: Path) -> dict[str, np.ndarray]:
    with path.open() as fh:
        reader = csv.DictReader(fh)
        cols: dict[str, list[float]] = {}
        for row in reader:
            for key in (
                "pz",
                "imu_acc_z",
                "pwr_pm_vbat",
                *(f"motor_motor_m{i}" for i in range(1, 5)),
            ):
                value = row.get(key, "")
                cols.setdefault(key, []).append(float(value) if value not in ("", None) else np.nan)
    return {k: np.asarray(v) for k, v in cols.items()}


def model_thrust_n(model: str, motors: np.ndarray, vbat_v: np.ndarray) -> np.ndarray:
    """Collective thrust per sample by one model, N."""
    if model == "pwm_map":
        return np.array([thrust_n(m, NOMINAL_MAP) for m in motors])
    coefficients = VMOTOR2THRUST[model]
    return np.array(
        [thrust_cubic_n(m, v, coefficients) for m, v in zip(motors, vbat_v, strict=True)]
    )


def flight(path: Path, mass_kg: float) -> list[tuple[str, str, float, float, float, float]]:
    """Per model: ``(flight, model, median vbat V, median thrust N, median scale, scale per V)``."""
    cols = _rows(path)
    motors = np.stack([cols[f"motor_motor_m{i}"] for i in range(1, 5)], axis=1)
    vbat = cols["pwr_pm_vbat"]
    ok = (cols["pz"] > AIRBORNE_Z_M) & np.isfinite(vbat) & np.all(motors > 0, axis=1)
    ok &= np.isfinite(cols["imu_acc_z"])
    true_n = mass_kg * G_MPS2 * cols["imu_acc_z"][ok]  # thrust = m · f_z (untethered)
    out = []
    for model in MODELS:
        thrust = model_thrust_n(model, motors[ok], vbat[ok])
        scale = true_n / thrust
        slope = float(np.polyfit(vbat[ok], scale, 1)[0])  # d scale / d vbat, 1/V
        out.append(
            (
                path.stem,
                model,
                float(np.median(vbat[ok])),
                float(np.median(thrust)),
                float(np.median(scale)),
                slope,
            )
        )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mass-kg", type=float, default=0.030, help="assumed (files say none)")
    parser.add_argument("--data", type=Path, default=DATA)
    args = parser.parse_args(argv)
    files = sorted(p for p in args.data.glob("*.csv") if p.stem != "B6_linear_ramp_rep1")
    if not files:
        print(f"no NanoBench files in {args.data}")
        return 1
    print(
        f"mass {args.mass_kg * 1000:.1f} g (weight {args.mass_kg * G_MPS2:.3f} N); "
        f"airborne > {AIRBORNE_Z_M} m"
    )
    print(
        f"{'flight':24s} {'model':14s} {'vbat V':>7s} {'thrust N':>9s} "
        f"{'scale':>6s} {'scale/V':>8s}"
    )
    rows = [r for p in files for r in flight(p, args.mass_kg)]
    for name, model, vbat, thrust, scale, slope in rows:
        print(f"{name:24s} {model:14s} {vbat:7.2f} {thrust:9.3f} {scale:6.3f} {slope:8.3f}")
    print()
    for model in MODELS:
        scales = np.array([r[4] for r in rows if r[1] == model])
        slopes = np.array([r[5] for r in rows if r[1] == model])
        print(
            f"{model:14s} scale {scales.min():.3f}-{scales.max():.3f} "
            f"(|1 - scale| median {np.median(np.abs(1 - scales)):.3f}), "
            f"spread over flights {scales.max() - scales.min():.3f}, "
            f"scale per V median {np.median(slopes):+.3f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
