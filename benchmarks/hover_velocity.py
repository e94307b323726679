"""How far a hovering drone's velocity strays: σ_v and T_c as ``calibrate`` fits them.

``python -m benchmarks.hover_velocity [--data DIR] [--sim]``

The computation is ``calibrate``'s own (groundstation.hover_fit): the service's hover test
run over the flight without motion capture marks the hover; in its stretches of at least
1 s, the motion-capture velocity's scatter about each stretch's mean (σ_v) and its
correlation time (T_c); nothing is fitted under 3 s of such stretches.

NanoBench (``../shared/data/nanobench``, real untethered Crazyflie flights with Vicon), per
flight: the share of the airborne samples the hover test calls a hover, and the fit. These
flights are trajectories: what the test calls a hover is mostly slow motion (the linear
ramp), so σ_v here is that of slow flight, not of a drone holding a spot.

``--sim``: the realistic simulator with motion capture, 60 s hovers at paper spots 0, 2 and
4 (1 m/s² of vibration, seed 900), fitted on the Telemetry's motion-capture positions (the
simulator's timing and noise classes on) and on the true positions.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.nanobench import MASS_KG
from benchmarks.nanobench import load as nanobench_flight
from benchmarks.nanobench_cli import AIR_MIN_Z_M, DATA, DAYS, check_data
from groundstation.calibration import CalibrationData
from groundstation.config import load_settings
from groundstation.estimator.drone import slow_accel_params
from groundstation.hover_fit import fit_hover_velocity, hover_flags

SIM_SPOTS = (0, 2, 4)
SIM_SECONDS = 60.0
SIM_NOISE_MPS2 = 1.0
SIM_SEED = 900


def _row(label: str, data: CalibrationData, share_of: np.ndarray, mass_kg: float) -> str:
    params = load_settings(None, {}, use_env=False).for_drone("cf1")
    flags = hover_flags(
        data,
        slow_accel_params(params),
        mass_kg=mass_kg,
        floor_z_m=params.base.floor_z_m,
        ground_thrust_ratio=params.filter.ground_thrust_ratio,
    )
    share = float(flags[share_of].mean()) if share_of.any() else 0.0
    fit, hover_s = fit_hover_velocity(data, flags)
    if fit is None:
        return f"| {label} | {100 * share:.0f} % | {hover_s:.1f} | not fitted | |"
    return (
        f"| {label} | {100 * share:.0f} % | {fit.hover_s:.1f} | {fit.std_mps:.4f} | "
        f"{fit.time_s:.3f} |"
    )


def sim_flight(spot: int, true_positions: bool) -> CalibrationData:
    """A realistic-simulator hover with motion capture, as ``calibrate`` would read it."""
    from benchmarks import bench_realistic as br
    from groundstation.sim.runner import Simulator

    scenario = br._scenario_for_spot(spot)
    cal = br._true_calibration(SIM_NOISE_MPS2, SIM_SEED, {}, scenario)
    settings = br._settings(SIM_NOISE_MPS2, SIM_SEED, {}, cal, True)
    sim = Simulator(settings, br._NullBus(), scenario=scenario)  # type: ignore[arg-type]
    rows: list[dict[str, object]] = []
    truth: dict[float, list[float]] = {}
    while sim.t_s < SIM_SECONDS:
        for sample in sim.step():
            kind = sample.key.split("/", 2)[2]
            body = json.loads(sample.payload)
            if kind == "truth":
                truth[round(body["stamp_s"], 6)] = body["position_m"]
            elif kind == "telemetry":
                rows.append(body)
    nan3 = [float("nan")] * 3
    pos = [
        truth.get(round(float(r["stamp_s"]), 6), nan3)  # type: ignore[arg-type]
        if true_positions
        else (r.get("position_m") or nan3)
        for r in rows
    ]
    return CalibrationData.from_arrays(
        [r["stamp_s"] for r in rows],
        [r["accel_mps2"] for r in rows],
        [r["quat_wxyz"] for r in rows],
        [r["thrust_n"] for r in rows],
        armed=[r.get("armed", True) for r in rows],
        position_world_m=pos,
        gyro_rps=[r.get("gyro_rps") or nan3 for r in rows],
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="the NanoBench CSV directory")
    ap.add_argument("--sim", action="store_true", help="the realistic simulator instead")
    args = ap.parse_args(argv)
    head = (
        "| {} | hover share | hover s (stretches ≥ 1 s) | σ_v m/s | T_c s |\n"
        "| --- | ---: | ---: | ---: | ---: |"
    )
    if args.sim:
        print(head.format("spot, positions"))
        for spot in SIM_SPOTS:
            for true_positions in (False, True):
                data = sim_flight(spot, true_positions)
                label = f"{spot}, {'true' if true_positions else 'motion capture'}"
                print(_row(label, data, np.ones(len(data), bool), 0.030))
        return 0
    check_data(ap, args.data)
    print(head.format("flight"))
    for name in DAYS:
        data = nanobench_flight(f"{name}.csv", args.data)
        airborne = data.armed & (data.position_world_m[:, 2] > AIR_MIN_Z_M)
        print(_row(name, data, airborne, MASS_KG))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
