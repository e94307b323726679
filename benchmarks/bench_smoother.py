"""Post-flight smoothing: `replay --offline`'s forward-backward (RTS) tension vs the causal one.

Two kinds of data, each compared with its truth:

- the realistic simulator (``benchmarks.bench_powerons``' flight: 2 s on the floor, spool-up,
  climb, four paper spots 15 s each; attitude levelled on the accelerometer, 0.8 m/s² of
  vibration), calibration = the flight's own airframe constants, no motion capture: tension
  RMSE and position error in the dwells (from 5 s after each spot is commanded) and in the
  first 2 s after each spot is commanded (where the causal filter lags);
- real untethered Crazyflie flights (NanoBench, true tension zero), calibrated with
  ``calibrate --untethered`` on the other days' flights, no motion capture: the median |T| in
  the air.

Both through ``groundstation.recording.replay.replay_offline`` (what ``replay --offline`` runs).

Run:  python -m benchmarks.bench_smoother [--seeds 2] [--out docs/smoother.md]

With ``--out docs/smoother.md`` the figures also go to ``docs/smoother.json``
(:mod:`benchmarks.figures`), and the page's reading below its tables, written by hand, is kept.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import bench_powerons as bp
from benchmarks import nanobench_cli as nb
from benchmarks.figures import AT_START, DOCS, kept_reading, write_figures
from groundstation.config import load_settings
from groundstation.pipeline import Pipeline
from groundstation.recording.reader import copy_messages, iter_messages
from groundstation.recording.replay import replay_offline


def _outputs(path: Path) -> tuple[dict[int, dict[str, Any]], dict[int, dict[str, Any]]]:
    causal: dict[int, dict[str, Any]] = {}
    smoothed: dict[int, dict[str, Any]] = {}
    for m in iter_messages(path):
        if m.key.endswith("/estimate"):
            e = json.loads(m.payload)
            causal[e["seq"]] = e
        elif m.key.endswith("/estimate_smoothed"):
            e = json.loads(m.payload)
            smoothed[e["seq"]] = e
    return causal, smoothed


def simulated(seeds: list[int], work: Path) -> dict[str, dict[str, float]]:
    """Per window kind: tension RMSE (mN) and position median (cm), causal and smoothed."""
    acc: dict[str, dict[str, list[float]]] = {
        w: {"tc": [], "ts": [], "pc": [], "ps": []} for w in ("dwell", "after a move")
    }
    for seed in seeds:
        rec = bp.record(seed, 0.8, mocap=False, levelled=True)
        path = work / f"sim{seed}.mcap"
        copy_messages(rec.messages, path)
        cal = {**rec.errors["airframe_equivalent"], "source": "truth"}
        out = work / f"sim{seed}-out.mcap"
        replay_offline(
            path, out, Pipeline(load_settings(None, {"calibration": cal}, use_env=False))
        )
        causal, smoothed = _outputs(out)
        moves = [(a - bp.SETTLE_S, a - bp.SETTLE_S + 2.0) for a, _ in rec.judged_from_s]
        for seq, e in causal.items():
            s = smoothed.get(seq)
            tr = rec.truth.get(round(e["stamp_s"], 6))
            if s is None or tr is None or e["on_ground"]:
                continue
            t = e["stamp_s"]
            if any(a <= t < b for a, b in rec.judged_from_s):
                kind = "dwell"
            elif any(a <= t < b for a, b in moves):
                kind = "after a move"
            else:
                continue
            d = acc[kind]
            d["tc"].append(float(np.sum(np.subtract(e["tension_n"], tr["tension_n"]) ** 2)))
            d["ts"].append(float(np.sum(np.subtract(s["tension_n"], tr["tension_n"]) ** 2)))
            for key, est in (("pc", e), ("ps", s)):
                p = est["position_m"]
                d[key].append(
                    float("inf")
                    if p is None
                    else float(np.linalg.norm(np.subtract(p, tr["position_m"])))
                )
    out: dict[str, dict[str, float]] = {}
    for kind, d in acc.items():
        out[kind] = {
            "tension_rmse_causal_mn": 1e3 * float(np.sqrt(np.mean(d["tc"]) / 3)),
            "tension_rmse_smoothed_mn": 1e3 * float(np.sqrt(np.mean(d["ts"]) / 3)),
            "position_median_causal_cm": 100 * float(np.median(d["pc"])),
            "position_median_smoothed_cm": 100 * float(np.median(d["ps"])),
            "position_p95_causal_cm": 100 * float(np.percentile(d["pc"], 95)),
            "position_p95_smoothed_cm": 100 * float(np.percentile(d["ps"], 95)),
            "samples": float(len(d["tc"])),
        }
    return out


def real(work: Path) -> list[tuple[str, float, float]]:
    """Per held-out NanoBench flight (cross-day): median |T| in the air, causal and smoothed."""
    flights = {n: nb.load(n) for n in nb.DAYS}
    (work / "base.toml").write_text(nb.CONFIG)
    rows = []
    for day in sorted(set(nb.DAYS.values())):
        held = [n for n in nb.DAYS if nb.DAYS[n] == day]
        cal, _ = nb.calibrate([flights[n] for n in nb.DAYS if n not in held], work, f"d{day}", [])
        for n in held:
            f = flights[n]
            path = work / f"{n}-nomocap.mcap"
            copy_messages(f.without_mocap, path)
            out = work / f"{n}-out.mcap"
            replay_offline(path, out, Pipeline(load_settings(cal, use_env=False)))
            causal, smoothed = _outputs(out)
            by_stamp = {round(e["stamp_s"], 6): seq for seq, e in causal.items()}
            nc, ns = [], []
            for t, air in zip(f.stamp_s.tolist(), f.airborne.tolist(), strict=True):
                seq = by_stamp.get(round(t, 6))
                if not air or seq is None or causal[seq]["on_ground"] or seq not in smoothed:
                    continue
                nc.append(float(np.linalg.norm(causal[seq]["tension_n"])))
                ns.append(float(np.linalg.norm(smoothed[seq]["tension_n"])))
            rows.append((n, 1e3 * float(np.median(nc)), 1e3 * float(np.median(ns))))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2, help="simulated flights (seeds 11..)")
    ap.add_argument("--out", help="write the markdown page here")
    args = ap.parse_args(argv)
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        sim = simulated(list(range(11, 11 + args.seeds)), work)
        rows = real(work)
    lines = [
        "# Post-flight smoothing (replay --offline)",
        "",
        f"`python -m benchmarks.bench_smoother --seeds {args.seeds} --out docs/smoother.md` "
        f"(this page and its figures, docs/smoother.json; {time.time() - t0:.0f} s at commit "
        f"{AT_START.commit}). "
        "`replay --offline` writes, beside each Estimate, `tether/{drone}/estimate_smoothed`: "
        "the tension filter's own steps run forward and backward (filterpy's `rts_smoother`, "
        "regimes cut at resets and detected tugs; groundstation/smoother.py) and the catenary "
        "position of the result. Method and data: the module docstring of "
        "`benchmarks/bench_smoother.py`.",
        "",
        "## Realistic simulator (calibration = truth, no motion capture)",
        "",
        "| window | samples | tension RMSE causal / smoothed, mN | position median causal / "
        "smoothed, cm | p95 causal / smoothed, cm |",
        "| --- | ---: | --- | --- | --- |",
    ]
    for kind, r in sim.items():
        lines.append(
            f"| {kind} | {r['samples']:.0f} | {r['tension_rmse_causal_mn']:.2f} / "
            f"{r['tension_rmse_smoothed_mn']:.2f} | {r['position_median_causal_cm']:.1f} / "
            f"{r['position_median_smoothed_cm']:.1f} | {r['position_p95_causal_cm']:.1f} / "
            f"{r['position_p95_smoothed_cm']:.1f} |"
        )
    lines += [
        "",
        "## Real untethered flights (NanoBench, true tension zero; cross-day calibration)",
        "",
        "| flight | median abs T causal, mN | smoothed, mN |",
        "| --- | ---: | ---: |",
    ]
    for n, c, s in rows:
        lines.append(f"| {n} | {c:.1f} | {s:.1f} |")
    page = "\n".join(lines) + "\n"
    if args.out:
        out = Path(args.out)
        page += kept_reading(out, "\n## Reading")  # the reading below the tables
        out.write_text(page, encoding="utf-8")
        if out.resolve() == DOCS / "smoother.md":
            figures = {
                "simulated": {k.replace(" ", "_"): v for k, v in sim.items()},
                "nanobench": [[n, c, s] for n, c, s in rows],
            }
            write_figures("smoother", figures, ["--seeds", str(args.seeds), "--out", args.out])
    sys.stdout.write(page)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
