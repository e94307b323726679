"""Why the published tension σ is wider than the error on a hover (a diagnosis, no page).

``python -m benchmarks.sigma_consistency [--noise 1.0] [--spots 0,2,4] [--seed 500]
[--hover-velocity-std MPS] [--hover-velocity-time S] [--thrust-noise N] [--wander N2PS]
[--balance N2S] [--calibration FILE]``

Realistic simulator, calibration = truth (``benchmarks.bench_realistic.fly``), 20 s hovers,
judged from 8 s. Per flight and world axis: the error's RMS against the median published
``tension_std_n`` (their ratio: about 1 for a consistent σ), and the tension filter's noise
model at the end of the flight: ``s_d`` (half the mean squared first difference of its
observation), ``κ`` (the long-run variance over ``s_d``, from 0.25 s block means) and
``r = s_d·κ``, the filter's R (tension_noise.NoiseEstimate), measured on the accelerometer
model, which the filter observes; while the drone hovers the thrust balance enters through
the velocity state (tension_kalman.HoverVelocity), and P is what σ_v allows it. The last
column is the true tension's own wander over the judged window, as a random walk's density
(:func:`truth_wander`, from its Allan variance at 1 s and 2 s blocks): what
``--wander`` would be if the filter were told the truth. Takes ~10 s per flight.

The options change one prior of the hover's (T, v) filter at a time, to see which one sets
the σ: ``--hover-velocity-std`` / ``--hover-velocity-time`` (σ_v and T_c, as
``[calibration] hover_velocity_std_mps`` / ``hover_velocity_time_s``), ``--thrust-noise``
(``[drone] thrust_noise_n``, the prior of the velocity's process noise while hovering),
``--wander`` (``[calibration] hover_wander_n2_per_s``, the tension's random walk) and
``--balance`` (``[calibration] hover_balance_density_n2s``, the thrust balance's white noise,
which takes the place of ``thrust_noise_n``'s), or a ``calibrate`` output's hover keys.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from benchmarks import bench_realistic as br
from groundstation.pipeline import Pipeline


def flight(noise: float, spot: int, seed: int) -> dict[str, Any]:
    """One hover: the error against σ per axis, and the filter's noise model at its end."""
    made: list[Pipeline] = []

    class Kept(Pipeline):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            made.append(self)

    original = br.Pipeline
    br.Pipeline = Kept  # type: ignore[misc]
    try:
        f = br.fly(br._scenario_for_spot(spot), 20.0, noise, seed)
    finally:
        br.Pipeline = original  # type: ignore[misc]
    noise_model = made[-1].drones[br.DRONE].filter._noise
    w = f.t_s >= br.STEADY_FROM_S
    err = f.est_tension_n[w] - f.true_tension_n[w]
    std = f.est_tension_std_n[w]
    s_d = [0.5 * d for d in noise_model.d1]
    return {
        "err_rms_mn": (1e3 * np.sqrt((err**2).mean(axis=0))).tolist(),
        "sigma_median_mn": (1e3 * np.median(std, axis=0)).tolist(),
        "within_2_sigma": (np.abs(err) <= 2.0 * std).mean(axis=0).tolist(),
        "kappa": float(noise_model.kappa),
        "s_d_mn": [1e3 * math.sqrt(v) for v in s_d],
        "r_mn": [1e3 * math.sqrt(v) for v in noise_model.long_run()],
        "truth_wander_n2_per_s": [
            truth_wander(f.t_s[w], f.true_tension_n[w], block_s) for block_s in WANDER_BLOCKS_S
        ],
    }


WANDER_BLOCKS_S = (1.0, 2.0)
"""Block lengths of the truth's Allan variance, s (the judged window is 12 s long)."""


def truth_wander_by_axis(t_s: Any, tension_n: Any, block_s: float) -> Any:
    """The true tension's wander as a random walk's density per world axis, (3,) N²/s: for a
    random walk of density q the Allan variance of block means of length τ is q·τ/3, so
    q = 3·AVAR(τ)/τ, AVAR = ½·mean((ȳ_(k+1) − ȳ_k)²) (fast swing adds to it at short τ:
    an upper bound of the wander at that scale); NaN with fewer than two whole blocks."""
    k = np.floor((np.asarray(t_s) - t_s[0]) / block_s).astype(int)
    means = np.array(
        [tension_n[k == i].mean(axis=0) for i in range(int(k.max())) if (k == i).any()]
    )
    if len(means) < 2:
        return np.full(3, math.nan)
    avar = 0.5 * (np.diff(means, axis=0) ** 2).mean(axis=0)
    return 3.0 * avar / block_s


def truth_wander(t_s: Any, tension_n: Any, block_s: float) -> float:
    """:func:`truth_wander_by_axis`, mean over the axes, N²/s."""
    return float(truth_wander_by_axis(t_s, tension_n, block_s).mean())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=1.0, help="vibration, m/s^2 (1.0)")
    ap.add_argument("--spots", default="0,2,4", help="paper hover spots (0,2,4)")
    ap.add_argument("--seed", type=int, default=500)
    ap.add_argument("--hover-velocity-std", type=float, help="σ_v, m/s (default: the filter's)")
    ap.add_argument("--hover-velocity-time", type=float, help="T_c, s (default: the filter's)")
    ap.add_argument("--thrust-noise", type=float, help="[drone] thrust_noise_n, N")
    ap.add_argument("--wander", type=float, help="[calibration] hover_wander_n2_per_s, N^2/s")
    ap.add_argument("--balance", type=float, help="[calibration] hover_balance_density_n2s, N^2*s")
    ap.add_argument(
        "--calibration",
        help="a calibrate output: its [drones.cf1.calibration] hover_* keys (σ_v, T_c, q_w, "
        "D) over the truth's calibration",
    )
    args = ap.parse_args(argv)
    cal_over: dict[str, float] = {}
    if args.calibration is not None:
        import tomllib

        with open(args.calibration, "rb") as fh:
            table = tomllib.load(fh)["drones"][br.DRONE]["calibration"]
        cal_over.update({k: v for k, v in table.items() if k.startswith("hover_")})
        print(f"from {args.calibration}: {cal_over}")
    if args.hover_velocity_std is not None:
        cal_over["hover_velocity_std_mps"] = args.hover_velocity_std
    if args.hover_velocity_time is not None:
        cal_over["hover_velocity_time_s"] = args.hover_velocity_time
    if args.wander is not None:
        cal_over["hover_wander_n2_per_s"] = args.wander
    if args.balance is not None:
        cal_over["hover_balance_density_n2s"] = args.balance
    if cal_over:
        truth = br._true_calibration

        def with_hover(*a: Any, **k: Any) -> dict[str, Any]:
            return {**truth(*a, **k), **cal_over}

        br._true_calibration = with_hover  # type: ignore[assignment]
    if args.thrust_noise is not None:
        load = br.load_settings

        def with_thrust_noise(path: Any, over: dict[str, Any], **k: Any) -> Any:
            over = {**over, "drone": {**over.get("drone", {}), "thrust_noise_n": args.thrust_noise}}
            return load(path, over, **k)

        br.load_settings = with_thrust_noise  # type: ignore[assignment]
    print(
        "| spot | error RMS x/y/z mN | median σ x/y/z mN | within 2σ x/y/z | κ | "
        "sqrt(s_d) x/y/z mN | sqrt(r) x/y/z mN | truth's wander N²/s (1 s / 2 s blocks) |"
    )
    print("| --- | --- | --- | --- | ---: | --- | --- | --- |")
    for spot in (int(s) for s in args.spots.split(",")):
        r = flight(args.noise, spot, args.seed)

        def three(v: list[float], fmt: str = "{:.2f}") -> str:
            return "/".join(fmt.format(x) for x in v)

        print(
            f"| {spot} | {three(r['err_rms_mn'])} | {three(r['sigma_median_mn'])} | "
            f"{three(r['within_2_sigma'], '{:.0%}')} | {r['kappa']:.2f} | "
            f"{three(r['s_d_mn'], '{:.1f}')} | {three(r['r_mn'], '{:.1f}')} | "
            f"{three(r['truth_wander_n2_per_s'], '{:.2g}')} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
