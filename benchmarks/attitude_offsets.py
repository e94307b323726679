"""Vicon's attitude against the drone's own, at rest and in the air (NanoBench; a diagnosis).

``python -m benchmarks.attitude_offsets [--data DIR]``

Per shared flight, the median rotation from the onboard attitude to Vicon's (a rotation
vector in the onboard body frame, degrees) over the samples disarmed on the floor before the
first arming, and over the airborne ones (motors on, Vicon z > 0.25 m). A rigid body whose
markers sit tilted against the IMU shows the same rotation at rest and in the air; the
question behind it (docs/estimator_design.md): can a rest on a level floor measure an
external attitude's tilt for the hover model? Only where the two columns agree.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.nanobench_cli import AIR_MIN_Z_M, DATA, DAYS, check_data


def offsets(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Median onboard → Vicon rotation vectors (deg) at rest and in the air."""
    a = np.genfromtxt(path, delimiter=",", names=True)
    pwm = np.stack([a[f"motor_motor_m{i}"] for i in range(1, 5)], axis=1)
    armed = pwm.max(axis=1) > 0
    vicon = np.stack([a[f"q{k}"] for k in "xyzw"], 1)  # scipy's order, scalar last
    onboard = np.stack([a[f"att_stateEstimate_q{k}"] for k in "xyzw"], 1)
    ok = np.all(np.isfinite(vicon), 1) & np.all(np.isfinite(onboard), 1)
    first_arm = int(np.argmax(armed)) if armed.any() else len(armed)
    rest = ok & ~armed & (np.arange(len(armed)) < first_arm)
    air = ok & armed & (a["pz"] > AIR_MIN_Z_M)

    def median_rotvec(sel: np.ndarray) -> np.ndarray:
        rel = Rotation.from_quat(onboard[sel]).inv() * Rotation.from_quat(vicon[sel])
        return np.asarray(np.median(rel.as_rotvec(degrees=True), axis=0))

    return median_rotvec(rest), median_rotvec(air)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="the NanoBench CSV directory")
    args = ap.parse_args(argv)
    check_data(ap, args.data)
    print("| flight | day | at rest x / y / z deg | in the air x / y / z deg |")
    print("| --- | --- | --- | --- |")
    for name, day in DAYS.items():
        rest, air = offsets(args.data / f"{name}.csv")
        cells = [" / ".join(f"{v:+.2f}" for v in r) for r in (rest, air)]
        print(f"| {name} | {day} | {cells[0]} | {cells[1]} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
