"""The reel tug's estimates here against another checkout's, sample by sample.

``python -m benchmarks.reel_tug_diff --before DIR [--seeds 8]``

``DIR`` is another checkout of this repository (``git worktree add /tmp/before COMMIT``);
its ``benchmarks.bench_reel_tug.fly`` flies the ideal profile's reel tug (seeds 700 on) in a
subprocess with that checkout first on the path, this checkout's flies the same seeds here,
and per seed this prints both t90 (the issue's criterion, :func:`bench_reel_tug.t90`), the
largest and the median difference of the two published tensions over the 1.6 s from the
reel's start (``bench_reel_tug.MEAN_ERROR_SPAN_S``; mN, the norm, on the stamps both
published), and each one's mean error norm over that span (mN).

Why: t90 is a threshold crossing (the error at most 10 % of the jump, then within 20 % for
a second); an estimate that moves by a fraction of a millinewton near the 10 % line can move
a seed's t90 by a tenth of a second. The differences say whether a change of t90 between two
commits is a change of the estimate or of where it crosses the line.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks import bench_reel_tug as reel

_DUMP = """
import sys, numpy as np
from benchmarks.bench_reel_tug import fly
out = {}
for seed in range(700, 700 + int(sys.argv[1])):
    f = fly("ideal", seed)
    for k in ("t_s", "est_n", "true_n"):
        out[f"{k}{seed}"] = f[k]
np.savez(sys.argv[2], **out)
"""


def _before(checkout: Path, seeds: int, out: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    subprocess.run(
        [sys.executable, "-c", _DUMP, str(seeds), str(out)], cwd=checkout, env=env, check=True
    )


def compare(
    before: dict[str, np.ndarray], after: dict[str, np.ndarray], seed: int
) -> dict[str, float | None]:
    """One seed's t90 before and after, and the estimates' differences (module doc)."""
    rows = {
        name: {k: f[f"{k}{seed}"] for k in ("t_s", "est_n", "true_n")}
        for name, f in (("before", before), ("after", after))
    }
    t_b, t_a = np.round(rows["before"]["t_s"], 6), np.round(rows["after"]["t_s"], 6)
    common = np.intersect1d(t_b, t_a)
    common = common[(common >= reel.TUG_S) & (common <= reel.TUG_S + reel.MEAN_ERROR_SPAN_S)]
    out: dict[str, float | None] = {}
    picked = {}
    for name, f in rows.items():
        t = f["t_s"]
        jump = reel.jump_n(t, f["true_n"])
        err = np.linalg.norm(f["est_n"] - f["true_n"], axis=1)
        out[f"t90_{name}_s"] = reel.t90(t, err, jump)
        keep = np.isin(np.round(t, 6), common)
        picked[name] = f["est_n"][keep]
        out[f"mean_error_{name}_mn"] = 1e3 * float(err[keep].mean())
    diff = 1e3 * np.linalg.norm(picked["after"] - picked["before"], axis=1)
    out["max_difference_mn"] = float(diff.max())
    out["median_difference_mn"] = float(np.median(diff))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, type=Path, help="another checkout")
    ap.add_argument("--seeds", type=int, default=8)
    args = ap.parse_args(argv)
    if not (args.before / "benchmarks" / "bench_reel_tug.py").is_file():
        ap.error(f"{args.before} is not a checkout of this repository with the reel tug")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "before.npz"
        _before(args.before.resolve(), args.seeds, path)
        with np.load(path) as z:
            before = {k: z[k] for k in z.files}
    after: dict[str, np.ndarray] = {}
    for seed in range(700, 700 + args.seeds):
        f = reel.fly("ideal", seed)
        for k in ("t_s", "est_n", "true_n"):
            after[f"{k}{seed}"] = f[k]

    def s(x: float | None) -> str:
        return "never" if x is None else f"{x:.3f}"

    print(
        "seed | t90 before s | t90 after s | max diff mN | median diff mN | "
        "mean error before / after mN"
    )
    for seed in range(700, 700 + args.seeds):
        r = compare(before, after, seed)
        print(
            f"{seed} | {s(r['t90_before_s'])} | {s(r['t90_after_s'])} | "
            f"{r['max_difference_mn']:.2f} | {r['median_difference_mn']:.2f} | "
            f"{r['mean_error_before_mn']:.2f} / {r['mean_error_after_mn']:.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
