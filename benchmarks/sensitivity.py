"""Which hand-set constants the figures depend on: each one at half and at twice its value.

``python -m benchmarks.sensitivity [--shard I/N] [--work DIR] [--out docs/sensitivity.md]``;
``python -m benchmarks.sensitivity --variant NAME=FACTOR [--family F]``: one row at one
factor (or ``baseline``), its figures printed as JSON; with ``--run MODULE ARGS`` another
benchmark run under that change (its ``--only`` modes print and write no page).

The issue that asks for one estimator with its parameters from data counts the tunables on
the per-message path (docs/constants.md: the one table). Before a value is replaced by a fit
or a derivation it helps to know whether the results depend on it at all. This runs every
**hand-set** row of docs/constants.md at ×½ and ×2 (a switch flipped; a count rounded, at
least 1) with everything else at its default and measures a small set of figures in the same
deterministic flights each time:

* **Estimator rows** (all but the contact family below):
  NanoBench, the six shared flights cross-day (calibrated with ``calibrate --untethered`` on
  the other days once, with the defaults; served by ``replay --offline`` with the value
  changed): median and worst of the flight medians of |T| (mN, truth zero) and the share
  within 2σ (median over the flights); the reel tug of ``benchmarks.bench_reel_tug`` (ideal
  profile, seeds 700–702): median t90 (s) and pre-tug error (mN); the realistic simulator at
  1 m/s², calibration = truth (``benchmarks.bench_realistic``): a 20 s hover at the paper's
  spots 0 and 4 (seed 500): position median and p95 (cm), tension RMS (mN), tension within
  2σ; its 30 mN tug (seeds 600, 601): t90 of the seed-averaged change (s).
* **Contact rows** (``ContactParams``, ``RestCriteria``, the lift-off prior, the gap and
  hold times, the warm-up): NanoBench's median of |T| and the least share of airborne rows not
  flagged on the ground; the simulator's ``takeoff_ramp`` (ideal and realistic, seed 10, no
  motion capture, uncalibrated): share of Estimates whose ``on_ground`` differs from the
  truth, lift-off seen after the truth's (s), tension RMS error over the 2 s after lift-off
  (mN); ``tug_landing`` (ideal, seed 10): ``on_ground`` mismatch.

How a value is changed: a field of ``TensionFilterParams``, ``SlowAccelParams``,
``BiasKalmanParams``, ``ContactParams`` or ``RestCriteria`` is scaled after the instance is
built (whatever the configuration gave it); a module constant is rebound in its module and in every
``groundstation`` module that imported it by name; a class constant on its class. A value
captured when a module was imported (a default argument, a constant computed from another)
is not reached that way: a row whose figures are all exactly the baseline's says so ("no
figure moved"), which means either that nothing these flights do depends on it or that the
change did not reach the code; the page does not tell the two apart.

Takes about 25 s per estimator or contact variant and 13 s per 2 m/s² one (295 runs, about
an hour on two processes): ``--shard 0/2`` and ``--shard 1/2`` share the work; results are
kept per run in ``--work`` (``results.jsonl``), so a run resumes; ``--render`` writes the
page from them.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import math
import os
import re
import runpy
import shutil
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import REPO, git_commit

CLASSES = {
    "TensionFilterParams": "groundstation.tension",
    "SlowAccelParams": "groundstation.slow_accel",
    "BiasKalmanParams": "groundstation.bias_kalman",
    "ContactParams": "groundstation.contact",
    "RestCriteria": "groundstation.calibration",
}
"""The parameter classes of docs/constants.md and their modules."""

CONTACT_ROWS = frozenset({"attitude.STILL_WINDOW_S"})
"""Rows judged on the contact figures besides ``ContactParams.*`` and ``RestCriteria.*``
(the one window of stillness is the rest's; the hover test's too, which the estimator
figures see)."""

FACTORS = (0.5, 2.0)

ROW = re.compile(r"^\| `([^`]+)` \| [^|]+ \| [^|]* \| [^|]* \| ([\w-]+) \|")


def hand_set_rows(constants_md: Path = REPO / "docs" / "constants.md") -> list[str]:
    """The names of docs/constants.md's hand-set rows, in the table's order."""
    names = []
    for line in constants_md.read_text(encoding="utf-8").splitlines():
        m = ROW.match(line)
        if m and m.group(2) == "hand-set":
            names.append(m.group(1))
    return names


def is_contact(name: str) -> bool:
    return name.split(".")[0] in ("ContactParams", "RestCriteria") or name in CONTACT_ROWS


def scaled(value: Any, factor: float) -> Any:
    """``value`` times ``factor``: a bool flipped, an int rounded (at least 1), a tuple per
    element."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return max(1, round(value * factor))
    if isinstance(value, tuple):
        return tuple(x * factor for x in value)
    return value * factor


def _functions() -> list[Any]:
    """Every function (and method) defined in a ``groundstation`` module."""
    seen: dict[int, Any] = {}
    for mod_name, mod in list(sys.modules.items()):
        if not mod_name.startswith("groundstation"):
            continue
        for value in list(vars(mod).values()):
            members = vars(value).values() if isinstance(value, type) else [value]
            for f in members:
                f = getattr(f, "__func__", f)
                if callable(f) and hasattr(f, "__defaults__"):
                    seen[id(f)] = f
    return list(seen.values())


def _rebind_defaults(match: Callable[[Any], bool], new: Callable[[Any], Any]) -> list[Any]:
    """Default arguments for which ``match`` holds get ``new(value)``; the undo steps."""
    undo: list[Callable[[], None]] = []
    for f in _functions():
        defaults = f.__defaults__
        if defaults and any(match(d) for d in defaults):
            f.__defaults__ = tuple(new(d) if match(d) else d for d in defaults)
            undo.append(lambda f=f, d=defaults: setattr(f, "__defaults__", d))
        kw = f.__kwdefaults__
        if kw and any(match(d) for d in kw.values()):
            f.__kwdefaults__ = {k: new(d) if match(d) else d for k, d in kw.items()}
            undo.append(lambda f=f, d=kw: setattr(f, "__kwdefaults__", d))
    return undo


def patch(name: str, factor: float) -> list[Callable[[], None]]:
    """Change the constant ``name`` (a docs/constants.md row) by ``factor``; the undo steps."""
    parts = name.split(".")
    undo: list[Callable[[], None]] = []
    if parts[0] in CLASSES:
        cls = getattr(importlib.import_module(CLASSES[parts[0]]), parts[0])
        field = parts[1]
        original_init = cls.__init__

        def init(self: Any, *args: Any, **kwargs: Any) -> None:
            original_init(self, *args, **kwargs)
            object.__setattr__(self, field, scaled(getattr(self, field), factor))

        # An instance made when a module was imported (a default argument) is replaced by
        # one with the value changed (made before the patched __init__ would scale it again).
        undo += _rebind_defaults(
            lambda d: isinstance(d, cls),
            lambda d: dataclasses.replace(d, **{field: scaled(getattr(d, field), factor)}),
        )
        cls.__init__ = init
        undo.append(lambda: setattr(cls, "__init__", original_init))
        return undo
    attr = parts[-1]
    try:
        module = importlib.import_module("groundstation." + ".".join(parts[:-1]))
        owner: Any = module
    except ModuleNotFoundError:
        module = importlib.import_module("groundstation." + ".".join(parts[:-2]))
        owner = getattr(module, parts[-2])
    original = getattr(owner, attr)
    new = scaled(original, factor)
    setattr(owner, attr, new)
    undo.append(lambda: setattr(owner, attr, original))
    if owner is module:
        for mod_name, mod in list(sys.modules.items()):
            if (
                mod_name.startswith("groundstation")
                and mod is not module
                and getattr(mod, attr, None) is original
            ):
                setattr(mod, attr, new)
                undo.append(lambda mod=mod: setattr(mod, attr, original))
    if isinstance(original, float | tuple):  # (an int may be a cached small-int object)
        undo += _rebind_defaults(lambda d: d is original, lambda d: new)
    return undo


class Figures:
    """The flights, loaded and calibrated once, and the figures measured on them."""

    def __init__(self, work: Path, data: Path) -> None:
        self.work = work
        self.data = data
        self.calibration: dict[str, Path] = {}
        self.flights: dict[str, Any] = {}

    def _calibrated(self) -> None:
        """The NanoBench flights loaded and calibrated cross-day, once (when first needed)."""
        from benchmarks import nanobench_cli as nc

        self.nc = nc
        if self.calibration:
            return
        self.work.mkdir(parents=True, exist_ok=True)
        self.flights = {n: nc.load(n, self.data) for n in nc.DAYS}
        for day in sorted(set(nc.DAYS.values())):
            train = [f for n, f in self.flights.items() if nc.DAYS[n] != day]
            self.calibration[day], _ = nc.calibrate(train, self.work, f"day{day}", [])

    def _nanobench(self) -> list[Any]:
        self._calibrated()
        nc = self.nc
        return [
            nc.judge(f, self.calibration[nc.DAYS[n]], self.work) for n, f in self.flights.items()
        ]

    def estimator(self) -> dict[str, float | None]:
        from benchmarks import bench_reel_tug as rt

        out: dict[str, float | None] = {}
        judged = self._nanobench()
        out["nb_median_mn"] = statistics.median(j.median_abs_t_mn for j in judged)
        out["nb_worst_mn"] = max(j.median_abs_t_mn for j in judged)
        out["nb_within_2_sigma"] = statistics.median(j.within_2_sigma for j in judged)
        tugs = [rt.judge(rt.fly("ideal", seed)) for seed in (700, 701, 702)]
        out["reel_t90_s"] = rt._median([j["t90_s"] for j in tugs])
        out["reel_pre_tug_mn"] = statistics.median(j["pre_tug_error_mn"] for j in tugs)
        return out | _realistic(1.0)

    def noisy(self) -> dict[str, float | None]:
        return _realistic(2.0)

    def contact(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        judged = self._nanobench()
        out["nb_median_mn"] = statistics.median(j.median_abs_t_mn for j in judged)
        out["nb_airborne_min"] = min(j.airborne_not_on_ground for j in judged)
        for profile in ("ideal", "realistic"):
            for key, value in _ground_run(profile, "takeoff_ramp", 10.0).items():
                out[f"{profile}_takeoff_{key}"] = value
        out["landing_mismatch"] = _ground_run("ideal", "tug_landing", 16.0)["mismatch"]
        return out


def _realistic(noise_mps2: float) -> dict[str, float | None]:
    """The realistic simulator at one vibration level, calibration = truth: a 20 s hover at
    the paper's spots 0 and 4 (seed 500) and the 30 mN tug (seeds 600, 601)."""
    from benchmarks import bench_realistic as br

    hover = br.hover(noise_mps2, [0, 4], 20.0, [500])
    return {
        "hover_median_cm": 100.0 * hover["ours_median_m"],
        "hover_p95_cm": 100.0 * hover["ours_p95_m"],
        "hover_tension_rms_mn": 1e3 * hover["ours_tension_rms_n"],
        "hover_within_2_sigma": hover["tension_within_2_sigma"],
        "tug_t90_s": br.tug(noise_mps2, [600, 601])["t90_s"],
    }


def _ground_run(profile: str, scenario: str, seconds: float) -> dict[str, float | None]:
    """``on_ground`` against the truth in one closed-loop flight (seed 10, no mocap)."""
    from groundstation.config import load_settings
    from groundstation.evaluation import closed_loop

    settings = load_settings(
        None, {"sim": {"profile": profile, "seed": 10, "mocap": False}}, use_env=False
    )
    run, _, _ = closed_loop(settings, scenario, seconds)
    est = run.estimates
    truth = [run.truth_at(e["stamp_s"]) for e in est]
    t = np.array([e["stamp_s"] for e in est])
    ground_est = np.array([e["on_ground"] for e in est], dtype=bool)
    ground_true = np.array([x["on_ground"] for x in truth], dtype=bool)
    err = np.linalg.norm(
        np.array([e["tension_n"] for e in est]) - np.array([x["tension_n"] for x in truth]), axis=1
    )
    lift_true = float(t[np.argmax(~ground_true)]) if (~ground_true).any() else math.nan
    lift_est = float(t[np.argmax(~ground_est)]) if (~ground_est).any() else math.nan
    after = ~ground_true & ~ground_est & (t > lift_true) & (t < lift_true + 2.0)
    return {
        "mismatch": float(np.mean(ground_est != ground_true)),
        "lift_delay_s": lift_est - lift_true,
        "error_2s_mn": 1e3 * float(np.sqrt(np.mean(err[after] ** 2))) if after.any() else None,
    }


def jobs(names: list[str]) -> list[tuple[str, str, float]]:
    """Every (family, row, factor) to run, the baselines first; a switch once. Estimator
    rows run twice: at 1 m/s² with NanoBench and the reel tug (``estimator``), and at the
    realistic simulator's 2 m/s² (``noisy``), where the change test needs its long windows."""
    return [
        ("estimator", "baseline", 1.0),
        ("contact", "baseline", 1.0),
        *(
            ("contact" if is_contact(name) else "estimator", name, factor)
            for name in names
            for factor in _factors(name)
        ),
        ("noisy", "baseline", 1.0),
        *(
            ("noisy", name, factor)
            for name in names
            if not is_contact(name)
            for factor in _factors(name)
        ),
    ]


def _factors(name: str) -> tuple[float, ...]:
    """The factors a row runs at: a switch is flipped once."""
    return FACTORS[:1] if _is_switch(name) else FACTORS


def _is_switch(name: str) -> bool:
    return name in ("TensionFilterParams.estimate_noise", "SlowAccelParams.hover")


def run(shard: int, shards: int, work: Path, data: Path, family: str | None = None) -> None:
    results = work / "results.jsonl"
    done = set()
    if results.exists():
        for line in results.read_text(encoding="utf-8").splitlines():
            d = json.loads(line)
            done.add((d["family"], d["name"], d["factor"]))
    every = [j for j in jobs(hand_set_rows()) if family is None or j[0] == family]
    todo = [job for k, job in enumerate(every) if k % shards == shard and job not in done]
    if not todo:
        return
    commit = git_commit()  # the code this process imported (a commit made later is not it)
    figures = Figures(work / f"shard{shard}-{family or 'all'}", data)
    measure = {"estimator": figures.estimator, "contact": figures.contact, "noisy": figures.noisy}
    for kind, name, factor in todo:
        t0 = time.perf_counter()
        undo: list[Callable[[], None]] = []
        try:
            if name != "baseline":
                undo = patch(name, factor)
            measured = measure[kind]()
            error = None
        except Exception as exc:  # a value out of its valid range: reported
            measured, error = {}, f"{type(exc).__name__}: {exc}"[:300]
        finally:
            for step in reversed(undo):
                step()
        record = {
            "name": name,
            "factor": factor,
            "family": kind,
            "error": error,
            "wall_s": round(time.perf_counter() - t0, 1),
            "commit": commit,
            **measured,
        }
        with results.open("a", encoding="utf-8") as fh:
            fh.write(json.dumps(record) + "\n")
        print(f"{kind}: {name} ×{factor:g}: {error or measured}", flush=True)


ESTIMATOR_COLUMNS = (
    ("nb_median_mn", "NB median mN", 1),
    ("nb_worst_mn", "NB worst mN", 1),
    ("nb_within_2_sigma", "NB in 2σ", "%"),
    ("reel_t90_s", "reel t90 s", 2),
    ("reel_pre_tug_mn", "reel pre mN", 2),
    ("hover_median_cm", "hover med cm", 2),
    ("hover_p95_cm", "hover p95 cm", 2),
    ("hover_tension_rms_mn", "hover RMS mN", 3),
    ("hover_within_2_sigma", "hover in 2σ", "%"),
    ("tug_t90_s", "tug t90 s", 2),
)
NOISY_COLUMNS = (
    ("hover_median_cm", "hover med cm", 2),
    ("hover_p95_cm", "hover p95 cm", 2),
    ("hover_tension_rms_mn", "hover RMS mN", 3),
    ("hover_within_2_sigma", "hover in 2σ", "%"),
    ("tug_t90_s", "tug t90 s", 2),
)
CONTACT_COLUMNS = (
    ("nb_median_mn", "NB median mN", 1),
    ("nb_airborne_min", "NB airborne min", "%"),
    ("ideal_takeoff_mismatch", "ideal ground mismatch", "%"),
    ("ideal_takeoff_lift_delay_s", "ideal lift-off lag s", 3),
    ("ideal_takeoff_error_2s_mn", "ideal 2 s error mN", 1),
    ("realistic_takeoff_mismatch", "realistic ground mismatch", "%"),
    ("realistic_takeoff_lift_delay_s", "realistic lift-off lag s", 3),
    ("realistic_takeoff_error_2s_mn", "realistic 2 s error mN", 1),
    ("landing_mismatch", "landing ground mismatch", "%"),
)

MOVED = 0.10
"""A figure "moved" when it changed by more than 10 % of the baseline's (for a share: by
more than 1 point; for a time: by more than 10 % or 0.02 s, whichever is larger). A reading
threshold for this page, not a value of the estimator."""


def _moved(key: str, value: Any, base: Any) -> bool:
    if value is None or base is None:
        return value is not base
    if key.endswith("within_2_sigma") or key.endswith("mismatch") or key.endswith("min"):
        return abs(value - base) > 0.01
    if key.endswith("_s"):
        return abs(value - base) > max(MOVED * abs(base), 0.02)
    return abs(value - base) > MOVED * abs(base)


def _fmt(value: Any, how: Any) -> str:
    if value is None:
        return "never"
    if how == "%":
        return f"{100.0 * value:.0f} %"
    return f"{value:.{how}f}"


def render(work: Path, out: Path) -> None:
    records = [
        json.loads(line)
        for line in (work / "results.jsonl").read_text(encoding="utf-8").splitlines()
    ]
    by = {(r["family"], r["name"], r["factor"]): r for r in records}
    commits = sorted({r["commit"] for r in records})
    names = hand_set_rows()
    lines = [
        "# Which hand-set constants the figures depend on",
        "",
        f"`python -m benchmarks.sensitivity --out docs/sensitivity.md` (at commit "
        f"{', '.join(commits)}; {len(records)} runs, "
        f"{sum(r['wall_s'] for r in records) / 60:.0f} min of CPU). Every **hand-set** row of "
        "docs/constants.md at ×½ and ×2 (a switch flipped once), all else at its default, "
        "in the same deterministic flights; benchmarks/sensitivity.py says which flights and "
        "how a value is changed. A diagnosis: this page is not held to the code by the docs "
        "check (it takes an hour to run); rerun it before relying on a row.",
        "",
    ]
    summary: list[str] = []
    moved_anywhere: set[str] = set()
    for family, columns, title in (
        ("estimator", ESTIMATOR_COLUMNS, "Estimator rows, 1 m/s² and NanoBench"),
        ("noisy", NOISY_COLUMNS, "Estimator rows, 2 m/s² (realistic simulator)"),
        ("contact", CONTACT_COLUMNS, "Contact rows"),
    ):
        base = by.get((family, "baseline", 1.0))
        if base is None:
            continue
        rows_here = [n for n in names if is_contact(n) == (family == "contact")]
        head = "| row | × | " + " | ".join(c[1] for c in columns) + " | moved |"
        table = [head, "|" + " --- |" * (len(columns) + 3)]
        table.append(
            "| **baseline** | 1 | "
            + " | ".join(_fmt(base.get(k), how) for k, _, how in columns)
            + " | |"
        )
        moved_rows, still_rows, silent_rows, failed_rows, missing = [], [], [], [], []
        for name in rows_here:
            if not any((family, name, f) in by for f in FACTORS):
                missing.append(name)
                continue
            any_moved, all_same, failed = False, True, False
            for factor in FACTORS:
                r = by.get((family, name, factor))
                if r is None:
                    continue
                if r["error"]:
                    failed = True
                    table.append(f"| `{name}` | {factor:g} | refused: {r['error']} |")
                    continue
                moved = [label for k, label, _ in columns if _moved(k, r.get(k), base.get(k))]
                any_moved |= bool(moved)
                all_same &= all(r.get(k) == base.get(k) for k, _, _ in columns)
                cells = " | ".join(_fmt(r.get(k), how) for k, _, how in columns)
                table.append(
                    f"| `{name}` | {'flip' if _is_switch(name) else f'{factor:g}'} | {cells} | "
                    f"{', '.join(moved) or '-'} |"
                )
            if failed and not any_moved:
                failed_rows.append(name)
            elif any_moved:
                moved_rows.append(name)
            elif all_same:
                silent_rows.append(name)
            else:
                still_rows.append(name)
        lines += [f"## {title} ({len(rows_here)})", "", *table, ""]
        moved_anywhere.update(moved_rows)
        summary += [
            f"- **{family}**: {len(rows_here)} rows. A figure moved (beyond the reading "
            f"threshold below) at ×½ or ×2 for **{len(moved_rows)}**: "
            + (", ".join(f"`{n}`" for n in moved_rows) or "none")
            + f". Figures changed, none beyond the threshold, for {len(still_rows)}: "
            + (", ".join(f"`{n}`" for n in still_rows) or "none")
            + f". No figure changed at all for {len(silent_rows)}: "
            + (", ".join(f"`{n}`" for n in silent_rows) or "none")
            + (
                f". Refused (the value out of its valid range) for {len(failed_rows)}: "
                + ", ".join(f"`{n}`" for n in failed_rows)
                if failed_rows
                else ""
            )
            + (f". Not run (yet) for {len(missing)}" if missing else "")
            + "."
        ]
    head_end = 4
    lines[head_end:head_end] = [
        "## Summary",
        "",
        f"**{len(moved_anywhere)} of the {len(names)} hand-set rows moved a figure in at least "
        f"one of the three sets of flights; {len(names) - len(moved_anywhere)} moved none "
        "beyond the reading threshold.**",
        "",
        *summary,
        "",
        "Moved: a figure changed by more than 10 % of the baseline's (a share by more than "
        '1 point; a time by more than 10 % or 0.02 s). "No figure changed" means these '
        "flights do not depend on the value *or* the change did not reach the code (a value "
        "captured at import); the page cannot tell the two apart. A row that moves nothing "
        "here may still matter in a regime these flights do not visit (a gap, a late "
        "sample, a motor spin-down): what it guards is in docs/constants.md.",
        "",
    ]
    tmp = out.with_suffix(out.suffix + ".tmp")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(out)
    print(f"wrote {out}")


def one_variant(
    name: str, factor: float, work: Path, data: Path, family: str | None = None
) -> dict[str, object]:
    """One row at one factor (``baseline``: none), its figures, nothing kept. Its flights'
    files go to a directory of this process's own under ``work``, removed after: two
    ``--variant`` runs at once shared one and read each other's replays (a baseline beside
    a variant read NanoBench's worst flight 12.3 mN instead of 10.2)."""
    undo = [] if name == "baseline" else patch(name, factor)
    own = work / f"variant-{os.getpid()}"
    try:
        figures = Figures(own, data)
        out: dict[str, object] = {"name": name, "factor": factor, "commit": git_commit()}
        for fam in (family,) if family else ("estimator", "noisy"):
            out[fam] = getattr(figures, fam)()
        return out
    finally:
        for step in reversed(undo):
            step()
        shutil.rmtree(own, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shard", default="0/1", help="I/N: run every N-th variant from I (0/1)")
    ap.add_argument("--work", default="/tmp/groundstation-sensitivity", help="results kept here")
    ap.add_argument("--data", default=None, help="the NanoBench directory (nanobench_cli's)")
    ap.add_argument("--out", help="write the markdown page here (after the run)")
    ap.add_argument("--render", action="store_true", help="only write the page from --work")
    ap.add_argument("--family", choices=("estimator", "noisy", "contact"), help="only these")
    ap.add_argument(
        "--variant",
        metavar="NAME=FACTOR",
        help="only print one variant's figures as JSON (NAME a docs/constants.md row, or "
        "'baseline'; FACTOR any, e.g. TensionFilterParams.drift_threshold=1e9 for the drift "
        "adaptation off): the families estimator and noisy, or --family's",
    )
    ap.add_argument(
        "--run",
        nargs=argparse.REMAINDER,
        metavar="MODULE ARGS",
        help="with --variant: run this benchmark module with these arguments under the "
        "change instead (e.g. --run benchmarks.bench_realistic --only tug,move --tug-seeds 8)",
    )
    args = ap.parse_args(argv)
    from benchmarks import nanobench_cli as nc

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    if args.variant:
        name, _, factor_text = args.variant.partition("=")
        factor = float(factor_text or 1.0)
        if args.run:
            if name != "baseline":
                patch(name, factor)
            module, *rest = args.run
            sys.argv = [module, *rest]
            runpy.run_module(module, run_name="__main__")
            return 0
        data = Path(args.data) if args.data else nc.DATA
        print(json.dumps(one_variant(name, factor, work, data, args.family)))
        return 0
    if not args.render:
        data = Path(args.data) if args.data else nc.DATA
        shard, shards = (int(x) for x in args.shard.split("/"))
        run(shard, shards, work, data, args.family)
    if args.out:
        render(work, Path(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
