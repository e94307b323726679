"""The tension filter's change detection on strong coloured noise: false alarms and delays.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_change_test          # docs/change_test_benchmark.md
    .venv/bin/python -m benchmarks.bench_change_test --quick  # a short run, prints only

Written to docs/change_test_benchmark.md (``--out`` elsewhere), the figures also go to
``docs/change_test_benchmark.json`` (:mod:`benchmarks.figures`).

:class:`groundstation.tension.TensionFilter` alone (no simulator, no pipeline), fed a constant
tension plus vibration noise at 1 and 2 m/s^2 per axis on a 30 g drone, at ~94 Hz with the
Crazyflie's 6-27 ms jittered spacing, and *not* told the noise (it is configured with the
0.3 m/s^2 default). Two colours: the realistic simulator's white + AR(0.6) mix (lag-1 0.2,
long-run variance 2 s2) and AR(1) with rho = 0.3 (the real flights' lag-1).

* **Hover**: ``--flights`` hovers of ``--minutes`` each (12 x 10 min; quick 3 x 2 min) per
  case; the largest ``change_statistic`` of each flight (a detection is a value above the
  change test's threshold, ``TensionFilter.change_threshold``, derived from the false-alarm
  rate at the measured spacing) and the detections.
* **Step**: after 40 s of hover, a 30 mN step in a random direction; the first detection
  after it (none within 9.5 s: counted as missed), against the information limit (the time
  at which the step's samples hold the change test's threshold as non-centrality, the level
  before the step known exactly).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.figures import AT_START, DOCS, marker, write_figures
from groundstation.tension import TensionFilter, TensionFilterParams

DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "change_test_benchmark.md"
FIGURES = "change_test_benchmark.json"
MASS_KG = 0.030
HOVER_N = np.array([-0.020, 0.005, -0.060])
CASES = ((1.0, "mix"), (2.0, "mix"), (1.0, "ar1"), (2.0, "ar1"))
LONG_RUN = {"mix": 2.0, "ar1": 1.3 / 0.7}  # r / s2


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    e = rng.normal(0.0, math.sqrt(1.0 - rho * rho), (n, 3))
    v = np.empty_like(e)
    v[0] = rng.normal(0.0, 1.0, 3)
    for k in range(1, n):
        v[k] = rho * v[k - 1] + e[k]
    return v


def noise(rng: np.random.Generator, n: int, sigma_n: float, colour: str) -> np.ndarray:
    """Vibration noise per world axis, N, shape (n, 3)."""
    if colour == "ar1":
        return sigma_n * _ar1(rng, n, 0.3)
    beta = 0.2 / 0.6  # white + AR(0.6) with lag-1 0.2, as groundstation/sim/sensors.py
    white = rng.normal(0.0, 1.0, (n, 3))
    return sigma_n * (math.sqrt(beta) * _ar1(rng, n, 0.6) + math.sqrt(1.0 - beta) * white)


def spacing(rng: np.random.Generator, n: int) -> np.ndarray:
    """Crazyflie-like stamps: 100 Hz nominal, scatter and late samples, 6-27 ms."""
    late = 0.012 * (rng.random(n) < 0.05)
    out: np.ndarray = np.clip(0.010 + rng.normal(0.0, 0.003, n) + late, 0.006, 0.027)
    return out


def hover(
    level: float, colour: str, minutes: float, flights: int, seed_base: int = 5000
) -> dict[str, Any]:
    largest, detections, r_ratio, thresholds = [], 0, [], []
    r_true = (MASS_KG * level) ** 2 * LONG_RUN[colour]
    for f in range(flights):
        seed = seed_base + f + int(100 * level) + (7 if colour == "ar1" else 0)
        rng = np.random.default_rng(seed)
        n = int(minutes * 60.0 / 0.0106)
        v = noise(rng, n, MASS_KG * level, colour)
        dts = spacing(rng, n)
        filt = TensionFilter()
        top = 0.0
        for k in range(n):
            e = filt.update(HOVER_N + v[k], float(dts[k]))
            detections += e.change_detected
            top = max(top, e.change_statistic)
        largest.append(top)
        thresholds.append(filt.change_threshold)
        r_ratio.append(float(np.mean(filt.noise_model()[2])) / r_true)
    return {
        "largest": largest,
        "detections": detections,
        "hours": flights * minutes / 60.0,
        "r_ratio": r_ratio,
        "thresholds": thresholds,
    }


def step_trial(
    level: float, colour: str, trial: int, seed_base: int = 900
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """One step trial: its noise (n, 3) N, spacing (n,) s, step (3,) N (30 mN in a random
    direction), and the samples before the step and in all (40 s of hover, then 9.5 s)."""
    rng = np.random.default_rng(seed_base + trial + int(10 * level) + (7 if colour == "ar1" else 0))
    n_hover, n = 4000, 4900
    v = noise(rng, n, MASS_KG * level, colour)
    dts = spacing(rng, n)
    d = rng.normal(0.0, 1.0, 3)
    step: np.ndarray = 0.030 * d / np.linalg.norm(d)
    return v, dts, step, n_hover, n


def steps(level: float, colour: str, trials: int) -> dict[str, Any]:
    sigma_n = MASS_KG * level
    r = sigma_n**2 * LONG_RUN[colour]
    delays: list[float | None] = []
    spacings = []
    for s in range(trials):
        v, dts, step, n_hover, n = step_trial(level, colour, s)
        spacings.append(float(np.mean(dts)))
        filt = TensionFilter()
        found = None
        for k in range(n):
            e = filt.update(HOVER_N + (step if k >= n_hover else 0.0) + v[k], float(dts[k]))
            if e.change_detected and k >= n_hover and found is None:
                found = float(np.sum(dts[n_hover : k + 1]))
        delays.append(found)
    dt = float(np.mean(spacings))
    h = TensionFilter().fast_threshold(dt)
    per_sample = 0.030**2 / r
    return {"delays": delays, "threshold": h, "limit_known_s": h / per_sample * dt}


def _key(level: float, colour: str) -> str:
    """A case's key in the figures: ``mix_1`` for 1 m/s² of the mix."""
    return f"{colour}_{level:g}"


def figures_of(res: dict[str, Any]) -> dict[str, Any]:
    """The page's figures (:func:`benchmarks.figures.write_figures`): per case its hover
    (hours, detections, the largest statistic per flight and the threshold, min / median /
    max) and its steps (delays, missed, the information limit), and the totals."""
    hover: dict[str, Any] = {}
    for h in res["hover"]:
        a = np.array(h["largest"])
        q = np.array(h["r_ratio"])
        th = np.array(h["thresholds"])
        hover[_key(h["level"], h["colour"])] = {
            "level_mps2": h["level"],
            "colour": h["colour"],
            "flights": len(h["largest"]),
            "hours": h["hours"],
            "detections": h["detections"],
            "largest_min": float(a.min()),
            "largest_median": float(np.median(a)),
            "largest_max": float(a.max()),
            "threshold_min": float(th.min()),
            "threshold_max": float(th.max()),
            "r_ratio_min": float(q.min()),
            "r_ratio_median": float(np.median(q)),
            "r_ratio_max": float(q.max()),
        }
    steps: dict[str, Any] = {}
    for st in res["steps"]:
        ok = [x for x in st["delays"] if x is not None]
        steps[_key(st["level"], st["colour"])] = {
            "level_mps2": st["level"],
            "colour": st["colour"],
            "trials": len(st["delays"]),
            "threshold": st["threshold"],
            "delay_min_s": min(ok) if ok else None,
            "delay_median_s": float(np.median(ok)) if ok else None,
            "delay_max_s": max(ok) if ok else None,
            "missed": len(st["delays"]) - len(ok),
            "limit_known_s": st["limit_known_s"],
        }
    hours = sum(h["hours"] for h in hover.values())
    detections = sum(h["detections"] for h in hover.values())
    return {
        "hours": hours,
        "detections": detections,
        "per_hour": detections / hours,
        "largest": max(h["largest_max"] for h in hover.values()),
        "threshold_min": min(h["threshold_min"] for h in hover.values()),
        "threshold_max": max(h["threshold_max"] for h in hover.values()),
        "false_alarms_per_h": TensionFilterParams().false_alarms_per_h,
        "hover": hover,
        "step_trials": sum(st["trials"] for st in steps.values()),
        "steps_missed": sum(st["missed"] for st in steps.values()),
        "steps": steps,
    }


def _fig(key: str) -> str:
    return marker(FIGURES, key)


def render(fig: dict[str, Any], cmd: str, wall_s: float) -> str:
    L = [
        "# Change detection on strong coloured noise",
        "",
        f"Generated by `{cmd}` (this page and its figures, docs/{FIGURES}; {wall_s:.0f} s "
        f"wall time, commit {AT_START.commit}, Python "
        f"{platform.python_version()}, {platform.machine()}). Method: the module docstring of "
        "`benchmarks/bench_change_test.py` (the tension filter alone, not told the noise, "
        "~94 Hz jittered; `mix`: white + AR(0.6), lag-1 0.2, as the realistic simulator; "
        "`ar1`: AR(1), rho = 0.3).",
        "",
        "## Hover: the largest change statistic per flight",
        "",
        "A detection is a value above the change test's threshold (derived from the filter's "
        "false-alarm rate at the measured spacing; its range over the flights in the column h).",
        "",
        "| noise | colour | hover | h | largest per flight (min / median / max) | detections "
        "| estimated / true long-run variance at the end (min / median / max) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for k, h in fig["hover"].items():
        L.append(
            f"| {h['level_mps2']:.1f} m/s^2 | {h['colour']} | "
            f"{h['hours']:.1f} h{_fig(f'hover.{k}.hours')} | "
            f"{h['threshold_min']:.1f}{_fig(f'hover.{k}.threshold_min')}–"
            f"{h['threshold_max']:.1f}{_fig(f'hover.{k}.threshold_max')} | "
            f"{h['largest_min']:.1f} / {h['largest_median']:.1f} / "
            f"{h['largest_max']:.1f}{_fig(f'hover.{k}.largest_max')} | "
            f"{h['detections']}{_fig(f'hover.{k}.detections')} | "
            f"{h['r_ratio_min']:.2f} / {h['r_ratio_median']:.2f} / {h['r_ratio_max']:.2f} |"
        )
    L += [
        "",
        f"In all: {fig['detections']}{_fig('detections')} false detections in "
        f"{fig['hours']:.1f} h{_fig('hours')} of hover, {fig['per_hour']:.4f} per hour "
        f"(the filter's `false_alarms_per_h`: {fig['false_alarms_per_h']:g}).",
    ]
    L += [
        "",
        "## A 30 mN step after 40 s of hover",
        "",
        "Information limit: the time at which the step's samples hold the threshold h as "
        "non-centrality, n step^2 / r = h, the level before the step known exactly (r the "
        "true long-run variance): a detector at this false-alarm rate detects about half "
        "the time by then.",
        "",
        "| noise | colour | trials | h | delay min / median / max | missed | information limit |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for k, st in fig["steps"].items():
        cells = (
            "n/a"
            if st["delay_median_s"] is None
            else f"{st['delay_min_s']:.2f} / "
            f"{st['delay_median_s']:.2f}{_fig(f'steps.{k}.delay_median_s')} / "
            f"{st['delay_max_s']:.2f} s"
        )
        L.append(
            f"| {st['level_mps2']:.1f} m/s^2 | {st['colour']} | {st['trials']} | "
            f"{st['threshold']:.1f}{_fig(f'steps.{k}.threshold')} | {cells} | "
            f"{st['missed']}{_fig(f'steps.{k}.missed')} | "
            f"{st['limit_known_s']:.2f} s{_fig(f'steps.{k}.limit_known_s')} |"
        )
    L.append("")
    return "\n".join(L)


def _case(job: tuple[float, str, float, int, int, int]) -> tuple[dict[str, Any], dict[str, Any]]:
    """One case's hovers and steps (a process of its own with ``--jobs``)."""
    level, colour, minutes, flights, seed_base, trials = job
    held = hover(level, colour, minutes, flights, seed_base)
    print(f"hover {level} {colour}: {held['detections']} detections", file=sys.stderr, flush=True)
    return held, steps(level, colour, trials)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short run; do not write docs")
    ap.add_argument("--minutes", type=float, help="minutes per hover flight (10; quick 2)")
    ap.add_argument("--flights", type=int, help="hover flights per case (12; quick 3)")
    ap.add_argument(
        "--seed-base",
        type=int,
        default=5000,
        help="the hovers' seeds start here (5000; another base flies other hovers, to add "
        "hours to an earlier run's)",
    )
    ap.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="cases run in parallel processes (1; the figures do not depend on it)",
    )
    ap.add_argument(
        "--out",
        help="write the page here (docs/change_test_benchmark.md; its figures, "
        "docs/change_test_benchmark.json, only there)",
    )
    args = ap.parse_args(argv)
    quick = args.quick
    minutes = args.minutes or (2.0 if quick else 10.0)
    flights = args.flights or (3 if quick else 12)
    trials = 4 if quick else 12
    t0 = time.time()
    res: dict[str, Any] = {"hover": [], "steps": []}
    jobs = [(level, colour, minutes, flights, args.seed_base, trials) for level, colour in CASES]
    if args.jobs > 1:
        with multiprocessing.Pool(args.jobs) as pool:
            done = pool.map(_case, jobs)
    else:
        done = [_case(j) for j in jobs]
    for (level, colour, *_), (held, stepped) in zip(jobs, done, strict=True):
        res["hover"].append({"level": level, "colour": colour, **held})
        res["steps"].append({"level": level, "colour": colour, **stepped})
    cmd = ".venv/bin/python -m benchmarks.bench_change_test" + (" --quick" if quick else "")
    if args.minutes is not None:
        cmd += f" --minutes {args.minutes:g}"
    if args.flights is not None:
        cmd += f" --flights {args.flights}"
    if args.seed_base != 5000:
        cmd += f" --seed-base {args.seed_base}"
    if args.out is not None:
        cmd += f" --out {args.out}"
    figures = figures_of(res)
    text = render(figures, cmd, time.time() - t0)
    print(text)
    if not quick:
        out = Path(args.out) if args.out else DOC_PATH
        out.write_text(text, encoding="utf-8")
        if out.resolve() == DOCS / "change_test_benchmark.md":
            write_figures("change_test_benchmark", figures, cmd.split()[3:])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
