"""NanoBench through the command line: record → ``calibrate --untethered`` → serve without mocap.

Real untethered Crazyflie 2.1 flights (../shared/data/nanobench, BSD-3; true tension zero).
Each flight becomes a recording of Telemetry as ``groundstation record`` writes it
(accel = imu_acc·9.80665, gyro, the onboard attitude, thrust = the nominal PWM map summed
over motor_motor_m1..m4, vbat; mass 30 g assumed), once with the Vicon position
(``position_m``, for calibration) and once without (to serve). ``groundstation calibrate
--untethered`` runs on some flights; ``groundstation replay --offline`` (the service's own
pipeline) re-estimates the others without motion capture. Per held-out flight: the median
|T| of the Estimates in the air (the truth is zero), the share of Telemetry answered by an
Estimate, the share of airborne rows not flagged ``on_ground``, and the share of airborne
per-axis tensions within twice their published σ (``tension_std_n``).

``B6_linear_ramp_rep1`` is left out (a ground-effect hover at 0.07–0.2 m; the data README).

Run:  python -m benchmarks.nanobench_cli --out docs/nanobench_cli.md [--data DIR]

The flights are not in the repository: ``--data`` names the directory of the NanoBench CSV
files, by default ``../shared/data/nanobench`` beside the repository. With ``--out
docs/nanobench_cli.md`` the figures also go to ``docs/nanobench_cli.json``
(:mod:`benchmarks.figures`).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.figures import AT_START, DOCS, write_figures
from groundstation.cli import main as gs_main
from groundstation.recording.reader import RecordedMessage, copy_messages, iter_messages

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "nanobench"
G0 = 9.80665
MASS_KG = 0.030
DAYS = {
    "B2_circle_slow_rep1": "2026-03-02",
    "B3_figure8_fast_rep1": "2026-03-02",
    "B6_linear_ramp_rep3": "2026-03-04",
    "B2_circle_medium_rep2": "2026-03-05",
    "B8_star_fast_rep2": "2026-03-05",
    "B5_helix_medium_rep3": "2026-03-05",
}
AIR_MIN_Z_M = 0.25
CONFIG = """\
[drone]
mass_kg = 0.030

[calibration]
thrust_vbat_ref_v = 3.5
thrust_model = "motor_voltage"
"""
"""The configuration calibrated from: config/crazyflie.toml's choices for these flights (30 g,
the battery model that holds below the calibrated voltages, docs/battery_model.md)."""


def nominal_thrust_n(pwm: np.ndarray) -> np.ndarray:
    """The nominal per-motor PWM→thrust map of the data README, summed, N."""
    per_motor = 2.130295e-11 * pwm**2 + 1.032633e-6 * pwm + 5.484560e-4
    return np.where(pwm > 0, per_motor, 0.0).sum(axis=1)


@dataclass(frozen=True)
class Flight:
    name: str
    stamp_s: np.ndarray
    airborne: np.ndarray
    """Truth: motors on and Vicon height above AIR_MIN_Z_M."""
    with_mocap: list[RecordedMessage]
    without_mocap: list[RecordedMessage]


def load(
    name: str,
    data_dir: Path = DATA,
    thrust_n: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> Flight:
    """One flight as recordings; ``thrust_n(pwm (n, 4), vbat (n,))`` makes Telemetry's
    thrust (None: :func:`nominal_thrust_n`, the bridge's default PWM map)."""
    a = np.genfromtxt(data_dir / f"{name}.csv", delimiter=",", names=True)
    pwm = np.stack([a[f"motor_motor_m{i}"] for i in range(1, 5)], axis=1)
    thrust = nominal_thrust_n(pwm) if thrust_n is None else thrust_n(pwm, a["pwr_pm_vbat"])
    acc = np.stack([a[f"imu_acc_{k}"] for k in "xyz"], 1) * G0
    gyro = np.stack([a[f"imu_gyro_{k}"] for k in "xyz"], 1)
    quat = np.stack([a[f"att_stateEstimate_q{k}"] for k in "wxyz"], 1)
    pos = np.stack([a["px"], a["py"], a["pz"]], 1)
    vbat = a["pwr_pm_vbat"]
    armed = pwm.max(axis=1) > 0
    t = a["t"]
    ok = np.all(np.isfinite(acc), 1) & np.all(np.isfinite(quat), 1) & np.isfinite(thrust)
    with_m: list[RecordedMessage] = []
    without: list[RecordedMessage] = []
    for seq, i in enumerate(np.flatnonzero(ok).tolist()):
        body = {
            "seq": seq,
            "stamp_s": float(t[i]),
            "accel_mps2": acc[i].tolist(),
            "quat_wxyz": quat[i].tolist(),
            "thrust_n": float(thrust[i]),
            "gyro_rps": gyro[i].tolist(),
            "armed": bool(armed[i]),
            **({"vbat_v": float(vbat[i])} if np.isfinite(vbat[i]) and vbat[i] > 0 else {}),
        }
        t_ns = round(float(t[i]) * 1e9)
        key = "tether/cf1/telemetry"
        without.append(RecordedMessage(key, json.dumps(body).encode(), t_ns, t_ns))
        if np.all(np.isfinite(pos[i])):
            body["position_m"] = pos[i].tolist()
        with_m.append(RecordedMessage(key, json.dumps(body).encode(), t_ns, t_ns))
    air = armed & (pos[:, 2] > AIR_MIN_Z_M)
    return Flight(name, t[ok], air[ok], with_m, without)


def _run(argv: list[str]) -> tuple[int, str]:
    """The CLI's exit code and what it printed: standard output, then standard error (where
    a refusal's reason goes)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = gs_main(argv)
    return rc, out.getvalue() + err.getvalue()


@dataclass(frozen=True)
class Judged:
    flight: str
    median_abs_t_mn: float
    answered: float
    airborne_not_on_ground: float
    within_2_sigma: float = math.nan
    """Share of the airborne per-axis tensions within twice their published σ (truth zero;
    a consistent σ: about 95 %)."""


def judge(flight: Flight, config: Path, work: Path) -> Judged:
    """Serve ``flight`` without motion capture (offline replay through the pipeline)."""
    rec = work / f"{flight.name}-nomocap.mcap"
    if not rec.exists():
        copy_messages(flight.without_mocap, rec)
    out = work / f"{flight.name}-{config.stem}-est.mcap"
    # The same flight is judged with the same configuration in more than one fold: --force.
    replay = ["replay", "--offline", str(rec), "--config", str(config)]
    rc, text = _run([*replay, "--out", str(out), "--force"])
    if rc != 0:
        raise RuntimeError(f"replay --offline failed ({rc}): {text}")
    return score(flight, out)


def score(flight: Flight, out: Path) -> Judged:
    """The measure of one held-out flight from a recording of its Estimates."""
    by_stamp: dict[float, dict] = {}
    for m in iter_messages(out):
        if m.key == "tether/cf1/estimate":
            est = json.loads(m.payload)
            by_stamp[round(est["stamp_s"], 6)] = est
    norms, air_ok, air_n, inside, axes = [], 0, 0, 0, 0
    for t, air in zip(flight.stamp_s.tolist(), flight.airborne.tolist(), strict=True):
        est = by_stamp.get(round(t, 6))
        if not air:
            continue
        air_n += 1
        if est is None:
            continue
        if not est["on_ground"]:
            air_ok += 1
            norms.append(float(np.linalg.norm(est["tension_n"])))
            for t_n, std_n in zip(est["tension_n"], est["tension_std_n"], strict=True):
                inside += abs(t_n) <= 2.0 * std_n
                axes += 1
    return Judged(
        flight.name,
        1e3 * float(np.median(norms)) if norms else float("nan"),
        len(by_stamp) / flight.stamp_s.size,
        air_ok / max(air_n, 1),
        inside / axes if axes else math.nan,
    )


def calibrate(train: list[Flight], work: Path, tag: str, extra: list[str]) -> tuple[Path, str]:
    base = work / "base.toml"
    base.write_text(CONFIG)
    files = []
    for f in train:
        p = work / f"{f.name}-mocap.mcap"
        if not p.exists():
            copy_messages(f.with_mocap, p)
        files.append(str(p))
    out = work / f"cal-{tag}.toml"
    # Variants that share the calibration share its file: --force.
    argv = ["calibrate", *files, "--untethered", "--config", str(base), "--out", str(out)]
    rc, text = _run([*argv, "--force", *extra])
    if rc != 0:
        raise RuntimeError(f"calibrate failed ({rc}): {text}")
    return out, text


HOVER_VELOCITY_DEFAULT = "# hover_velocity_* removed\n"
"""A variant's marker: the calibration without its fitted σ_v and T_c."""


def variant_config(src: Path, dst: Path, extra_toml: str) -> Path:
    """``src`` with ``extra_toml`` appended, except ``accel_slow = false``, which replaces the
    calibration's own ``accel_slow = true``, and ``HOVER_VELOCITY_DEFAULT``, which removes the
    calibration's ``hover_velocity_*`` (the filter's defaults then)."""
    text = src.read_text()
    if extra_toml == HOVER_VELOCITY_DEFAULT:
        dst.write_text(re.sub(r"(?m)^hover_velocity_(std_mps|time_s) = .*\n", "", text))
    elif extra_toml.strip() == "accel_slow = false":
        if "accel_slow = true" not in text:
            raise RuntimeError(f"{src}: no accel_slow = true to turn off")
        dst.write_text(text.replace("accel_slow = true", "accel_slow = false"))
    elif extra_toml.strip() == "rotor_drag_n_s_per_m = 0.0":
        new, n = re.subn(r"(?m)^rotor_drag_n_s_per_m = .*$", "rotor_drag_n_s_per_m = 0.0", text)
        if n != 1:
            raise RuntimeError(f"{src}: no rotor_drag_n_s_per_m to zero")
        dst.write_text(new)
    else:
        dst.write_text(text + "\n" + extra_toml)
    return dst


def check_data(ap: argparse.ArgumentParser, data: Path) -> None:
    """Exit with a usage error naming ``--data`` when the flights are not in ``data``."""
    missing = [f"{n}.csv" for n in DAYS if not (data / f"{n}.csv").is_file()]
    if missing:
        what = "missing " + ", ".join(missing) if data.is_dir() else "no such directory"
        ap.error(
            f"--data {data}: {what}. The NanoBench flights are not in the repository: "
            "pass --data DIR, the directory of their CSV files (../shared/data/nanobench "
            "beside the repository on the project's machines)"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="write the markdown page here")
    ap.add_argument(
        "--data",
        type=Path,
        default=DATA,
        help="the directory of the NanoBench CSV files (default: ../shared/data/nanobench "
        "beside the repository)",
    )
    args = ap.parse_args(argv)
    check_data(ap, args.data)
    t0 = time.time()
    flights = {n: load(n, args.data) for n in DAYS}
    lines: list[str] = []
    say = lines.append
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        base = work / "base.toml"
        base.write_text(CONFIG)
        folds: list[tuple[str, list[str], list[str]]] = []
        days = sorted(set(DAYS.values()))
        for d in days:
            held = [n for n in DAYS if DAYS[n] == d]
            folds.append((f"day {d} held out", [n for n in DAYS if n not in held], held))
        for n in DAYS:
            folds.append((f"{n} held out", [m for m in DAYS if m != n], [n]))
        variants = [
            ("uncalibrated", None, ""),
            ("full model (--model full)", ["--model", "full"], ""),
            (
                "airframe, accelerometer mean trusted",
                [],
                "accel_slow = false\n",
            ),
            (
                "airframe + slow accelerometer, rotor drag not applied",
                [],
                "rotor_drag_n_s_per_m = 0.0\n",
            ),
            ("airframe + slow accelerometer (default)", [], ""),
            (
                "airframe + slow accelerometer, the filter's σ_v and T_c (the calibration's "
                "fitted `hover_velocity_std_mps` / `hover_velocity_time_s` removed)",
                [],
                HOVER_VELOCITY_DEFAULT,
            ),
        ]
        results: dict[str, dict[str, list[Judged]]] = {v[0]: {} for v in variants}
        keys = (
            "uncalibrated",
            "full",
            "mean_trusted",
            "no_rotor_drag",
            "default",
            "hover_velocity_default",
        )
        figures: dict[str, dict[str, Any]] = {}
        reports: dict[str, str] = {}
        refused: dict[str, str] = {}
        for fold, train, held in folds:
            for index, (label, extra, toml) in enumerate(variants):
                if extra is None:
                    cfg = base
                else:
                    tag = f"{abs(hash((fold, tuple(extra)))) % 10**8}"
                    try:
                        cal, report = calibrate([flights[n] for n in train], work, tag, extra)
                    except RuntimeError as exc:
                        said = [x for x in str(exc).splitlines() if x.strip()]
                        refused[label] = said[-1] if said else str(exc)
                        continue
                    if label.endswith("(default)"):
                        reports[fold] = report
                    cfg = variant_config(cal, work / f"v-{tag}-{index}.toml", toml)
                results[label][fold] = [judge(flights[n], cfg, work) for n in held]
        say("# NanoBench through the command line (real untethered Crazyflie flights)")
        say("")
        say(
            "`python -m benchmarks.nanobench_cli --out docs/nanobench_cli.md` (this page and "
            f"its figures, docs/nanobench_cli.json; {time.time() - t0:.0f} s at commit "
            f"{AT_START.commit}). The flights are not in the repository: `--data DIR` names the "
            "directory of the NanoBench CSV files (default `../shared/data/nanobench`, beside "
            "the repository; its README says where they come from). "
            "Six shared flights (B6_linear_ramp_rep1 left out), "
            "recorded as Telemetry with Vicon `position_m`, calibrated with `groundstation "
            "calibrate --untethered`, served without motion capture by `groundstation replay "
            "--offline` (the service's pipeline). Truth: zero tension. Per held-out flight: "
            "median |T| of the Estimates in the air (mN); answered = share of Telemetry with an "
            "Estimate; airborne = share of airborne rows (motors on, Vicon z > 0.25 m) not "
            "`on_ground`; within 2σ = share of their per-axis tensions within twice the "
            "published `tension_std_n` (a consistent σ: about 95 %)."
        )
        say("")
        for label, _, _ in variants:
            say(f"## {label}")
            say("")
            key = keys[[v[0] for v in variants].index(label)]
            figures[key] = {"label": label}
            if label in refused:
                figures[key]["refused"] = refused[label].replace(f"{work}/", "")
                say(f"calibrate refused: `{refused[label]}`")
                say("")
                say(
                    "(The full model fits the accelerometer's bias from steady hovers under "
                    "motion capture; these flights are trajectories with none.)"
                )
                say("")
                continue
            say("| fold | flight | median abs T mN | answered | airborne | within 2σ |")
            say("| --- | --- | ---: | ---: | ---: | ---: |")
            loo = []
            for fold, _, _ in folds:
                for j in results[label][fold]:
                    figures[key].setdefault("rows", []).append(
                        [
                            fold,
                            j.flight,
                            j.median_abs_t_mn,
                            j.answered,
                            j.airborne_not_on_ground,
                            j.within_2_sigma,
                        ]
                    )
                    say(
                        f"| {fold} | {j.flight} | {j.median_abs_t_mn:.1f} | "
                        f"{100 * j.answered:.1f} % | {100 * j.airborne_not_on_ground:.1f} % | "
                        f"{100 * j.within_2_sigma:.0f} % |"
                    )
                    if fold.endswith("held out") and not fold.startswith("day"):
                        loo.append(j.median_abs_t_mn)
            cross = [
                j.median_abs_t_mn
                for fold, _, _ in folds
                if fold.startswith("day")
                for j in results[label][fold]
            ]
            cover = [
                j.within_2_sigma
                for fold, _, _ in folds
                if fold.startswith("day")
                for j in results[label][fold]
            ]
            figures[key].update(
                cross_day_median_mn=statistics.median(cross),
                cross_day_worst_mn=max(cross),
                leave_one_out_median_mn=statistics.median(loo),
                leave_one_out_worst_mn=max(loo),
                cross_day_within_2_sigma=statistics.median(cover),
            )
            say("")
            say(
                f"Cross-day: median over flights {statistics.median(cross):.1f} mN, worst "
                f"{max(cross):.1f}; leave-one-out: median {statistics.median(loo):.1f}, worst "
                f"{max(loo):.1f}. The published σ holds the truth within 2σ per axis in "
                f"{100 * statistics.median(cover):.0f} % of the airborne samples (median over "
                "the cross-day flights; a consistent σ: about 95 %)."
            )
            say("")
        say("## What calibrate printed (default model, one fold per held-out day)")
        say("")
        for fold, text in reports.items():
            if fold.startswith("day"):
                say(f"{fold}:")
                say("```")
                say(text.strip())
                say("```")
    page = "\n".join(lines).replace(f"{work}/", "") + "\n"  # the file names alone
    if args.out:
        Path(args.out).write_text(page, encoding="utf-8")
        if Path(args.out).resolve() == DOCS / "nanobench_cli.md":
            write_figures("nanobench_cli", figures, ["--out", "docs/nanobench_cli.md"])
    sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
