"""Long hovers on the realistic simulator: the whole pipeline's change detections per hour,
and the published tension σ over them (a diagnosis, no page).

``python -m benchmarks.long_hover [--flights 24] [--minutes 4] [--noise 0.8] [--seed-base 7000]
[--jobs 2] [--thrust-model vbat_linear|motor_voltage]``

The change test's false-alarm rate (``TensionFilterParams.false_alarms_per_h``, 0.005 per
hour per drone) is measured on the tension filter alone in docs/change_test_benchmark.md
(240 h of simulated noise, the filter driven directly). Here the whole service runs
(``benchmarks.bench_realistic.fly``: the realistic simulator's rigid body, lumped-mass
tether, controller, motor lag and vibration; the pipeline with its hover test, slow stage
and contact stage, as the service runs it without motion capture; calibration = the
flight's own airframe constants, the hover priors the defaults; ``--thrust-model``: the
battery's law in them as the straight line, first order about the simulator's reference
voltage, or as the motor-voltage model, the simulator's law at every voltage:
groundstation.sim.sensors), each flight a hover at one
of the paper's six spots (in turn) for ``--minutes`` (4: a Crazyflie's battery lasts ~7,
and the simulator's drains), judged from ``SETTLE_S`` on. Nothing pulls and nothing moves
the drone, so every change detection in the judged time is a false one, as far as the
filter's model goes: the truth's own slow changes (the battery's sag under the thrust map,
the tether's swing) are what the full simulator adds to the filter-alone page.

Printed: per flight the judged hours, the detections and their times; in all, detections
per hour and, if none, the rate a Poisson count of zero bounds at 95 % (3 / hours: this run
can refute a rate far above 0.005 per hour, not confirm 0.005), and the tension's error RMS
and the share of samples within 2σ per world axis (the published ``tension_std_n``), in
all and per minute of flight (with the error's mean: a bias that grows with the flight,
as the battery sags, shows there).
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from benchmarks import bench_realistic as br
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M

SETTLE_S = 20.0
"""Judged from this long after the flight's start (the filter's start and the first hover
regime; bench_realistic judges its 20 s hovers from 8 s)."""


def one(job: tuple[int, int, float, float, str]) -> dict[str, Any]:
    """One flight: ``(spot, seed, minutes, noise, thrust_model)`` → what is judged."""
    spot, seed, minutes, noise, thrust_model = job
    f = br.fly(br._scenario_for_spot(spot), 60.0 * minutes, noise, seed, thrust_model=thrust_model)
    w = f.t_s >= SETTLE_S
    err = f.est_tension_n[w] - f.true_tension_n[w]
    std = f.est_tension_std_n[w]
    within = np.abs(err) <= 2.0 * std
    judged_s = float(f.t_s[w][-1] - f.t_s[w][0]) if w.any() else 0.0
    # Per minute of flight (the judged samples in it), sums over the samples: the error,
    # its square, the σ, the samples within 2σ, and their count; the run's totals and its
    # per-minute means are formed from them.
    minute = np.floor(f.t_s[w] / 60.0).astype(int)
    per_minute = {}
    for k in np.unique(minute).tolist():
        m = minute == k
        per_minute[k] = (
            err[m].sum(axis=0),
            (err[m] * err[m]).sum(axis=0),
            std[m].sum(axis=0),
            within[m].sum(axis=0),
            int(m.sum()),
        )
    return {
        "spot": spot,
        "seed": seed,
        "judged_h": judged_s / 3600.0,
        "detections": [s for s in f.change_stamps_s if s >= SETTLE_S],
        "all_detections": list(f.change_stamps_s),
        "sigma_median_mn": (1e3 * np.median(std, axis=0)).tolist(),
        "per_minute": per_minute,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=24)
    ap.add_argument("--minutes", type=float, default=4.0, help="per flight (4)")
    ap.add_argument("--noise", type=float, default=0.8, help="vibration, m/s^2 (0.8)")
    ap.add_argument("--seed-base", type=int, default=7000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument(
        "--thrust-model",
        choices=("vbat_linear", "motor_voltage"),
        default="vbat_linear",
        help="the truth calibration's battery law (vbat_linear)",
    )
    args = ap.parse_args(argv)
    spots = len(PAPER_HOVER_SPOTS_M)
    jobs = [
        (k % spots, args.seed_base + k, args.minutes, args.noise, args.thrust_model)
        for k in range(args.flights)
    ]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(one, jobs))
    hours = sum(r["judged_h"] for r in rows)
    detections = sum(len(r["detections"]) for r in rows)
    parts = [p for r in rows for p in r["per_minute"].values()]
    samples = sum(p[4] for p in parts)
    rms = np.sqrt(np.sum([p[1] for p in parts], axis=0) / samples)
    within = np.sum([p[3] for p in parts], axis=0) / samples
    print(
        f"Realistic simulator, {args.noise} m/s^2, {args.flights} hovers of {args.minutes:g} min "
        f"(seeds {args.seed_base}-{args.seed_base + args.flights - 1}, the paper's six spots in "
        f"turn), judged from {SETTLE_S:g} s; truth calibration's battery law "
        f"{args.thrust_model}; {time.perf_counter() - t0:.0f} s wall."
    )
    print()
    print(
        "| spot | seed | judged h | detections (judged) | detections before | median σ x/y/z mN |"
    )
    print("| --- | --- | ---: | --- | --- | --- |")
    for r in rows:
        before = [s for s in r["all_detections"] if s < SETTLE_S]
        print(
            f"| {r['spot']} | {r['seed']} | {r['judged_h']:.3f} | "
            f"{', '.join(f'{s:.1f} s' for s in r['detections']) or '0'} | "
            f"{', '.join(f'{s:.1f} s' for s in before) or '0'} | "
            f"{'/'.join(f'{x:.2f}' for x in r['sigma_median_mn'])} |"
        )
    print()
    rate = detections / hours if hours > 0 else math.nan
    bound = (
        f"; none: a rate above {3.0 / hours:.2f} per hour is refuted at 95 %"
        if not detections
        else ""
    )
    print(
        f"In all: {detections} change detections in {hours:.2f} h of hover, "
        f"{rate:.3f} per hour{bound}."
    )
    print(
        f"Tension error RMS x/y/z {'/'.join(f'{1e3 * x:.3f}' for x in rms)} mN; within 2σ "
        f"{'/'.join(f'{100 * x:.1f}' for x in within)} % of {samples} samples."
    )
    print()
    print("Per minute of flight, pooled over the flights (judged samples only):")
    print()
    print("| minute | mean error x/y/z mN | mean σ x/y/z mN | within 2σ x/y/z |")
    print("| --- | --- | --- | --- |")
    for k in sorted({k for r in rows for k in r["per_minute"]}):
        in_k = [r["per_minute"][k] for r in rows if k in r["per_minute"]]
        n = sum(p[4] for p in in_k)
        e = np.sum([p[0] for p in in_k], axis=0) / n
        sd = np.sum([p[2] for p in in_k], axis=0) / n
        inn = np.sum([p[3] for p in in_k], axis=0) / n
        print(
            f"| {k} | {'/'.join(f'{1e3 * x:.2f}' for x in e)} | "
            f"{'/'.join(f'{1e3 * x:.2f}' for x in sd)} | "
            f"{'/'.join(f'{100 * x:.0f} %' for x in inn)} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
