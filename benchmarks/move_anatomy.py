"""Where the estimate's lag after a move between hover spots comes from (a diagnosis, no page).

``python -m benchmarks.move_anatomy [--noise 1.0] [--seeds 900,901,902,903]``

The realistic benchmark's move (``benchmarks.bench_realistic``: calibration = truth, no motion
capture; hover at the paper's spot 0, at 20 s the controller's target becomes spot 4), each
flight followed through the filter stage (``estimator.filter_control.FilterControl.step``:
whether the hover model is fused, the observation, the accelerometer model, the detections),
in seconds after the target changed:

* **hover end**: the hover test lets go of the hover model;
* **hover model's error**: the observation's mean error (norm, mN) from the target change to
  the hover end, while the hover model ``m·g·e3 − R·u·F``, which has no ``m·a``, still
  carries its low band;
* **accel model's error**: the accelerometer model's mean error (norm, mN) from the hover end
  to the next hover: what the observation gets wrong while the drone manoeuvres (thrust
  and attitude against the accelerometer, drag);
* **detection**: the first change detection, and the estimate's error just after it (the
  filter restarts from the mean of the samples since the change it found);
* **new hover**: the hover test takes the hover model again (the filter's ``new_hover``
  raises P to one sample's R); the tension error and the published |σ_T| then and 1 s later;
* **estimate arrives**: the benchmark's criterion (within 10 % of the move's distance for
  1 s), and the truth's.

Takes ~15 s per flight.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from benchmarks import bench_realistic as br
from groundstation.estimator import filter_control as fc
from groundstation.sim import PAPER_HOVER_SPOTS_M, SCENARIOS, Scenario, Waypoint

NAME = "move_anatomy"


def _scenario() -> tuple[np.ndarray, float]:
    """Registers the move (the benchmark's: ``br.MOVE_FROM`` → ``br.MOVE_TO`` at
    ``br.MOVE_AT_S``); returns the new spot and the move's distance."""
    a, b = PAPER_HOVER_SPOTS_M[br.MOVE_FROM], PAPER_HOVER_SPOTS_M[br.MOVE_TO]
    SCENARIOS[NAME] = Scenario(
        NAME,
        f"hover at {a}; at {br.MOVE_AT_S:g} s to {b}",
        start_m=a,
        waypoints=(Waypoint(0.0, a), Waypoint(br.MOVE_AT_S, b)),
    )
    return np.array(b), float(np.linalg.norm(np.subtract(b, a)))


def flight(noise: float, seed: int, seconds: float = 32.0) -> dict[str, Any]:
    """One move, followed through the filter stage."""
    spot_b, dist = _scenario()
    steps: list[tuple[bool, bool, np.ndarray, np.ndarray, np.ndarray]] = []
    original = fc.FilterControl.step

    def step(self: fc.FilterControl, **kw: Any) -> fc.FilterOutput:
        out = original(self, **kw)
        est = out.estimate
        if est is not None:
            obs = kw["observation"].tension_world_n
            am = kw.get("accel_model_world_n")
            steps.append(
                (
                    bool(kw.get("hovering")),
                    bool(est.change_detected or out.hover_change),
                    np.array(obs if obs is not None else (math.nan,) * 3, float),
                    np.array(am if am is not None else (math.nan,) * 3, float),
                    np.array(out.tension_world_n, float),
                )
            )
        return out

    fc.FilterControl.step = step  # type: ignore[method-assign]
    try:
        f = br.fly(NAME, seconds, noise, seed)
    finally:
        fc.FilterControl.step = original  # type: ignore[method-assign]
    # The filter's steps with an estimate are the flight's last rows (checked).
    m = min(len(steps), len(f.t_s))
    rows = slice(len(f.t_s) - m, None)
    steps = steps[len(steps) - m :]
    x = np.array([s[4] for s in steps])
    if not np.allclose(x, f.est_tension_n[rows]):
        raise RuntimeError("the filter's steps do not line up with the flight's rows")
    t = f.t_s[rows] - br.MOVE_AT_S
    truth = f.true_tension_n[rows]
    hovering = np.array([s[0] for s in steps])
    detected = np.array([s[1] for s in steps])
    obs = np.array([s[2] for s in steps])
    am = np.array([s[3] for s in steps])
    std = np.linalg.norm(f.est_tension_std_n[rows], axis=1)
    after = t >= 0.0

    def first(mask: np.ndarray) -> int | None:
        idx = np.flatnonzero(mask)
        return int(idx[0]) if idx.size else None

    i_end = first(after & ~hovering)
    i_det = first(after & detected)
    i_new = None if i_end is None else first((np.arange(len(t)) > i_end) & hovering)

    def err_mn(i: int | None) -> float:
        return math.nan if i is None else 1e3 * float(np.linalg.norm(x[i] - truth[i]))

    def mean_err_mn(y: np.ndarray, lo: int | None, hi: int | None) -> float:
        if lo is None or hi is None or hi <= lo:
            return math.nan
        return 1e3 * float(np.linalg.norm(np.nanmean(y[lo:hi] - truth[lo:hi], axis=0)))

    i_move = first(after)
    i_new_1s = None if i_new is None else first(t >= t[i_new] + 1.0)
    to_b_est = np.linalg.norm(f.est_pos_m[rows] - spot_b, axis=1)
    to_b_est[~np.isfinite(to_b_est)] = np.inf
    to_b_true = np.linalg.norm(f.true_pos_m[rows] - spot_b, axis=1)
    return {
        "seed": seed,
        "hover_end_s": None if i_end is None else float(t[i_end]),
        "hover_model_err_mn": mean_err_mn(obs, i_move, i_end),
        "accel_model_err_mn": mean_err_mn(am, i_end, i_new),
        "detection_s": None if i_det is None else float(t[i_det]),
        "err_after_detection_mn": err_mn(i_det),
        "new_hover_s": None if i_new is None else float(t[i_new]),
        "err_at_new_hover_mn": err_mn(i_new),
        "sigma_at_new_hover_mn": math.nan if i_new is None else 1e3 * float(std[i_new]),
        "err_1s_later_mn": err_mn(i_new_1s),
        "sigma_1s_later_mn": math.nan if i_new_1s is None else 1e3 * float(std[i_new_1s]),
        "truth_arrives_s": br._arrival_s(t[after], to_b_true[after], 0.1 * dist),
        "estimate_arrives_s": br._arrival_s(t[after], to_b_est[after], 0.1 * dist),
    }


def _s(v: float | None) -> str:
    return "-" if v is None or v != v else f"{v:.2f}"


def _mn(v: float) -> str:
    return "-" if v != v else f"{v:.1f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=1.0, help="vibration, m/s^2 (1.0)")
    ap.add_argument("--seeds", default="900,901,902,903", help="flight seeds")
    args = ap.parse_args(argv)
    print(f"move spot {br.MOVE_FROM} -> {br.MOVE_TO}, vibration {args.noise:g} m/s^2")
    print(
        "| seed | hover end s | hover model err mN | accel model err mN | detection s (err mN) "
        "| new hover s | err / σ_T there mN | err / σ_T 1 s later mN | truth / estimate "
        "arrive s |"
    )
    print("| --- | ---: | ---: | ---: | --- | ---: | --- | --- | --- |")
    for seed in (int(s) for s in args.seeds.split(",")):
        r = flight(args.noise, seed)
        print(
            f"| {seed} | {_s(r['hover_end_s'])} | {_mn(r['hover_model_err_mn'])} | "
            f"{_mn(r['accel_model_err_mn'])} | {_s(r['detection_s'])} "
            f"({_mn(r['err_after_detection_mn'])}) | {_s(r['new_hover_s'])} | "
            f"{_mn(r['err_at_new_hover_mn'])} / {_mn(r['sigma_at_new_hover_mn'])} | "
            f"{_mn(r['err_1s_later_mn'])} / {_mn(r['sigma_1s_later_mn'])} | "
            f"{_s(r['truth_arrives_s'])} / {_s(r['estimate_arrives_s'])} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
