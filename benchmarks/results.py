"""The results page: the paper's experiments in simulation, peers, scale and the envelope.

Run from the repository root::

    .venv/bin/python -m benchmarks.results            # full: ~12 min on 2 idle cores
    .venv/bin/python -m benchmarks.results --quick    # every section, smaller: ~1.5 min
    .venv/bin/python -m benchmarks.results --quick --out-dir /tmp/results
    .venv/bin/python -m benchmarks.results --only envelope   # section (d) into the page

Writes ``<out-dir>/RESULTS.md`` and ``<out-dir>/figures/*.png`` (default ``docs/``). A full
run into ``docs/`` also rewrites the block of ``docs/results_summary.md`` (once part of
the README) between ``<!-- results:start`` and ``<!-- results:end -->``, so every number
there comes from this command; a quick run or another ``--out-dir`` never touches it.
``--only envelope`` reruns section (d) (and (a)'s deterministic runs, which its bullets cite)
into the existing page and that block's bullets and figure, leaving the timing sections as
they were, and says so on the page ((a) and (d)'s flights cost ~11 CPU-minutes; the timing
sections want a quiet machine).

Sections:

(a) the paper's experiments in the simulator (:mod:`benchmarks.results_paper`);
(b) the catenary solver against its peers (:mod:`benchmarks.bench_catenary`'s cases and
    peers, via :mod:`benchmarks.results_peers`);
(c) the service at scale (:func:`benchmarks.bench_service.run_case`) and the dashboard's cost
    (:mod:`benchmarks.bench_dashboard`);
(d) the envelope on the realistic profile: which sensor error costs how many cm,
    uncalibrated and with calibration = truth, and the model's factors (ω error, tether
    length, distance from the base) (:mod:`benchmarks.results_envelope`).

Each section and figure names its simulator profile: (a) is the ``ideal`` profile (the
estimator's own assumptions), (d) the ``realistic`` one (real Crazyflie sensor errors).

The closed-loop runs are deterministic (seeded simulator, no bus, no clock) and run first,
on ``--workers`` processes; the timing benchmarks then run alone, one after the other.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import re
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks import git, git_commit
from benchmarks import results_envelope as renv
from benchmarks import results_figures as rfig
from benchmarks import results_paper as rp
from benchmarks import results_peers as rpeers
from benchmarks.bench_catenary import machine
from benchmarks.figures import write_figures
from benchmarks.results_sim import run_jobs

REPO = Path(__file__).resolve().parents[1]
README = REPO / "docs" / "results_summary.md"
"""The page whose results block a full run rewrites (the paper-notation results, once in the
README; the constant keeps its name for the tests)."""
README_START = re.compile(r"^<!-- results:start.*-->[ \t]*$", re.MULTILINE)
README_END = "<!-- results:end -->"
SECTIONS = (
    "## Summary",
    "## (a) The paper's experiments in the simulator (ideal profile)",
    "## (b) The catenary solver against its peers",
    "## (c) The service at scale",
    "## (d) The envelope on the realistic profile: which error costs how many cm",
)


# ---------------------------------------------------------------------------- formatting


def _f(x: float | None, scale: float = 1.0, digits: int = 1, unit: str = "") -> str:
    """A number for a table; '—' for None/NaN."""
    if x is None or not math.isfinite(x):
        return "—" if x is None or math.isnan(x) else ("∞" if x > 0 else "−∞")
    s = f"{x * scale:.{digits}f}".replace("-", "−")
    return f"{s} {unit}".rstrip()


def _pct(x: float | None, digits: int = 1) -> str:
    return _f(x, 100.0, digits, "%")


def _mn(x: float | None, digits: int = 2) -> str:
    return _f(x, 1e3, digits, "mN")


def _cm(x: float | None, digits: int = 1) -> str:
    return _f(x, 100.0, digits, "cm")


def _s(x: float | None, digits: int = 2) -> str:
    return "not settled" if x is None else _f(x, 1.0, digits, "s")


def _mm(v: tuple[float, float] | None) -> str:
    """'median … (max …)' of settle times."""
    return "not settled" if v is None else f"median {v[0]:.3f} s (max {v[1]:.3f} s)"


def _table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return [*out, ""]


def _tick(ok: bool) -> str:
    return "✔ met" if ok else "✘ **missed**"


# ---------------------------------------------------------------------------- provenance


def provenance() -> dict[str, str]:
    commit = git_commit()
    dirty = git("status", "--porcelain", "--", "groundstation", "benchmarks")
    changed = sorted({line[3:] for line in dirty.splitlines() if line.strip()})
    return {
        "commit": commit,
        "dirty": ", ".join(changed),
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
        "machine": machine(),
    }


# ---------------------------------------------------------------------------- the run


@dataclass(frozen=True)
class Outcome:
    quick: bool
    paper: rp.PaperResults
    envelope: renv.EnvelopeResult
    catenary: rpeers.CatenaryResult
    service: rpeers.ServiceResult
    dashboard: rpeers.DashboardResult
    figures: dict[str, str]
    phases_s: dict[str, float]
    load_start: float


@dataclass(frozen=True)
class EnvelopeOutcome:
    """What section (d) and the bullets need: ``--only envelope`` runs just this."""

    quick: bool
    paper: rp.PaperResults
    envelope: renv.EnvelopeResult
    figures: dict[str, str]


def _log(msg: str, t0: float) -> None:
    print(f"[results {time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def _closed_loop(
    quick: bool, workers: int, t0: float
) -> tuple[dict[str, Any], rp.PaperResults, renv.EnvelopeResult]:
    """The closed-loop flights of sections (a) and (d) on worker processes.

    Returns:
        (a)'s traces by key, (a)'s summary, (d)'s envelope summary.
    """
    pplan, eplan = rp.plan(quick), renv.plan(quick)
    jobs = rp.jobs(pplan) + renv.jobs(eplan)
    _log(f"closed loop: {len(jobs)} runs, {sum(j.seconds for j in jobs):.0f} s simulated", t0)
    done = [0]

    def progress(key: str) -> None:
        done[0] += 1
        if done[0] % 20 == 0 or done[0] == len(jobs):
            _log(f"closed loop: {done[0]}/{len(jobs)}", t0)

    results = run_jobs(jobs, workers, progress)
    traces = {k: v for k, v in results.items() if not k.startswith(("envr/", "envm/"))}
    return traces, rp.summarize(traces, pplan), renv.summarize(results, eplan)


def run(quick: bool, out_dir: Path, workers: int) -> Outcome:
    t0 = time.perf_counter()
    load_start = os.getloadavg()[0]
    phases: dict[str, float] = {}

    # 1. Closed loop (a) and (d), on worker processes, before anything starts threads.
    t = time.perf_counter()
    traces, paper, envelope = _closed_loop(quick, workers, t0)
    phases["closed loop (a), (d)"] = time.perf_counter() - t

    # 2. Catenary (b): alone, timing-sensitive.
    t = time.perf_counter()
    cat = rpeers.catenary(quick)
    phases["catenary (b)"] = time.perf_counter() - t
    _log(f"catenary done ({phases['catenary (b)']:.0f} s)", t0)

    # 3. Service at scale (c), then the dashboard's cost.
    t = time.perf_counter()
    if quick:
        svc = rpeers.service(
            (8,), 3.0, (), progress=lambda m: _log(m, t0), backlog=1000, capacity_suts=("service",)
        )
    else:
        # 30 s windows: a 10 s window ended just before the load client's first full garbage
        # collection and so hid it; the rig keeps the client's collector out.
        svc = rpeers.service(
            (1, 8, 16, 24, 32), 30.0, (8,), extend_to=128, progress=lambda m: _log(m, t0)
        )
    phases["service (c)"] = time.perf_counter() - t
    t = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # viser's start-up banner
        dash = rpeers.dashboard((8,) if quick else (1, 8), 1.5 if quick else 5.0)
    phases["dashboard (c)"] = time.perf_counter() - t
    _log("service and dashboard done", t0)

    # 4. Figures.
    t = time.perf_counter()
    figures = rfig.all_figures(traces, paper, cat, svc, dash, envelope, out_dir / "figures")
    phases["figures"] = time.perf_counter() - t
    _log("figures written", t0)
    return Outcome(quick, paper, envelope, cat, svc, dash, figures, phases, load_start)


# ---------------------------------------------------------------------------- derived facts


def _service_row(o: Outcome, drones: int) -> dict[str, Any] | None:
    return next((r for r in o.service.rows if r["drones"] == drones), None)


def saturation_text(o: Outcome) -> str:
    """Where the service saturates: delivery or latency set by a growing backlog."""
    rows = sorted(o.service.rows, key=lambda r: r["drones"])
    if len(rows) < 2:
        return "not measured (--quick runs 8 drones only)"

    def saturated(r: dict[str, Any]) -> bool:
        # A backlog: latency far above the processing time, or messages lost.
        return bool(r["delivered"] < rpeers.SERVICE_TARGET_DELIVERY or r["p50_ms"] > 50.0)

    ok = [r for r in rows if not saturated(r)]
    bad = [r for r in rows if saturated(r)]
    if not bad:
        top = rows[-1]
        return (
            f"not reached: {top['drones']} drones ({top['offered_hz']:.0f} msg/s) delivered "
            f"{_pct(top['delivered'], 2)} with p50 {top['p50_ms']:.1f} ms"
        )
    first_bad = bad[0]
    if not ok:
        return f"already at {first_bad['drones']} drone(s)"
    last_ok = max((r for r in ok if r["drones"] < first_bad["drones"]), key=lambda r: r["drones"])
    return (
        f"between {last_ok['drones']} drones ({last_ok['offered_hz']:.0f} msg/s: p50 "
        f"{last_ok['p50_ms']:.1f} ms, {_pct(last_ok['delivered'], 2)} delivered) and "
        f"{first_bad['drones']} drones ({first_bad['offered_hz']:.0f} msg/s: p50 "
        f"{first_bad['p50_ms']:.0f} ms, {_pct(first_bad['delivered'], 2)} delivered): beyond "
        f"it a backlog builds"
    )


def _signed(x: float) -> str:
    return f"{x:+g}".replace("-", "−")


def _digits(x: float) -> int:
    """Decimals to print a swept value as given (0.5, 2.25, 1.3 …)."""
    for d in range(4):
        if abs(round(x, d) - x) < 1e-9:
            return d
    return 4


def trust_bullets(o: Outcome | EnvelopeOutcome) -> list[str]:
    """'When it works, when it doesn't', each with its numbers and its profile: the envelope
    (d) on the realistic profile, and (a) on the ideal one."""
    out: list[str] = []
    env = o.envelope
    pos = o.paper.position.all3d
    base = env.cls("vibration").at(renv.BASELINE_NOISE_MPS2).raw
    out.append(
        f"**Works, on the ideal profile** (the estimator's own assumptions: ω and L known, "
        f"thrust exact, white noise 0.3 m/s² the service is told): median "
        f"{_cm(pos.median_abs)}, p95 {_cm(pos.p95_abs)} over the paper's six spots, no motion "
        f"capture, azimuth from the tension itself. **On the realistic profile** with only "
        f"vibration noise of {renv.BASELINE_NOISE_MPS2:g} m/s² (not told; every other error "
        f"class off): median {_cm(base.median_m)}, p95 {_cm(base.p95_m)} "
        f"({len(env.plan.spots)} of the spots): the baseline of every realistic figure below."
    )
    every = env.cls("all").real
    if every.cal is not None:
        out.append(
            f"**Uncalibrated it does not work (realistic profile, every error class at its "
            f"real size):** median {_cm(every.raw.median_m)}, p95 {_cm(every.raw.p95_m)} "
            f"(tension {_mn(every.raw.tension_median_n, 1)}); with calibration = the "
            f"simulator's truth median {_cm(every.cal.median_m)}, p95 {_cm(every.cal.p95_m)} "
            f"(tension {_mn(every.cal.tension_median_n, 1)}). Calibrate "
            "(`groundstation calibrate`, docs/calibration.md)."
        )
    tm = env.cls("thrust_map")
    tmr = tm.real
    hi = tm.points[-1]
    out.append(
        f"**The thrust map costs most (realistic):** reported thrust {_signed(tm.cls.real)} % "
        f"off (the paper's flights: true = 1.10 × reported) gives a median "
        f"{_cm(tmr.raw.median_m)} (height {_cm(tmr.raw.vertical_median_m)})"
        + (f", calibrated {_cm(tmr.cal.median_m)}" if tmr.cal is not None else "")
        + (
            f"; newer firmware's {_signed(hi.value)} % {_cm(hi.raw.median_m)}"
            if hi.value != tm.cls.real and hi.value > 0
            else ""
        )
        + ". A thrust error reads as vertical tension and s2 sets the height."
    )
    parts = []
    for name, what in (
        ("thrust_axis", "thrust axis 2.3°"),
        ("misalignment", "accelerometer misalignment (≤ 3° per boot)"),
        ("accel_scale", "accelerometer scale (≤ 2.5 %)"),
        ("accel_bias", "accelerometer bias"),
    ):
        if any(c.cls.name == name for c in env.classes):
            pt = env.cls(name).real
            parts.append(
                f"{what} {_cm(pt.raw.median_m)}"
                + (f" → {_cm(pt.cal.median_m)}" if pt.cal is not None else "")
            )
    out.append(
        "**Attitude and accelerometer offsets (realistic), median uncalibrated → calibration "
        "= truth:** " + "; ".join(parts) + ". They cannot be averaged away: they bias the "
        "horizontal tension, hence the distance and the azimuth."
    )
    if any(c.cls.name == "battery" for c in env.classes):
        bat = env.cls("battery")
        drained = [p for p in bat.points if p.value not in (0.0, bat.cls.real)]
        out.append(
            "**The thrust map drifts as the battery sags (realistic):** a map exact at "
            "4.05 V, uncalibrated → calibration = truth (with its `vbat_v` term), median: "
            + "; ".join(
                f"{renv.size_text(bat.cls, p.value)} ({_drawn_text(bat.cls, p.drawn)}) "
                f"{_cm(p.raw.median_m)} → {_cal_text(p.cal).split(' / ')[0]}"
                for p in [bat.real, *drained]
            )
            + ". The calibration's voltage term is linear in V, the map's drift is not: the "
            "further the battery from the calibration's voltage, the more remains."
        )
    vib = env.cls("vibration")
    out.append(
        "**Vibration noise grows the error and no calibration removes it (realistic):** "
        + ", ".join(
            f"{renv.size_text(vib.cls, pt.value)}: {_cm(pt.raw.median_m)}" for pt in vib.points
        )
        + " (median)."
    )
    dyn = [c for c in env.classes if c.cls.name in renv.DYNAMICS_CLASSES]
    if dyn:
        worst = max(
            ((c, pt) for c in dyn for pt in c.points if not renv.is_baseline(c.cls, pt.value)),
            key=lambda cp: abs(cp[1].raw.median_m - base.median_m),
        )
        out.append(
            "**The dynamics cost little (realistic):** "
            + ", ".join(f"{c.cls.name.replace('_', ' ')} {_cm(c.real.raw.median_m)}" for c in dyn)
            + f" against the baseline's {_cm(base.median_m)} (largest change: "
            f"{worst[0].cls.name.replace('_', ' ')} at "
            f"{renv.size_text(worst[0].cls, worst[1].value)}, "
            f"{_cm(worst[1].raw.median_m)})."
        )
    sw = env.sweep("omega_error")
    off = [p for p in sw.points if p.value != sw.sweep.nominal]
    nominal = next(p for p in sw.points if p.value == sw.sweep.nominal)
    out.append(
        "**ω must be known (realistic):** with the weight per metre configured "
        + ", ".join(
            f"{_signed(p.value)} % off: median {_cm(p.stats.median_m)} (height "
            f"{_cm(p.stats.vertical_median_m)})"
            for p in off
        )
        + f"; known: {_cm(nominal.stats.median_m)} (height "
        f"{_cm(nominal.stats.vertical_median_m)}). Weigh the tether."
    )
    sw = env.sweep("length")
    longest = sw.points[-1]
    floor_from = next((p.value for p in sw.points if p.floor_contact > 0.5), None)
    out.append(
        "**A slack tether lying on the floor hides the distance (realistic):** "
        + (
            f"from L = {floor_from:g} m the tether rests on the floor at the paper's spots, "
            "the horizontal tension no longer tells the distance and the service says so "
            f"(`floor_contact`, `radial_interval_m`, `azimuth_determined`): at L = "
            f"{longest.value:g} m the median error is {_cm(longest.stats.median_m)} "
            f"(horizontal {_cm(longest.stats.horizontal_median_m)}, height "
            f"{_cm(longest.stats.vertical_median_m)})."
            if floor_from is not None
            else f"not reached up to L = {longest.value:g} m "
            f"(median {_cm(longest.stats.median_m)})."
        )
    )
    sw = env.sweep("distance")
    plumb = [p for p in sw.points if p.azimuth_determined < 0.9]
    if plumb:
        out.append(
            "**Close to plumb the azimuth is unknown (realistic):** at z = 1 m "
            + ", ".join(
                f"r = {p.value:g} m: azimuth undetermined in {_pct(1 - p.azimuth_determined, 0)}"
                f" of the samples, median {_cm(p.stats.median_m)}"
                for p in plumb
            )
            + "; the service then places the drone above the base with `azimuth_determined: "
            "false` and a horizontal σ covering the reach."
        )
    fol = {f.tag: f for f in o.paper.follow}
    land = {lr.tag: lr for lr in o.paper.landing}
    tl = land["tether"]
    ft, fm = fol["tether"], fol["mocap"]
    pulls_t = " / ".join(_f(m, 1, 2, "m") for m in ft.along_pull_m)
    pulls_m = " / ".join(_f(m, 1, 2, "m") for m in fm.along_pull_m)
    corrupted = (
        f"A hand pulling the tether adds a force the catenary model does not contain, so "
        f"during a pull the tether-based position is off by a median "
        f"{_cm(ft.pull_pos_error_m, 0)} (at hover {_cm(ft.hover_pos_error_m)})."
    )
    if follows_without_mocap(o.paper):
        out.append(
            f"**Following without motion capture works (ideal profile), but not on the "
            f"position estimate.** "
            f"{corrupted} So without motion capture the goal moves from the pre-tug position "
            f"along the pull (admittance): the drone moved {pulls_t} along the two pulls of "
            f"`follow` (with motion capture, the paper's rule: {pulls_m}); tug-to-land stopped "
            f"the motors in {tl.landed}/{tl.runs} runs ({tl.stops:g} Stop per run; with "
            f"motion capture {land['mocap'].landed}/{land['mocap'].runs})."
        )
    else:
        out.append(
            f"**Doesn't work (ideal profile): following or landing on the tether estimate.** "
            f"{corrupted} "
            f"Following it, the drone moved {pulls_t} along the two pulls of `follow` (with "
            f"motion capture {pulls_m}). Tug-to-land on the tether estimate sent "
            f"{tl.stops:g} Stop(s) per run and the drone climbed to z = {tl.max_z_m:.2f} m; "
            f"with motion capture (the paper's setup) it landed in "
            f"{land['mocap'].landed}/{land['mocap'].runs} runs. Follow and tug-to-land need "
            f"motion capture or another position source."
        )
    return out


def follows_without_mocap(p: Any) -> bool:
    """Whether following and tug-to-land worked on the runs without motion capture."""
    ft = next(f for f in p.follow if f.tag == "tether")
    tl = next(lr for lr in p.landing if lr.tag == "tether")
    return all(m > 0.1 for m in ft.along_pull_m) and tl.runs > 0 and tl.landed == tl.runs


def targets(o: Outcome) -> list[tuple[str, str, str, bool]]:
    """(what, target, ours, met) for the at-a-glance table."""
    p = o.paper
    out: list[tuple[str, str, str, bool]] = []
    pos = p.position.all3d
    out.append(
        (
            "hover position, six spots, no mocap",
            "median < 10 cm",
            _cm(pos.median_abs),
            pos.median_abs < 0.10,
        )
    )
    out.append(
        ("hover position, six spots, no mocap", "p95 < 10 cm", _cm(pos.p95_abs), pos.p95_abs < 0.10)
    )
    rms = [s.rmse for s in p.position.tension_axis]
    out.append(
        (
            "tension at hover, RMS per axis",
            "≤ 0.5 mN (filter design)",
            " / ".join(_mn(r) for r in rms),
            max(rms) <= 0.5e-3,
        )
    )
    tug = p.tug
    on = tug.onset_norm_s
    out.append(
        (
            "30 mN tug: error norm within 3 mN after",
            "median ≤ 0.3 s (filter design)",
            f"{_mm(on)}; the step oracle in the same runs {_mm(tug.oracle_onset_norm_s)}",
            on is not None and on[0] <= 0.3 and tug.unsettled == 0,
        )
    )
    for tk in p.takeoff:
        out.append(
            (
                f"take-off {tk.height_m:g} m: on the floor",
                "no tension reported (paper: ~0.3 N)",
                f"{_mn(tk.ours_on_ground_max_n)} (on_ground)",
                tk.ours_on_ground_max_n == 0.0,
            )
        )
    tk = p.takeoff[-1]
    out.append(
        (
            f"take-off {tk.height_m:g} m: H in vertical flight (hover)",
            "< 10 mN (paper)",
            f"max {_mn(tk.h_hover.max_abs)}",
            tk.h_hover.max_abs < 0.01,
        )
    )
    h_lift = max(t.h_after_liftoff_max_n for t in p.takeoff)
    out.append(
        (
            "take-off: H from lift-off on, incl. the first samples",
            "< 10 mN (paper)",
            f"max {_mn(h_lift)}",
            h_lift < 0.01,
        )
    )
    first_z = [s.first_pos_m[2] for s in p.position.spots]
    out.append(
        (
            "first position estimate",
            "above the floor (paper: z = −0.846 m)",
            f"z from {min(first_z):.2f} to {max(first_z):.2f} m",
            min(first_z) > 0.0,
        )
    )
    mocap = p.landing[0]
    out.append(
        (
            "tug-to-land, motion capture",
            "exactly one Stop, landed",
            f"{mocap.stops:g} Stop/run, landed {mocap.landed}/{mocap.runs}",
            mocap.stops == 1.0 and mocap.landed == mocap.runs,
        )
    )
    tl = p.landing[1]
    out.append(
        (
            "tug-to-land, tether estimate",
            "exactly one Stop, landed",
            f"{tl.stops:g} Stop/run, landed {tl.landed}/{tl.runs}, highest z {tl.max_z_m:.2f} m",
            tl.stops == 1.0 and tl.landed == tl.runs,
        )
    )
    ours_vec = o.catenary.methods[0]
    out.append(
        ("catenary: cases within 1e-9 of mpmath", "100 %", _pct(ours_vec.ok), ours_vec.ok == 1.0)
    )
    r8 = _service_row(o, 8)
    if r8 is not None:
        out.append(
            (
                "service 8 drones × 250 Hz: delivery",
                "≥ 99.9 %",
                _pct(r8["delivered"], 2),
                r8["delivered"] >= rpeers.SERVICE_TARGET_DELIVERY,
            )
        )
        out.append(
            (
                "service 8 drones × 250 Hz: latency",
                "p99 ≤ 10 ms",
                f"p99 {r8['p99_ms']:.1f} ms" + _vs_floor(o, r8),
                r8["p99_ms"] <= rpeers.SERVICE_TARGET_P99_MS,
            )
        )
    b = o.service.bursts
    if "service" in b and "echo" in b:
        ratio = b["service"]["p99_ms"] / b["echo"]["p99_ms"]
        out.append(
            (
                "service under bursts (100 ms pause/s): latency",
                f"p99 ≤ {rpeers.SERVICE_TARGET_BURST_RATIO:g}× the echo floor's",
                f"p99 {b['service']['p99_ms']:.1f} ms vs {b['echo']['p99_ms']:.1f} ms "
                f"({ratio:.1f}×)" + _contract_floor_ratio(b),
                ratio <= rpeers.SERVICE_TARGET_BURST_RATIO,
            )
        )
    cap = o.service.capacity.get("service")
    if cap is not None:
        out.append(
            (
                "service capacity with a backlog (one worker)",
                f"≥ {rpeers.SERVICE_TARGET_CAPACITY_HZ:,.0f} msg/s (≤ 50 µs/msg)",
                f"{cap['msgs_per_s']:,.0f} msg/s ({cap['wall_us_per_msg']:.0f} µs/msg)"
                + _contract_floor_capacity(o.service.capacity.get("floor")),
                cap["msgs_per_s"] >= rpeers.SERVICE_TARGET_CAPACITY_HZ,
            )
        )
    return out


def _contract_floor_bursts(b: dict[str, dict[str, Any]]) -> str:
    """The bursts paragraph's sentence on the contract floor, where it was measured."""
    if "floor" not in b:
        return ""
    f, e = b["floor"], b["echo"]
    return (
        f" The contract floor (`benchmarks/floor_service.py`: validation, observation, one "
        f"Kalman step and the Estimate per message, nothing else) under the same bursts: "
        f"p99 {f['p99_ms']:.1f} ms, **{f['p99_ms'] / e['p99_ms']:.1f}×** the echo's; the "
        f"service is at {b['service']['p99_ms'] / f['p99_ms']:.1f}× the contract floor."
    )


def _contract_floor_ratio(b: dict[str, dict[str, Any]]) -> str:
    """The contract floor's own p99 under the same bursts, over the echo's."""
    if "floor" not in b:
        return ""
    return f"; contract floor {b['floor']['p99_ms'] / b['echo']['p99_ms']:.1f}×"


def _contract_floor_capacity(floor: dict[str, Any] | None) -> str:
    """The contract floor's drain rate in the same run (where it was measured)."""
    if floor is None:
        return ""
    return f"; contract floor {floor['msgs_per_s']:,.0f} msg/s"


def _vs_floor(o: Outcome, row: dict[str, Any]) -> str:
    floor = o.service.floor(row["drones"])
    if floor is None:
        return ""
    return f" (echo floor {floor['p99_ms']:.1f} ms: {row['p99_ms'] / floor['p99_ms']:.1f}×)"


def headline(o: Outcome) -> dict[str, Any]:
    """Machine-readable headline numbers (SI units), embedded in RESULTS.md for tests."""
    p = o.paper
    r8 = _service_row(o, 8)
    floor8 = o.service.floor(8)
    return {
        "quick": o.quick,
        "hover_median_m": p.position.all3d.median_abs,
        "hover_p95_m": p.position.all3d.p95_abs,
        "tension_rms_n": [s.rmse for s in p.position.tension_axis],
        "tug_settle_s": None if p.tug.onset_norm_s is None else p.tug.onset_norm_s[0],
        "tug_oracle_settle_s": None
        if p.tug.oracle_onset_norm_s is None
        else p.tug.oracle_onset_norm_s[0],
        "takeoff_hover_rmse_n": [tk.hover.rmse for tk in p.takeoff],
        "takeoff_on_ground_n": [tk.ours_on_ground_max_n for tk in p.takeoff],
        "coin_rmse_n": p.coin.stats.rmse,
        "first_z_m": [s.first_pos_m[2] for s in p.position.spots],
        "catenary_ok": {m.name: m.ok for m in o.catenary.methods},
        "catenary_us": {m.name: m.us_per_solve for m in o.catenary.methods},
        "service_8_delivered": None if r8 is None else r8["delivered"],
        "service_8_p99_ms": None if r8 is None else r8["p99_ms"],
        "service_8_floor_p99_ms": None if floor8 is None else floor8["p99_ms"],
        "service_bursts_p99_ms": {k: v["p99_ms"] for k, v in o.service.bursts.items()},
        "service_capacity_msgs_per_s": {k: v["msgs_per_s"] for k, v in o.service.capacity.items()},
        **envelope_headline(o.envelope),
    }


def envelope_headline(env: renv.EnvelopeResult) -> dict[str, Any]:
    """Section (d)'s headline numbers (SI units): per class at its real size, uncalibrated
    and calibration = truth (None: not flown)."""
    return {
        "envelope_profile": renv.PROFILE,
        "envelope_quick": env.plan.quick,
        "envelope_real_median_m": {
            c.cls.name: [c.real.raw.median_m, None if c.real.cal is None else c.real.cal.median_m]
            for c in env.classes
        },
        "envelope_real_tension_median_n": {
            c.cls.name: c.real.raw.tension_median_n for c in env.classes
        },
    }


def _stats_figures(st: renv.Stats | None) -> dict[str, float] | None:
    """A point's errors in the units the pages print them (cm, mN)."""
    if st is None:
        return None
    return {
        "median_cm": 100 * st.median_m,
        "p95_cm": 100 * st.p95_m,
        "horizontal_median_cm": 100 * st.horizontal_median_m,
        "height_median_cm": 100 * st.vertical_median_m,
        "tension_median_mn": 1e3 * st.tension_median_n,
        "tension_p95_mn": 1e3 * st.tension_p95_n,
        "availability": st.availability,
    }


def envelope_figures(env: renv.EnvelopeResult) -> dict[str, Any]:
    """Section (d) as ``docs/results_envelope.json``'s figures (:mod:`benchmarks.figures`):
    per error class its real size uncalibrated and with calibration = truth, every size
    flown, and the sweeps."""
    return {
        "profile": renv.PROFILE,
        "quick": env.plan.quick,
        "spots": list(env.plan.spots),
        "seconds": env.plan.seconds,
        "steady_from_s": env.plan.steady_from_s,
        "baseline_noise_mps2": renv.BASELINE_NOISE_MPS2,
        "classes": {
            c.cls.name: {
                "real": c.cls.real,
                "uncalibrated": _stats_figures(c.real.raw),
                "calibrated": _stats_figures(c.real.cal),
                "points": [
                    {
                        "value": p.value,
                        "uncalibrated": _stats_figures(p.raw),
                        "calibrated": _stats_figures(p.cal),
                    }
                    for p in c.points
                ],
            }
            for c in env.classes
        },
        "sweeps": {
            sw.sweep.name: [
                {
                    "value": pt.value,
                    **(_stats_figures(pt.stats) or {}),
                    "azimuth_determined": pt.azimuth_determined,
                    "floor_contact": pt.floor_contact,
                }
                for pt in sw.points
            ]
            for sw in env.sweeps
        },
    }


# ---------------------------------------------------------------------------- markdown


# Why the take-off's hover T_v error grew (python -m benchmarks.takeoff_lag).
TAKEOFF_LAG_NOTE = (
    "The hover error at 1.3 m is a lag, not noise: the climb overshoots to ~1.40 m and "
    "settles to 1.30 m over ~8 s (T_v falls by ~5 mN, the last 0.3 mN after 8 s), "
    "a ramp below the drift adaptation's threshold, which the filter follows with a lag of "
    "rate × tau. It grew with the hover time constant (2.5 → 6 s, made for the realistic "
    "profile's noise: groundstation/tension.py, *Process noise in seconds*). Same runs "
    "(`python -m benchmarks.takeoff_lag`: seeds 10, 11, 16 s, ideal profile, no motion "
    "capture), RMSE / bias from 8 s: 0.51 / 0.46 mN at 2.5 s, 0.76 / 0.73 mN at 6 s, "
    "1.17 / 1.12 mN at 6 s without the drift adaptation; 0.7 mN of T_v is 1.4 cm of "
    "height at ω = 0.05 N/m. "
    "The earlier 0.43 / 0.38 mN (commit 690b574) also differs by other changes since. "
    "Kept, because at hover the longer memory is worth more: on the realistic profile at "
    "1 m/s^2 the oracle's median hover error is 13.3 cm at 2.5 s and 9.3 cm at 6 s "
    "(docs/realistic_benchmark.md)."
)


def _summary_table(o: Outcome) -> list[str]:
    p = o.paper
    pos = p.position.all3d
    rms = p.position.tension_axis
    t13 = p.takeoff[-1]
    cat = {m.name: m for m in o.catenary.methods}
    ov, os_ = cat["ours, vectorised"], cat["ours, scalar"]
    pr, fs = cat["paper recipe, scalar"], cat["scipy fsolve (5 equations), scalar"]
    r8 = _service_row(o, 8)
    first_z = [s.first_pos_m[2] for s in p.position.spots]
    rows = [
        (
            "hover position, paper's six spots, no motion capture",
            f"median **{_cm(pos.median_abs)}**, p95 {_cm(pos.p95_abs)}",
            "figures only (β from motion capture)",
        ),
        (
            "first position estimate",
            f"z = {min(first_z):.2f} … {max(first_z):.2f} m at "
            f"t = {p.position.spots[0].first_t_s:.2f} s",
            "z = −0.846 m (under the floor)",
        ),
        ("tension error at hover, RMS x / y / z", " / ".join(_mn(s.rmse) for s in rms), "—"),
        (
            "30 mN tug: tension error within 3 mN after",
            f"{_mm(p.tug.onset_norm_s)} (step oracle, same runs: {_mm(p.tug.oracle_onset_norm_s)})",
            "filter design: 0.3 s",
        ),
        (
            "vertical tension T_v vs ω·z, hover at 1.3 m",
            f"RMSE {_mn(t13.hover.rmse)}, bias {_mn(t13.hover.bias)}",
            "figure only",
        ),
        (
            "T_v on the floor before lift-off",
            f"{_mn(t13.ours_on_ground_max_n, 0)} (`on_ground: true`)",
            "~0.3 N (the drone's weight)",
        ),
        ("H in vertical flight (1.3 m)", f"max {_mn(t13.h_hover.max_abs)}", "< 10 mN"),
        (
            "coin test H = cos γ·T (4.1 g)",
            f"RMSE {_mn(p.coin.stats.rmse)} of {_mn(p.coin.h_truth_n, 1)}",
            "figure only",
        ),
        (
            "catenary solve, ours vectorised / scalar",
            f"{ov.us_per_solve * 1e3:.0f} ns ({ov.solves_per_s / 1e6:.1f} M/s) / "
            f"{os_.us_per_solve:.2f} µs; {_pct(ov.ok, 0)} within 1e-9",
            "—",
        ),
        (
            "catenary solve, paper recipe / scipy fsolve",
            f"{pr.us_per_solve:.1f} µs, {_pct(pr.ok, 0)} ok / {fs.us_per_solve:.0f} µs, "
            f"{_pct(fs.ok, 0)} ok",
            "peers on the same cases",
        ),
    ]
    if r8 is not None:
        rows.append(
            (
                "service, 8 drones × 250 Hz",
                f"{_pct(r8['delivered'], 2)} delivered, p50 {r8['p50_ms']:.1f} ms, "
                f"p99 {r8['p99_ms']:.1f} ms{_vs_floor(o, r8)}, {r8['cpu_share']:.2f} cores, "
                f"RSS {r8['rss_mb']:.0f} MB",
                "target ≥ 99.9 %, p99 ≤ 10 ms",
            )
        )
    rows.append(("service saturation on this machine", saturation_text(o), "—"))
    return _table(SUMMARY_COLUMNS, rows)


README_PROFILES = (
    "Simulation, each figure with its profile: the table and the bullets marked *ideal "
    "profile* are the **ideal** profile (the estimator's own assumptions: quasi-static "
    "catenary, white accelerometer noise, exact thrust and IMU alignment); the bullets "
    "marked *realistic* and the envelope figure are the **realistic** profile (real "
    "Crazyflie sensor errors, one error class at a time, uncalibrated and with "
    "calibration = truth: docs/simulator.md); and this machine for speed"
)
README_TAIL = "### When it works, when it doesn't"


def _readme_tail(o: Outcome | EnvelopeOutcome) -> list[str]:
    return [
        README_TAIL,
        "",
        *[f"- {b}" for b in trust_bullets(o)],
        "",
        "![envelope](figures/envelope.png)",
    ]


def readme_block(o: Outcome, prov: dict[str, str], wall_s: float) -> str:
    lines = [
        f"{README_PROFILES} ({prov['machine']}); from "
        f"`.venv/bin/python -m benchmarks.results` ({wall_s / 60:.1f} min; `--quick`, "
        f"every section, shorter, runs in CI), {prov['date']}, commit "
        f"`{prov['commit']}`. Tables, figures and method: [RESULTS.md](RESULTS.md).",
        "",
        *_summary_table(o),
        *_readme_tail(o),
    ]
    return "\n".join(lines)


def _paper_section(o: Outcome) -> list[str]:
    p = o.paper
    pl = p.plan
    fig = o.figures
    L: list[str] = [
        SECTIONS[1],
        "",
        "The simulator (`groundstation/sim/`) stands in for the paper's lab: a 30 g quadrotor "
        "on a 1.6 m tether of ω = 0.05 N/m from a base at (0, 0, 0.754) m, quasi-static "
        "catenary force with floor contact, 250 Hz telemetry with accelerometer noise "
        "0.3 m/s² and thrust noise 3 mN. Each run goes through the service's own pipeline "
        "(`Pipeline.handle`) in lock-step (`groundstation.evaluation.closed_loop`). No motion "
        "capture reaches the service except in the follow runs marked *mocap*. Tolerances for "
        f'"converged": tension {_mn(rp.TENSION_TOL_N, 0)}, position '
        f"{_cm(rp.POSITION_TOL_M, 0)} (the error stays within it to the end). Seeds per "
        f"experiment: take-off {pl.takeoff_seeds}, coin {pl.coin_seeds}, spots "
        f"{pl.spot_seeds} each, tug {pl.tug_seeds}, follow {pl.follow_seeds}; figures show "
        "the first seed.",
        "",
        "### Vertical tension: take-off to 0.3 m and 1.3 m",
        "",
        "Truth: T_v = ω·z (base on the floor, drone straight above it). Before the propellers "
        "carry the drone the floor's reaction looks like tension; the paper's estimate showed "
        "it (~0.3 N, the drone's weight). The service detects ground contact (disarmed, or "
        "thrust below half the weight) and reports `on_ground: true` with zero tension; the "
        "red curve is the same filter fed the same samples without that detection. At "
        "lift-off the filter restarts from the first airborne observation (one sample: about "
        "9 mN of noise per axis), so H briefly exceeds the paper's 10 mN before it settles; "
        "in hover it stays far below.",
        "",
    ]
    t03, t13 = p.takeoff
    L += _table(
        ("", "0.3 m", "1.3 m", "paper"),
        [
            ("runs (seeds)", str(t03.runs), str(t13.runs), ""),
            (
                "on the floor: tension reported (ours)",
                f"{_mn(t03.ours_on_ground_max_n, 0)}",
                f"{_mn(t13.ours_on_ground_max_n, 0)}",
                "~0.3 N",
            ),
            (
                "on the floor: T_v without ground detection",
                _mn(t03.naive_on_ground_tv_n, 0),
                _mn(t13.naive_on_ground_tv_n, 0),
                "~0.3 N (sign: up)",
            ),
            ("lift-off (truth)", _s(t03.liftoff_s), _s(t13.liftoff_s), ""),
            ("lift-off → T_v within 3 mN, ours", _s(t03.converge_s), _s(t13.converge_s), ""),
            ("… without ground detection", _s(t03.naive_converge_s), _s(t13.naive_converge_s), ""),
            (
                f"T_v error, climb (lift-off … {rp.TAKEOFF_HOVER_FROM_S:g} s): RMSE / bias / p95",
                f"{_mn(t03.climb.rmse)} / {_mn(t03.climb.bias)} / {_mn(t03.climb.p95_abs)}",
                f"{_mn(t13.climb.rmse)} / {_mn(t13.climb.bias)} / {_mn(t13.climb.p95_abs)}",
                "",
            ),
            (
                f"T_v error, hover (≥ {rp.TAKEOFF_HOVER_FROM_S:g} s): RMSE / bias / p95",
                f"{_mn(t03.hover.rmse)} / {_mn(t03.hover.bias)} / {_mn(t03.hover.p95_abs)}",
                f"{_mn(t13.hover.rmse)} / {_mn(t13.hover.bias)} / {_mn(t13.hover.p95_abs)}",
                "",
            ),
            (
                f"H in vertical flight (truth 0), hover ≥ {rp.TAKEOFF_HOVER_FROM_S:g} s: p95 / max",
                f"{_mn(t03.h_hover.p95_abs)} / {_mn(t03.h_hover.max_abs)}",
                f"{_mn(t13.h_hover.p95_abs)} / {_mn(t13.h_hover.max_abs)}",
                "< 10 mN",
            ),
            (
                "H: max from lift-off on (filter restarts at lift-off)",
                _mn(t03.h_after_liftoff_max_n),
                _mn(t13.h_after_liftoff_max_n),
                "< 10 mN",
            ),
        ],
    )
    L += [f"![vertical tension](figures/{fig['vertical_tension']})", ""]
    L += [TAKEOFF_LAG_NOTE, ""]
    c = p.coin
    L += [
        "### Horizontal tension: the 4.1 g coin",
        "",
        "A thread over an arm at (0.3, 0, 1) m with a 4.1 g coin replaces the tether; the "
        "drone hovers at (0, 0, 0.9) m. Truth: H = cos(γ)·m_coin·g with "
        "γ = atan((z_q − z_a)/r_q) (eq:exp_HorGroundThruth, eq:exp_gamma). The paper shows "
        "this as a figure without a number.",
        "",
    ]
    L += _table(
        (
            "runs",
            "H truth",
            "H estimate (mean)",
            "RMSE",
            "bias",
            "p95 |error|",
            "converged (3 mN) after",
        ),
        [
            (
                str(c.runs),
                _mn(c.h_truth_n),
                _mn(c.h_est_mean_n),
                _mn(c.stats.rmse),
                _mn(c.stats.bias),
                _mn(c.stats.p95_abs),
                _s(c.converge_s),
            )
        ],
    )
    L += [f"![coin](figures/{fig['coin']})", ""]
    pos = p.position
    L += [
        "### Position from tension: the paper's six hover spots",
        "",
        "No motion capture; the azimuth β comes from the horizontal tension (the paper took β "
        "from motion capture). Error statistics from "
        f"t ≥ {pos.steady_from_s:g} s; the first estimate is the first published position "
        "(the filter initialises from the first observation and reports a position once "
        "converged, 25 samples). The paper's filter started from T = 0, so its first "
        "estimate was the plumb-line limit z = z_i − L = 0.754 − 1.6 = −0.846 m, under the "
        "floor (eq:in_instants).",
        "",
    ]
    rows: list[tuple[str, ...]] = []
    for i, s in enumerate(pos.spots):
        rows.append(
            (
                f"{i + 1}: ({s.spot_m[0]:g}, {s.spot_m[1]:g}, {s.spot_m[2]:g})",
                f"t = {s.first_t_s:.3f} s: ({s.first_pos_m[0]:.2f}, {s.first_pos_m[1]:.2f}, "
                f"{s.first_pos_m[2]:.2f}) m, off {_cm(s.first_error_m)}",
                _s(s.converge_s),
                " / ".join(_cm(a.rmse) for a in s.axis),
                " / ".join(_cm(a.bias) for a in s.axis),
                f"{_cm(s.error3d.median_abs)} / {_cm(s.error3d.p95_abs)}",
            )
        )
    rows.append(
        (
            "all six",
            "paper: z = −0.846 m",
            "",
            "",
            "",
            f"**{_cm(pos.all3d.median_abs)} / {_cm(pos.all3d.p95_abs)}**",
        )
    )
    L += _table(
        (
            "spot (m)",
            "first estimate",
            "within 10 cm after",
            "RMSE x / y / z",
            "bias x / y / z",
            "3D median / p95",
        ),
        rows,
    )
    L += [f"![position at the six spots](figures/{fig['position_spots']})", ""]
    L += [f"![start of the estimate](figures/{fig['position_start']})", ""]
    L += ["Tension error at hover (the same runs, all spots pooled):", ""]
    L += _table(
        ("axis", "RMSE", "bias", "p95 |error|"),
        [
            (n, _mn(s.rmse), _mn(s.bias), _mn(s.p95_abs))
            for n, s in zip(("T_x", "T_y", "T_z"), pos.tension_axis, strict=True)
        ],
    )
    tug = p.tug
    L += [
        "### Tug response (30 mN step toward the base, 10 s … 15 s)",
        "",
    ]
    L += [
        "Settle time: from the step until the error stays within 3 mN until the next event, "
        "per axis (largest component) and for the norm, as `benchmarks/bench_filter.py` "
        "measures it (its open-loop figures: docs/filter_benchmark.md). Here the drone is in "
        "closed loop: it moves under the pull and the tether force changes with it. Step "
        "oracle: the mean of the raw observations since the step, its time known, in the "
        "same runs: the information limit of the 3 mN settle (after a restart the filter is "
        "that mean, so equal times mean the filter lost nothing to the detection).",
        "",
    ]
    L += _table(
        (
            "runs",
            "hover error before (RMSE of |ΔT|)",
            "onset: per axis",
            "onset: norm",
            "release: per axis",
            "release: norm",
            "not settled",
            "step oracle onset: per axis / norm",
        ),
        [
            (
                str(tug.runs),
                _mn(tug.hover.rmse),
                _mm(tug.onset_axis_s),
                _mm(tug.onset_norm_s),
                _mm(tug.release_axis_s),
                _mm(tug.release_norm_s),
                str(tug.unsettled),
                f"{_mm(tug.oracle_onset_axis_s)} / {_mm(tug.oracle_onset_norm_s)}",
            )
        ],
    )
    L += [f"![tension at hover and the tug](figures/{fig['tension']})", ""]
    L += [
        "### Tension following and tug-to-land",
        "",
        "`follow`: the operator enables following (threshold 150 mN) at 3 s; a hand pulls "
        "with 0.21 N at 6–8 s and 0.20 N at 14–16 s. `tug_landing`: following with "
        "`land_below_m` 0.25 m at 3 s; a pull down and toward the base (0.23 N) from 6 s. "
        "The paper ran both with motion capture (*mocap*); *tether* gives the service only "
        "IMU and thrust, so its setpoints come from the tether-based position.",
        "",
    ]
    rows = []
    for f in p.follow:
        rows.append(
            (
                f.tag,
                str(f.runs),
                f"{f.setpoints:.0f}",
                " / ".join(_s(r, 3) for r in f.reaction_s),
                " / ".join(_f(m, 1, 2, "m") for m in f.along_pull_m),
                _s(f.active_without_pull_s, 1),
                " / ".join(_cm(d) for d in f.hold_drift_m),
                f"{_cm(f.hover_pos_error_m)} / {_cm(f.pull_pos_error_m, 0)}",
            )
        )
    L += _table(
        (
            "follow",
            "runs",
            "setpoints/run",
            "first setpoint after pull 1 / 2",
            "moved along pull 1 / 2 (+: yields to it)",
            "following active with no pull",
            "drift 1–4 s after release 1 / 2",
            "tether position error: hover / during pulls",
        ),
        rows,
    )
    rows = []
    for lr in p.landing:
        rows.append(
            (
                lr.tag,
                str(lr.runs),
                f"{lr.stops:g}",
                f"{lr.landed}/{lr.runs}",
                "no Stop" if lr.stop_after_pull_s is None else _s(lr.stop_after_pull_s),
                _f(lr.z_at_stop_m, 1, 3, "m"),
                _f(lr.max_z_m, 1, 2, "m"),
                _f(lr.final_z_m, 1, 2, "m"),
            )
        )
    L += _table(
        (
            "tug-to-land",
            "runs",
            "Stops/run",
            "landed",
            "pull → Stop",
            "z at Stop",
            "max z",
            "final z",
        ),
        rows,
    )
    fm, ft = p.follow
    lm, lt = p.landing
    with_mocap = (
        f"With motion capture the drone yields to each pull within "
        f"{_s(fm.reaction_s[0], 3)} and holds after it; tug-to-land sends exactly one Stop "
        f"{_s(lm.stop_after_pull_s)} after the pull starts, at z = "
        f"{_f(lm.z_at_stop_m, 1, 3, 'm')}. "
    )
    pulls_t = " / ".join(_f(m, 1, 2, "m") for m in ft.along_pull_m)
    pulls_m = " / ".join(_f(m, 1, 2, "m") for m in fm.along_pull_m)
    if follows_without_mocap(p):
        text = (
            with_mocap + "**Without motion capture the position estimate cannot be followed:** "
            "the hand's pull is a force the catenary model does not contain, so while it acts "
            f"the tether-based position is off by {_cm(ft.pull_pos_error_m, 0)} (median). The "
            "service therefore moves the goal from the position before the tug along the pull "
            "(admittance, `groundstation/follow.py` rule 6b) and watches the goal's height for "
            f"tug-to-land. In `follow` the drone moved {pulls_t} along the two pulls (mocap: "
            f"{pulls_m}); following stayed active for {_s(ft.active_without_pull_s, 1)} with no "
            f"pull acting (mocap: {_s(fm.active_without_pull_s, 1)}). In `tug_landing` it sent "
            f"{lt.stops:g} Stop per run, at a true height of {_f(lt.z_at_stop_m, 1, 3, 'm')}, "
            f"and landed in {lt.landed}/{lt.runs} runs. (Without motion capture the service "
            "follows only with a calibration in force; these runs declare the ideal profile's "
            "exact sensors as one. Uncalibrated on the realistic profile it refuses: "
            "docs/realistic_benchmark.md.)"
        )
    else:
        text = (
            with_mocap + "**Without motion capture this does not work:** the "
            "hand's pull is a force the catenary model does not contain, so while it acts the "
            f"tether-based position is off by {_cm(ft.pull_pos_error_m, 0)} (median) and the "
            "setpoints chase that error. In `tug_landing` the drone climbed (to z = "
            f"{lt.max_z_m:.2f} m) instead of landing: {lt.stops:g} Stop(s). In `follow` the "
            f"drone moved {pulls_t} along the two pulls (mocap: {pulls_m}; negative: away from "
            f"the hand); following stayed active for {_s(ft.active_without_pull_s, 1)} with no "
            f"pull acting (mocap: {_s(fm.active_without_pull_s, 1)})."
        )
    L += [
        text,
        "",
        f"![follow](figures/{fig['follow']})",
        "",
        f"![tug-to-land](figures/{fig['tug_landing']})",
        "",
    ]
    return L


def _catenary_section(o: Outcome) -> list[str]:
    cat = o.catenary
    L = [
        SECTIONS[2],
        "",
        f"`benchmarks/bench_catenary.py`'s mixed case set (nearly taut, slack, equal heights, "
        f"leftward and near-plumb spans) and peers, run here at: vectorised "
        f"{cat.n_vectorised:,} cases, scalar {cat.n_scalar:,} (fsolve {cat.n_fsolve:,}), "
        f"accuracy against a 50-digit mpmath reference on {cat.n_reference:,} of them. "
        "'ok': a, x0 and the curve all within 1e-9; 'returned': a finite answer without an "
        "exception. The paper recipe is Newton on eq:cat7 from the Taylor start of eq:tayl4 "
        "(with NOTES' corrected constant); fsolve solves the five equations eq:sys2_eq1–5. "
        "Worst errors are ∞ where a method failed on some case (raised or returned a "
        "non-finite answer).",
        "",
    ]
    rows: list[tuple[str, ...]] = []
    for m in cat.methods:
        rows.append(
            (
                m.name,
                f"{m.us_per_solve:.3g} µs",
                f"{m.solves_per_s:,.0f}",
                f"{m.raised} of {m.timed_cases:,}",
                _pct(m.returned),
                _pct(m.ok),
                f"{m.worst_a:.1e} / {m.worst_x0:.1e} / {m.worst_curve:.1e}",
            )
        )
    L += _table(
        (
            "method",
            "time per solve",
            "solves/s",
            "raised (timed cases)",
            "returned",
            "ok",
            "worst a (rel) / x0 / curve",
        ),
        rows,
    )
    cats = list(cat.methods[0].ok_by_category)
    L += ["Cases within 1e-9 by category:", ""]
    L += _table(
        ("method", *cats),
        [(m.name, *(_pct(m.ok_by_category[c], 0) for c in cats)) for m in cat.methods],
    )
    L += [f"![catenary](figures/{o.figures['catenary']})", ""]
    return L


def _service_section(o: Outcome) -> list[str]:
    svc, dash = o.service, o.dashboard
    L = [
        SECTIONS[3],
        "",
        "`benchmarks/bench_service.run_case` on the rig of `benchmarks/service_rig.py`: a "
        "zenoh router, the system under test and a load client, each its own process on "
        "127.0.0.1 over TCP; the client publishes hover telemetry for N drones at 250 Hz each "
        "and times publish → estimate. The system is `groundstation serve --headless` or, as "
        "the floor, a bare echo (`benchmarks/echo_service.py`: transport, router and one "
        "Python callback) measured the same way in the same run. The client's garbage "
        "collector is off in the window (collections still seen are counted) and ticks it "
        "published more than 4 ms late are counted. CPU and RSS are the service process's. "
        "The machine is shared (other work on its two cores adds noise): 1-minute load "
        f"average {svc.load_before:.1f} when this section started, {svc.load_after:.1f} "
        f"when it ended; compare with the floor. {svc.seconds:g} s per case.",
        "",
    ]
    rows: list[tuple[str, ...]] = []
    for r in (
        sorted(svc.rows, key=lambda r: r["drones"])
        + list(svc.dashboard_rows)
        + list(svc.floor_rows)
    ):
        system = "echo floor" if r.get("sut") == "echo" else "service"
        rows.append(
            (
                f"{r['drones']}" + (" + dashboard" if r["dashboard"] else ""),
                system,
                f"{r['offered_hz']:.0f}",
                _pct(r["delivered"], 2),
                f"{r['p50_ms']:.1f}",
                f"{r['p99_ms']:.1f}",
                f"{r['max_ms']:.0f}",
                f"{r['cpu_us_per_msg']:.0f}",
                f"{r['cpu_share']:.2f}",
                f"{r['rss_mb']:.0f}",
                str(r["queue_overflow"]),
                str(r.get("late_ticks", r.get("generator_late_ticks", 0))),
            )
        )
    L += _table(
        (
            "drones × 250 Hz",
            "system",
            "offered msg/s",
            "delivered",
            "p50 ms",
            "p99 ms",
            "max ms",
            "CPU µs/msg",
            "CPU (cores)",
            "RSS MB",
            "queue overflow",
            "late ticks",
        ),
        rows,
    )
    L += [
        f"**Saturation:** {saturation_text(o)}. The estimator runs on one worker thread "
        "(Python), so one core bounds it whatever the machine; scale out with "
        "`serve --drones` (docs/deployment.md). CPU per message falls with load because "
        "the service's fixed per-second cost is shared by more messages, and the worker "
        "drains what has queued in batches.",
        "",
    ]
    b, cap = svc.bursts, svc.capacity
    if "service" in b and "echo" in b:
        bs, be = b["service"], b["echo"]
        L += [
            f"**Bursts:** {bs['drones']} drones × 250 Hz, the upstream pausing 100 ms once a "
            f"second and then releasing the held {bs['drones'] * 25} messages back to back "
            f"(latency from the actual publish): service p50 {bs['p50_ms']:.1f} ms, p99 "
            f"{bs['p99_ms']:.1f} ms, max {bs['max_ms']:.0f} ms; echo floor p50 "
            f"{be['p50_ms']:.1f} ms, p99 {be['p99_ms']:.1f} ms: "
            f"**{bs['p99_ms'] / be['p99_ms']:.1f}×** the floor's p99 (target ≤ "
            f"{rpeers.SERVICE_TARGET_BURST_RATIO:g}×)." + _contract_floor_bursts(b),
            "",
        ]
    if "service" in cap:
        c = cap["service"]
        echo = cap.get("echo")
        L += [
            f"**Capacity with a backlog:** {c['backlog']} messages published back to back "
            f"(every filter converged first): the service drained "
            f"**{c['msgs_per_s']:,.0f} msg/s** ({c['wall_us_per_msg']:.0f} µs per message, "
            f"{c['cpu_us_per_msg']:.0f} µs of process CPU)"
            + (f"; the echo floor {echo['msgs_per_s']:,.0f} msg/s" if echo else "")
            + (
                f"; the contract floor {cap['floor']['msgs_per_s']:,.0f} msg/s "
                f"({cap['floor']['cpu_us_per_msg']:.0f} µs of process CPU)"
                if "floor" in cap
                else ""
            )
            + f". The per-message maths alone (`Pipeline.handle` in one thread, no bus, same "
            f"run) costs {svc.offline_us_per_msg:.0f} µs of CPU per message here, i.e. at most "
            f"{1e6 / svc.offline_us_per_msg:,.0f} msg/s per worker. The target of "
            f"{rpeers.SERVICE_TARGET_CAPACITY_HZ:,.0f} msg/s (≤ 50 µs/msg) is at or beyond "
            "what the contract floor itself does (validation, observation, one Kalman step "
            "and the Estimate per message, nothing else): no service that keeps the contract "
            "(one Estimate per accepted Telemetry) and steps a Kalman filter per message "
            "reaches it on this machine, so one instance scales out per core with `serve --drones` "
            "(docs/service_profile.md sections 5 and 6).",
            "",
        ]
    r8 = _service_row(o, 8)
    if svc.dashboard_rows and r8 is not None:
        d8 = svc.dashboard_rows[0]
        L += [
            f"**Dashboard, end to end:** `serve` runs the dashboard in a process of its own "
            f"(a bus client), so drawing never takes the interpreter lock from estimation. At "
            f"{d8['drones']} drones with the dashboard (no browser connected) the service "
            f"process used {d8['cpu_share']:.2f} cores against {r8['cpu_share']:.2f} headless "
            f"and the dashboard process {d8.get('dashboard_process_cpu_share', float('nan')):.2f}"
            f" cores; p99 {d8['p99_ms']:.1f} ms against {r8['p99_ms']:.1f} ms headless, "
            f"{100 * d8['delivered']:.2f} % delivered.",
            "",
        ]
    L += [
        f"**Dashboard, in process** (`benchmarks/bench_dashboard`: telemetry + estimates "
        f"at 250 Hz per drone on an in-memory bus, no browser, {dash.seconds:g} s per run): "
        f"bus callback {dash.callback_us:.2f} µs per sample.",
        "",
    ]
    L += _table(
        (
            "drones",
            "process CPU without dashboard",
            "with dashboard",
            "dashboard's cost",
            "update thread",
            "scene passes/s",
        ),
        [
            (str(n), f"{a:.3f}", f"{b:.3f}", f"**{b - a:.3f}**", f"{u:.3f}", f"{k:.1f}")
            for n, (a, b, u, k) in sorted(dash.runs.items())
        ],
    )
    L += [
        "CPU in cores (1.0 = one core busy). The cost with a browser connected is measured "
        "by `python -m benchmarks.bench_dashboard` (needs Chromium) into "
        "docs/dashboard_cost.md.",
        "",
        f"![service](figures/{o.figures['service']})",
        "",
    ]
    return L


def _drawn_text(c: renv.ErrorClass, drawn: Mapping[str, float]) -> str:
    """What the simulator drew for this class (mean over the flights), or '—'."""
    if c.drawn is None or c.drawn not in drawn:
        return "—"
    v = drawn[c.drawn]
    if c.drawn == "misalignment_deg":
        return f"{v:.2f}°"
    if c.drawn == "accel_scale_pct":
        return f"{v:.2f} %"
    if c.drawn == "accel_bias_mps2":
        return f"|b| {v:.3f} m/s²"
    if c.drawn == "hover_vbat_v":
        f = drawn.get("thrust_report_factor", math.nan)
        return f"{v:.2f} V: reported/true {f:.3f}"
    return f"{v:g}"


STATS_HEADERS = (
    "median 3D",
    "p95 3D",
    "median horizontal",
    "median |Δz|",
    "tension median / p95",
    "position available",
)
"""The column headers of :func:`_stats_cells`."""


def _stats_cells(st: renv.Stats) -> tuple[str, ...]:
    """A point's errors as table cells, in the order of :data:`STATS_HEADERS`."""
    return (
        _cm(st.median_m),
        _cm(st.p95_m),
        _cm(st.horizontal_median_m),
        _cm(st.vertical_median_m),
        f"{_mn(st.tension_median_n)} / {_mn(st.tension_p95_n)}",
        _pct(st.availability, 0),
    )


def _cal_text(st: renv.Stats | None) -> str:
    if st is None:
        return "—"
    return f"{_cm(st.median_m)} / {_cm(st.p95_m)}"


def _envelope_section(o: Outcome | EnvelopeOutcome) -> list[str]:
    env = o.envelope
    ep = env.plan
    spots = ", ".join(str(i + 1) for i in ep.spots)
    L = [
        SECTIONS[4],
        "",
        "Profile **realistic** (`groundstation/sim/`, docs/simulator.md: rigid body, motor "
        "lag, rotor drag, yaw, lumped-mass tether, 100 Hz IMU), flown through the service's "
        "pipeline in lock-step (`benchmarks.bench_realistic.fly`); no motion capture reaches "
        "the service, which is not told the noise level (`[drone] accel_noise_mps2` stays "
        "0.3 m/s²). **Baseline:** vibration noise "
        f"{renv.BASELINE_NOISE_MPS2:g} m/s² per axis (white + coloured, lag-1 0.2) and every "
        "other error class off, L = 1.6 m, ω = 0.05 N/m known. Each row turns one error "
        "class on (sized as stated) on top of the baseline. **Uncalibrated:** `[calibration]` "
        "at its defaults. **Calibration = truth:** `[calibration]` set to the simulator's "
        "drawn errors (their equivalent calibration), the best any calibration can do; flown "
        "for the classes the calibration model has parameters for (accelerometer "
        "misalignment, scale and bias → `accel_bias_mps2`, thrust axis, thrust map and its "
        "battery term), at the real size; '—' where there is nothing to calibrate. Each "
        f"point pools the paper's hover spots {spots}, {ep.seconds:g} s each, errors from "
        f"t ≥ {ep.steady_from_s:g} s, the same seed per spot in every row (the per-flight "
        "draws scale with the size, the noise is shared). Position: 3D error of the "
        "published position; tension: |T_est − T_true|. Per-boot classes (misalignment, "
        "scale, bias) draw a size up to the stated one: 'drawn' is the mean over the "
        "flights. Motion-capture timing (rate, bursts, latency) acts only on motion-capture "
        "frames, none of which reach the service here: it is not a row.",
        "",
        "### Each error class at its real size (realistic profile)",
        "",
    ]
    base = env.cls("vibration").at(renv.BASELINE_NOISE_MPS2).raw
    rows = [
        (
            "baseline",
            f"vibration σ {renv.BASELINE_NOISE_MPS2:g} m/s², every other class off",
            "—",
            f"{_cm(base.median_m)} / {_cm(base.p95_m)}",
            "—",
            _mn(base.tension_median_n),
            "—",
        )
    ]
    for c in env.classes:
        if c.cls.name == "vibration":
            continue
        pt = c.real
        rows.append(
            (
                c.cls.name.replace("_", " "),
                renv.size_text(c.cls, pt.value),
                _drawn_text(c.cls, pt.drawn),
                f"**{_cm(pt.raw.median_m)}** / {_cm(pt.raw.p95_m)}",
                _cal_text(pt.cal),
                _mn(pt.raw.tension_median_n),
                "—" if pt.cal is None else _mn(pt.cal.tension_median_n),
            )
        )
    L += _table(
        (
            "error class",
            "size",
            "drawn",
            "position median / p95, uncalibrated",
            "… calibration = truth",
            "tension median, uncalibrated",
            "… calibration = truth",
        ),
        rows,
    )
    L += [f"![envelope](figures/{o.figures['envelope']})", ""]
    L += ["### Each error class over its range (realistic profile)", ""]
    for c in env.classes:
        L += [
            f"**{c.cls.name.replace('_', ' ')}: {c.cls.label}** (real size: "
            f"{renv.size_text(c.cls, c.cls.real)})",
            "",
        ]
        L += _table(
            (
                "size",
                "drawn",
                *STATS_HEADERS,
                "calibration = truth: median / p95",
            ),
            [
                (
                    renv.size_text(c.cls, pt.value)
                    + (" (baseline)" if renv.is_baseline(c.cls, pt.value) else ""),
                    _drawn_text(c.cls, pt.drawn),
                    *_stats_cells(pt.raw),
                    _cal_text(pt.cal),
                )
                for pt in c.points
            ],
        )
    L += [
        "### The model: ω error, tether length, distance (realistic profile, baseline)",
        "",
        "On the baseline above, uncalibrated (nothing to calibrate there). ω error: the service "
        "is configured with ω·(1 + e), the simulated tether weighs ω = 0.05 N/m. Tether "
        "length: both sides know it; long tethers rest on the floor. Distance: hover at "
        f"z = 1 m, {ep.azimuths} azimuth(s) per point. The nominal of ω and L is the "
        "baseline's flights.",
        "",
    ]
    for sw in env.sweeps:
        L += [f"**{sw.sweep.label}** (nominal {sw.sweep.nominal:g})", ""]
        L += _table(
            (
                "value",
                *STATS_HEADERS,
                "azimuth determined",
                "tether on the floor",
            ),
            [
                (
                    f"{pt.value:g}",
                    *_stats_cells(pt.stats),
                    "—" if math.isnan(pt.azimuth_determined) else _pct(pt.azimuth_determined, 0),
                    "—" if math.isnan(pt.floor_contact) else _pct(pt.floor_contact, 0),
                )
                for pt in sw.points
            ],
        )
    L += [f"![envelope, the model](figures/{o.figures['envelope_model']})", ""]
    L += ["### When it works, when it doesn't", ""]
    L += [f"- {b}" for b in trust_bullets(o)] + [""]
    return L


PAGE_PROFILES = (
    "Everything here is simulation or this machine. Two simulator profiles, named in "
    "every section and figure: the summary, (a) and the 'ideal profile' bullets are the "
    "**ideal** profile, whose tether is the quasi-static catenary the estimator assumes "
    "(no tether dynamics, no stretch, no drag) and whose sensors are exact but for white "
    "noise, so those numbers are an upper bound on what the method does in a lab; (d) is "
    "the **realistic** profile (a lumped-mass tether of its own and real Crazyflie "
    "sensor errors, one class at a time: docs/simulator.md). The paper's figures are "
    "missing from its source; where its text states a number it is given beside ours."
)
SUMMARY_COLUMNS = ("", "ours (ideal-profile simulation / this machine)", "paper / target")


def results_markdown(o: Outcome, prov: dict[str, str], wall_s: float) -> str:
    cmd = ".venv/bin/python -m benchmarks.results" + (" --quick" if o.quick else "")
    phases = ", ".join(f"{k} {v:.0f} s" for k, v in o.phases_s.items())
    L = [
        "# Results",
        "",
        f"Generated by `{cmd}` on {prov['date']}, commit `{prov['commit']}`"
        + (f" (with uncommitted changes in {prov['dirty']})" if prov["dirty"] else "")
        + f". Machine: {prov['machine']}; 1-minute load average {o.load_start:.1f} at the "
        f"start. Wall time {wall_s:.0f} s ({phases}).",
        "",
    ]
    if o.quick:
        L += [
            "**This is a --quick run** (fewer seeds, shorter runs, fewer sweep points, one "
            "service case): numbers are indicative only; the full run is the reference.",
            "",
        ]
    L += [
        PAGE_PROFILES,
        "",
        SECTIONS[0],
        "",
        *_summary_table(o),
        "### Targets at a glance",
        "",
        *_table(
            ("what", "target", "ours", ""),
            [(w, t, v, _tick(ok)) for w, t, v, ok in targets(o)],
        ),
        *_paper_section(o),
        *_catenary_section(o),
        *_service_section(o),
        *_envelope_section(o),
        f"<!-- headline: {json.dumps(headline(o))} -->",
        "",
    ]
    return "\n".join(L)


def run_envelope_only(quick: bool, out_dir: Path, workers: int) -> EnvelopeOutcome:
    """Section (d) alone: its flights and (a)'s (the bullets cite both), its two figures."""
    t0 = time.perf_counter()
    _traces, paper, env = _closed_loop(quick, workers, t0)
    figures = {
        "envelope": rfig.envelope(env, out_dir / "figures"),
        "envelope_model": rfig.envelope_model(env, out_dir / "figures"),
    }
    _log("envelope done", t0)
    return EnvelopeOutcome(quick, paper, env, figures)


_SECTION_D = re.compile(r"^## \(d\) .*$", re.MULTILINE)
_SECTION_A = re.compile(r"^## \(a\) .*$", re.MULTILINE)
_HEADLINE = re.compile(r"^<!-- headline: (\{.*\}) -->$", re.MULTILINE)
_ONLY_NOTE = re.compile(r"^Section \(d\) regenerated alone by .*\n\n", re.MULTILINE)


def splice_envelope(page: str, o: EnvelopeOutcome, prov: dict[str, str], wall_s: float) -> str:
    """``page`` (a RESULTS.md) with section (d), its headline numbers and the profile labels
    replaced from ``o``; every other section as it was (and says so)."""
    d, head = _SECTION_D.search(page), _HEADLINE.search(page)
    if d is None or head is None or head.start() < d.start():
        raise RuntimeError("RESULTS.md: section (d) or the headline comment not found")
    numbers = {**json.loads(head.group(1)), **envelope_headline(o.envelope)}
    page = (
        page[: d.start()]
        + "\n".join(_envelope_section(o))
        + f"<!-- headline: {json.dumps(numbers)} -->"
        + page[head.end() :]
    )
    page = _SECTION_A.sub(lambda _: SECTIONS[1], page, count=1)
    page = re.sub(
        r"^Everything here is simulation.*$", lambda _: PAGE_PROFILES, page, count=1, flags=re.M
    )
    header = _table(SUMMARY_COLUMNS, [])[0]
    page = re.sub(
        r"^\|  \| ours \(.*\| paper / target \|$", lambda _: header, page, count=1, flags=re.M
    )
    note = (
        f"Section (d) regenerated alone by `.venv/bin/python -m benchmarks.results --only "
        f"envelope{' --quick' if o.quick else ''}` on {prov['date']}, commit "
        f"`{prov['commit']}`"
        + (f" (with uncommitted changes in {prov['dirty']})" if prov["dirty"] else "")
        + f", {wall_s:.0f} s; the other sections are from the run above.\n\n"
    )
    page = _ONLY_NOTE.sub("", page)
    first = page.index("\n\n", page.index("Generated by")) + 2
    return page[:first] + note + page[first:]


def splice_readme_block(text: str, o: EnvelopeOutcome, prov: dict[str, str]) -> str:
    """The README block with its bullets, figure and profile sentence from ``o`` (and a line
    saying so); its table as it was."""
    start = README_START.search(text)
    end = text.find(README_END)
    if start is None or end < start.end():
        raise RuntimeError(f"{README}: results markers not found")
    block = text[start.end() : end]
    tail = block.find(README_TAIL)
    if tail < 0:
        raise RuntimeError(f"{README}: {README_TAIL!r} not found in the results block")
    tail_lines = _readme_tail(o)
    tail_lines[-1:-1] = [
        f"(Section (d), the bullets marked *realistic* and the figure: `.venv/bin/python -m "
        f"benchmarks.results --only envelope`, {prov['date']}, commit `{prov['commit']}`.)",
        "",
    ]
    block = block[:tail] + "\n".join(tail_lines) + "\n"
    block = re.sub(
        r"^\nSimulation.*?and this machine for speed",
        lambda _: "\n" + README_PROFILES,
        block,
        count=1,
        flags=re.S,
    )
    header = _table(SUMMARY_COLUMNS, [])[0]
    block = re.sub(
        r"^\|  \| ours \(.*\| paper / target \|$", lambda _: header, block, count=1, flags=re.M
    )
    return text[: start.end()] + block + text[end:]


def write_readme_block(block: str, readme: Path = README) -> None:
    """Replace the lines between the results markers (markers kept)."""
    text = readme.read_text(encoding="utf-8")
    start = README_START.search(text)
    end = text.find(README_END)
    if start is None or end < start.end():
        raise RuntimeError(f"{readme}: results markers not found")
    new = text[: start.end()] + "\n" + block.rstrip() + "\n" + text[end:]
    readme.write_text(new, encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.results", description=__doc__.splitlines()[0] if __doc__ else ""
    )
    parser.add_argument("--quick", action="store_true", help="every section, smaller (~1.5 min)")
    parser.add_argument(
        "--out-dir",
        type=Path,
        default=REPO / "docs",
        help="where RESULTS.md and figures/ go (default: docs/)",
    )
    parser.add_argument("--workers", type=int, default=2, help="processes for closed-loop runs")
    parser.add_argument(
        "--no-readme",
        action="store_true",
        help="do not rewrite the block of docs/results_summary.md (full runs into docs/ do)",
    )
    parser.add_argument(
        "--only",
        choices=("envelope",),
        help="rerun one section into the existing <out-dir>/RESULTS.md (and, for docs/, the "
        "summary block's bullets and figure); the other sections stay as they are",
    )
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    out_dir: Path = args.out_dir.resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    prov = provenance()
    if args.only == "envelope":
        page_path = out_dir / "RESULTS.md"
        if not page_path.exists():
            parser.error(f"--only envelope: {page_path} does not exist (run the full page first)")
        only = run_envelope_only(args.quick, out_dir, max(1, args.workers))
        wall = time.perf_counter() - t0
        page = splice_envelope(page_path.read_text(encoding="utf-8"), only, prov, wall)
        page_path.write_text(page, encoding="utf-8")
        print(f"rewrote section (d) of {page_path}", file=sys.stderr)
        if not args.quick and not args.no_readme and out_dir == (REPO / "docs").resolve():
            text = splice_readme_block(README.read_text(encoding="utf-8"), only, prov)
            README.write_text(text, encoding="utf-8")
            print(
                f"rewrote the bullets and figure of the results block of {README}", file=sys.stderr
            )
            write_figures(
                "results_envelope", envelope_figures(only.envelope), ["--only", "envelope"]
            )
        print(f"wall time {wall:.0f} s", file=sys.stderr)
        return 0
    outcome = run(args.quick, out_dir, max(1, args.workers))
    wall = time.perf_counter() - t0
    (out_dir / "RESULTS.md").write_text(results_markdown(outcome, prov, wall), encoding="utf-8")
    print(f"wrote {out_dir / 'RESULTS.md'} and {len(outcome.figures)} figures", file=sys.stderr)
    if not args.quick and not args.no_readme and out_dir == (REPO / "docs").resolve():
        write_readme_block(readme_block(outcome, prov, wall))
        print(f"rewrote the results block of {README}", file=sys.stderr)
        write_figures("results_envelope", envelope_figures(outcome.envelope))
    print(f"wall time {wall:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
