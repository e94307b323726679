"""The take-off's hover T_v error against the hover time constant.

Run from the repository root::

    .venv/bin/python -m benchmarks.takeoff_lag

Ideal profile, scenario ``takeoff_1.3``, the seeds and length of ``benchmarks.results``
(seeds 10 and 11, 16 s, no motion capture), the service's pipeline with the tension
filter's hover time constant set per row: T_v error against omega * z from 8 s (the results
page's "T_v error, hover"), and the true height per second, which shows the climb's
overshoot and slow settle that the filter lags.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

import groundstation.estimator.drone as drone_mod
from groundstation.config import load_settings
from groundstation.evaluation import closed_loop

ROWS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("hover time constant 2.5 s", {"hover_time_constant_s": 2.5}),
    ("hover time constant 6 s (default)", {}),
    ("6 s, drift adaptation off", {"drift_min_time_constant_s": 6.0}),
)


def main() -> int:
    original = drone_mod.TensionFilterParams
    try:
        for label, kwargs in ROWS:
            drone_mod.TensionFilterParams = functools.partial(original, **kwargs)  # type: ignore[misc,assignment]
            errors, heights = [], []
            for seed in (10, 11):
                s = load_settings(None, {"sim": {"mocap": False, "seed": seed}}, use_env=False)
                run, _, _ = closed_loop(s, "takeoff_1.3", 16.0)
                omega = s.for_drone("cf1").tether.weight_n_per_m
                for e in run.estimates:
                    truth = run.truth.get(round(e["stamp_s"], 6))
                    if truth is None or e.get("on_ground"):
                        continue
                    z = truth["position_m"][2]
                    heights.append((e["stamp_s"], z))
                    if e["stamp_s"] >= 8.0:
                        errors.append(-e["tension_n"][2] - omega * z)
            err = np.array(errors)
            print(
                f"{label}: T_v error from 8 s RMSE {1e3 * np.sqrt(np.mean(err**2)):.2f} mN, "
                f"bias {1e3 * np.mean(err):.2f} mN"
            )
        h = np.array(heights)
        cells = []
        for lo in range(3, 16):
            m = (h[:, 0] >= lo) & (h[:, 0] < lo + 1)
            cells.append(f"{lo}-{lo + 1} s: {h[m, 1].mean():.3f}")
        print("true height, m (mean of both seeds): " + ", ".join(cells))
    finally:
        drone_mod.TensionFilterParams = original  # type: ignore[misc]
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
