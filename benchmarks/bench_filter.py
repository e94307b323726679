"""Monte-Carlo benchmark of the tension filter against fixed-gain baselines.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_filter            # full, writes docs/filter_benchmark.md
    .venv/bin/python -m benchmarks.bench_filter --quick    # a smoke run, prints only

Noise model (the simulator's): 30 g drone, accelerometer noise 0.3 m/s^2 per axis and
sample, thrust noise 3 mN, 250 Hz. The drone holds still against the tether, so its
thrust axis is -(T + m g); an observation is then T + m R n_a - R e3 n_F, which is the
exact distribution :func:`groundstation.tension.observe_tension` produces (its
exactness is a unit test), generated here in bulk for speed.

Filters compared:

* ``adaptive``: :class:`groundstation.tension.TensionFilter` with its defaults.
* ``fixed-hover``: the same constant-tension Kalman filter with the same hover
  process noise, no change detection, no drift adaptation.
* ``fixed-fast``: a fixed-gain filter tuned to settle a 30 mN step to 10 % in 0.3 s
  (time constant 0.13 s).
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.figures import AT_START, write_figures
from groundstation.tension import (
    GRAVITY_MPS2,
    TensionFilter,
    TensionFilterParams,
    observe_tension,
)

DT_S = 0.004
MASS_KG = 0.030
ACCEL_NOISE_MPS2 = 0.3
THRUST_NOISE_N = 0.003
STEP_N = 0.030
TOL_N = 0.003
HOVER_TENSION_N = np.array([-0.020, 0.005, -0.060])
DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "filter_benchmark.md"

# Fixed gains: no change test, no drift adaptation (its shortest time constant is the hover
# one); "fast" holds tau = 0.13 s, the time constant a fixed filter needs for the tug target.
FILTERS: dict[str, TensionFilterParams] = {
    "adaptive": TensionFilterParams(),
    "fixed-hover": TensionFilterParams(
        false_alarms_per_h=0.0, drift_min_time_constant_s=6.0, hover_wander_n2_per_s=0.0
    ),
    "fixed-fast": TensionFilterParams(
        hover_time_constant_s=0.13,
        false_alarms_per_h=0.0,
        drift_min_time_constant_s=0.13,
        hover_wander_n2_per_s=0.0,
    ),
}


# ---------------------------------------------------------------- simulation


def hover_quats(truth_n: np.ndarray) -> np.ndarray:
    """Attitudes (w, x, y, z) whose thrust axis holds the drone still against ``truth_n``."""
    thrust = -(truth_n + MASS_KG * np.array([0.0, 0.0, -GRAVITY_MPS2]))
    u = thrust / np.linalg.norm(thrust, axis=1, keepdims=True)
    # Minimal rotation e3 -> u: q = normalise(1 + u_z, -u_y, u_x, 0).
    q = np.stack([1.0 + u[:, 2], -u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def observations(truth_n: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Noisy tension observations (N) and attitudes for a drone held against ``truth_n``."""
    quats = hover_quats(truth_n)
    w, x, y = quats[:, 0], quats[:, 1], quats[:, 2]
    # Third column of R_world_body for q = (w, x, y, 0): the thrust axis in the world.
    u = np.stack([2 * w * y, -2 * w * x, 1 - 2 * (x * x + y * y)], axis=1)
    n = len(truth_n)
    obs = truth_n + MASS_KG * ACCEL_NOISE_MPS2 * rng.standard_normal((n, 3))
    obs -= u * (THRUST_NOISE_N * rng.standard_normal(n))[:, None]
    return obs, quats


@dataclass
class Run:
    est_n: np.ndarray
    std_n: np.ndarray
    detections: np.ndarray
    statistic: np.ndarray
    seconds_per_update: float


def run(params: TensionFilterParams, truth_n: np.ndarray, rng: np.random.Generator) -> Run:
    obs, quats = observations(truth_n, rng)
    filt = TensionFilter(params)
    n = len(truth_n)
    est = np.empty((n, 3))
    std = np.empty((n, 3))
    det = np.zeros(n, dtype=bool)
    stat = np.zeros(n)
    t0 = time.perf_counter()
    for k in range(n):
        e = filt.update(obs[k], DT_S, quats[k])
        est[k] = e.tension_world_n
        std[k] = e.std_n
        det[k] = e.change_detected
        stat[k] = e.change_statistic
    elapsed = time.perf_counter() - t0
    return Run(est, std, det, stat, elapsed / n)


def settle_s(err_n: np.ndarray, reduce: Callable[[np.ndarray], np.ndarray]) -> float:
    bad = np.nonzero(reduce(err_n) > TOL_N)[0]
    return 0.0 if len(bad) == 0 else (int(bad[-1]) + 1) * DT_S


def random_direction(rng: np.random.Generator) -> np.ndarray:
    d = rng.standard_normal(3)
    return d / np.linalg.norm(d)


# ---------------------------------------------------------------- scenarios


def bench_hover(params: TensionFilterParams, seeds: int, seconds: float) -> dict[str, object]:
    n = int(seconds / DT_S)
    start = int(5.0 / DT_S)
    per_seed_rms = []
    errs = []
    stds = []
    dets = 0
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        tension = HOVER_TENSION_N + rng.uniform(-0.03, 0.03, 3)
        truth = np.tile(tension, (n, 1))
        r = run(params, truth, rng)
        err = r.est_n[start:] - truth[start:]
        per_seed_rms.append(np.sqrt(np.mean(err**2, axis=0)))
        errs.append(err)
        stds.append(r.std_n[start:].mean(axis=0))
        dets += int(r.detections.sum())
    pooled = np.concatenate(errs)
    return {
        "rms_mn": np.sqrt(np.mean(pooled**2, axis=0)) * 1e3,
        "err_std_mn": pooled.std(axis=0) * 1e3,
        "worst_seed_rms_mn": np.max(per_seed_rms, axis=0) * 1e3,
        "reported_std_mn": np.mean(stds, axis=0) * 1e3,
        "detections": dets,
    }


def bench_steps(params: TensionFilterParams, trials: int) -> dict[str, object]:
    step_at = int(3.0 / DT_S)
    n = step_at + int(1.5 / DT_S)
    axis, norm, delay, late = [], [], [], []
    for trial in range(trials):
        rng = np.random.default_rng(5000 + trial)
        truth = np.tile(HOVER_TENSION_N, (n, 1))
        truth[step_at:] += STEP_N * random_direction(rng)
        r = run(params, truth, rng)
        err = r.est_n[step_at:] - truth[step_at:]
        axis.append(settle_s(err, lambda e: np.abs(e).max(axis=1)))
        norm.append(settle_s(err, lambda e: np.linalg.norm(e, axis=1)))
        late.append(err[int(0.3 / DT_S) :])
        hits = np.nonzero(r.detections[step_at:])[0]
        delay.append(hits[0] * DT_S if len(hits) else math.nan)
    late_err = np.concatenate(late)
    return {
        "axis_s": np.array(axis),
        "norm_s": np.array(norm),
        "delay_s": np.array(delay),
        "late_rms_mn": float(np.sqrt(np.mean(late_err**2))) * 1e3,
    }


def bench_false_alarms(params: TensionFilterParams, hours: float, chunks: int) -> dict[str, object]:
    n = int(hours * 3600.0 / DT_S / chunks)
    dets = 0
    max_stat = 0.0
    over_half = 0
    for chunk in range(chunks):
        rng = np.random.default_rng(9000 + chunk)
        tension = HOVER_TENSION_N + rng.uniform(-0.05, 0.05, 3)
        r = run(params, np.tile(tension, (n, 1)), rng)
        dets += int(r.detections.sum())
        max_stat = max(max_stat, float(r.statistic.max()))
        over_half += int(np.sum(r.statistic > 0.5 * TensionFilter(params).fast_threshold(DT_S)))
    return {
        "hours": n * chunks * DT_S / 3600.0,
        "detections": dets,
        "max_statistic": max_stat,
        "samples_over_half_threshold": over_half,
    }


def bench_cost(params: TensionFilterParams, repeats: int = 20, n: int = 500) -> float:
    """Best-of-``repeats`` cost of one ``update``, µs (the machine is shared: take the min)."""
    rng = np.random.default_rng(1)
    obs, quats = observations(np.tile(HOVER_TENSION_N, (n, 1)), rng)
    best = math.inf
    for _ in range(repeats):
        filt = TensionFilter(params)
        t0 = time.perf_counter()
        for k in range(n):
            filt.update(obs[k], DT_S, quats[k])
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def bench_observe_cost(repeats: int = 20, n: int = 500) -> float:
    """Best-of-``repeats`` cost of one ``observe_tension``, µs."""
    accel = np.array([0.1, -0.2, 9.8])
    quat = np.array([0.99, 0.05, -0.03, 0.1])
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            observe_tension(accel, quat, 0.35, MASS_KG)
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def bench_ramps(params: TensionFilterParams, rates_n_per_s: list[float]) -> list[dict[str, float]]:
    out = []
    n = int(20.0 / DT_S)
    t = np.arange(n) * DT_S
    d = np.array([1.0, 0.5, -1.0]) / 1.5
    for rate in rates_n_per_s:
        rng = np.random.default_rng(77)
        truth = HOVER_TENSION_N + np.outer(np.clip(t - 5.0, 0.0, None) * rate, d)
        r = run(params, truth, rng)
        err = (r.est_n - truth)[int(8.0 / DT_S) :]
        out.append(
            {
                "rate_mn_per_s": rate * 1e3,
                "rms_mn": float(np.sqrt(np.mean(err**2))) * 1e3,
                "max_mn": float(np.abs(err).max()) * 1e3,
                "detections": float(r.detections[int(5.0 / DT_S) :].sum()),
            }
        )
    return out


def bench_irregular(params: TensionFilterParams, seeds: int) -> dict[str, float]:
    worst = 0.0
    rms = []
    for seed in range(seeds):
        rng = np.random.default_rng(3000 + seed)
        n = int(20.0 / DT_S)
        dts = rng.uniform(0.001, 0.02, n)
        dts[rng.integers(0, n, 5)] = rng.uniform(0.5, 3.0, 5)
        truth = np.tile(HOVER_TENSION_N, (n, 1))
        obs, quats = observations(truth, rng)
        filt = TensionFilter(params)
        est = np.array([filt.update(obs[k], dts[k], quats[k]).tension_world_n for k in range(n)])
        err = (est - truth)[int(5.0 / DT_S) :]
        worst = max(worst, float(np.abs(err).max()))
        rms.append(float(np.sqrt(np.mean(err**2))))
    return {"rms_mn": float(np.mean(rms)) * 1e3, "max_mn": worst * 1e3}


# ---------------------------------------------------------------- report


def fmt3(v: object) -> str:
    a = np.asarray(v, dtype=float)
    return " / ".join(f"{x:.3f}" for x in a)


def pct(a: np.ndarray, q: float) -> float:
    a = a[np.isfinite(a)]
    return float(np.percentile(a, q)) if len(a) else math.nan


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--quick", action="store_true", help="small smoke run; do not write docs")
    args = ap.parse_args(argv)
    quick = args.quick
    hover_seeds, hover_s = (3, 15.0) if quick else (20, 30.0)
    step_trials = 20 if quick else 200
    fa_hours, fa_chunks = (0.02, 2) if quick else (1.0, 12)
    base_steps = 10 if quick else 60

    t_start = time.perf_counter()
    results: dict[str, dict[str, object]] = {}
    for name, params in FILTERS.items():
        print(f"[{name}] hover ...", file=sys.stderr)
        hover = bench_hover(params, hover_seeds, hover_s)
        print(f"[{name}] steps ...", file=sys.stderr)
        steps = bench_steps(params, step_trials if name == "adaptive" else base_steps)
        results[name] = {"hover": hover, "steps": steps, "cost_us": bench_cost(params)}
    adaptive = FILTERS["adaptive"]
    print("[adaptive] false alarms ...", file=sys.stderr)
    fa = bench_false_alarms(adaptive, fa_hours, fa_chunks)
    print("[adaptive] ramps, irregular dt ...", file=sys.stderr)
    ramps = bench_ramps(adaptive, [1e-3, 3e-3, 10e-3, 30e-3, 100e-3])
    ramps_fixed = bench_ramps(FILTERS["fixed-hover"], [1e-3, 3e-3, 10e-3, 30e-3, 100e-3])
    irregular = bench_irregular(adaptive, 3 if quick else 10)
    observe_us = bench_observe_cost()
    wall_s = time.perf_counter() - t_start

    lines = [
        "# Tension filter benchmark",
        "",
        "Generated by `.venv/bin/python -m benchmarks.bench_filter`"
        + (" --quick" if quick else "")
        + f" (this page and its figures, docs/filter_benchmark.json; {wall_s:.0f} s wall time"
        + f" at commit {AT_START.commit}, Python {platform.python_version()},"
        + f" {platform.machine()}). Noise model: 30 g drone, accelerometer 0.3 m/s^2 per"
        " axis, thrust 3 mN, 250 Hz; observations with exactly the distribution of"
        " `observe_tension` (see the module docstring of `benchmarks/bench_filter.py`).",
        "Design and reasoning: the `TensionFilter` docstring in `groundstation/tension.py`.",
        "",
        "## Steady hover (error from 5 s on; mN, x / y / z)",
        "",
        f"{hover_seeds} seeds x {hover_s:.0f} s, tension drawn around (-20, 5, -60) mN.",
        "",
        "| filter | RMS error | error std | worst seed RMS | reported std (mean) |"
        " false detections | cost per update |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, res in results.items():
        h = res["hover"]
        assert isinstance(h, dict)
        lines.append(
            f"| {name} | {fmt3(h['rms_mn'])} | {fmt3(h['err_std_mn'])} |"
            f" {fmt3(h['worst_seed_rms_mn'])} | {fmt3(h['reported_std_mn'])} |"
            f" {h['detections']} | {res['cost_us']:.0f} µs |"
        )
    lines += [
        "",
        "Target: RMS <= 0.5 mN per axis. The reported std is sqrt(diag P); under the",
        "random-walk model it is sqrt(2) larger than the error of a truly constant tension.",
        "Worst seed: the RMS of one 25 s window of a slow (6 s) average scatters widely (a",
        "few independent averages). Cost: best of 20 x 500 updates on a shared 2-core machine;"
        f" `observe_tension` adds {observe_us:.0f} µs per sample.",
        "",
        "## 30 mN steps in random directions",
        "",
        "Settle time: from the step until the error stays within 3 mN for the remaining",
        "1.5 s of the trial; per axis (largest |error| component) and for the error norm.",
        "",
        "| filter | trials | per-axis median / p95 / max | norm median / p95 / max |"
        " <= 0.3 s (axis / norm) | RMS error per axis from 0.3 s on |"
        " detection delay median / max |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, res in results.items():
        s = res["steps"]
        assert isinstance(s, dict)
        ax, nm, dl = s["axis_s"], s["norm_s"], s["delay_s"]
        delay = (
            f"{np.nanmedian(dl) * 1e3:.0f} / {np.nanmax(dl) * 1e3:.0f} ms"
            if np.any(np.isfinite(dl))
            else "n/a"
        )
        lines.append(
            f"| {name} | {len(ax)} | {np.median(ax):.3f} / {pct(ax, 95):.3f} / {ax.max():.3f} s"
            f" | {np.median(nm):.3f} / {pct(nm, 95):.3f} / {nm.max():.3f} s"
            f" | {np.mean(ax <= 0.3) * 100:.0f} % / {np.mean(nm <= 0.3) * 100:.0f} %"
            f" | {s['late_rms_mn']:.2f} mN | {delay} |"
        )
    lines += [
        "",
        "Information limit: 0.3 s after a step there are 75 samples of 9 mN noise, so even",
        "the mean of exactly the post-step samples (which is what the adaptive filter",
        "returns after its change-point replay) has 1.04 mN std per axis; a 3 mN band on",
        "the norm of a 3-D error of that size is left with about 4 % probability at that",
        "instant, and first-passage over the following samples adds to it. The p95 figures",
        "near or above 0.3 s are that limit, not filter lag. The fixed-fast filter does",
        "reach the new tension in 0.3 s on average, but its 1.1 mN hover noise keeps",
        'crossing the 3 mN band, so it never "settles" by this measure; the fixed-hover',
        "filter is still about 90 % of the step away after 0.3 s.",
        "",
        "## False change detections at hover (adaptive)",
        "",
        f"- hover time: {fa['hours']:.2f} h in {fa_chunks} runs, tension drawn around"
        " (-20, 5, -60) mN +- 50 mN",
        f"- false detections: {fa['detections']}",
        f"- largest change statistic: {fa['max_statistic']:.1f}"
        f" (threshold {TensionFilter(adaptive).fast_threshold(DT_S):.1f}; chi-square 3 dof"
        " per window)",
        f"- samples with the statistic above half the threshold: "
        f"{fa['samples_over_half_threshold']}",
        "",
        "## Ramps (slow drifts; error from 8 s on, the ramp starts at 5 s)",
        "",
        "Direction (1, 0.5, -1)/1.5; the x component ramps at 2/3 of the rate.",
        "",
        "| rate | adaptive RMS / max | adaptive re-initialisations | fixed-hover RMS / max |",
        "| --- | --- | --- | --- |",
    ]
    for a, f in zip(ramps, ramps_fixed, strict=True):
        lines.append(
            f"| {a['rate_mn_per_s']:.0f} mN/s | {a['rms_mn']:.2f} / {a['max_mn']:.2f} mN"
            f" | {a['detections']:.0f} | {f['rms_mn']:.2f} / {f['max_mn']:.2f} mN |"
        )
    lines += [
        "",
        "## Irregular dt (adaptive)",
        "",
        "dt uniform in [1, 20] ms plus five gaps of 0.5-3 s per 20 s run;"
        f" RMS {irregular['rms_mn']:.3f}<!-- fig filter_benchmark.json irregular.rms_mn --> mN,"
        f" max |error| {irregular['max_mn']:.2f}<!-- fig filter_benchmark.json irregular.max_mn"
        " --> mN"
        " (from 5 s on).",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if not quick:
        DOC_PATH.write_text(text, encoding="utf-8")
        print(f"wrote {DOC_PATH}", file=sys.stderr)
        figures = {
            "filters": results,
            "false_alarms": fa,
            "ramps": ramps,
            "ramps_fixed_hover": ramps_fixed,
            "irregular": irregular,
            "observe_cost_us": observe_us,
        }
        write_figures("filter_benchmark", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
