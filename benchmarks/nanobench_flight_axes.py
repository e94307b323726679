"""One NanoBench flight's tension error per world axis, held out by day (a diagnosis, no page).

``python -m benchmarks.nanobench_flight_axes [--flight B6_linear_ramp_rep3] [--attitude vicon]
[--variant NAME=FACTOR] [--data DIR]``

Calibrates with ``calibrate --untethered`` on the other days' flights with the attitude named
(as ``benchmarks.attitude_source`` does), serves the flight without motion-capture position
through ``replay --offline`` and prints the median of |T| and of each world axis over the
airborne samples (truth zero), and the estimate along the flight. ``--variant`` changes one
docs/constants.md row by a factor first (``benchmarks.sensitivity.patch``; e.g.
``BiasKalmanParams.flight_bias_std_mps2=2`` for a bias in the air allowed to stray twice as
far from the rest's). Then, per shared
flight, the rotation of Vicon's attitude relative to the drone's own (median rotation vector,
body frame, degrees): a motion-capture body frame defined differently on one day would show
there.

docs/estimator_design.md (*The drift adaptation where the model holds*) reads the worst
flight with Vicon's attitude this way.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import cast

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks import attitude_source as at
from benchmarks.nanobench_cli import CONFIG, DATA, DAYS, _run
from benchmarks.sensitivity import patch
from groundstation.recording import iter_messages


def axes(flight: str, attitude: str, data: Path, work: Path) -> dict[str, object]:
    """The held-out flight's airborne estimate: medians and a trace (mN, s from the first)."""
    base = work / "base.toml"
    base.write_text(CONFIG)
    day = DAYS[flight]
    train = [n for n in DAYS if DAYS[n] != day]
    files = [
        str(at._write(at.load(n, attitude, data).with_mocap, work / f"{n}-{attitude}-m.mcap"))
        for n in train
    ]
    cal = work / f"cal-{attitude}.toml"
    argv = ["calibrate", *files, "--untethered", "--config", str(base), "--out", str(cal)]
    rc, text = _run(argv)
    if rc != 0:
        raise RuntimeError(f"calibrate failed ({rc}): {text}")
    rec = at._write(at.load(flight, attitude, data).without_mocap, work / "flight.mcap")
    out = work / "est.mcap"
    rc, text = _run(["replay", "--offline", str(rec), "--config", str(cal), "--out", str(out)])
    if rc != 0:
        raise RuntimeError(f"replay failed ({rc}): {text}")
    rows = []
    for m in iter_messages(out):
        if m.key == "tether/cf1/estimate":
            e = json.loads(m.payload)
            if not e["on_ground"]:
                rows.append([e["stamp_s"], *e["tension_n"]])
    a = np.array(rows)
    t = a[:, 0] - a[0, 0]
    mn = 1e3 * a[:, 1:4]
    picks = np.linspace(0, len(a) - 1, 8).astype(int)
    return {
        "flight": flight,
        "attitude": attitude,
        "samples": len(a),
        "median_abs_t_mn": round(float(np.median(np.linalg.norm(mn, axis=1))), 2),
        "median_xyz_mn": [round(float(v), 2) for v in np.median(mn, axis=0)],
        "trace_s_xyz_mn": [[round(float(t[k]), 1), *np.round(mn[k], 1).tolist()] for k in picks],
    }


def relative_rotations(data: Path) -> dict[str, list[float]]:
    """Per shared flight: the median rotation vector of Vicon's attitude relative to the
    onboard one (body frame, degrees), airborne samples."""
    out = {}
    for name in DAYS:
        a = np.genfromtxt(data / f"{name}.csv", delimiter=",", names=True)
        q_on = np.stack([a[f"att_stateEstimate_q{k}"] for k in "xyzw"], 1)
        q_vi = np.stack([a[f"q{k}"] for k in "xyzw"], 1)
        ok = np.all(np.isfinite(q_on), 1) & np.all(np.isfinite(q_vi), 1) & (a["pz"] > 0.25)
        rel = (Rotation.from_quat(q_on[ok]).inv() * Rotation.from_quat(q_vi[ok])).as_rotvec()
        out[f"{name} ({DAYS[name]})"] = np.round(np.degrees(np.median(rel, axis=0)), 2).tolist()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flight", default="B6_linear_ramp_rep3", choices=sorted(DAYS))
    ap.add_argument("--attitude", default="vicon", choices=at.ATTITUDES)
    ap.add_argument("--variant", metavar="NAME=FACTOR", help="one docs/constants.md row changed")
    ap.add_argument("--data", default=str(DATA), help="the NanoBench directory")
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not data.is_dir():
        ap.error(f"--data {data}: no such directory (the NanoBench flights; see its README)")
    if args.variant:
        name, _, factor = args.variant.partition("=")
        patch(name, float(factor))
    with tempfile.TemporaryDirectory() as tmp:
        result = axes(args.flight, args.attitude, data, Path(tmp))
    trace = cast("list[list[float]]", result.pop("trace_s_xyz_mn"))
    print(json.dumps(result))
    print("t s, x / y / z mN:", "; ".join(" ".join(f"{v:g}" for v in row) for row in trace))
    print("Vicon's attitude relative to the onboard one, rotation vector, body frame, deg:")
    for name, rotvec in relative_rotations(data).items():
        print(f"  {name}: {rotvec}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
