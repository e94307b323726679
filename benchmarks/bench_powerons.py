"""Calibrate on some power-ons, judge others: the realistic simulator as real flights are used.

Each seed is one power-on of one airframe (docs/simulator.md): the per-boot draws
(accelerometer misalignment, scale and bias; thrust-map spread; motion-capture rate) change
from seed to seed, the thrust axis (the airframe's) does not, and with ``attitude_levelled``
the reported attitude is levelled on the same misaligned accelerometer, as a Crazyflie's is.
Every flight: disarmed on the floor 2 s, spool-up, a climb, then four of the paper's spots,
15 s each. The calibration flights are recorded with motion capture and calibrated with
``groundstation calibrate`` (``run_calibrate``: the airframe model by default, ``--model full``
beside it); the judged flights are recorded without motion capture and re-estimated offline
(``replay --offline``'s code) with each configuration, and compared with the simulator's
truth. Beside them, in the same run, the same estimator *told the truth*: each judged flight
with its own airframe constants as the airframe model sees them (the best any airframe
calibration could be), and the earlier per-flight oracle (the full model's own equivalent,
accelerometer bias included, the accelerometer's mean trusted).

Run:  python -m benchmarks.bench_powerons [--train 3] [--judge 3] [--no-misalignment | --both]
      [--out FILE]

docs/powerons_benchmark.md holds both runs (``--both --out docs/powerons_benchmark.md``): the
reading above them, written by hand, is kept, and the figures go to
``docs/powerons_benchmark.json`` (:mod:`benchmarks.figures`).
"""

from __future__ import annotations

import argparse
import functools
import io
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.figures import AT_START, DOCS, kept_reading, marker, write_figures
from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.pipeline import Pipeline
from groundstation.recording.calibrate import run_calibrate
from groundstation.recording.reader import RecordedMessage, copy_messages
from groundstation.sim.runner import Simulator
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M, SCENARIOS, Scenario, Waypoint

DRONE = "cf1"
SCENARIO = "bench_poweron"
SPOTS = PAPER_HOVER_SPOTS_M[:4]
DWELL_S = 15.0
SETTLE_S = 5.0
"""Judged: samples of each dwell from this long after the spot is commanded."""


class _NullBus:
    def publish(self, key: str, payload: bytes) -> None:  # pragma: no cover - unused
        pass


def _scenario() -> str:
    climb_end = 6.0
    wps = [Waypoint(0.0, (0.5, 0.0, 0.0)), Waypoint(4.0, (0.8, 0.0, 0.6))]
    for i, spot in enumerate(SPOTS):
        wps.append(Waypoint(climb_end + i * DWELL_S, spot))
    SCENARIOS[SCENARIO] = Scenario(
        SCENARIO,
        "power-on benchmark: floor, spool-up, climb, four paper spots 15 s each",
        start_m=(0.5, 0.0, 0.0),
        waypoints=tuple(wps),
        start_on_ground=True,
        arm_at_s=2.0,
        thrust_ramp_s=1.5,
        duration_s=climb_end + len(SPOTS) * DWELL_S,
    )
    return SCENARIO


MISALIGNMENT = True
"""Per-boot accelerometer misalignment (the simulator's default, up to 3°); ``--no-misalignment``
leaves the bias and scale as the per-boot errors (the IMU soldered: its tilt an airframe
constant, absorbed in the thrust axis)."""


def _sim_settings(seed: int, noise_mps2: float, mocap: bool, levelled: bool) -> Settings:
    realistic = {
        "accel_noise_mps2": noise_mps2,
        "attitude_levelled": levelled,
        "misalignment": MISALIGNMENT,
    }
    over: dict[str, Any] = {
        "sim": {"profile": "realistic", "seed": seed, "mocap": mocap, "realistic": realistic}
    }
    return load_settings(None, over, use_env=False)


@dataclass
class Recorded:
    seed: int
    messages: list[RecordedMessage]
    truth: dict[float, dict[str, Any]]
    errors: dict[str, Any]
    judged_from_s: list[tuple[float, float]]


def record(seed: int, noise_mps2: float, mocap: bool, levelled: bool) -> Recorded:
    """Fly one power-on; its Telemetry/Reel as a recording, and the truth by stamp."""
    name = _scenario()
    settings = _sim_settings(seed, noise_mps2, mocap, levelled)
    sim = Simulator(settings, _NullBus(), scenario=name)  # type: ignore[arg-type]
    duration = SCENARIOS[name].duration_s or 0.0
    msgs: list[RecordedMessage] = []
    truth: dict[float, dict[str, Any]] = {}
    while sim.t_s < duration:
        t_ns = round(sim.t_s * 1e9)
        for s in sim.step():
            kind = s.key.split("/", 2)[2]
            if kind == "truth":
                t = json.loads(s.payload)
                truth[round(t["stamp_s"], 6)] = t
            elif kind in ("telemetry", "reel", "params"):
                msgs.append(RecordedMessage(s.key, bytes(s.payload), t_ns, t_ns))
    errors = sim.drawn_errors(DRONE)
    assert errors is not None
    windows = [(6.0 + i * DWELL_S + SETTLE_S, 6.0 + (i + 1) * DWELL_S) for i in range(len(SPOTS))]
    return Recorded(seed, msgs, truth, errors, windows)


@dataclass(frozen=True)
class Score:
    median_m: float
    p95_m: float
    tension_rmse_n: float
    samples: int
    tension_within_2_sigma: float
    position_within_2_sigma: float


Judged = tuple[list[float], list[np.ndarray], list[tuple[int, int]]]
"""Per judged sample: the position error (m), the tension error (N, 3-vector), and how many of
the three axes the published σ holds within 2σ (tension, position; a position without a σ
holds none)."""


def served(rec: Recorded, settings: Settings) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """Serve a recording (no motion capture in it) through the pipeline: each Estimate in a
    judged stretch (``rec.judged_from_s``) with the simulator's truth at its stamp."""
    pipe = Pipeline(settings)
    pairs: list[tuple[dict[str, Any], dict[str, Any]]] = []
    for m in rec.messages:
        now = m.log_time_ns / 1e9
        for out in pipe.handle(Sample(m.key, m.payload), now):
            if not out.key.endswith("/estimate"):
                continue
            est = json.loads(out.payload)
            stamp = est["stamp_s"]
            if not any(a <= stamp < b for a, b in rec.judged_from_s):
                continue
            tr = rec.truth.get(round(stamp, 6))
            if tr is not None:
                pairs.append((est, tr))
        pipe.tick(now)
    return pairs


def judge(pairs: list[tuple[dict[str, Any], dict[str, Any]]]) -> Judged:
    """Per served sample (:func:`served`) the position error (m), the tension error (N,
    3-vector) and the axes within 2σ."""
    pos_err: list[float] = []
    ten_err: list[np.ndarray] = []
    within: list[tuple[int, int]] = []
    for est, tr in pairs:
        d_t = np.subtract(est["tension_n"], tr["tension_n"])
        ten_err.append(d_t)
        t_in = int(np.sum(np.abs(d_t) <= 2.0 * np.asarray(est["tension_std_n"], float)))
        if est["position_m"] is None:
            pos_err.append(float("inf"))
            p_in = 0
        else:
            d_p = np.subtract(est["position_m"], tr["position_m"])
            pos_err.append(float(np.linalg.norm(d_p)))
            std = est.get("position_std_m")
            p_in = 0 if std is None else int(np.sum(np.abs(d_p) <= 2.0 * np.asarray(std)))
        within.append((t_in, p_in))
    return pos_err, ten_err, within


def dwells(rec: Recorded, pairs: list[tuple[dict[str, Any], dict[str, Any]]]) -> list[str]:
    """Per spot of one judged flight (its served samples, :func:`served`): the tension error's
    mean and RMS per world axis (mN), the median published σ and the share within 2σ, as
    table rows: does the σ miss a bias or a motion of the truth?"""
    a = np.array(
        [
            (est["stamp_s"], *np.subtract(est["tension_n"], tr["tension_n"]), *est["tension_std_n"])
            for est, tr in pairs
        ],
        float,
    ).reshape(-1, 7)
    out_rows = []
    for lo, hi in rec.judged_from_s:
        w = (a[:, 0] >= lo) & (a[:, 0] < hi)
        d, sd = 1e3 * a[w, 1:4], 1e3 * a[w, 4:7]

        def three(v: np.ndarray, fmt: str = "{:.1f}") -> str:
            return " / ".join(fmt.format(x) for x in v)

        out_rows.append(
            f"| {rec.seed} | {lo:.0f}–{hi:.0f} s | {three(d.mean(axis=0))} | "
            f"{three(np.sqrt((d**2).mean(axis=0)))} | {three(np.median(sd, axis=0), '{:.2f}')} | "
            f"{three(100 * (np.abs(d) <= 2 * sd).mean(axis=0), '{:.0f}')} |"
        )
    return out_rows


def score(parts: list[Judged]) -> Score:
    p = np.concatenate([np.asarray(a, float) for a, _, _ in parts])
    t = np.concatenate([np.asarray(b, float).reshape(-1, 3) for _, b, _ in parts])
    w = np.concatenate([np.asarray(c, float).reshape(-1, 2) for _, _, c in parts])
    axes = 3.0 * max(len(w), 1)
    return Score(
        float(np.median(p)),
        float(np.percentile(p, 95)),
        float(np.sqrt(np.mean(np.sum(t**2, axis=1) / 3.0))),
        int(p.size),
        float(w[:, 0].sum() / axes),
        float(w[:, 1].sum() / axes),
    )


def _cal_settings(cal: dict[str, Any]) -> Settings:
    return load_settings(None, {"calibration": cal}, use_env=False)


ROWS = {
    "uncalibrated": "uncalibrated",
    "calibrate --model airframe": "airframe",
    "calibrate --model full": "full",
    "told the truth: own airframe constants (slow stage on)": "told_airframe",
    "told the truth: own full-model equivalent (bias known)": "told_full",
    "told the truth: own airframe constants, calibrate's hover fit": "told_airframe_hover_fit",
    "the same two, judged with motion capture: the prior": "told_airframe_mocap",
    "the same two, judged with motion capture: calibrate's hover fit": (
        "told_airframe_hover_fit_mocap"
    ),
}
"""The table's configurations, each with its key in the figures."""

PAGE = "powerons_benchmark"
RUNS = "\n---\n\n# Calibrate on some power-ons"
"""Where the page's runs begin: the reading above them is written by hand."""


def score_figures(s: Score | None) -> dict[str, float] | None:
    """A configuration's row as figures, in the table's units (within 2σ: a share); None
    where ``calibrate`` refused."""
    if s is None:
        return None
    return {
        "position_median_cm": 100 * s.median_m,
        "position_p95_cm": 100 * s.p95_m,
        "tension_rmse_mn": 1e3 * s.tension_rmse_n,
        "samples": s.samples,
        "tension_within_2_sigma": s.tension_within_2_sigma,
        "position_within_2_sigma": s.position_within_2_sigma,
    }


def _fig(key: str, scale: str = "") -> str:
    return marker(f"{PAGE}.json", key, scale)


def run(args: argparse.Namespace, misalignment: bool) -> tuple[str, dict[str, Any]]:
    """One run (per-boot misalignment on or off): its section of the page, and its figures
    (:data:`ROWS` → :func:`score_figures`)."""
    global MISALIGNMENT
    MISALIGNMENT = misalignment
    variant = "misalignment" if misalignment else "no_misalignment"
    t0 = time.time()
    levelled = not args.not_levelled
    train_seeds = list(range(1, args.train + 1))
    judge_seeds = list(range(args.train + 1, args.train + args.judge + 1))
    lines: list[str] = []
    say = lines.append
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        files = []
        for seed in train_seeds:
            rec = record(seed, args.noise, mocap=True, levelled=levelled)
            path = work / f"poweron{seed}.mcap"
            copy_messages(rec.messages, path)
            files.append(str(path))
        default = load_settings(None, {}, use_env=False)
        configs: dict[str, Settings | None] = {"uncalibrated": default}
        printed: dict[str, str] = {}
        for model in ("airframe", "full"):
            out = work / f"{model}.toml"
            buf = io.StringIO()
            try:
                run_calibrate(
                    default,
                    None,
                    files,
                    str(out),
                    model=model,
                    echo=functools.partial(print, file=buf),
                )
                configs[f"calibrate --model {model}"] = load_settings(out, use_env=False)
            except Exception as exc:  # a refusal is a result here
                buf.write(f"refused: {exc}")
                configs[f"calibrate --model {model}"] = None
            printed[model] = buf.getvalue().replace(f"{work}/", "")  # the file names alone
        judged = [record(seed, args.noise, mocap=False, levelled=levelled) for seed in judge_seeds]
        rows: dict[str, Score | None] = {}
        for label, cfg in configs.items():
            rows[label] = None if cfg is None else score([judge(served(r, cfg)) for r in judged])
        # told the truth, per judged flight
        own_air = []
        own_full = []
        own_fit = []
        told_rows: list[str] = []
        fit_rows: list[str] = []
        # calibrate's fit of the hover (σ_v, T_c, q_w, D) from the airframe calibration
        fitted = configs["calibrate --model airframe"]
        hover_fit: dict[str, Any] = {}
        if fitted is not None:
            section = fitted.for_drone(DRONE).calibration
            hover_fit = {
                k: v
                for k, v in section.model_dump().items()
                if k.startswith("hover_") and v is not None
            }
        for r in judged:
            eq_air = dict(r.errors["airframe_equivalent"])
            told = served(r, _cal_settings({**eq_air, "source": "truth"}))
            own_air.append(judge(told))
            told_rows += dwells(r, told)
            told_fit = served(r, _cal_settings({**eq_air, **hover_fit, "source": "truth"}))
            own_fit.append(judge(told_fit))
            fit_rows += dwells(r, told_fit)
            eq = r.errors["calibration"]
            full = {
                "thrust_scale": eq["thrust_scale"],
                "thrust_vbat_slope_per_v": eq["thrust_vbat_slope_per_v"],
                "thrust_vbat_ref_v": eq["thrust_vbat_ref_v"],
                "thrust_axis_rad": eq["thrust_axis_rad"],
                "accel_bias_mps2": eq["accel_bias_mps2"],
                "accel_slow": False,
                "source": "truth",
            }
            own_full.append(judge(served(r, _cal_settings(full))))
        rows["told the truth: own airframe constants (slow stage on)"] = score(own_air)
        rows["told the truth: own full-model equivalent (bias known)"] = score(own_full)
        rows["told the truth: own airframe constants, calibrate's hover fit"] = score(own_fit)
        # the same power-ons flown again with motion capture reaching the service
        with_mocap = [
            record(seed, args.noise, mocap=True, levelled=levelled) for seed in judge_seeds
        ]
        for label, extra in (
            ("the same two, judged with motion capture: the prior", {}),
            ("the same two, judged with motion capture: calibrate's hover fit", hover_fit),
        ):
            rows[label] = score(
                [
                    judge(
                        served(
                            r,
                            _cal_settings(
                                {**r.errors["airframe_equivalent"], **extra, "source": "truth"}
                            ),
                        )
                    )
                    for r in with_mocap
                ]
            )

    say("# Calibrate on some power-ons, judge others (realistic simulator)")
    say("")
    say(
        f"`python -m benchmarks.bench_powerons --train {args.train} --judge {args.judge} "
        f"--noise {args.noise}{' --not-levelled' if args.not_levelled else ''}"
        f"{'' if misalignment else ' --no-misalignment'}` "
        f"({time.time() - t0:.0f} s at commit {AT_START.commit}). Realistic profile, every "
        f"error class on, vibration "
        f"{args.noise} m/s², attitude levelled on the accelerometer: {levelled}, per-boot "
        f"misalignment: {misalignment}. Power-ons = "
        f"seeds {train_seeds} calibrated (with motion capture), seeds {judge_seeds} judged "
        "(without). Each flight: 2 s on the floor, spool-up, climb, four paper spots 15 s each; "
        f"judged from {SETTLE_S:.0f} s after each spot is commanded. Position error is 3-D "
        "(undetermined counts as infinite); tension RMSE per axis."
    )
    say("")
    say(
        "| configuration | position median cm | p95 cm | tension RMSE mN | samples "
        "| within 2σ: tension | position |"
    )
    say("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for label, s in rows.items():
        if s is None:
            say(f"| {label} | refused | | | | | |")
        else:
            k = f"{variant}.{ROWS[label]}"
            say(
                f"| {label} | {100 * s.median_m:.1f}{_fig(f'{k}.position_median_cm')} | "
                f"{100 * s.p95_m:.1f}{_fig(f'{k}.position_p95_cm')} | "
                f"{1e3 * s.tension_rmse_n:.2f}{_fig(f'{k}.tension_rmse_mn')} | {s.samples} | "
                f"{100 * s.tension_within_2_sigma:.0f} %"
                f"{_fig(f'{k}.tension_within_2_sigma', '100')} | "
                f"{100 * s.position_within_2_sigma:.0f} %"
                f"{_fig(f'{k}.position_within_2_sigma', '100')} |"
            )
    say("")
    say(
        "Within 2σ: the share of per-axis errors within twice the published σ "
        "(`tension_std_n`, `position_std_m`; a position without a σ counts as outside); a "
        "consistent σ holds about 95 %."
    )
    say("")
    say(
        "Told the truth (own airframe constants), per judged flight and spot: the tension "
        "error's mean and RMS per world axis x / y / z (mN), the median published σ (mN) "
        "and the share within 2σ (%)."
    )
    say("")
    say("| power-on | judged | error mean | error RMS | median σ | within 2σ |")
    say("| --- | --- | --- | --- | --- | --- |")
    for row in told_rows:
        say(row)
    say("")
    say(
        "The same, told the truth with the hover's four values that `calibrate --model "
        "airframe` fitted from the calibration power-ons (σ_v, T_c and the thrust balance's "
        f"q_w and D, groundstation.hover_fit): {hover_fit or 'none fitted'}."
    )
    say("")
    say("| power-on | judged | error mean | error RMS | median σ | within 2σ |")
    say("| --- | --- | --- | --- | --- | --- |")
    for row in fit_rows:
        say(row)
    say("")
    for model, text in printed.items():
        say(f"`calibrate --model {model}` printed:")
        say("```")
        say(text.strip())
        say("```")
    return "\n".join(lines) + "\n", {ROWS[label]: score_figures(s) for label, s in rows.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", type=int, default=3, help="calibration power-ons (seeds 1..N)")
    ap.add_argument("--judge", type=int, default=3, help="judged power-ons (the next seeds)")
    ap.add_argument("--noise", type=float, default=0.8, help="accel vibration, m/s²")
    ap.add_argument("--not-levelled", action="store_true", help="attitude not levelled")
    variants = ap.add_mutually_exclusive_group()
    variants.add_argument(
        "--no-misalignment", action="store_true", help="no per-boot accelerometer misalignment"
    )
    variants.add_argument(
        "--both",
        action="store_true",
        help="both runs, with per-boot misalignment and without (docs/powerons_benchmark.md)",
    )
    ap.add_argument(
        "--out",
        help="write the markdown page here (docs/powerons_benchmark.md, with --both: the "
        "reading above its runs kept, the figures to docs/powerons_benchmark.json)",
    )
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else None
    to_docs = out is not None and out.resolve() == DOCS / f"{PAGE}.md"
    if to_docs and not args.both:
        ap.error(f"docs/{PAGE}.md holds both runs: add --both")
    runs = [run(args, m) for m in ((True, False) if args.both else (not args.no_misalignment,))]
    page = "\n---\n\n".join(section for section, _ in runs)
    if out is not None:
        head = kept_reading(out, RUNS, above=True)
        page = f"{head}\n---\n\n{page}" if head else page
        out.write_text(page, encoding="utf-8")
        if to_docs:
            figures = {"misalignment": runs[0][1], "no_misalignment": runs[1][1]}
            argv = ["--train", str(args.train), "--judge", str(args.judge)]
            argv += ["--noise", f"{args.noise:g}"]
            argv += ["--not-levelled"] if args.not_levelled else []
            write_figures(PAGE, figures, [*argv, "--both", "--out", args.out])
    sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
