"""What the few mN of vertical tension error at hover are, with calibration = truth.

Run:  python -m benchmarks.vertical_bias [--noise 2.0] [--seed-bases 100 200 300 500]

Realistic profile (groundstation/sim/), the paper's six hover spots, one flight per spot and
seed base (flight seed = base + spot, as ``benchmarks.bench_realistic``), every error class
at its default size, ``[calibration]`` = the simulator's truth. No pipeline: the *raw*
observation (``tension.observe_tension`` with the true calibration, ``eq:NE_tether``) against
the true tether force, averaged over the window the hover figures use (from
``STEADY_FROM_S`` to the end). Its vertical error is split per sample into

* the vibration noise the simulator injected, as the observation sees it (m R n, R the
  reported attitude): a random draw per flight;
* everything else (the rest of the accelerometer and thrust errors left by the calibration,
  the dynamics): what a calibration could still be blamed for.

Each flight is flown with two calibrations = truth: its own (the simulator's equivalent at
this flight's hover attitude, what ``bench_realistic`` uses) and the first spot's (what it
used before). Printed: a table per flight and the spread of each part.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from benchmarks.bench_realistic import (
    DRONE,
    STEADY_FROM_S,
    _NullBus,
    _scenario_for_spot,
    _settings,
    _true_full_calibration,
)
from groundstation.config import CalibrationSection
from groundstation.pipeline import calibration_from_config
from groundstation.sim import Simulator
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M
from groundstation.tension import observe_tension, rotation_world_body


def flight_tz_mn(
    seed: int, spot: int, noise_mps2: float, own: bool, seconds: float
) -> tuple[float, float]:
    """(mean raw T_z error, its vibration-noise part), mN, over the hover window."""
    scenario = _scenario_for_spot(spot)
    cal = _true_full_calibration(noise_mps2, seed, {}, scenario if own else "hover")
    settings = _settings(noise_mps2, seed, {}, cal)
    sim = Simulator(settings, _NullBus(), scenario=scenario)  # type: ignore[arg-type]
    drone: Any = sim.drones[DRONE]
    # The noise drawn for each IMU sample, kept beside the sample's truth (the simulator's
    # own sampling, observed, not changed).
    last_noise: dict[str, np.ndarray] = {}
    draw = drone._imu_noise.sample

    def noise_seen(ratio: float) -> np.ndarray:
        n: np.ndarray = draw(ratio)
        last_noise["n"] = n.copy()
        return n

    drone._imu_noise.sample = noise_seen
    noise_at: dict[float, np.ndarray] = {}
    truth: dict[float, float] = {}  # the true T_z at each IMU sample, N
    sample = drone._sample

    def sample_seen(stamp_s: float, ratio: float) -> dict[str, Any]:
        out: dict[str, Any] = sample(stamp_s, ratio)
        noise_at[stamp_s] = last_noise["n"]
        truth[stamp_s] = float(out["truth"]["tension_n"][2])
        return out

    drone._sample = sample_seen
    obs_cal, _ = calibration_from_config(CalibrationSection(**cal))
    mass = settings.for_drone(DRONE).drone.mass_kg
    err, part = [], []
    while sim.t_s < seconds:
        for s in sim.step():
            kind = s.key.split("/", 2)[2]
            payload = json.loads(s.payload)
            if kind == "telemetry" and payload["stamp_s"] >= STEADY_FROM_S:
                obs = observe_tension(
                    payload["accel_mps2"],
                    payload["quat_wxyz"],
                    payload["thrust_n"],
                    mass,
                    payload.get("armed", True),
                    calibration=obs_cal,
                    vbat_v=payload.get("vbat_v"),
                )
                t_true = truth.get(payload["stamp_s"])
                if obs.tension_world_n is None or t_true is None:
                    continue
                r = rotation_world_body(payload["quat_wxyz"])
                err.append(float(obs.tension_world_n[2]) - t_true)
                part.append(float(mass * (r @ noise_at[payload["stamp_s"]])[2]))
    return 1e3 * float(np.mean(err)), 1e3 * float(np.mean(part))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, default=2.0, help="vibration, m/s^2 per axis")
    ap.add_argument("--seed-bases", type=int, nargs="+", default=[100, 200, 300, 500])
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    print(
        f"realistic profile, vibration {args.noise:g} m/s^2, every class on, calibration = "
        f"truth; raw T_z error over {STEADY_FROM_S:g}-{args.seconds:g} s, mN"
    )
    print(
        "| seed | spot | raw, own calibration | noise part | rest "
        "| rest with spot 1's calibration |"
    )
    print("|---|---|---|---|---|---|")
    raws, noises, rests, rests_first = [], [], [], []
    for base in args.seed_bases:
        for spot in range(len(PAPER_HOVER_SPOTS_M)):
            seed = base + spot
            raw, noise = flight_tz_mn(seed, spot, args.noise, True, args.seconds)
            raw1, noise1 = flight_tz_mn(seed, spot, args.noise, False, args.seconds)
            raws.append(raw)
            noises.append(noise)
            rests.append(raw - noise)
            rests_first.append(raw1 - noise1)
            print(
                f"| {seed} | {spot} {PAPER_HOVER_SPOTS_M[spot]} | {raw:+.2f} | {noise:+.2f} "
                f"| {raw - noise:+.2f} | {raw1 - noise1:+.2f} |",
                flush=True,
            )

    def spread(xs: list[float]) -> str:
        return (
            f"mean {np.mean(xs):+.2f}, sd {np.std(xs, ddof=1):.2f}, "
            f"range {min(xs):+.2f} .. {max(xs):+.2f} mN"
        )

    print(f"\n{len(raws)} flights. raw T_z error: {spread(raws)}")
    print(f"its vibration-noise part: {spread(noises)}")
    print(f"the rest, own calibration: {spread(rests)}")
    print(f"the rest, spot 1's calibration (before): {spread(rests_first)}")
    print(f"flights with |raw| >= 4 mN: {sum(abs(x) >= 4.0 for x in raws)}")


if __name__ == "__main__":
    main()
