"""Where the attitude comes from: the drone's own estimator or motion capture, on real flights.

NanoBench (../shared/data/nanobench, BSD-3; real untethered Crazyflie 2.1 flights, true
tension zero) recorded twice: with the onboard attitude (``att_stateEstimate_q*``, levelled
on the same accelerometer the observation reads) and with Vicon's (``qw,qx,qy,qz``: a rigid
body defined by the markers, not by the thrust axis). Calibrated with ``groundstation
calibrate --untethered`` on two days, judged on the third (as docs/nanobench_cli.md), served
without motion-capture position by ``groundstation replay --offline``, in the models the
estimator can use: the hover model's slow part ``m·g·e3 − R·u·F`` (``[calibration]
accel_slow = true``, which trusts the attitude) or the accelerometer model ``m·R·f − R·u·F``
(``accel_slow = false``, in which a tilt of the attitude enters both terms and cancels).
Per held-out flight: the median |T| of the Estimates in the air, mN.

The estimator chooses between them by the attitude's source (Telemetry ``attitude_source``,
``onboard`` for the drone's own, ``external`` for Vicon's, as the Crazyflie bridge writes
it) against the source the calibration's thrust axis was fitted with (``[calibration]
attitude_source``, written by ``calibrate``): the hover model where they are the same, the
accelerometer model where they differ. The rows force each model where it would not be chosen.

Run:  python -m benchmarks.attitude_source [--out docs/attitude_source.md] [--data DIR]

With ``--out docs/attitude_source.md`` the figures also go to ``docs/attitude_source.json``
(:mod:`benchmarks.figures`); the page's text after its table (from its first ``## `` heading
on) is kept as written by hand, and quotes the figures through markers.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.figures import AT_START, DOCS, kept_reading, write_figures
from benchmarks.nanobench_cli import (
    AIR_MIN_Z_M,
    CONFIG,
    DATA,
    DAYS,
    G0,
    Flight,
    _run,
    nominal_thrust_n,
    score,
)
from groundstation.recording.reader import RecordedMessage, copy_messages

ATTITUDES = ("onboard", "vicon")


def load(name: str, attitude: str, data_dir: Path) -> Flight:
    """A flight's Telemetry with the chosen attitude, ``onboard`` or ``vicon``."""
    a = np.genfromtxt(data_dir / f"{name}.csv", delimiter=",", names=True)
    pwm = np.stack([a[f"motor_motor_m{i}"] for i in range(1, 5)], axis=1)
    thrust = nominal_thrust_n(pwm)
    acc = np.stack([a[f"imu_acc_{k}"] for k in "xyz"], 1) * G0
    gyro = np.stack([a[f"imu_gyro_{k}"] for k in "xyz"], 1)
    if attitude == "onboard":
        quat = np.stack([a[f"att_stateEstimate_q{k}"] for k in "wxyz"], 1)
    else:
        quat = np.stack([a[f"q{k}"] for k in "wxyz"], 1)  # the file is scalar-last: reorder
    quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
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
            "attitude_source": "onboard" if attitude == "onboard" else "external",
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


def _write(msgs: list[RecordedMessage], path: Path) -> Path:
    if not path.exists():
        copy_messages(msgs, path)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="write the markdown page here")
    ap.add_argument("--data", default=str(DATA), help="the NanoBench directory")
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not data.is_dir():
        ap.error(f"--data {data}: no such directory (the NanoBench flights; see its README)")
    t0 = time.time()
    flights = {(n, att): load(n, att, data) for n in DAYS for att in ATTITUDES}
    days = sorted(set(DAYS.values()))
    # (label, attitude calibrated with, attitude served with, change to the calibration)
    variants = [
        ("onboard, calibrated onboard (hover model)", "onboard", "onboard", ""),
        ("onboard, calibrated onboard, accel_slow = false", "onboard", "onboard", "off"),
        ("Vicon, calibrated Vicon (hover model)", "vicon", "vicon", ""),
        ("Vicon, calibrated Vicon, accel_slow = false", "vicon", "vicon", "off"),
        (
            "Vicon, calibrated onboard (the sources differ: accelerometer model)",
            "onboard",
            "vicon",
            "",
        ),
        (
            "Vicon, calibrated onboard, hover model forced (the calibration relabelled "
            '`attitude_source = "external"`)',
            "onboard",
            "vicon",
            "relabel",
        ),
    ]
    keys = (
        "onboard_hover",
        "onboard_accel",
        "vicon_hover",
        "vicon_accel",
        "vicon_cal_onboard",
        "vicon_cal_onboard_hover_forced",
    )
    per: dict[str, list[tuple[str, str, float]]] = {v[0]: [] for v in variants}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        base = work / "base.toml"
        base.write_text(CONFIG)
        for day in days:
            train = [n for n in DAYS if DAYS[n] != day]
            held = [n for n in DAYS if DAYS[n] == day]
            cals: dict[str, Path] = {}
            for att in ATTITUDES:
                files = [
                    str(_write(flights[(n, att)].with_mocap, work / f"{n}-{att}-m.mcap"))
                    for n in train
                ]
                out = work / f"cal-{day}-{att}.toml"
                rc, text = _run(
                    ["calibrate", *files, "--untethered", "--config", str(base), "--out", str(out)]
                )
                if rc != 0:
                    raise RuntimeError(f"calibrate failed ({rc}): {text}")
                cals[att] = out
            for label, cal_att, serve_att, mode in variants:
                cfg = cals[cal_att]
                if mode:
                    old, new = {
                        "off": ("accel_slow = true", "accel_slow = false"),
                        "relabel": ('attitude_source = "onboard"', 'attitude_source = "external"'),
                    }[mode]
                    text = cfg.read_text()
                    if old not in text:
                        raise RuntimeError(f"{cfg}: no {old} to change")
                    cfg = work / f"cal-{day}-{cal_att}-{mode}.toml"
                    cfg.write_text(text.replace(old, new))
                for n in held:
                    f = flights[(n, serve_att)]
                    rec = _write(f.without_mocap, work / f"{n}-{serve_att}-n.mcap")
                    est = work / f"est-{n}-{abs(hash(label)) % 10**8}.mcap"
                    replay = ["replay", "--offline", str(rec), "--config", str(cfg)]
                    rc, text = _run([*replay, "--out", str(est), "--force"])
                    if rc != 0:
                        raise RuntimeError(f"replay failed ({rc}): {text}")
                    per[label].append((day, n, score(f, est).median_abs_t_mn))
    lines = [
        "# Where the attitude comes from: onboard or motion capture (NanoBench)",
        "",
        "`python -m benchmarks.attitude_source --out docs/attitude_source.md` (this page and "
        f"its figures, docs/attitude_source.json; {time.time() - t0:.0f} s at commit "
        f"{AT_START.commit}; data: ../shared/data/nanobench, six flights, "
        "B6_linear_ramp_rep1 left out; the configuration of docs/nanobench_cli.md, "
        '`thrust_model = "motor_voltage"`). Calibrated with `calibrate --untethered` on two '
        "days with the attitude named, judged on the third day's flights served without "
        "motion-capture position. Truth: zero tension; median |T| in the air per flight, mN "
        "(flights in the order of the folds: day 2026-03-02, 03-04, 03-05).",
        "",
        "| attitude served, calibration | median of flights mN | worst flight mN | flights |",
        "| --- | ---: | ---: | --- |",
    ]
    figures: dict[str, dict[str, object]] = {}
    for key, (label, *_) in zip(keys, variants, strict=True):
        vals = [v for _, _, v in per[label]]
        figures[key] = {
            "label": label,
            "median_mn": statistics.median(vals),
            "worst_mn": max(vals),
            "flights_mn": [[n, v] for _, n, v in per[label]],
        }
        flights_txt = ", ".join(f"{v:.1f}" for _, _, v in per[label])
        lines.append(
            f"| {label} | {statistics.median(vals):.1f} | {max(vals):.1f} | {flights_txt} |"
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        out = Path(args.out)
        text += kept_reading(out, "\n## ")  # the analysis below the table
        out.write_text(text, encoding="utf-8")
        if out.resolve() == DOCS / "attitude_source.md":
            write_figures("attitude_source", figures, ["--out", "docs/attitude_source.md"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
