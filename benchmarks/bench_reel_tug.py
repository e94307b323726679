"""The estimator issue's reel tug on this project's simulator: t90 against a step oracle.

The issue's case (its item 3, measured on an independent simulator that is not in this
repository): a 30 g drone hovers at (1, 0, 1) m on a 1.6 m tether from a base at 0.754 m,
250 Hz telemetry, 0.3 m/s² of white accelerometer vibration, and the reel shortens the
tether to 1.06 m, which near taut is a jump of the tension of about 30 mN. Acceptance: t90
≤ 0.6 s with a pre-tug error ≤ 1.5 mN.

Here the same geometry, rate and noise on this repository's simulator (``groundstation.sim``,
which imports none of the estimator), two profiles: ``ideal`` (quasi-static catenary, exact
sensors, white noise; the drone holds its spot exactly) and ``realistic`` with every drawn
error class off but the vibration, which is white at 0.3 m/s² here (``accel_noise_ar`` and
``accel_noise_lag1`` 0), and the IMU at 250 Hz on time
(rigid body, lumped-mass tether, motor lag, rotor drag: the drone's controller answers the
tug, so the truth keeps moving after it). The reel runs in at ``REEL_RATE_MPS`` from
``TUG_S``: the jump is over in ~0.1 s. The service gets IMU, attitude, thrust and the reel's
length, no motion capture, calibration = the simulator's truth (exact on the ideal profile).

Per seed, with the issue's criterion (its words: "error ≤ 10 % of the jump, then within 20 %
for the next second"): t90 is the first time after the reel starts at which the error norm
is at most 10 % of the jump and stays within 20 % of it for the next second; the jump is the
true tension's change (norm of the difference of its means over the 2 s before and 2–4 s
after). Pre-tug error: the median error norm over the 2 s before. First within 10 %: the first time
after the reel stopped (counted from its start) at which the error norm is at most 10 % of
the jump, without the hold. The step oracle, in the
same flights: the mean of the observations (the accelerometer model with the flight's true
calibration) since the reel stopped, its time known, judged the same way: what a simple
estimator told the step's time could do; it cannot follow a truth that keeps moving. And
the estimator issue's own baseline, "an estimator told the noise" (:func:`told_the_noise`):
a GLR test for a change of mean told the true noise and the true level before the tug, at
the service's false-alarm rate, then a random-walk Kalman filter from its detection, run
with each time constant of ``told_noise.TAUS_S`` and reported at the best one (by median t90,
chosen in hindsight: a bound the service, which is told neither, is not expected to beat).

    python -m benchmarks.bench_reel_tug [--seeds 8] [--out docs/reel_tug.md]

With ``--out docs/reel_tug.md`` the figures also go to ``docs/reel_tug.json``
(:mod:`benchmarks.figures`).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.figures import AT_START, DOCS, kept_reading, marker, write_figures
from benchmarks.told_noise import TAUS_S, glr_random_walk
from groundstation.config import Settings, load_settings
from groundstation.pipeline import Pipeline
from groundstation.sim import SCENARIOS, Scenario, Simulator, Waypoint
from groundstation.tension import observe_tension

DRONE = "cf1"
SPOT_M = (1.0, 0.0, 1.0)
BASE_Z_M = 0.754
LENGTH_M = 1.6
SHORT_M = 1.06
REEL_RATE_MPS = -5.4
"""Reel speed, m/s (in): 1.6 → 1.06 m in 0.1 s."""
TUG_S = 10.0
DURATION_S = 14.0
RATE_HZ = 250.0
NOISE_MPS2 = 0.3
MASS_KG = 0.030
T90_TARGET_S = 0.6
PRE_TUG_TARGET_N = 0.0015


def _scenario() -> str:
    name = "bench_reel_tug"
    SCENARIOS[name] = Scenario(  # registered for this process only (as bench_calibration does)
        name,
        "hover at (1, 0, 1) m; the reel shortens the tether 1.6 -> 1.06 m at 10 s",
        start_m=SPOT_M,
        waypoints=(Waypoint(0.0, SPOT_M),),
        length_m=LENGTH_M,
        reel_rate_mps=REEL_RATE_MPS,
        reel_window_s=(TUG_S, TUG_S + (LENGTH_M - SHORT_M) / -REEL_RATE_MPS),
        duration_s=DURATION_S,
    )
    return name


def _settings(profile: str, seed: int) -> Settings:
    sim: dict[str, Any] = {
        "profile": profile,
        "seed": seed,
        "rate_hz": RATE_HZ,
        "accel_noise_mps2": NOISE_MPS2,
        "mocap": False,
    }
    if profile == "realistic":
        sim["realistic"] = {
            "accel_noise_mps2": NOISE_MPS2,
            "accel_noise_ar": 0.0,
            "accel_noise_lag1": 0.0,
            "accel_noise_lag1_range": (0.0, 0.0),
            "imu_rate_hz": RATE_HZ,
            "imu_timing": False,
            "imu_spacing_min_s": 0.002,
            **{c: False for c in REALISTIC_CLASSES_OFF},
        }
    over: dict[str, Any] = {
        "sim": sim,
        "drone": {"mass_kg": MASS_KG},
        "base": {"position_m": [0.0, 0.0, BASE_Z_M]},
        "tether": {"length_m": LENGTH_M},
    }
    return load_settings(None, over, use_env=False)


REALISTIC_CLASSES_OFF = (
    "misalignment",
    "accel_scale",
    "accel_bias",
    "thrust_axis",
    "thrust_map",
    "battery",
    "mocap_timing",
)
"""The realistic profile's error classes turned off here: the issue's case is the vibration."""


def fly(profile: str, seed: int) -> dict[str, np.ndarray]:
    """One flight through the service's pipeline: per Telemetry its stamp, the published
    tension, the true tension and the accelerometer model's observation."""
    name = _scenario()
    settings = _settings(profile, seed)
    sim = Simulator(settings, None, scenario=name)  # type: ignore[arg-type]
    errors = sim.drawn_errors(DRONE) or {}
    cal = errors.get("airframe_equivalent") if profile == "realistic" else None
    if cal is not None:
        settings = load_settings(
            None,
            {**_overrides(settings), "calibration": {**cal, "source": "truth"}},
            use_env=False,
        )
    pipe = Pipeline(settings)
    truth: dict[float, list[float]] = {}
    rows: list[tuple[float, list[float], list[float]]] = []
    while sim.t_s < DURATION_S:
        now = sim.t_s
        for sample in sim.step():
            kind = sample.key.split("/", 2)[2]
            if kind == "truth":
                t = json.loads(sample.payload)
                truth[round(t["stamp_s"], 6)] = t["tension_n"]
                continue
            outs = pipe.handle(sample, now)
            if kind != "telemetry":
                continue
            msg = json.loads(sample.payload)
            obs = observe_tension(
                msg["accel_mps2"], msg["quat_wxyz"], msg["thrust_n"], MASS_KG, armed=True
            ).tension_world_n
            for out in outs:
                if out.key.endswith("/estimate"):
                    e = json.loads(out.payload)
                    rows.append(
                        (
                            msg["stamp_s"],
                            e["tension_n"],
                            [math.nan] * 3 if obs is None else list(obs),
                        )
                    )
    t = np.array([r[0] for r in rows])
    keep = np.array([round(s, 6) in truth for s in t])
    return {
        "t_s": t[keep],
        "est_n": np.array([r[1] for r in rows])[keep],
        "obs_n": np.array([r[2] for r in rows])[keep],
        "true_n": np.array([truth[round(s, 6)] for s in t[keep]]),
    }


def _overrides(settings: Settings) -> dict[str, Any]:
    return {
        "sim": settings.sim.model_dump(),
        "drone": {"mass_kg": MASS_KG},
        "base": {"position_m": [0.0, 0.0, BASE_Z_M]},
        "tether": {"length_m": LENGTH_M},
    }


MEAN_ERROR_SPAN_S = 1.6
"""The span of the mean error, from the reel's start, s: the reel's 0.1 s and t90's second
beyond the slowest seed's crossing (~0.6 s)."""


def t90(t_s: np.ndarray, err_n: np.ndarray, jump_n: float) -> float | None:
    """The issue's t90: the first time from ``TUG_S`` at which the error norm is at most 10 %
    of the jump and stays within 20 % of it for the next second; None if never."""
    after = t_s >= TUG_S
    tt, ee = t_s[after] - TUG_S, err_n[after]
    for i in range(len(tt)):
        if ee[i] > 0.1 * jump_n:
            continue
        within = (tt >= tt[i]) & (tt <= tt[i] + 1.0)
        if tt[-1] < tt[i] + 1.0:
            return None
        if np.all(ee[within] <= 0.2 * jump_n):
            return float(tt[i])
    return None


def first_within(t_s: np.ndarray, err_n: np.ndarray, jump_n: float) -> float | None:
    """The first time, counted from ``TUG_S``, after the reel has stopped at which the error
    norm is at most 10 % of the jump."""
    stop_s = TUG_S + (LENGTH_M - SHORT_M) / -REEL_RATE_MPS
    after = (t_s >= stop_s) & (err_n <= 0.1 * jump_n)
    return float(t_s[after][0] - TUG_S) if after.any() else None


def told_the_noise(f: dict[str, np.ndarray], tau_s: float) -> tuple[np.ndarray, float | None]:
    """The estimator issue's "estimator told the noise" on this flight
    (:func:`benchmarks.told_noise.glr_random_walk`, the change at ``TUG_S``): estimates and
    its detection time from ``TUG_S`` (None: none)."""
    return glr_random_walk(f["t_s"], f["obs_n"], f["true_n"], TUG_S, tau_s)


def jump_n(t_s: np.ndarray, true_n: np.ndarray) -> float:
    """The tug's jump, N: the true tension's mean over 2–4 s after ``TUG_S`` less its mean
    over the 2 s before."""
    before = (t_s >= TUG_S - 2.0) & (t_s < TUG_S)
    late = (t_s >= TUG_S + 2.0) & (t_s < TUG_S + 4.0)
    return float(np.linalg.norm(true_n[late].mean(0) - true_n[before].mean(0)))


def judge(f: dict[str, np.ndarray]) -> dict[str, Any]:
    t, est, true, obs = f["t_s"], f["est_n"], f["true_n"], f["obs_n"]
    before = (t >= TUG_S - 2.0) & (t < TUG_S)
    jump = jump_n(t, true)
    err = np.linalg.norm(est - true, axis=1)
    stop_s = TUG_S + (LENGTH_M - SHORT_M) / -REEL_RATE_MPS
    since = t >= stop_s
    cum = np.full_like(obs, np.nan)
    cum[since] = np.cumsum(obs[since], axis=0) / np.arange(1, since.sum() + 1)[:, None]
    oracle = np.where(since[:, None], cum, est)
    err_oracle = np.linalg.norm(oracle - true, axis=1)
    told: dict[str, float | None] = {}
    detection_s = None
    for tau in TAUS_S:
        est_t, detection_s = told_the_noise(f, tau)
        told[f"{tau:g}"] = t90(t, np.linalg.norm(est_t - true, axis=1), jump)
    return {
        "told_noise_t90_s": told,
        "told_noise_detection_s": detection_s,
        "jump_mn": 1e3 * jump,
        "pre_tug_error_mn": 1e3 * float(np.median(err[before])),
        "t90_s": t90(t, err, jump),
        "first_within_10pct_s": first_within(t, err, jump),
        "oracle_t90_s": t90(t, err_oracle, jump),
        "mean_error_mn": 1e3 * float(err[(t >= TUG_S) & (t <= TUG_S + MEAN_ERROR_SPAN_S)].mean()),
    }


def _median(xs: list[float | None]) -> float | None:
    """The median, counting a never (None) as infinitely late; None if most never reach."""
    vals = [math.inf if x is None else x for x in xs]
    m = statistics.median(vals)
    return None if math.isinf(m) else m


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--out", help="write the markdown page here")
    args = ap.parse_args(argv)
    t0 = time.time()
    figures: dict[str, Any] = {}
    for profile in ("ideal", "realistic"):
        runs = [judge(fly(profile, 700 + s)) for s in range(args.seeds)]
        figures[profile] = {
            "seeds": args.seeds,
            "runs": runs,
            "jump_mn": statistics.median(r["jump_mn"] for r in runs),
            "pre_tug_error_mn": statistics.median(r["pre_tug_error_mn"] for r in runs),
            "t90_s": _median([r["t90_s"] for r in runs]),
            "oracle_t90_s": _median([r["oracle_t90_s"] for r in runs]),
            "first_within_10pct_s": _median([r["first_within_10pct_s"] for r in runs]),
            "mean_error_mn": statistics.median(r["mean_error_mn"] for r in runs),
            "told_noise_detection_s": _median([r["told_noise_detection_s"] for r in runs]),
        }
        by_tau = {
            k: _median([r["told_noise_t90_s"][k] for r in runs])
            for k in runs[0]["told_noise_t90_s"]
        }
        reached = {k: v for k, v in by_tau.items() if v is not None}
        best = min(reached, key=lambda k: reached[k]) if reached else None
        figures[profile]["told_noise_t90_by_tau_s"] = by_tau
        figures[profile]["told_noise_best_tau_s"] = None if best is None else float(best)
        figures[profile]["told_noise_t90_s"] = None if best is None else reached[best]
        print(profile, {k: v for k, v in figures[profile].items() if k != "runs"}, flush=True)

    def s(x: float | None) -> str:
        return "never" if x is None else f"{x:.2f} s"

    lines = [
        "# The reel tug of the estimator issue (this project's simulator)",
        "",
        f"`python -m benchmarks.bench_reel_tug --seeds {args.seeds} --out docs/reel_tug.md` "
        f"(this page and its figures, docs/reel_tug.json; {time.time() - t0:.0f} s at commit "
        f"{AT_START.commit}). Method: the module docstring of `benchmarks/bench_reel_tug.py`. "
        "A 30 g drone at (1, 0, 1) m, base at 0.754 m, tether 1.6 → 1.06 m by the reel from "
        f"{TUG_S:g} s (0.1 s), 250 Hz, 0.3 m/s² white vibration, no motion capture, "
        "calibration = the simulator's truth. Per seed: t90 by the issue's criterion (error ≤ "
        "10 % of the jump, then within 20 % for the next second), the pre-tug error (median "
        "error norm over the 2 s before), and the step oracle (the mean of the observations "
        "since the reel stopped, its time known) judged the same way, and the issue's "
        "'estimator told the noise' (a GLR told the true noise and level before the tug, at "
        "0.005 false alarms per hour, then a random-walk filter; its best time constant "
        "chosen in hindsight). Medians over seeds "
        "('never' where most seeds never meet the criterion). The issue's targets: t90 ≤ "
        f"{T90_TARGET_S:g} s, pre-tug error ≤ {1e3 * PRE_TUG_TARGET_N:g} mN (measured there "
        "on another, independent simulator). Mean error: the error norm's mean over the "
        f"{MEAN_ERROR_SPAN_S:g} s from the reel's start, a figure without a threshold (t90 "
        "is a crossing: an estimate that moves by a fraction of a millinewton near the 10 % "
        "line moves a seed's t90 by a tenth of a second; `python -m "
        "benchmarks.reel_tug_diff --before DIR` compares two commits sample by sample).",
        "",
        "| profile | seeds | jump mN | pre-tug error mN | t90 | step oracle t90 | "
        "told the noise t90 (best τ) | its detection | first within 10 % | mean error mN | "
        "t90 per seed |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    for profile, fig in figures.items():
        per = ", ".join("never" if r["t90_s"] is None else f"{r['t90_s']:.2f}" for r in fig["runs"])
        lines.append(
            f"| {profile} | {fig['seeds']} | {fig['jump_mn']:.1f} | "
            f"{fig['pre_tug_error_mn']:.2f}"
            + marker("reel_tug.json", f"{profile}.pre_tug_error_mn")
            + f" | {s(fig['t90_s'])}"
            + ("" if fig["t90_s"] is None else marker("reel_tug.json", f"{profile}.t90_s"))
            + f" | {s(fig['oracle_t90_s'])} | {s(fig['told_noise_t90_s'])}"
            + (
                ""
                if fig["told_noise_t90_s"] is None
                else marker("reel_tug.json", f"{profile}.told_noise_t90_s")
                + f" (τ {fig['told_noise_best_tau_s']:g} s)"
            )
            + f" | {s(fig['told_noise_detection_s'])}"
            + f" | {s(fig['first_within_10pct_s'])}"
            + f" | {fig['mean_error_mn']:.2f}"
            + marker("reel_tug.json", f"{profile}.mean_error_mn")
            + f" | {per} |"
        )
    page = "\n".join(lines) + "\n"
    if args.out:
        out = Path(args.out)
        page += kept_reading(out, "\n## ")  # the reading below the table
        out.write_text(page, encoding="utf-8")
        if out.resolve() == DOCS / "reel_tug.md":
            write_figures("reel_tug", figures, ["--seeds", str(args.seeds), "--out", args.out])
    sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
