"""How much a hovering Crazyflie's velocity moves: the basis of ``hover_velocity_std_mps``.

``python -m benchmarks.hover_velocity [--data DIR]``

NanoBench (``../shared/data/nanobench``, real untethered Crazyflie flights with Vicon): the
Vicon velocity (first differences of the positions, a 0.05 s moving mean) in the stretches
where the drone flies as the hover test would call quasi-static (in the air above 0.25 m,
speed below 0.3 m/s, the 1 s mean of the acceleration below 0.2 m/s²); per flight with at
least 0.5 s of them, the share of the flight and the RMS per world axis of the velocity
about its mean over each stretch (what the thrust balance's average has to allow for: a
constant velocity is no acceleration).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks.nanobench_cli import AIR_MIN_Z_M, DATA, DAYS, check_data

SPEED_MAX_MPS = 0.3
ACCEL_1S_MAX_MPS2 = 0.2
"""The hover test's fixed thresholds (``SlowAccelParams.quasi_static_*``)."""


def _moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    kernel = np.ones(n) / n
    return np.stack([np.convolve(x[:, i], kernel, mode="same") for i in range(3)], axis=1)


def flight(path: Path) -> tuple[float, np.ndarray | None]:
    """The quasi-static share of a flight and the velocity's RMS about each stretch's
    mean per axis, m/s (None: under 0.5 s of them)."""
    a = np.genfromtxt(path, delimiter=",", names=True)
    pos = np.stack([a["px"], a["py"], a["pz"]], 1)
    ok = np.all(np.isfinite(pos), 1)
    t, pos = a["t"][ok], pos[ok]
    dt = float(np.median(np.diff(t)))
    v = _moving_mean(np.gradient(pos, t, axis=0), max(1, round(0.05 / dt)))
    a1 = _moving_mean(np.gradient(v, t, axis=0), max(1, round(1.0 / dt)))
    quasi = (
        (pos[:, 2] > AIR_MIN_Z_M)
        & (np.linalg.norm(v, axis=1) < SPEED_MAX_MPS)
        & (np.linalg.norm(a1, axis=1) < ACCEL_1S_MAX_MPS2)
    )
    if quasi.sum() * dt < 0.5:
        return float(quasi.mean()), None
    # Stretches: consecutive quasi-static samples; the velocity about each one's mean.
    edges = np.flatnonzero(np.diff(np.concatenate([[0], quasi.astype(int), [0]])))
    dev = [v[s:e] - v[s:e].mean(axis=0) for s, e in zip(edges[::2], edges[1::2], strict=True)]
    d = np.concatenate(dev)
    return float(quasi.mean()), np.sqrt((d**2).mean(axis=0))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="the NanoBench CSV directory")
    args = ap.parse_args(argv)
    check_data(ap, args.data)
    print("| flight | quasi-static | velocity RMS about the stretch mean x / y / z, m/s |")
    print("| --- | ---: | --- |")
    every: list[float] = []
    for name in DAYS:
        share, rms = flight(args.data / f"{name}.csv")
        cells = "under 0.5 s" if rms is None else " / ".join(f"{x:.3f}" for x in rms)
        print(f"| {name} | {100 * share:.0f} % | {cells} |")
        every += [] if rms is None else rms.tolist()
    if every:
        print(
            f"\nMedian over the flights' axes: {np.median(every):.3f} m/s "
            f"({len(every)} axes, {min(every):.3f}–{max(every):.3f})."
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
