"""Leave-one-out evidence for ``groundstation calibrate`` on the realistic simulator (issue 10 §4).

One flight per case tours the paper's six hover spots under motion capture (realistic profile:
rigid body, lumped-mass tether, motor lag, rotor drag, vibration, misalignment, scale, bias,
thrust axis, thrust map with a sagging battery, IMU jitter, bursty mocap). For each of three
folds, four spots are written to an MCAP recording (Telemetry with ``position_m``, Reel), as
``groundstation record`` would, and calibrated with the CLI's own code
(:func:`groundstation.recording.calibrate.run_calibrate`); the written configuration is loaded
and the service's pipeline re-estimates the flight *without* motion capture, judged on the
two held-out spots. Each held-out spot is judged once. Three configurations side by side:
uncalibrated (defaults), fitted, and the simulator's drawn truth as its equivalent
``[calibration]`` (``Simulator.drawn_errors``).

Targets: each fitted parameter within two standard errors of the drawn truth (mapped to the
fit's convention where a parameter was fixed: see docs/calibration.md); the fitted position
error within 1.2× the true calibration's, at each noise level.

    python -m benchmarks.bench_calibration [--quick]     # writes docs/calibration.md + figure
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.pipeline import Pipeline
from groundstation.recording.calibrate import run_calibrate
from groundstation.recording.reader import RecordedMessage, copy_messages
from groundstation.sim import PAPER_HOVER_SPOTS_M, SCENARIOS, Scenario, Simulator, Waypoint

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "calibration.md"
FIGURE = ROOT / "docs" / "figures" / "calibration_position_error.png"

ACCEL = ("misalignment", "accel_scale", "accel_bias")
ALL_CLASSES = (*ACCEL, "thrust_axis", "thrust_map")
FOLDS = ((0, 1, 2, 3), (2, 3, 4, 5), (0, 1, 4, 5))
"""Calibration spots of each fold; the other two spots are held out (each once)."""
SETTLE_FRACTION = 0.4
"""Position error is judged over the last 60 % of each dwell (after the move and the filter's
re-convergence)."""


@dataclass(frozen=True)
class Case:
    name: str
    classes: tuple[str, ...]
    accel_noise_mps2: float


@dataclass
class Flight:
    telemetry: list[tuple[float, bytes]] = field(default_factory=list)  # (stamp, payload)
    reel: list[tuple[float, bytes]] = field(default_factory=list)
    truth: dict[float, dict[str, Any]] = field(default_factory=dict)
    errors: dict[str, Any] = field(default_factory=dict)


def _scenario(dwell_s: float) -> str:
    name = f"calib_tour_{dwell_s:g}"
    SCENARIOS[name] = Scenario(  # registered for this process only (as results_sim does)
        name,
        f"the paper's six spots, {dwell_s:g} s each",
        start_m=PAPER_HOVER_SPOTS_M[0],
        waypoints=tuple(Waypoint(i * dwell_s, s) for i, s in enumerate(PAPER_HOVER_SPOTS_M)),
        duration_s=6 * dwell_s,
    )
    return name


def _sim_settings(case: Case, seed: int) -> Settings:
    realistic: dict[str, Any] = {c: (c in case.classes) for c in ALL_CLASSES}
    realistic["accel_noise_mps2"] = case.accel_noise_mps2
    realistic["battery"] = True
    return load_settings(
        None, {"sim": {"profile": "realistic", "seed": seed, "realistic": realistic}}, use_env=False
    )


def fly(case: Case, dwell_s: float, seed: int) -> Flight:
    settings = _sim_settings(case, seed)
    sim = Simulator(settings, None, scenario=_scenario(dwell_s))  # type: ignore[arg-type]
    flight = Flight()
    while sim.t_s < 6 * dwell_s:
        for s in sim.step():
            kind = s.key.split("/", 2)[2]
            if kind == "telemetry":
                flight.telemetry.append((json.loads(s.payload)["stamp_s"], s.payload))
            elif kind == "reel":
                flight.reel.append((sim.t_s, s.payload))
            elif kind == "truth":
                t = json.loads(s.payload)
                flight.truth[round(t["stamp_s"], 6)] = t
    flight.errors = sim.drawn_errors("cf1") or {}
    return flight


def _window(spot: int, dwell_s: float, settle: float = 0.0) -> tuple[float, float]:
    return spot * dwell_s + settle * dwell_s, (spot + 1) * dwell_s


def write_calibration_recording(path: Path, flight: Flight, spots: tuple[int, ...], dwell_s: float):
    """The calibration spots' telemetry (with motion capture) and the reel, as MCAP."""
    wins = [_window(i, dwell_s) for i in spots]
    msgs = []
    t0 = 1_700_000_000_000_000_000
    for _t, payload in flight.reel[:1]:
        msgs.append(RecordedMessage("tether/cf1/reel", payload, t0, t0))
    for t, payload in flight.telemetry:
        if any(a <= t < b for a, b in wins):
            ns = t0 + int((t + 1.0) * 1e9)
            msgs.append(RecordedMessage("tether/cf1/telemetry", payload, ns, ns))
    copy_messages(msgs, path)


def position_errors(
    settings: Settings, flight: Flight, spots: tuple[int, ...], dwell_s: float
) -> dict[int, float]:
    """Median tether-based position error at each of ``spots``, without motion capture."""
    pipe = Pipeline(settings)
    reel = list(flight.reel)
    errs: dict[int, list[float]] = {i: [] for i in spots}
    wins = {i: _window(i, dwell_s, SETTLE_FRACTION) for i in spots}
    r = 0
    for t, payload in flight.telemetry:
        while r < len(reel) and reel[r][0] <= t:
            pipe.handle(Sample("tether/cf1/reel", reel[r][1]), reel[r][0])
            r += 1
        tel = json.loads(payload)
        tel.pop("position_m", None)  # flown without motion capture
        for out in pipe.handle(Sample("tether/cf1/telemetry", json.dumps(tel).encode()), t):
            if not out.key.endswith("/estimate"):
                continue
            est = json.loads(out.payload)
            for i, (a, b) in wins.items():
                if a <= t < b:
                    truth = flight.truth.get(round(t, 6))
                    if truth is None:
                        continue
                    if est["position_m"] is None:
                        errs[i].append(math.inf)
                    else:
                        errs[i].append(
                            float(
                                np.linalg.norm(np.subtract(est["position_m"], truth["position_m"]))
                            )
                        )
    return {i: float(np.median(v)) if v else math.nan for i, v in errs.items()}


def true_calibration(errors: dict[str, Any]) -> dict[str, Any]:
    eq = errors["calibration"]
    return {
        "thrust_scale": eq["thrust_scale"],
        "thrust_vbat_slope_per_v": eq["thrust_vbat_slope_per_v"],
        "thrust_vbat_ref_v": eq["thrust_vbat_ref_v"],
        "thrust_axis_rad": list(eq["thrust_axis_rad"]),
        "accel_bias_mps2": list(eq["accel_bias_mps2"]),
        "source": "simulator truth",
    }


def truth_in_convention(
    errors: dict[str, Any], fit_lines: dict[str, Any], hover_thrust_n: float, vbat_v: float
) -> dict[str, float]:
    """The drawn truth as the fit's parameters, mapped to its convention where it fixed one.

    With the z bias fixed at 0 the thrust scale absorbs ``m·b_z/F``; with the axis fixed at 0
    the x/y bias absorbs ``F·sin(a_y)/m`` and ``−F·sin(a_x)/m`` (module doc of
    groundstation.calibration); with the voltage slope not fitted the scale is the one at the
    flight's mean hover voltage.
    """
    eq = errors["calibration"]
    m = 0.030
    ax, ay = eq["thrust_axis_rad"]
    bx, by, bz = eq["accel_bias_mps2"]
    fitted = fit_lines["fitted"]
    slope = eq["thrust_vbat_slope_per_v"]
    ref = fit_lines["vbat_ref_v"]
    s_at_v = eq["thrust_scale"] + slope * (vbat_v - eq["thrust_vbat_ref_v"])
    if "vbat_slope_per_v" in fitted:
        s = eq["thrust_scale"] + slope * (ref - eq["thrust_vbat_ref_v"])
    else:
        s = s_at_v
    out = {
        "thrust_scale": s,
        "about_x_rad": ax,
        "about_y_rad": ay,
        "bias_x_mps2": bx,
        "bias_y_mps2": by,
        "bias_z_mps2": bz,
        "vbat_slope_per_v": slope,
    }
    f_true = hover_thrust_n * s_at_v  # true thrust at hover, N
    if "bias_z_mps2" not in fitted:
        out["thrust_scale"] = s + m * bz / hover_thrust_n
        out["bias_z_mps2"] = 0.0
    if "about_y_rad" not in fitted:
        out["bias_x_mps2"] = bx + f_true * math.sin(ay) / m
        out["about_y_rad"] = 0.0
    if "about_x_rad" not in fitted:
        out["bias_y_mps2"] = by - f_true * math.sin(ax) / m
        out["about_x_rad"] = 0.0
    return out


def run_case(case: Case, dwell_s: float, seed: int, workdir: Path) -> dict[str, Any]:
    t0 = time.monotonic()
    flight = fly(case, dwell_s, seed)
    # The filter is told the vibration level, as a lab would configure it ([drone]).
    drone = {"accel_noise_mps2": case.accel_noise_mps2}
    default = load_settings(None, {"drone": drone}, use_env=False)
    true_cal = true_calibration(flight.errors)
    true_cfg = load_settings(None, {"drone": drone, "calibration": true_cal}, use_env=False)
    no_slope = load_settings(
        None,
        {"drone": drone, "calibration": true_cal | {"thrust_vbat_slope_per_v": 0.0}},
        use_env=False,
    )
    everything = tuple(range(6))
    uncal = position_errors(default, flight, everything, dwell_s)
    true = position_errors(true_cfg, flight, everything, dwell_s)
    true_no_slope = position_errors(no_slope, flight, everything, dwell_s)
    fitted: dict[int, float] = {}
    folds = []
    for k, spots in enumerate(FOLDS):
        held_out = tuple(i for i in everything if i not in spots)
        rec = workdir / f"{case.name}_fold{k}.mcap"
        out = workdir / f"{case.name}_fold{k}.toml"
        write_calibration_recording(rec, flight, spots, dwell_s)
        lines: list[str] = []
        cfg_in = workdir / f"{case.name}_in.toml"
        cfg_in.write_text(f"[drone]\naccel_noise_mps2 = {case.accel_noise_mps2!r}\n")
        run_calibrate(default, str(cfg_in), [str(rec)], str(out), echo=lines.append)
        cfg = load_settings(out, use_env=False)
        fitted.update(position_errors(cfg, flight, held_out, dwell_s))
        fit = _last_fit
        hov_thrust = float(np.mean(_last_hover_thrust))
        vbat = float(np.nanmean(_last_hover_vbat))
        truth = truth_in_convention(
            flight.errors, {"fitted": fit.fitted, "vbat_ref_v": fit.vbat_ref_v}, hov_thrust, vbat
        )
        z = {
            name: (fit.values[name] - truth[name]) / fit.std[name]  # type: ignore[operator]
            for name in fit.fitted
            if name in truth and fit.std[name]
        }
        folds.append(
            {
                "spots": spots,
                "held_out": held_out,
                "report": "\n".join(lines),
                "z": z,
                "values": {n: fit.values[n] for n in fit.fitted},
                "std": {n: fit.std[n] for n in fit.fitted},
                "truth": {n: truth[n] for n in fit.fitted if n in truth},
                "fixed": [(f.name, f.value) for f in fit.fixed],
                "fitted_error": {i: fitted[i] for i in held_out},
                "true_error": {i: true[i] for i in held_out},
            }
        )
    return {
        "case": case,
        "uncalibrated": uncal,
        "fitted": fitted,
        "true": true,
        "true_no_slope": true_no_slope,
        "folds": folds,
        "errors": flight.errors,
        "wall_s": time.monotonic() - t0,
    }


# The fit object of the last run_calibrate call (the CLI prints it; the bench also wants the
# numbers): captured by wrapping calibrate_drone.
_last_fit: Any = None
_last_hover_thrust: Any = None
_last_hover_vbat: Any = None


def _capture_fits() -> None:
    import groundstation.recording.calibrate as cal
    from groundstation.calibration import hover_mask

    original = cal.calibrate_drone

    def wrapped(rec: Any, settings: Settings, **kw: Any) -> Any:
        global _last_fit, _last_hover_thrust, _last_hover_vbat
        fit = original(rec, settings, **kw)
        mask = hover_mask(rec.data, settings.for_drone(rec.drone).drone.mass_kg)
        _last_fit = fit
        _last_hover_thrust = rec.data.thrust_n[mask]
        _last_hover_vbat = rec.data.vbat_v[mask]
        return fit

    cal.calibrate_drone = wrapped  # type: ignore[assignment]


def _mean(d: dict[int, float]) -> float:
    return float(np.mean([v for v in d.values()]))


workdir_of_report: list[Path] = [Path(".")]


def _nanobench_rows() -> list[str]:
    from benchmarks import nanobench

    rows = []
    for name in nanobench.FILES:
        data, f, mask = nanobench.fit(name)
        v = data.vbat_v[mask]
        slope = (
            f"{f.values['vbat_slope_per_v']:.3f} ± {f.std['vbat_slope_per_v']:.3f}"
            if f.std["vbat_slope_per_v"] is not None
            else "fixed at 0 (undetermined)"
        )
        m = f.mean_after_n * 1e3
        where = (
            f"at {f.vbat_ref_v:g} V"
            if f.std["vbat_slope_per_v"] is not None
            else "at the flight's voltage"
        )
        rows.append(
            f"| {name.split('_rep')[0]} | {np.nanmin(v):.2f}–{np.nanmax(v):.2f} | "
            f"{f.values['thrust_scale']:.3f} ± {f.std['thrust_scale']:.3f} ({where}) | {slope} | "
            f"×{nanobench.reading_over_weight(data, f, mask):.2f}"
            f" at the median voltage | {m[0]:.1f} / {m[1]:.1f} / {m[2]:.1f} | "
            f"{f.rms_before_n[2] * 1e3:.0f} → {f.rms_after_n[2] * 1e3:.0f} | "
            f"{f.hover_samples} / {f.n_eff:.0f} |"
        )
    return rows


def write_doc(
    results: list[dict[str, Any]],
    quick: bool,
    dwell_s: float,
    seed: int,
    doc: Path = DOC,
) -> tuple[Path, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = doc.parent / "figures" / FIGURE.name
    figure.parent.mkdir(parents=True, exist_ok=True)
    names = [f"{r['case'].name}\n({r['case'].accel_noise_mps2:g} m/s²)" for r in results]
    x = np.arange(len(results))
    fig, ax = plt.subplots(figsize=(8, 4.4))
    for j, (key, label) in enumerate(
        (("uncalibrated", "uncalibrated"), ("fitted", "fitted (leave-one-out)"), ("true", "true"))
    ):
        vals = [100 * _mean(r[key]) for r in results]
        ax.bar(x + (j - 1) * 0.27, vals, 0.27, label=label)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("median position error, cm")
    ax.set_yscale("log")
    ax.set_title(
        "Tether-based position without motion capture, held-out spots\n"
        "(realistic simulator profile; error classes as labelled)",
        fontsize=9,
    )
    ax.legend(fontsize=8, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.22))
    fig.tight_layout()
    fig.savefig(figure, dpi=120)
    plt.close(fig)

    cmd = "python -m benchmarks.bench_calibration" + (" --quick" if quick else "")
    lines = [
        "# Calibration",
        "",
        "`groundstation calibrate FILE.mcap [FILE.mcap ...] [--config PATH] [--drone ID] "
        "[--fit-tether] --out PATH.toml` fits, per drone, the `[calibration]` of "
        "`groundstation/config.py` from recordings made by `groundstation record` with motion",
        "capture, and writes the input configuration plus `[drones.<id>.calibration]`.",
        "",
        "## Method (groundstation/calibration.py)",
        "",
        "- Observation model (eq:NE_tether with the corrections): `T = m·R·(a − b) − R·u·F`,",
        "  `F = thrust_n·(s + k·(vbat − v_ref))`, `u = R_x(about_x)·R_y(about_y)·e3`, against the",
        "  catenary's force at the motion-capture position (`catenary.tether_force`; the reel's",
        "  length and base, else the configuration's). Hover samples only: armed, thrust ≥ half",
        "  the weight, speed ≤ 0.1 m/s, acceleration ≤ 0.6 m/s², body rate ≤ 0.5 rad/s, 1 s away",
        "  from anything else, runs ≥ 1 s. Samples still and disarmed on the floor add",
        "  `R·m·(a − b) = (0, 0, m·g)` (the floor and the tether carry the weight).",
        "- Robust least squares: each world axis whitened by its robust scale, scipy",
        "  `least_squares` with a Huber loss, re-whitened and refitted. Standard errors: Huber's",
        "  M-estimator covariance times τ, the residuals' integrated autocorrelation time",
        "  (Sokal window): vibration and wobble are coloured, n_eff = n/τ.",
        "- What the data cannot tell apart. In the body frame the residual is",
        "  `m·(a − b) − s·F·u − Rᵀ·T_ref`: `b` enters as a constant, `s·u` times the nominal",
        "  thrust, the attitude not at all. So the z bias and the thrust scale are separated only",
        "  by the spread of the thrust, the x/y bias and the thrust axis likewise; samples at rest",
        "  separate them. A combination whose standard error exceeds half a typical magnitude",
        "  (scale 0.05, axis 0.02 rad, bias 0.2 m/s², slope 0.1/V, ω 0.01 N/m, base 5 cm) is",
        "  undetermined; the first of `CONVENTIONS` in it is fixed (z bias 0: the scale absorbs",
        "  m·b_z/F; axis 0: the x/y bias absorbs F·sin(a)/m; slope 0; tether as configured), and",
        "  the output says so. At the paper's spots the vertical tension differs little, so hover",
        "  alone fixes the z bias and the axis. Exact where it matters: at the calibration's",
        "  hover thrust the convention gives the same tension.",
        "- With `[calibration] rest = true` (default) the rest offsets the service would apply are",
        "  applied in the fit too; where they cover the hovers, the configured x/y bias has no",
        "  effect at run time, so it is kept and the thrust axis fitted instead.",
        "- Rest calibration (`RestCalibrator`, in the pipeline): while a drone is disarmed and",
        "  still for ≥ 1 s (gyro ≤ 0.05 rad/s, accelerometer within 0.15 m/s² of the window's",
        "  mean), `o = mean(a − b − Rᵀ·(0, 0, g))` (x, y) is added to the bias until the next",
        "  disarm; `status` reports it (`rest_calibration`). Assumption: the floor is what the",
        "  attitude says; an unseen tilt becomes an offset of g·tilt (0.17 m/s² per degree).",
        "",
        "## Real flights: NanoBench (untethered, true tension 0)",
        "",
        "The fit against the true tension, zero, on two real Crazyflie 2.1 flights (excerpts",
        "in tests/data/nanobench/, every 4th row; mass assumed 30 g; the attitude the drone",
        "reports; `benchmarks/nanobench.py`, asserted by tests/test_calibration_nanobench.py).",
        "The nominal PWM→thrust map of the data README over-reads by 1/scale:",
        "",
        "| flight | battery in flight V | thrust_scale | slope 1/V | map over-reads | residual"
        " mean x/y/z mN | RMS z before → after mN | n / n_eff |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *_nanobench_rows(),
        "",
        "## Leave-one-out on the realistic simulator",
        "",
        f"Numbers from `{cmd}` (seed {seed}, {dwell_s:g} s per spot); rerun it to reproduce.",
        "",
        "Each case is one flight of the realistic simulator profile touring the paper's six",
        "hover spots under motion capture, with the error classes named (the others off;",
        "vibration, battery sag, motor lag, rotor drag, yaw motion, IMU jitter and bursty motion",
        "capture always on). Three folds: four spots are recorded to MCAP and calibrated with",
        "`groundstation calibrate`'s code; the service's pipeline then re-estimates the flight",
        "with the written configuration and *without* motion capture, judged on the two",
        "held-out spots (median position error over the last 60 % of each dwell; every spot",
        "is held out once). `uncalibrated`: the default configuration. `true`: the simulator's",
        "drawn errors as their equivalent `[calibration]` (`Simulator.drawn_errors`);",
        "`true, no slope`: the same without its battery slope. The filter's `[drone]",
        "accel_noise_mps2` is set to the case's vibration level in all three.",
        "",
        "### Position error, held-out spots (mean over the six spots of the per-spot median)",
        "",
        "| case | accel noise m/s² | uncalibrated cm | fitted cm | true cm | true, no slope cm "
        "| fitted / true |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in results:
        u, f, t = _mean(r["uncalibrated"]), _mean(r["fitted"]), _mean(r["true"])
        ns = _mean(r["true_no_slope"])
        lines.append(
            f"| {r['case'].name} | {r['case'].accel_noise_mps2:g} | {100 * u:.1f} | "
            f"{100 * f:.1f} | {100 * t:.1f} | {100 * ns:.1f} | {f / t:.2f} |"
        )
    lines += [
        "",
        "Per fold (held-out spots: fitted / true, cm):",
        "",
    ]
    for r in results:
        parts = []
        for fold in r["folds"]:
            spots = ",".join(str(i + 1) for i in fold["held_out"])
            fe = np.mean(list(fold["fitted_error"].values()))
            te = np.mean(list(fold["true_error"].values()))
            parts.append(f"spots {spots}: {100 * fe:.1f} / {100 * te:.1f}")
        lines.append(f"- {r['case'].name}: " + "; ".join(parts))
    lines += [
        "",
        f"![position error before/after calibration]({figure.relative_to(doc.parent)})",
        "",
        "## Fitted parameters against the drawn truth",
        "",
        "z = (fitted − truth) / standard error, truth mapped to the fit's convention where a",
        "parameter was fixed (z bias 0: the scale absorbs m·b_z/F; axis 0: the x/y bias absorbs",
        "F·sin(a)/m). Target: |z| ≤ 2 for every fitted parameter.",
        "",
        "| case | fold (calibration spots) | fixed | z per fitted parameter |",
        "| --- | --- | --- | --- |",
    ]
    within = total = 0
    for r in results:
        for fold in r["folds"]:
            zs = ", ".join(f"{n} {z:+.1f}" for n, z in fold["z"].items())
            within += sum(abs(z) <= 2 for z in fold["z"].values())
            total += len(fold["z"])
            fixed = ", ".join(n for n, _ in fold["fixed"]) or "none"
            spots = ",".join(str(i + 1) for i in fold["spots"])
            lines.append(f"| {r['case'].name} | {spots} | {fixed} | {zs} |")
    lines += [
        "",
        f"Within 2 standard errors: {within} of {total} fitted parameters.",
        "",
        "## Targets",
        "",
    ]
    for r in results:
        f, t = _mean(r["fitted"]), _mean(r["true"])
        ok = "met" if f <= 1.2 * t else "NOT met"
        lines.append(
            f"- {r['case'].name}: fitted position error {100 * f:.1f} cm vs true {100 * t:.1f} cm"
            f" (ratio {f / t:.2f}, target ≤ 1.2: {ok})."
        )
        slope_fixed = [fd for fd in r["folds"] if "vbat_slope_per_v" not in fd["values"]]
        if f > 1.2 * t and slope_fixed:
            lines.append(
                f"  Why: in {len(slope_fixed)} of 3 folds the battery slope was not determined"
                " by the calibration spots (their voltage spans a few hundredths of a volt; at"
                " this vibration level that does not pin it) and the fit fixed it at 0, as it"
                " printed; the held-out spots fly at other voltages. The true calibration"
                f" without its slope errs by {100 * _mean(r['true_no_slope']):.1f} cm."
            )
    lines += [
        f"- Parameters within 2 standard errors: {within}/{total}"
        + (" (target: all: met)." if within == total else " (target: all: NOT met)."),
        "",
        "## One fold's report, as `groundstation calibrate` prints it",
        "",
        "```",
        results[0]["folds"][0]["report"].replace(str(workdir_of_report[0]) + "/", ""),
        "```",
        "",
    ]
    doc.write_text("\n".join(lines), encoding="utf-8")
    return doc, figure


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two cases, 8 s per spot")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument(
        "--doc", type=Path, default=DOC, help="page to write (figure in figures/ beside it)"
    )
    args = ap.parse_args(argv)
    _capture_fits()
    if args.quick:
        dwell = 8.0
        cases = [Case("all classes", ALL_CLASSES, 1.0), Case("all, low noise", ALL_CLASSES, 0.2)]
    else:
        dwell = 12.0
        cases = [
            Case("all classes", ALL_CLASSES, 1.0),
            Case("all, low noise", ALL_CLASSES, 0.2),
            Case("thrust map", ("thrust_map",), 1.0),
            Case("thrust axis", ("thrust_axis",), 1.0),
            Case("accelerometer", ACCEL, 1.0),
        ]
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        workdir_of_report[0] = Path(tmp)
        for case in cases:
            r = run_case(case, dwell, args.seed, Path(tmp))
            results.append(r)
            print(
                f"{case.name}: uncalibrated {100 * _mean(r['uncalibrated']):.1f} cm, fitted "
                f"{100 * _mean(r['fitted']):.1f} cm, true {100 * _mean(r['true']):.1f} cm "
                f"({r['wall_s']:.0f} s)",
                flush=True,
            )
    doc, figure = write_doc(results, args.quick, dwell, args.seed, args.doc)
    print(f"wrote {doc} and {figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
