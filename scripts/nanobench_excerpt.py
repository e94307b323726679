"""Write the NanoBench excerpts under tests/data/nanobench/ (every 4th row, the columns the
calibration test reads, ``t`` from the first row), from the full recordings in
../shared/data/nanobench/ (Ullah and Baca 2026, BSD 3-Clause: LICENSE beside the excerpts).

    python scripts/nanobench_excerpt.py [SOURCE_DIR]
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

COLUMNS = (
    ["t", "px", "py", "pz"]
    + [f"att_stateEstimate_q{k}" for k in "wxyz"]
    + [f"imu_acc_{k}" for k in "xyz"]
    + [f"imu_gyro_{k}" for k in "xyz"]
    + [f"motor_motor_m{i}" for i in range(1, 5)]
    + ["pwr_pm_vbat"]
)
FILES = (
    "B6_linear_ramp_rep1.csv",
    "B3_figure8_fast_rep1.csv",
    "B6_linear_ramp_rep3.csv",
    "B5_helix_medium_rep3.csv",
)
STEP = 4


def main() -> None:
    src = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/nanobench")
    dst = Path(__file__).resolve().parent.parent / "tests" / "data" / "nanobench"
    dst.mkdir(parents=True, exist_ok=True)
    for name in FILES:
        with (src / name).open(newline="") as fh:
            rows = list(csv.DictReader(fh))[::STEP]
        with (dst / name).open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(COLUMNS)
            t0 = float(rows[0]["t"])
            for r in rows:
                t = f"{float(r['t']) - t0:.4f}"  # seconds from the first row
                w.writerow([t] + [f"{float(r[c]):.6g}" if r[c] else "" for c in COLUMNS[1:]])


if __name__ == "__main__":
    main()
