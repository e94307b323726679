"""Which thrust and battery model holds below the calibration's battery range (NanoBench).

Real untethered Crazyflie 2.1 flights (../shared/data/nanobench, BSD-3; firmware 2025.12.1,
whose ``motor.m*`` is the duty after its battery compensation; true tension zero), recorded
as Telemetry exactly as ``benchmarks.nanobench_cli`` does (thrust = the nominal PWM map
summed over the motors, the bridge's default; 30 g assumed), calibrated with ``groundstation
calibrate --untethered`` and served without motion capture by ``groundstation replay
--offline``. The measure is nanobench_cli's: per flight, the median |T| of the Estimates in
the air (mN), here also split by the sample's own ``vbat_v``: below the split voltage and at
or above it. Three ways to hold data out:

* **voltage split**: calibrated on the runs of samples of the six flights whose battery
  reads at or above ``--split-v`` (3.5 V; runs of at least 1 s, each a recording of its
  own), judged on each flight's samples below it (and, in range, on those at or above it,
  which the calibration saw);
* **voltage and day split**: the same, calibrated on the other days' flights only, so the
  judged flight's power-on was never seen either;
* **day split**: whole flights, calibrated on the other days (nanobench_cli's
  cross-day figure).

and, for the firmware's own thrust model, Telemetry's thrust made as the bridge makes it
with ``[crazyflie] thrust_model = "cubic_21plus"`` (the 2.1+ propellers' cubic in the
motor voltage, ``VMOTOR2THRUST``), calibrated with today's straight line on top.

Per thrust model (``[calibration] thrust_model``, groundstation.thrust_model):
``vbat_linear`` (a straight line in the battery voltage), ``motor_voltage`` with its
exponent fitted within the physical bounds 1–2 (the default), left free (0.2–5), and fixed
at 2 (thrust ∝ (duty·V)²). ``B6_linear_ramp_rep1`` stays out (a ground-effect hover, the
data README), as in nanobench_cli.

Run:  python -m benchmarks.battery_model [--out docs/battery_model.md]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from unittest import mock

import numpy as np

import groundstation.recording.calibrate as calibrate_mod
from benchmarks.figures import AT_START, DOCS, write_figures
from benchmarks.nanobench_cli import DATA, DAYS, Flight, _run, load
from groundstation.airframe import fit_airframe
from groundstation.bridges.crazyflie.bridge import VMOTOR2THRUST
from groundstation.recording.reader import RecordedMessage, copy_messages, iter_messages
from groundstation.thrust_model import PWM_FULL_SCALE

SPLIT_V = 3.5
"""The split voltage of the acceptance test, V (issue: "calibrated on the parts flown above
3.5 V and judged on the parts below")."""
MIN_PART_S = 3.0
"""A flight's part (below or above the split) is judged only with this much flight in it."""


@dataclass(frozen=True)
class Variant:
    label: str
    short: str
    model: str
    bounds: tuple[float, float] | None
    """Exponent bounds for ``motor_voltage`` (None: calibrate's own)."""
    telemetry: str = "pwm_map"
    """What made Telemetry's thrust: the bridge's ``[crazyflie] thrust_model``."""
    key: str = ""
    """Its name in docs/battery_model.json's figures."""


VARIANTS = (
    Variant(
        "vbat_linear (the straight line, before)",
        "vbat_linear",
        "vbat_linear",
        None,
        key="vbat_linear",
    ),
    Variant(
        "motor_voltage, exponent within 1–2 (default)",
        "motor n 1–2",
        "motor_voltage",
        None,
        key="motor_voltage",
    ),
    Variant(
        "motor_voltage, exponent free (0.2–5)",
        "motor n free",
        "motor_voltage",
        (0.2, 5.0),
        key="motor_voltage_free",
    ),
    Variant(
        "motor_voltage, exponent 2: thrust ∝ (duty·V)²",
        "motor n = 2",
        "motor_voltage",
        (2.0, 2.0),
        key="motor_voltage_n2",
    ),
    Variant(
        "the firmware's cubic (bridge thrust_model cubic_21plus), vbat_linear on top",
        "firmware cubic + line",
        "vbat_linear",
        None,
        "cubic_21plus",
        key="firmware_cubic",
    ),
)


def cubic_thrust_n(pwm: np.ndarray, vbat_v: np.ndarray) -> np.ndarray:
    """The bridge's thrust with ``[crazyflie] thrust_model = "cubic_21plus"``, N (n,)."""
    c0, c1, c2, c3 = VMOTOR2THRUST["cubic_21plus"]
    v = np.nan_to_num(vbat_v)[:, None] * pwm / PWM_FULL_SCALE
    per_motor = np.maximum(c0 + v * (c1 + v * (c2 + v * c3)), 0.0)
    return np.where(pwm > 0, per_motor, 0.0).sum(axis=1)


MODELS_TEXT = """\
The models (`[calibration] thrust_model`, `groundstation/thrust_model.py`):
`vbat_linear` is `F = thrust_n·(s + k·(vbat_v − 3.5 V))`; `motor_voltage` inverts the
nominal PWM map at `thrust_n/4` to the mean motor command `pwm`, takes the motor voltage
`v = vbat_v·pwm/65535` (what the 2025+ firmware's battery compensation works in: it sets
the duty so that the motor voltage gives the thrust asked) and `F = 4·f_ref·(v/v_ref)^n`;
`firmware cubic + line` makes Telemetry's thrust as the bridge does with `[crazyflie]
thrust_model = "cubic_21plus"` (the firmware's own cubic in each motor's voltage, 2.1+
propellers) and calibrates `vbat_linear` on top.
Held-out ways: **voltage split**, calibrated on the runs (≥ 1 s) of samples at or above the
split voltage and judged on the samples below it (in range: on those at or above it,
which the calibration saw); **voltage + day split**, the same calibrated on the
other days only; **day split**, whole flights calibrated on the other days (nanobench_cli's
cross-day figure)."""


def config_text(model: str) -> str:
    return (
        "[drone]\nmass_kg = 0.030\n\n[calibration]\nthrust_vbat_ref_v = 3.5\n"
        f'thrust_model = "{model}"\n'
    )


def vbat_of(messages: list[RecordedMessage]) -> np.ndarray:
    """Each Telemetry's ``vbat_v`` (NaN without), V."""
    return np.array([json.loads(m.payload).get("vbat_v", np.nan) for m in messages])


MIN_RUN_S = 1.0
"""A run of samples at or above the split voltage shorter than this is not calibrated on."""


def runs_above(
    messages: list[RecordedMessage], vbat_v: np.ndarray, split_v: float, dt_s: float
) -> list[list[RecordedMessage]]:
    """The flight's runs of consecutive samples with ``vbat_v`` at or above ``split_v``, each
    at least :data:`MIN_RUN_S` long.

    Each run becomes a recording of its own: a sample dropped from the middle of a recording
    would leave a gap that the motion-capture derivatives would differentiate across.
    """
    keep = np.concatenate(([0], (vbat_v >= split_v).astype(np.int8), [0]))
    edges = np.diff(keep)
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [messages[a:b] for a, b in zip(starts, ends, strict=True) if (b - a) * dt_s >= MIN_RUN_S]


def battery_term(report: str) -> str:
    """The battery term from what calibrate printed: the line's slope or the motor's
    exponent, with its ± or ``(fixed)``, and ``at a bound`` when it says so."""
    m = re.search(
        r"(thrust_vbat_slope_per_v|thrust_motor_exponent)\s+(\S+ (± \S+|\(fixed\)))", report
    )
    if m is None:
        return "?"
    return m.group(2) + (" at a bound" if "at its bound" in report else "")


@contextmanager
def exponent_bounds(bounds: tuple[float, float] | None) -> Iterator[None]:
    """``calibrate`` with the motor-voltage exponent fitted within ``bounds``."""
    if bounds is None:
        yield
        return
    with mock.patch.object(
        calibrate_mod, "fit_airframe", partial(fit_airframe, exponent_bounds=bounds)
    ):
        yield


def calibrate(
    parts: list[tuple[str, list[RecordedMessage]]], work: Path, tag: str, variant: Variant
) -> tuple[Path, str]:
    base = work / f"base-{variant.model}.toml"
    base.write_text(config_text(variant.model))
    files = []
    for name, messages in parts:
        p = work / f"{name}.mcap"
        if not p.exists():
            copy_messages(messages, p)
        files.append(str(p))
    out = work / f"cal-{tag}.toml"
    with exponent_bounds(variant.bounds):
        rc, text = _run(
            ["calibrate", *files, "--untethered", "--config", str(base), "--out", str(out)]
        )
    if rc != 0:
        raise RuntimeError(f"calibrate failed ({rc}): {text}")
    return out, text


@dataclass(frozen=True)
class Parts:
    """One held-out flight's median |T| in the air, mN (NaN: too little flight there)."""

    flight: str
    below: float
    above: float
    whole: float


def judge(flight: Flight, vbat: np.ndarray, config: Path, work: Path, split_v: float) -> Parts:
    rec = work / f"{flight.name}-nomocap.mcap"
    if not rec.exists():
        copy_messages(flight.without_mocap, rec)
    out = work / f"{flight.name}-{config.stem}-est.mcap"
    rc, text = _run(["replay", "--offline", str(rec), "--config", str(config), "--out", str(out)])
    if rc != 0:
        raise RuntimeError(f"replay --offline failed ({rc}): {text}")
    norms: dict[float, float] = {}
    for m in iter_messages(out):
        if m.key == "tether/cf1/estimate":
            est = json.loads(m.payload)
            if not est["on_ground"]:
                norms[round(est["stamp_s"], 6)] = float(np.linalg.norm(est["tension_n"]))
    t_mn = np.array([1e3 * norms.get(round(t, 6), np.nan) for t in flight.stamp_s.tolist()])
    air = flight.airborne & np.isfinite(t_mn)
    dt_s = float(np.median(np.diff(flight.stamp_s)))

    def med(sel: np.ndarray) -> float:
        return float(np.median(t_mn[sel])) if sel.sum() * dt_s >= MIN_PART_S else float("nan")

    return Parts(
        flight.name,
        med(air & (vbat < split_v)),
        med(air & (vbat >= split_v)),
        med(air),
    )


def _summary(values: list[float]) -> tuple[float, float, int]:
    vals = [v for v in values if np.isfinite(v)]
    return statistics.median(vals), max(vals), len(vals)


Fold = tuple[str, str, list[tuple[str, list[RecordedMessage]]], list[str]]


def _setup(
    data: Path, thrust_n: Callable[[np.ndarray, np.ndarray], np.ndarray] | None, split_v: float
) -> tuple[dict[str, Flight], dict[str, np.ndarray], list[Fold]]:
    """The flights with Telemetry's thrust made by ``thrust_n``, their ``vbat_v``, and the
    folds: ``(kind, name, recordings to calibrate on, flights to judge)``."""
    flights = {n: load(n, data, thrust_n) for n in DAYS}
    vbat = {n: vbat_of(f.without_mocap) for n, f in flights.items()}
    above = {
        n: runs_above(f.with_mocap, vbat[n], split_v, float(np.median(np.diff(f.stamp_s))))
        for n, f in flights.items()
    }

    def above_parts(names: list[str]) -> list[tuple[str, list[RecordedMessage]]]:
        return [(f"{n}-above{k}", run) for n in names for k, run in enumerate(above[n])]

    folds: list[Fold] = [("voltage", "all flights", above_parts(list(DAYS)), list(DAYS))]
    for d in sorted(set(DAYS.values())):
        held = [n for n in DAYS if DAYS[n] == d]
        rest = [n for n in DAYS if n not in held]
        folds.append(("voltage+day", f"day {d} held out", above_parts(rest), held))
        mocap = [(f"{n}-mocap", flights[n].with_mocap) for n in rest]
        folds.append(("day", f"day {d} held out", mocap, held))
    return flights, vbat, folds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="write the markdown page here")
    ap.add_argument("--data", default=str(DATA), help="the NanoBench directory")
    ap.add_argument("--split-v", type=float, default=SPLIT_V, help="split voltage, V")
    args = ap.parse_args(argv)
    t0 = time.time()
    split_v = args.split_v
    thrusts = {"pwm_map": None, "cubic_21plus": cubic_thrust_n}
    setups = {
        tele: _setup(Path(args.data), thrusts[tele], split_v)
        for tele in dict.fromkeys(v.telemetry for v in VARIANTS)
    }
    lines: list[str] = []
    say = lines.append
    results: dict[str, dict[str, list[Parts]]] = {}
    reports: dict[str, str] = {}
    terms: dict[str, list[tuple[str, str]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for vi, variant in enumerate(VARIANTS):
            work = Path(tmp) / variant.telemetry  # recordings named by flight: one set each
            work.mkdir(exist_ok=True)
            flights, vbat, folds = setups[variant.telemetry]
            results[variant.label] = {"voltage": [], "voltage+day": [], "day": []}
            for fi, (kind, fold, parts, held) in enumerate(folds):
                cal, report = calibrate(parts, work, f"{vi}-{fi}", variant)
                if kind == "voltage":
                    reports[variant.label] = report
                terms.setdefault(variant.label, []).append(
                    (f"{kind}, {fold}", battery_term(report))
                )
                for n in held:
                    results[variant.label][kind].append(
                        judge(flights[n], vbat[n], cal, work, split_v)
                    )
                print(f"{variant.label}: {kind} {fold} done", file=sys.stderr, flush=True)
        commit = AT_START.commit
        figures: dict[str, dict[str, float]] = {v.key: {} for v in VARIANTS}
        say("# The thrust and battery model below the calibration's battery range (NanoBench)")
        say("")
        say(
            f"`python -m benchmarks.battery_model` (this page; commit {commit or 'unknown'}, "
            f"{time.time() - t0:.0f} s). Data: the six shared NanoBench flights "
            "(`../shared/data/nanobench/`, B6_linear_ramp_rep1 left out), recorded as "
            "`benchmarks.nanobench_cli` records them (thrust: the nominal PWM map), calibrated "
            "with `groundstation calibrate --untethered` and served without motion capture by "
            "`groundstation replay --offline`. Truth: zero tension. Per flight: the median |T| "
            f"of the Estimates in the air, mN, over its samples with `vbat_v` below {split_v} V "
            f"(**below**), at or above it (**in range**), or all (**whole**); a part with less "
            f"than {MIN_PART_S:g} s of flight is not judged (–)."
        )
        say("")
        say(MODELS_TEXT)
        say("")
        say("## Summary (median over flights / worst flight, mN)")
        say("")
        say(
            "| thrust model | split | below | in range | below ÷ in range, medians | "
            "worst below ÷ worst in range |"
        )
        say("| --- | --- | ---: | ---: | ---: | ---: |")
        for variant in VARIANTS:
            r = results[variant.label]
            for kind, name in (("voltage", "voltage"), ("voltage+day", "voltage + day")):
                b_med, b_max, _ = _summary([p.below for p in r[kind]])
                a_med, a_max, _ = _summary([p.above for p in r[kind]])
                split = kind.replace("+", "_")
                figures[variant.key].update(
                    {
                        f"{split}_below_median_mn": b_med,
                        f"{split}_below_worst_mn": b_max,
                        f"{split}_in_range_median_mn": a_med,
                        f"{split}_in_range_worst_mn": a_max,
                        f"{split}_ratio_median": b_med / a_med,
                        f"{split}_ratio_worst": b_max / a_max,
                    }
                )
                say(
                    f"| {variant.label} | {name} | {b_med:.1f} / {b_max:.1f} | "
                    f"{a_med:.1f} / {a_max:.1f} | {b_med / a_med:.2f} | {b_max / a_max:.2f} |"
                )
        say("")
        say(
            "Acceptance (issue): calibrated above 3.5 V and judged below, within 1.5× of the "
            "in-range figure (the two ratio columns: of the medians over flights, and of the "
            "worst flights)."
        )
        say("")
        say("| thrust model | day split, whole flights: median / worst |")
        say("| --- | ---: |")
        for variant in VARIANTS:
            w_med, w_max, _ = _summary([p.whole for p in results[variant.label]["day"]])
            figures[variant.key].update({"day_median_mn": w_med, "day_worst_mn": w_max})
            say(f"| {variant.label} | {w_med:.1f} / {w_max:.1f} |")
        say("")
        for kind, title in (
            ("voltage", f"Voltage split: calibrated on every flight's runs at ≥ {split_v} V"),
            ("voltage+day", "Voltage and day split: the same, on the other days' flights"),
            ("day", "Day split: whole flights, calibrated on the other days"),
        ):
            say(f"## {title}")
            say("")
            say("| flight | " + " | ".join(v.short for v in VARIANTS) + " |")
            say("| --- |" + " ---: |" * len(VARIANTS))
            names = [p.flight for p in results[VARIANTS[0].label][kind]]
            for i, name in enumerate(names):
                cells = []
                for v in VARIANTS:
                    p = results[v.label][kind][i]
                    if kind == "day":
                        cells.append(f"{p.whole:.1f}")
                    else:
                        cells.append(
                            f"{'–' if not np.isfinite(p.below) else f'{p.below:.1f}'} below, "
                            f"{'–' if not np.isfinite(p.above) else f'{p.above:.1f}'} in range"
                        )
                say(f"| {name} ({DAYS[name]}) | " + " | ".join(cells) + " |")
            say("")
        say("## The battery term calibrate fitted, per fold")
        say("")
        say(
            "`thrust_vbat_slope_per_v` (1/V) for the line, `thrust_motor_exponent` for the "
            "motor model (± its standard error; at a bound: the data would put it outside "
            "1–2)."
        )
        say("")
        fold_names = [f for f, _ in terms[VARIANTS[0].label]]
        say("| fold | " + " | ".join(v.short for v in VARIANTS) + " |")
        say("| --- |" + " --- |" * len(VARIANTS))
        for i, fold_name in enumerate(fold_names):
            say(f"| {fold_name} | " + " | ".join(terms[v.label][i][1] for v in VARIANTS) + " |")
        say("")
        say("## What calibrate printed (voltage split, each model)")
        say("")
        for label, text in reports.items():
            say(f"{label}:")
            say("```")
            say(text.strip())
            say("```")
        say("")
        page = "\n".join(lines)
        for tele in setups:
            page = page.replace(f"{Path(tmp) / tele}/", "")
        page += "\n"
    if args.out:
        Path(args.out).write_text(page, encoding="utf-8")
        if Path(args.out).resolve() == DOCS / "battery_model.md":
            write_figures("battery_model", figures, ["--out", "docs/battery_model.md"])
    sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
