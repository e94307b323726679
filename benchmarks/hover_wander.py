"""What the hover fit's wander is in the simulated power-ons (a diagnosis, no page).

``python -m benchmarks.hover_wander [--seeds 1,2,3] [--noise 0.8]``

``groundstation calibrate`` fits the hover's tension wander q_w (``[calibration]
hover_wander_n2_per_s``, groundstation.hover_fit.fit_hover_balance) from the hover
stretches of its recordings. On the realistic simulator's power-on flights
(``benchmarks.bench_powerons``: four of the paper's spots, 15 s each, recorded with motion
capture; the same flights that page calibrates on) it reads 10-1000 times the wander of
``benchmarks.sigma_consistency``'s 20 s hovers, whose truth wanders at 3e-10-2.3e-9 N²/s;
this command says why, from the simulator's truth of the same flights:

- per flight and dwell, over the samples that page judges (from ``SETTLE_S`` after the
  spot is commanded to the dwell's end), the true tension's standard deviation per world
  axis and its block-mean random-walk density (``sigma_consistency.truth_wander_by_axis``
  at B = 0.25 s, the fit's block: ``3·AVAR(B)/B``; a swing about a mean reads as wander at
  that scale too);
- the balance fit of ``calibrate``'s own likelihood per world axis (q_w, D), on the same
  flights with the airframe constants ``calibrate`` fits from them, over the hover test's
  whole stretches and over the judged windows alone.

A fit over swinging flights is a fit of the swing: its σ is then honest on flights that
swing as these do (docs/powerons_benchmark.md, judged on others) and wide on a hover that
does not (``sigma_consistency --calibration``).
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import bench_powerons as bp
from benchmarks.sigma_consistency import truth_wander_by_axis
from groundstation import hover_fit as hf
from groundstation.config import load_settings
from groundstation.estimator.drone import calibration_from_config
from groundstation.recording.calibrate import read_recordings, run_calibrate, slow_accel_params
from groundstation.recording.reader import copy_messages


def fit_by_axis(
    data: Any, mask: np.ndarray, balance: np.ndarray, velocity: np.ndarray, mass_kg: float
) -> list[str]:
    """``calibrate``'s balance likelihood on one world axis at a time: "q_w / D" per axis
    (``fit_hover_balance`` with ``axes`` one axis; calibrate sums the three)."""
    out = []
    for axis in range(3):
        fit, _ = hf.fit_hover_balance(
            data, mask, balance, mass_kg=mass_kg, velocity_world_mps=velocity, axes=(axis,)
        )
        out.append(
            "-" if fit is None else f"{fit.wander_n2_per_s:.2g} / {fit.balance_density_n2s:.2g}"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--seeds", default="1,2,3", help="power-on seeds (1,2,3: the page's calibration flights)"
    )
    ap.add_argument("--noise", type=float, default=0.8, help="vibration, m/s^2 (0.8)")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    print(
        f"Realistic simulator, power-on flights {seeds} at {args.noise} m/s^2 "
        "(benchmarks.bench_powerons.record)."
    )
    print()
    print("| flight | dwell | truth std x/y/z mN | truth block wander x/y/z N²/s |")
    print("| --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        windows: list[list[tuple[float, float]]] = []
        for seed in seeds:
            rec = bp.record(seed, args.noise, mocap=True, levelled=True)
            path = Path(tmp) / f"poweron{seed}.mcap"
            copy_messages(rec.messages, path)
            files.append(str(path))
            windows.append(rec.judged_from_s)
            stamps = np.array(sorted(rec.truth))
            tension = np.array([rec.truth[s]["tension_n"] for s in stamps], float)
            for i, (a, b) in enumerate(rec.judged_from_s):
                w = (stamps >= a) & (stamps <= b)
                std = tension[w].std(axis=0)
                q = truth_wander_by_axis(stamps[w], tension[w], hf.BALANCE_BLOCK_S)
                print(
                    f"| {seed} | {i} | {'/'.join(f'{1e3 * x:.2f}' for x in std)} | "
                    f"{'/'.join(f'{x:.2g}' for x in q)} |"
                )
        cal = Path(tmp) / "cal.toml"
        run_calibrate(
            load_settings(None, {}, use_env=False), None, files, str(cal), echo=lambda _s: None
        )
        settings = load_settings(str(cal), {}, use_env=False)
        recs = read_recordings(files, settings)
        drone = next(iter(recs))
        data = recs[drone].data
        params = settings.for_drone(drone)
        phases = hf.flight_phases(
            data,
            slow_accel_params(params),
            mass_kg=params.drone.mass_kg,
            floor_z_m=params.base.floor_z_m,
            ground_thrust_ratio=params.filter.ground_thrust_ratio,
        )
        velocity = hf.bridged_velocity(data)
        balance = hf.balance_world_n(
            data,
            phases.hovering,
            mass_kg=params.drone.mass_kg,
            calibration=calibration_from_config(params.calibration)[0],
            velocity_world_mps=velocity,
        )
        # The recordings' clocks start at the flight's start, as the truth's: the judged
        # windows are the same stamps in each segment (one per file, in order).
        judged = np.zeros(len(data), bool)
        for seg, wins in enumerate(windows):
            in_seg = data.segment == seg
            for a, b in wins:
                judged |= in_seg & (data.stamp_s >= a) & (data.stamp_s <= b)
        print()
        print(
            "Balance fit per world axis (calibrate's likelihood, its airframe constants), "
            "q_w / D (N²/s / N²·s):"
        )
        print()
        print("| stretches | x | y | z |")
        print("| --- | --- | --- | --- |")
        m = params.drone.mass_kg
        whole = fit_by_axis(data, phases.hovering, balance, velocity, m)
        print(f"| the hover test's, whole | {' | '.join(whole)} |")
        part = fit_by_axis(data, phases.hovering & judged, balance, velocity, m)
        print(f"| the judged windows alone | {' | '.join(part)} |")
        q_all = float(params.calibration.hover_wander_n2_per_s or math.nan)
        print()
        print(f"calibrate's own fit (three axes pooled): q_w = {q_all:.2g} N²/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
