"""The information limit of the 30 mN tug target: the step oracle at 250 Hz and 100 Hz.

Run from the repository root::

    .venv/bin/python -m benchmarks.step_oracle

The oracle knows the step's time and returns the mean of every observation since it (white
noise of 9 mN per axis and sample: 0.3 m/s^2 on 30 g). Printed: the time after which its
error norm stays within 3 mN (10 % of the step) for the rest of 1.5 s, median / p90 / p95
over 400 trials, and the fraction within 0.3 s. The TensionFilter docstring cites these.
"""

from __future__ import annotations

import numpy as np


def settle_s(err_n: np.ndarray, dt_s: float, tol_n: float = 0.003) -> float:
    bad = np.flatnonzero(np.linalg.norm(err_n, axis=1) > tol_n)
    return 0.0 if len(bad) == 0 else float((bad[-1] + 1) * dt_s)


def main() -> int:
    for rate_hz in (250.0, 100.0):
        dt = 1.0 / rate_hz
        n = int(1.5 / dt)
        out = []
        for k in range(400):
            noise = np.random.default_rng(k).normal(0.0, 0.009, (n, 3))
            mean = np.cumsum(noise, axis=0) / np.arange(1, n + 1)[:, None]
            out.append(settle_s(mean, dt))
        x = np.array(out)
        print(
            f"{rate_hz:.0f} Hz: step oracle within 3 mN after median {np.median(x):.3f} s, "
            f"p90 {np.quantile(x, 0.9):.3f} s, p95 {np.quantile(x, 0.95):.3f} s; "
            f"<= 0.3 s in {100 * np.mean(x <= 0.3):.0f} %"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
