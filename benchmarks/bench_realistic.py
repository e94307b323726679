"""The estimator on the realistic simulator against an oracle computed in the same run.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_realistic            # writes docs/realistic_benchmark.md
    .venv/bin/python -m benchmarks.bench_realistic --quick    # a short run, prints only
    .venv/bin/python -m benchmarks.bench_realistic --only tug,false_tugs  # those; prints only

Every flight is the ``realistic`` profile of :mod:`groundstation.sim` (rigid body, motors with
lag, rotor drag, yaw, lumped-mass tether; vibration noise white + AR(0.6) with lag-1 0.2;
IMU at ~100 Hz with 6-27 ms spacing; per-flight accelerometer misalignment, scale and bias,
thrust axis offset, thrust map error drifting with a sagging battery), driven in lock-step
through :meth:`groundstation.pipeline.Pipeline.handle` (the service's seam), without motion
capture. The accelerometer noise level is set per experiment; the pipeline is *not* told it
(``[drone] accel_noise_mps2`` stays at its 0.3 m/s^2 default).

* **Hover** at the paper's six spots, three seeds per spot (``--hover-seeds``; seeds 500,
  600, 700, flight seed = seed + spot), error from 8 s on, pooled, with each seed's ratio
  to the oracle for the spread. ``[calibration]`` is set to the
  simulator's drawn truth (its equivalent calibration). Ours: the pipeline's Estimate.
  **Oracle**: a fixed Kalman filter (``TensionFilter`` with the noise estimate, the change
  test and the drift adaptation off) told the true noise (the long-run variance of the
  observation error against the true tension, measured in the same run) and given its best
  hover time constant (the best of a grid, chosen per noise level on the pooled median),
  fed the full model's observations with every drawn error known (the accelerometer's
  mean trusted as read) and localized with the same
  :func:`groundstation.localization.localize`. Ours has the airframe's constants only and
  its slow stage rests the slow part of the observation on thrust and attitude at hover,
  which the oracle does not: a ratio below 1 is that stage's gain.
* **False tugs**: hover at the first spot for 10 min (``--quick``: 1 min) per noise level,
  change detections counted by the pipeline.
* **Tug**: a 30 mN step pull toward the base at 10 s for 5 s, 4 seeds (``--quick``: 2).
  t90: time until the seed-averaged estimated change along the pull reaches 90 % of the
  seed-averaged true change; settle: time until the error norm stays within 3 mN (10 %)
  for the rest of the pull, median over seeds; both also for the oracle of a step (the
  mean of the observations since the step, its time known). Detection: the first change
  detection after the pull began, per seed; its **information limit** is the time at which
  the step's samples hold a non-centrality ``n step^2 / r`` (r the true long-run noise
  variance along the pull, measured in the same flights before the pull) equal to the
  change test's threshold at that spacing (set for ``false_alarms_per_h``): a detector
  with that false-alarm rate finds
  the step about half the time by then, with the level before it known exactly.
* **Uncalibrated envelope**: one error class on at a time (vibration at 1.0 m/s^2 on in
  all, calibration ``none``), hover at the six spots: which error costs how many cm.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import git_commit
from benchmarks.figures import write_figures
from benchmarks.told_noise import TAUS_S, glr_random_walk, long_run_variance_n2
from groundstation.bus import Sample
from groundstation.config import CalibrationSection, Settings, load_settings
from groundstation.evaluation import closed_loop
from groundstation.localization import localize
from groundstation.pipeline import Pipeline, calibration_from_config
from groundstation.sim import PAPER_HOVER_SPOTS_M, SCENARIOS, Pull, Scenario, Simulator, Waypoint
from groundstation.tension import TensionFilter, TensionFilterParams, observe_tension

DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "realistic_benchmark.md"
NOISE_LEVELS_MPS2 = (0.5, 1.0, 2.0)
TUG_ACCEPTANCE_MPS2 = 0.8
"""The estimator issue's tug level (t90 within 1.5x of a detector told the noise): the tug
section also runs it, after the others (so their indices in the figures stay)."""
STEADY_FROM_S = 8.0
HOVER_SEED_BASE = 500  # 100-400: the seeds the hover time constant was studied on
TAU_GRID_S = (1.0, 2.5, 4.0, 6.0, 10.0, 20.0, 40.0)
ERROR_CLASSES = (
    "misalignment",
    "accel_scale",
    "accel_bias",
    "thrust_axis",
    "thrust_map",
    "motor_lag",
    "rotor_drag",
    "yaw_motion",
    "imu_timing",
)
ALL_CLASSES = (*ERROR_CLASSES, "vibration", "battery", "mocap_timing")
CAL_KEYS = ("thrust_scale", "thrust_vbat_slope_per_v", "thrust_vbat_ref_v", "thrust_axis_rad")
DRONE = "cf1"


class _NullBus:
    def publish(self, key: str, payload: bytes) -> None:  # pragma: no cover - unused
        pass


def _scenario_for_spot(i: int) -> str:
    name = f"bench_hover_{i}"
    spot = PAPER_HOVER_SPOTS_M[i]
    SCENARIOS[name] = Scenario(
        name, f"hover at {spot}", start_m=spot, waypoints=(Waypoint(0.0, spot),)
    )
    return name


def _tug_scenario() -> str:
    name = "bench_tug"
    spot = (1.0, 0.0, 1.0)
    SCENARIOS[name] = Scenario(
        name,
        "hover at (1, 0, 1); 30 mN toward the base at 10 s for 5 s",
        start_m=spot,
        waypoints=(Waypoint(0.0, spot),),
        pulls=(Pull(10.0, 15.0, (-0.03, 0.0, 0.0)),),
    )
    return name


FILTER_OVERRIDES: dict[str, Any] = {}
"""``[filter]`` values every flight of this module is served with (a study sets them before
it flies); empty: the defaults."""


def _settings(
    noise_mps2: float,
    seed: int,
    classes: dict[str, bool],
    calibration: dict[str, Any] | None,
    mocap: bool = False,
) -> Settings:
    realistic: dict[str, Any] = {"accel_noise_mps2": noise_mps2, **classes}
    over: dict[str, Any] = {
        "sim": {"profile": "realistic", "seed": seed, "mocap": mocap, "realistic": realistic}
    }
    if calibration is not None:
        over["calibration"] = calibration
    if FILTER_OVERRIDES:
        over["filter"] = dict(FILTER_OVERRIDES)
    return load_settings(None, over, use_env=False)


def _true_calibration(
    noise_mps2: float,
    seed: int,
    classes: dict[str, bool],
    scenario: str = "hover",
    thrust_model: str = "vbat_linear",
) -> dict[str, Any]:
    """The flight's drawn errors as ``[calibration]`` values (the simulator's equivalent).

    ``thrust_model``: the battery's law as the straight line (``vbat_linear``, first order
    about the simulator's reference voltage, what every page uses) or as the motor-voltage
    model, which is the simulator's law at every voltage (``motor_voltage``;
    groundstation.sim.sensors).

    ``scenario`` is the flight's own: the accelerometer bias that stands for the per-boot
    misalignment and scale is exact at one attitude only, the flight's hover (the
    estimator's calibration model, a constant bias, has no term for the rest), so the
    equivalent of a flight at another spot differs by up to 0.8 mN of T_z at 2 m/s^2-level
    misalignments (``python -m benchmarks.vertical_bias``)."""
    sim = Simulator(_settings(noise_mps2, seed, classes, None), _NullBus(), scenario=scenario)  # type: ignore[arg-type]
    errors = sim.drawn_errors(DRONE)
    assert errors is not None
    # The estimator's own oracle: the airframe's constants as the airframe model
    # sees them (thrust scale and battery term, the thrust axis in the frame the attitude is
    # reported in); the accelerometer's per-power-on errors are left to the service, which
    # learns them at this power-on (accel_slow, the default), exactly as after `calibrate`.
    if thrust_model == "vbat_linear":
        eq = errors["airframe_equivalent"]
        cal: dict[str, Any] = {k: eq[k] for k in CAL_KEYS}
    else:
        drone = sim.drones[DRONE]
        cal = drone.errors.airframe_equivalent(drone.sensors.attitude_levelled, thrust_model)  # type: ignore[union-attr]
    cal["source"] = f"simulator truth (seed {seed})"
    return cal


def _true_full_calibration(
    noise_mps2: float, seed: int, classes: dict[str, bool], scenario: str = "hover"
) -> dict[str, Any]:
    """The earlier oracle: the full model's equivalent (a constant accelerometer bias exact at
    this flight's hover), with the accelerometer's mean trusted as read."""
    sim = Simulator(_settings(noise_mps2, seed, classes, None), _NullBus(), scenario=scenario)  # type: ignore[arg-type]
    errors = sim.drawn_errors(DRONE)
    assert errors is not None
    eq = errors["calibration"]
    cal: dict[str, Any] = {k: eq[k] for k in CAL_KEYS}
    cal["accel_bias_mps2"] = eq["accel_bias_mps2"]
    cal["accel_slow"] = False
    cal["source"] = f"simulator truth, full model (seed {seed})"
    return cal


@dataclass
class Flight:
    """One lock-step flight: what the pipeline published and what the oracle needs."""

    t_s: np.ndarray  # (n,) stamps of accepted telemetry with an estimate
    est_pos_m: np.ndarray  # (n, 3), NaN where undetermined
    est_tension_n: np.ndarray  # (n, 3)
    true_pos_m: np.ndarray  # (n, 3)
    true_tension_n: np.ndarray  # (n, 3)
    obs_n: np.ndarray  # (n, 3) raw observations with the oracle's (true) calibration, NaN if none
    dt_s: np.ndarray  # (n,) spacing of the telemetry stamps
    changes: int
    settings: Settings
    change_stamps_s: list[float]  # telemetry stamps at which the filter detected a change
    est_tension_std_n: np.ndarray  # (n, 3) the published tension_std_n
    est_pos_std_m: np.ndarray  # (n, 3) the published position_std_m, NaN where none


def fly(
    scenario: str,
    seconds: float,
    noise_mps2: float,
    seed: int,
    *,
    classes: dict[str, bool] | None = None,
    calibrated: bool = True,
    thrust_model: str = "vbat_linear",
) -> Flight:
    """Runs one flight through the pipeline; records what the oracle needs (``thrust_model``:
    the truth calibration's battery law, :func:`_true_calibration`)."""
    classes = classes or {}
    true_cal = _true_calibration(noise_mps2, seed, classes, scenario, thrust_model)
    settings = _settings(noise_mps2, seed, classes, true_cal if calibrated else None)
    sim = Simulator(settings, _NullBus(), scenario=scenario)  # type: ignore[arg-type]
    pipe = Pipeline(settings)
    # The oracle's observations: the full model with every drawn error known (this flight's
    # own accelerometer bias too): the best a simple estimator told the truth could do.
    full_cal = _true_full_calibration(noise_mps2, seed, classes, scenario)
    oracle_cal, _ = calibration_from_config(CalibrationSection(**full_cal))
    mass = settings.for_drone(DRONE).drone.mass_kg
    truth: dict[float, dict[str, Any]] = {}
    rows: list[tuple[Any, ...]] = []
    last_stamp: float | None = None
    change_stamps: list[float] = []
    while sim.t_s < seconds:
        now_s = sim.t_s
        for sample in sim.step():
            kind = sample.key.split("/", 2)[2]
            if kind == "truth":
                t = json.loads(sample.payload)
                truth[round(t["stamp_s"], 6)] = t
                continue
            if kind != "telemetry":
                pipe.handle(sample, now_s)
                continue
            msg = json.loads(sample.payload)
            outs = pipe.handle(sample, now_s)
            runtime = pipe.drones.get(DRONE)
            if runtime is not None and runtime.change_detections > len(change_stamps):
                change_stamps.append(msg["stamp_s"])
            obs = observe_tension(
                msg["accel_mps2"],
                msg["quat_wxyz"],
                msg["thrust_n"],
                mass,
                armed=msg.get("armed", True),
                calibration=oracle_cal,
                vbat_v=msg.get("vbat_v"),
            )
            stamp = msg["stamp_s"]
            dt = 0.0 if last_stamp is None else stamp - last_stamp
            last_stamp = stamp
            for out in outs:
                if out.key.endswith("/estimate"):
                    e = json.loads(out.payload)
                    y = obs.tension_world_n if obs.tension_world_n is not None else [math.nan] * 3
                    rows.append(
                        (
                            stamp,
                            e["position_m"],
                            e["tension_n"],
                            list(y),
                            dt,
                            e["tension_std_n"],
                            e.get("position_std_m"),
                        )
                    )
                elif out.key.endswith(("/cmd/setpoint", "/cmd/stop")):
                    sim.handle_command(Sample(out.key, out.payload))
        pipe.tick(now_s)
    status = pipe.status(DRONE, sim.t_s) or {}
    t = np.array([r[0] for r in rows])
    tr = [truth[round(s, 6)] for s in t]
    nan3 = [math.nan] * 3
    return Flight(
        t_s=t,
        est_pos_m=np.array([r[1] if r[1] is not None else nan3 for r in rows], dtype=float),
        est_tension_n=np.array([r[2] for r in rows], dtype=float),
        true_pos_m=np.array([x["position_m"] for x in tr], dtype=float),
        true_tension_n=np.array([x["tension_n"] for x in tr], dtype=float),
        obs_n=np.array([r[3] for r in rows], dtype=float),
        dt_s=np.array([r[4] for r in rows], dtype=float),
        changes=int(status.get("filter", {}).get("change_detections", 0)),
        settings=settings,
        change_stamps_s=change_stamps,
        est_tension_std_n=np.array([r[5] for r in rows], dtype=float),
        est_pos_std_m=np.array([r[6] if r[6] is not None else nan3 for r in rows], dtype=float),
    )


def oracle_estimates(f: Flight, tau_s: float, r_n2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fixed Kalman filter told the true noise r, time constant tau: tension and position."""
    dt_mean = float(np.mean(f.dt_s[1:]))
    # accel_noise such that the filter's (fixed) R per axis is the true long-run variance
    mass = f.settings.for_drone(DRONE).drone.mass_kg
    params = TensionFilterParams(
        mass_kg=mass,
        accel_noise_mps2=math.sqrt(float(np.mean(r_n2))) / mass,
        thrust_noise_n=0.0,
        estimate_noise=False,
        hover_time_constant_s=tau_s,
        hover_wander_n2_per_s=0.0,
        drift_min_time_constant_s=tau_s,
        false_alarms_per_h=0.0,
    )
    filt = TensionFilter(params)
    tp = f.settings.for_drone(DRONE)
    base = np.array(tp.base.position_m)
    ten = np.full((len(f.t_s), 3), math.nan)
    pos = np.full((len(f.t_s), 3), math.nan)
    for k in range(len(f.t_s)):
        y = f.obs_n[k]
        if not np.all(np.isfinite(y)):
            filt.reset()
            continue
        e = filt.update(y, float(f.dt_s[k]) if k else dt_mean)
        ten[k] = e.tension_world_n
        p = localize(
            e.tension_world_n,
            e.cov_n2,
            tp.tether.weight_n_per_m,
            tp.tether.length_m,
            base,
            tp.base.floor_z_m,
        )
        if p is not None:
            pos[k] = p.position_world_m
    return ten, pos


def _pos_err(f: Flight, pos: np.ndarray) -> np.ndarray:
    m = f.t_s >= STEADY_FROM_S
    err = np.linalg.norm(pos[m] - f.true_pos_m[m], axis=1)
    err[~np.isfinite(err)] = 10.0  # undetermined counts as a miss (10 m)
    return err


def _tension_err(f: Flight, ten: np.ndarray) -> np.ndarray:
    m = f.t_s >= STEADY_FROM_S
    return ten[m] - f.true_tension_n[m]


def within_2_sigma(flights: list[Flight]) -> tuple[float, float]:
    """The share of per-axis errors within twice the published σ, tension and position,
    pooled over the flights' steady part (a position without a σ, or none, counts as
    outside). A consistent estimator: about 95 %."""
    t_in, p_in, n = 0, 0, 0
    for f in flights:
        m = f.t_s >= STEADY_FROM_S
        t_err = np.abs(f.est_tension_n[m] - f.true_tension_n[m])
        t_in += int(np.sum(t_err <= 2.0 * f.est_tension_std_n[m]))
        p_err = np.abs(f.est_pos_m[m] - f.true_pos_m[m])
        with np.errstate(invalid="ignore"):
            p_in += int(np.sum(p_err <= 2.0 * f.est_pos_std_m[m]))
        n += 3 * int(np.sum(m))
    return t_in / max(n, 1), p_in / max(n, 1)


MOVE_FROM, MOVE_TO, MOVE_AT_S, MOVE_END_S = 0, 4, 20.0, 45.0
"""The move: hover at the paper's spot 0, at 20 s the controller's target becomes spot 4
(0.92 m away), the flight ends at 45 s."""


def _arrival_s(t_s: np.ndarray, dist_m: np.ndarray, within_m: float) -> float | None:
    """The first time after which ``dist_m`` stays within ``within_m`` for 1 s (None: never)."""
    ok = dist_m <= within_m
    for i in np.flatnonzero(ok).tolist():
        j = np.searchsorted(t_s, t_s[i] + 1.0)
        if j < len(t_s) and np.all(ok[i:j]):
            return float(t_s[i])
    return None


MOVE_ORACLE_WINDOWS_S = (0.0, 0.5, 1.0, 2.0, 4.0)
"""The move's oracle: the true tension, as it is (0) or its mean over the last 0.5-4 s,
localized by the service's own catenary (``localize``, a covariance of 0.1 mN per axis);
the earliest of these arrivals per flight. What a quasi-static localization told the
tension could do while the tether still swings after the move."""


def _truth_localized_arrival_s(
    f: Flight, spot_m: np.ndarray, within_m: float
) -> tuple[float | None, float | None]:
    """The move's oracle (:data:`MOVE_ORACLE_WINDOWS_S`): its earliest arrival over the
    windows, s after the target changed, and that window (None, None: never)."""
    tp = f.settings.for_drone(DRONE)
    base = np.array(tp.base.position_m)
    after = f.t_s >= MOVE_AT_S
    t = f.t_s[after] - MOVE_AT_S
    sums = np.vstack([np.zeros(3), np.cumsum(f.true_tension_n, axis=0)])
    best: tuple[float | None, float | None] = (None, None)
    for window in MOVE_ORACLE_WINDOWS_S:
        first = np.searchsorted(f.t_s, f.t_s - window, side="right")
        first = np.minimum(first, np.arange(len(f.t_s)))  # at least the sample itself
        n = (np.arange(len(f.t_s)) + 1 - first)[:, None]
        mean_n = (sums[1:] - sums[first]) / n
        dist = np.full(len(f.t_s), np.inf)
        for k in np.flatnonzero(after).tolist():
            p = localize(
                mean_n[k],
                np.eye(3) * 1e-8,
                tp.tether.weight_n_per_m,
                tp.tether.length_m,
                base,
                tp.base.floor_z_m,
            )
            if p is not None:
                dist[k] = float(np.linalg.norm(p.position_world_m - spot_m))
        arrival = _arrival_s(t, dist[after], within_m)
        if arrival is not None and (best[0] is None or arrival < best[0]):
            best = (arrival, window)
    return best


def move(noise: float, seeds: list[int]) -> dict[str, Any]:
    """A move between two hover spots without motion capture: when the truth and the
    estimate reach 90 % of it (within 10 % of the distance of the new spot for 1 s), s
    after the target changed; and the oracle (:data:`MOVE_ORACLE_WINDOWS_S`)."""
    name = "bench_move"
    a, b = PAPER_HOVER_SPOTS_M[MOVE_FROM], PAPER_HOVER_SPOTS_M[MOVE_TO]
    SCENARIOS[name] = Scenario(
        name,
        f"hover at {a}; at {MOVE_AT_S:g} s to {b}",
        start_m=a,
        waypoints=(Waypoint(0.0, a), Waypoint(MOVE_AT_S, b)),
    )
    dist = float(np.linalg.norm(np.subtract(b, a)))
    truth, est, oracle, oracle_window = [], [], [], []
    for seed in seeds:
        f = fly(name, MOVE_END_S, noise, seed)
        after = f.t_s >= MOVE_AT_S
        t = f.t_s[after] - MOVE_AT_S
        to_b_true = np.linalg.norm(f.true_pos_m[after] - np.array(b), axis=1)
        to_b_est = np.linalg.norm(f.est_pos_m[after] - np.array(b), axis=1)
        to_b_est[~np.isfinite(to_b_est)] = np.inf
        truth.append(_arrival_s(t, to_b_true, 0.1 * dist))
        est.append(_arrival_s(t, to_b_est, 0.1 * dist))
        arrival, window = _truth_localized_arrival_s(f, np.array(b), 0.1 * dist)
        oracle.append(arrival)
        oracle_window.append(window)
    lags = [e - t for e, t in zip(est, truth, strict=True) if e is not None and t is not None]
    oracle_lags = [
        o - t for o, t in zip(oracle, truth, strict=True) if o is not None and t is not None
    ]
    return {
        "noise": noise,
        "seeds": list(seeds),
        "distance_m": dist,
        "truth_arrival_s": truth,
        "estimate_arrival_s": est,
        "median_lag_s": float(np.median(lags)) if len(lags) > len(seeds) / 2 else None,
        "arrived": len(lags),
        "oracle_arrival_s": oracle,
        "oracle_window_s": oracle_window,
        "oracle_median_lag_s": (
            float(np.median(oracle_lags)) if len(oracle_lags) > len(seeds) / 2 else None
        ),
    }


def hover(noise: float, spots: list[int], seconds: float, seeds: list[int]) -> dict[str, Any]:
    """Hover at ``spots`` for each seed (flight seed ``seed + spot``), pooled, against the oracle.

    The oracle's time constant is the best of the grid on the pooled median; the per-seed
    ratios (each seed's six flights against the oracle on the same flights) give the spread.
    """
    flights = [
        fly(_scenario_for_spot(i), seconds, noise, seed + i) for seed in seeds for i in spots
    ]
    r_true = [
        long_run_variance_n2(f.obs_n[f.t_s >= 2.0] - f.true_tension_n[f.t_s >= 2.0])
        for f in flights
    ]
    per_tau = {}
    for tau in TAU_GRID_S:
        per_tau[tau] = [oracle_estimates(f, tau, r) for f, r in zip(flights, r_true, strict=True)]

    def pooled(sel: list[int], ests: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, ...]:
        p = np.concatenate([_pos_err(flights[k], ests[k][1]) for k in sel])
        t = np.concatenate([_tension_err(flights[k], ests[k][0]) for k in sel])
        return float(np.median(p)), float(np.percentile(p, 95)), float(np.sqrt(np.mean(t**2)))

    ours = [(f.est_tension_n, f.est_pos_m) for f in flights]
    everything = list(range(len(flights)))
    by_tau = {tau: pooled(everything, e) for tau, e in per_tau.items()}
    best = min(by_tau, key=lambda k: by_tau[k][0])
    o_med, o_p95, o_rms = pooled(everything, ours)
    b_med, b_p95, b_rms = by_tau[best]
    per_seed = []
    for j, seed in enumerate(seeds):
        sel = list(range(j * len(spots), (j + 1) * len(spots)))
        mine, orc = pooled(sel, ours), pooled(sel, per_tau[best])
        per_seed.append((seed, *(a / b for a, b in zip(mine, orc, strict=True))))
    per_spot = []
    for n, i in enumerate(spots):
        e = np.concatenate(
            [
                _pos_err(flights[j * len(spots) + n], ours[j * len(spots) + n][1])
                for j in range(len(seeds))
            ]
        )
        per_spot.append((PAPER_HOVER_SPOTS_M[i], float(np.median(e)), float(np.percentile(e, 95))))
    t_cover, p_cover = within_2_sigma(flights)
    return {
        "noise": noise,
        "seeds": list(seeds),
        "tension_within_2_sigma": t_cover,
        "position_within_2_sigma": p_cover,
        "ours_median_m": o_med,
        "ours_p95_m": o_p95,
        "ours_tension_rms_n": o_rms,
        "oracle_tau_s": best,
        "oracle_median_m": b_med,
        "oracle_p95_m": b_p95,
        "oracle_tension_rms_n": b_rms,
        "oracle_by_tau": {tau: (v[0], v[2]) for tau, v in by_tau.items()},
        "per_seed_ratios": per_seed,
        "true_sigma_n": float(np.sqrt(np.mean([np.mean(r) for r in r_true]))),
        "per_spot": per_spot,
        "changes": sum(f.changes for f in flights),
    }


def false_tugs(noise: float, seconds: float, seed: int) -> dict[str, Any]:
    f = fly(_scenario_for_spot(0), seconds, noise, seed)
    return {"noise": noise, "hover_s": float(f.t_s[-1] - f.t_s[0]), "detections": f.changes}


def tug(noise: float, seeds: list[int]) -> dict[str, Any]:
    name = _tug_scenario()
    start, end = 10.0, 15.0
    grid = np.arange(0.0, end - start, 0.01)
    est_ch, true_ch, orc_ch, settle, orc_settle, detected = [], [], [], [], [], []
    told_ch: dict[float, list[np.ndarray]] = {tau: [] for tau in TAUS_S}
    told_det: list[float | None] = []
    delays: list[float | None] = []
    r_along, dt_means = [], []
    d = np.array([-1.0, 0.0, 0.0])
    for seed in seeds:
        f = fly(name, end, noise, seed)
        quiet = (f.t_s >= 2.0) & (f.t_s < start)
        r_along.append(float(long_run_variance_n2(f.obs_n[quiet] - f.true_tension_n[quiet])[0]))
        dt_means.append(float(np.mean(f.dt_s[quiet])))
        after = [s - start for s in f.change_stamps_s if s >= start]
        delays.append(after[0] if after else None)
        before = (f.t_s >= start - 2.0) & (f.t_s < start)
        w = f.t_s >= start
        tt = f.t_s[w] - start
        e_before = f.est_tension_n[before].mean(axis=0)
        t_before = f.true_tension_n[before].mean(axis=0)
        est_ch.append(np.interp(grid, tt, (f.est_tension_n[w] - e_before) @ d))
        true_ch.append(np.interp(grid, tt, (f.true_tension_n[w] - t_before) @ d))
        y = f.obs_n[w]
        cum = np.cumsum(y, axis=0) / np.arange(1, len(y) + 1)[:, None]
        orc_ch.append(np.interp(grid, tt, (cum - t_before) @ d))
        err = np.linalg.norm(f.est_tension_n[w] - f.true_tension_n[w], axis=1)
        settle.append(_settle(tt, err))
        orc_settle.append(_settle(tt, np.linalg.norm(cum - f.true_tension_n[w], axis=1)))
        detected.append(f.changes)
        for tau in TAUS_S:  # the estimator issue's baseline told the noise (told_noise.py)
            est_t, det_t = glr_random_walk(f.t_s, f.obs_n, f.true_tension_n, start, tau)
            told_ch[tau].append(np.interp(grid, tt, (est_t[w] - t_before) @ d))
        told_det.append(det_t)
    mean_true = np.mean(true_ch, axis=0)
    target = 0.9 * float(np.mean(mean_true[grid > 0.5]))
    step_n = float(np.mean(mean_true[grid > 0.5]))
    # Information limit of detection: the time at which n samples of the step hold a
    # non-centrality n step^2 / r (level before it known, r the true long-run variance
    # along the pull) equal to the change test's threshold: detected about half the time.
    r_mean, dt_mean = float(np.mean(r_along)), float(np.mean(dt_means))
    h = TensionFilter().fast_threshold(dt_mean)
    info_s = h * r_mean / step_n**2 * dt_mean
    ok_delays = [x for x in delays if x is not None]
    told_t90 = {tau: _first(grid, np.mean(told_ch[tau], axis=0), target) for tau in TAUS_S}
    told_ok = {tau: v for tau, v in told_t90.items() if v is not None}
    told_best = min(told_ok, key=lambda tau: told_ok[tau]) if told_ok else None
    return {
        "told_noise_t90_by_tau_s": {f"{tau:g}": v for tau, v in told_t90.items()},
        "told_noise_best_tau_s": told_best,
        "told_noise_t90_s": None if told_best is None else told_ok[told_best],
        "told_noise_detection_s": [None if x is None else round(x, 2) for x in told_det],
        "told_noise_median_detection_s": _median_or_none(told_det),
        "noise": noise,
        "seeds": len(seeds),
        "t90_s": _first(grid, np.mean(est_ch, axis=0), target),
        "oracle_t90_s": _first(grid, np.mean(orc_ch, axis=0), target),
        "settle_median_s": _median_or_none(settle),
        "oracle_settle_median_s": _median_or_none(orc_settle),
        "unsettled": sum(s is None for s in settle),
        "detections": detected,
        "first_detection_s": [None if x is None else round(x, 2) for x in delays],
        "median_detection_s": float(np.median(ok_delays))
        if len(ok_delays) > len(delays) / 2
        else None,
        "info_limit_s": info_s,
        "threshold": h,
        "true_sigma_along_n": math.sqrt(float(np.mean(r_along))),
    }


def _true_at(run: Any, stamps_s: np.ndarray) -> np.ndarray:
    """True drone positions (n, 3) at the simulator's truth stamps nearest to ``stamps_s``."""
    keys = np.array(sorted(run.truth))
    idx = np.clip(np.searchsorted(keys, stamps_s), 0, len(keys) - 1)
    return np.array([run.truth[float(keys[i])]["position_m"] for i in idx], dtype=float)


def _refusals(pipe: Pipeline) -> int:
    status = pipe.status(DRONE, math.inf) or {}
    return int(status.get("drops", {}).get("follow_refused", 0))


def follow_flights(
    noise: float, seeds: list[int], mocap: bool, calibration: str = "truth"
) -> dict[str, Any]:
    """The ``follow`` and ``tug_landing`` scenarios in closed loop.

    ``calibration``: ``truth`` (the drawn errors as ``[calibration]``), ``none`` (every
    drawn error uncorrected; the service refuses follow without motion capture then), or
    ``declared`` (uncorrected, but ``[calibration] source`` set, so the service takes the
    defaults for a calibration and follows: what it did before it refused).

    ``follow``: the operator enables following (threshold 0.15 N) at 3 s, a hand pulls
    with ~0.2 N at 6-8 s and 14-16 s. ``tug_landing``: the same with ``land_below_m``
    0.25 m, pulled down and toward the base from 6 s. Counted per flight: setpoints before
    the operator enabled following (must be 0), the drone's true displacement along each
    pull (from the pull's start to 0.5 s after its end), time with following active and no
    hand pulling, Stops (``follow``: must be 0; ``tug_landing``: exactly 1, after the pull
    began), and whether the motors were stopped at the end.
    """
    fol_sc, land_sc = SCENARIOS["follow"], SCENARIOS["tug_landing"]
    enable_s = fol_sc.operator[0][0]
    along: list[list[float]] = [[] for _ in fol_sc.pulls]
    early_sp, fol_stops, free_active = [], [], []
    stops, early_stops, landed, z_stop, stop_delay = [], [], 0, [], []
    refused: list[int] = []
    for seed in seeds:
        cal: dict[str, Any] | None = None  # "none"
        if calibration == "truth":
            cal = _true_calibration(noise, seed, {}, "follow")
        elif calibration == "declared":
            cal = {"source": "declared, not calibrated"}
        settings = _settings(noise, seed, {}, cal, mocap)
        run, pipe, _ = closed_loop(settings, "follow", fol_sc.duration_s or 22.0)
        refused.append(_refusals(pipe))
        early_sp.append(sum(1 for sp in run.setpoints if sp["stamp_s"] < enable_s))
        fol_stops.append(len(run.stops))
        t = np.array([e["stamp_s"] for e in run.estimates])
        active = np.array([bool(e["follow"]["active"]) for e in run.estimates])
        in_pull = np.zeros(t.size, dtype=bool)
        for j, pull in enumerate(fol_sc.pulls):
            in_pull |= (t >= pull.start_s) & (t < pull.end_s + 0.5)
            a, b = _true_at(run, np.array([pull.start_s, pull.end_s + 0.5]))
            f = np.asarray(pull.force_world_n, dtype=float)
            along[j].append(float((b - a) @ f / np.linalg.norm(f)))
        dt = float(np.median(np.diff(t)))
        free_active.append(float(np.sum(active & ~in_pull)) * dt)

        run, pipe, sim = closed_loop(settings, "tug_landing", land_sc.duration_s or 16.0)
        refused.append(_refusals(pipe))
        pull0 = land_sc.pulls[0]
        stops.append(len(run.stops))
        early_stops.append(sum(1 for st in run.stops if st["stamp_s"] < pull0.start_s))
        landed += int(not sim.drones[DRONE].armed)
        if run.stops:
            t_stop = float(run.stops[0]["stamp_s"])
            stop_delay.append(t_stop - pull0.start_s)
            z_stop.append(float(_true_at(run, np.array([t_stop]))[0, 2]))
    return {
        "noise": noise,
        "mocap": mocap,
        "calibration": calibration,
        "seeds": len(seeds),
        "follow_refused": sum(refused),
        "flights": len(refused),
        "setpoints_before_enable": early_sp,
        "along_pull_m": [float(np.mean(v)) for v in along],
        "active_without_pull_s": float(np.mean(free_active)),
        "follow_stops": fol_stops,
        "landing_stops": stops,
        "stops_before_pull": early_stops,
        "landed": landed,
        "stop_after_pull_s": float(np.median(stop_delay)) if stop_delay else None,
        "z_at_stop_m": float(np.median(z_stop)) if z_stop else None,
        "z_at_stop_range_m": [min(z_stop), max(z_stop)] if z_stop else None,
    }


def _settle(t: np.ndarray, err: np.ndarray, tol: float = 0.003) -> float | None:
    bad = np.flatnonzero(~(err <= tol))
    if len(bad) == 0:
        return 0.0
    if bad[-1] + 1 >= len(t):
        return None
    return float(t[bad[-1] + 1])


def _first(grid: np.ndarray, values: np.ndarray, level: float) -> float | None:
    hit = np.flatnonzero(values >= level)
    return float(grid[hit[0]]) if len(hit) else None


def _median_or_none(values: list[float | None]) -> float | None:
    ok = [v for v in values if v is not None]
    return float(np.median(ok)) if len(ok) > len(values) / 2 else None


def envelope(spots: list[int], seconds: float, seed: int) -> list[dict[str, Any]]:
    """One error class at a time (vibration 1.0 m/s^2 on in all), uncalibrated."""
    base_off = {c: False for c in ALL_CLASSES}
    base_off["vibration"] = True
    rows = []
    for cls in ("none", *ERROR_CLASSES):
        classes = dict(base_off)
        if cls != "none":
            classes[cls] = True
            if cls == "thrust_map":
                classes["battery"] = True
        errs = np.concatenate(
            [
                _pos_err(f, f.est_pos_m)
                for f in (
                    fly(
                        _scenario_for_spot(i),
                        seconds,
                        1.0,
                        seed + i,
                        classes=classes,
                        calibrated=False,
                    )
                    for i in spots
                )
            ]
        )
        rows.append(
            {
                "class": cls,
                "median_m": float(np.median(errs)),
                "p95_m": float(np.percentile(errs, 95)),
            }
        )
    return rows


def _cm(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:.1f} cm"


def _s(v: float | None) -> str:
    return "not reached" if v is None else f"{v:.2f} s"


def _render_move(res: dict[str, Any]) -> list[str]:
    L = [
        "## A move between hover spots, without motion capture",
        "",
        f"Hover at the paper's spot {MOVE_FROM} {PAPER_HOVER_SPOTS_M[MOVE_FROM]}; at "
        f"{MOVE_AT_S:g} s the controller's target becomes spot {MOVE_TO} "
        f"{PAPER_HOVER_SPOTS_M[MOVE_TO]}. Arrival: s after the target changed until the "
        "position stays within 10 % of the distance of the new spot for 1 s (90 % of the "
        "move), for the truth and for the published estimate; lag = estimate − truth. "
        "'never' = not within the flight's "
        f"{MOVE_END_S - MOVE_AT_S:g} s. Oracle, in the same flights: the true tension "
        "localized by the service's catenary, as it is or its mean over the last "
        + ", ".join(f"{w:g}" for w in MOVE_ORACLE_WINDOWS_S[1:])
        + " s, the earliest arrival of these per flight (the window in brackets): what a "
        "quasi-static localization told the tension could do while the tether still swings "
        "after the move.",
        "",
        "| accel noise | seeds | truth arrives, s | estimate arrives, s | median lag s "
        "| oracle arrives, s (window s) | oracle median lag s |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]

    def fmt(xs: list[float | None]) -> str:
        return ", ".join("never" if x is None else f"{x:.1f}" for x in xs)

    for r in res["move"]:
        lag = r["median_lag_s"]
        olag = r["oracle_median_lag_s"]
        L.append(
            f"| {r['noise']:g} m/s^2 | {', '.join(map(str, r['seeds']))} | "
            f"{fmt(r['truth_arrival_s'])} | {fmt(r['estimate_arrival_s'])} | "
            + ("never (most seeds)" if lag is None else f"{lag:.1f}")
            + " | "
            + ", ".join(
                "never" if a is None else f"{a:.1f} ({w:g})"
                for a, w in zip(r["oracle_arrival_s"], r["oracle_window_s"], strict=True)
            )
            + " | "
            + ("never (most seeds)" if r["oracle_median_lag_s"] is None else f"{olag:.1f}")
            + " |"
        )
    L.append("")
    return L


def render(res: dict[str, Any], cmd: str, wall_s: float) -> str:
    """The page, with the sections ``res`` holds (all of them in a full run)."""
    L = [
        "# Realistic-simulator benchmark",
        "",
        f"Generated by `{cmd}` ({wall_s:.0f} s wall time, commit {res['commit']}, Python "
        f"{platform.python_version()}, {platform.machine()}).",
        "",
        "Profile **realistic** (`groundstation/sim/`, docs/simulator.md): rigid body, motor lag "
        "(30 ms), rotor drag, yaw swing, lumped-mass tether; vibration noise white + AR(0.6) with "
        "lag-1 0.2; IMU ~100 Hz, 6-27 ms spacing; per flight drawn accelerometer misalignment "
        "(<= 3 deg), scale (<= 2.5 %), bias, thrust axis (-0.037, -0.016) rad, thrust map "
        "1/1.10 and its drift with a sagging battery (`vbat_v` in Telemetry). No motion capture "
        "reaches the service. The service is not told the noise level (`[drone] accel_noise_mps2` "
        "= 0.3 default). Method: the module docstring of `benchmarks/bench_realistic.py`.",
        "",
    ]
    if "hover" in res:
        L += _render_hover(res)
    if "false" in res:
        L += _render_false(res)
    if "tug" in res:
        L += _render_tug(res)
    if "move" in res:
        L += _render_move(res)
    if "follow" in res:
        L += _render_follow(res)
    if "envelope" in res:
        L += _render_envelope(res)
    L += _render_reading(res)
    return "\n".join(L)


def _render_hover(res: dict[str, Any]) -> list[str]:
    L = [
        "## Hover at the paper's six spots, calibration = the simulator's truth",
        "",
        f"Error from {STEADY_FROM_S:.0f} s to {res['hover_seconds']:.0f} s of hover, pooled over "
        f"the spots ({res['spots']} spots) and the seeds (one flight per spot and seed, flight "
        "seed = seed + spot index). Oracle: a fixed Kalman filter told the true noise, with "
        f"the best hover time constant of {', '.join(f'{t:g}' for t in TAU_GRID_S)} s (on the "
        "pooled median), same localization, on the full model's observations with every "
        "drawn error of the flight known (its accelerometer bias too), the accelerometer's "
        "mean trusted as read. Ours has the airframe's constants only and learns the "
        "accelerometer's per-power-on error in flight (the slow stage, "
        "docs/estimator_design.md): at hover it rests the slow part of the observation on "
        "thrust and attitude, not on the accelerometer's mean, which the oracle does not do, so "
        "a ratio below 1 is the slow stage's gain, not a fault of the oracle's maths; no oracle "
        "of the hover model is computed here. Target: ours within 1.2x the "
        "oracle. Per seed: each seed's six flights against the oracle on the same flights, "
        "the range over the seeds (median / p95 / tension RMS ratios). Seeds 100-400 were "
        "the ones the hover time constant was studied on; these are others.",
        "",
        "| accel noise | seeds | ours median / p95 | oracle median / p95 (tau) "
        "| ratio median / p95 | tension RMS ours / oracle | ratio | per seed: ratio ranges "
        "| within 1.2x |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for h in res["hover"]:
        rm = h["ours_median_m"] / h["oracle_median_m"]
        rp = h["ours_p95_m"] / h["oracle_p95_m"]
        rt = h["ours_tension_rms_n"] / h["oracle_tension_rms_n"]
        ps = h["per_seed_ratios"]
        spread = " / ".join(
            f"{min(x[k] for x in ps):.2f}-{max(x[k] for x in ps):.2f}" for k in (1, 2, 3)
        )
        worst = max(max(x[1:]) for x in ps)
        ok = "yes" if max(rm, rp, rt) <= 1.2 else "**no**"
        ok += "; every seed" if worst <= 1.2 else f"; **not every seed** (worst {worst:.2f})"
        L.append(
            f"| {h['noise']:.1f} m/s^2 | {', '.join(str(x) for x in h['seeds'])} "
            f"| {_cm(h['ours_median_m'])} / {_cm(h['ours_p95_m'])} | "
            f"{_cm(h['oracle_median_m'])} / {_cm(h['oracle_p95_m'])} ({h['oracle_tau_s']:g} s) | "
            f"{rm:.2f} / {rp:.2f} | {1e3 * h['ours_tension_rms_n']:.2f} / "
            f"{1e3 * h['oracle_tension_rms_n']:.2f} mN | {rt:.2f} | {spread} | {ok} |"
        )
    L += [
        "",
        "Is the published σ honest? The share of per-axis errors within twice the published "
        "σ over the same samples (`tension_std_n`, `position_std_m`; a consistent estimator: "
        "about 95 %): "
        + "; ".join(
            f"{h['noise']:g} m/s^2: tension {100 * h['tension_within_2_sigma']:.0f} %, "
            f"position {100 * h['position_within_2_sigma']:.0f} %"
            for h in res["hover"]
        )
        + ".",
    ]
    L += ["", "Oracle median position error by time constant (tension RMS):", ""]
    for h in res["hover"]:
        cells = ", ".join(
            f"{tau:g} s: {_cm(v[0])} ({1e3 * v[1]:.2f} mN)" for tau, v in h["oracle_by_tau"].items()
        )
        L.append(f"- {h['noise']:.1f} m/s^2: {cells}")
    L += ["", "Per spot, ours, pooled over the seeds (median / p95):", ""]
    for h in res["hover"]:
        cells = "; ".join(f"{s} {_cm(m)} / {_cm(p)}" for s, m, p in h["per_spot"])
        L.append(f"- {h['noise']:.1f} m/s^2: {cells}")
    L.append("")
    return L


def _render_false(res: dict[str, Any]) -> list[str]:
    L = [
        "## False tug detections at hover",
        "",
        "| accel noise | hover time | detections |",
        "| --- | --- | --- |",
    ]
    for f in res["false"]:
        L.append(f"| {f['noise']:.1f} m/s^2 | {f['hover_s'] / 60:.1f} min | {f['detections']} |")
    L.append("")
    return L


def _render_tug(res: dict[str, Any]) -> list[str]:
    L = [
        "## 30 mN tug toward the base",
        "",
        "t90: the seed-averaged estimated change along the pull reaches 90 % of the true change. "
        "Settle: the error norm stays within 3 mN (10 %) for the rest of the 5 s pull (median "
        "over seeds; 'not reached' when most seeds never settle). Told the noise: the "
        "estimator issue's baseline (benchmarks/told_noise.py: a GLR told the true long-run "
        "noise and the level before the pull, at 0.005 false alarms per hour, then a "
        "random-walk filter; t90 at its best time constant, chosen in hindsight, and its "
        "median detection). Step oracle: the mean of the "
        "observations since the step, its time known. Detection: the first change detection "
        "after the pull began, per seed ('-': none in the 5 s), and its median; information "
        "limit: the time at which the step's samples, the level before it known, hold a "
        "non-centrality n step^2 / r equal to the change test's threshold h (column h, set "
        f"for {TensionFilterParams().false_alarms_per_h:g} false alarms per hour; r the true "
        "long-run noise variance along the pull, measured in the same flights): a test at that "
        "false-alarm rate detects the step about half the time by then.",
        "",
        "| accel noise | seeds | t90 ours / oracle | t90 told the noise (best τ) | settle ours / "
        "oracle | never settled | detections per seed | first detection per seed | median "
        "detection / information limit (h) / told the noise |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for t in res["tug"]:
        firsts = ", ".join("-" if x is None else f"{x:.2f}" for x in t["first_detection_s"])
        L.append(
            f"| {t['noise']:.1f} m/s^2 | {t['seeds']} | {_s(t['t90_s'])} / "
            f"{_s(t['oracle_t90_s'])} | {_s(t.get('told_noise_t90_s'))}"
            + (
                f" ({t['told_noise_best_tau_s']:g} s)"
                if t.get("told_noise_best_tau_s") is not None
                else ""
            )
            + f" | {_s(t['settle_median_s'])} / {_s(t['oracle_settle_median_s'])} | "
            f"{t['unsettled']} | {t['detections']} | {firsts} s | "
            f"{_s(t['median_detection_s'])} / {_s(t['info_limit_s'])} ({t['threshold']:.1f}) / "
            f"{_s(t.get('told_noise_median_detection_s'))} |"
        )
    L.append("")
    return L


def _render_follow(res: dict[str, Any]) -> list[str]:
    L = [
        "## Tension following and tug-to-land",
        "",
        "The scenarios of the results page's section (a), here on the realistic profile: "
        "`follow` (following enabled at 3 s with threshold 0.15 N; a hand pulls ~0.2 N at "
        "6-8 s and 14-16 s) and `tug_landing` (the same with `land_below_m` 0.25 m; a pull "
        "down and toward the base from 6 s). *mocap*: the service gets the motion-capture "
        "position (the paper's follow mode); *tether*: IMU, attitude and thrust only. Moved "
        "along pull: the drone's true displacement along the pull's direction from its start "
        "to 0.5 s after its end, mean over seeds (+: it yields). Active with no pull: time "
        "with following active outside the pulls (and 0.5 s after them), mean per flight. "
        "Stops per flight: `follow` must send none, `tug_landing` exactly one after the pull "
        "began. Calibration: *truth* (the simulator's drawn errors, as for hover), or "
        "*none* (every drawn error uncorrected), or none but *declared* (`[calibration] "
        "source` set over the defaults: the service takes them for a calibration, as it did "
        "for every drone before it refused follow without motion capture and without a "
        "calibration). Follow refused: the operator's command was rejected.",
        "",
        "| accel noise | position | calibration | seeds | follow refused "
        "| setpoints before enabled | moved along pull 1 / 2 "
        "| active with no pull | Stops in follow | Stops in tug_landing (before the pull) "
        "| landed | pull -> Stop | true z at Stop, median (range) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for f in res["follow"]:
        moved = " / ".join(f"{m:.2f} m" for m in f["along_pull_m"])
        pos = "mocap" if f["mocap"] else "tether"
        cal = {"truth": "truth", "none": "**none**", "declared": "none, *declared*"}[
            f["calibration"]
        ]
        zr = f["z_at_stop_range_m"]
        z_at = "n/a" if zr is None else f"{_cm(f['z_at_stop_m'])} ({_cm(zr[0])}-{_cm(zr[1])})"
        L.append(
            f"| {f['noise']:.1f} m/s^2 | {pos} | {cal} | {f['seeds']} "
            f"| {f['follow_refused']} of {f['flights']} flights "
            f"| {f['setpoints_before_enable']} | {moved} | {f['active_without_pull_s']:.2f} s "
            f"| {f['follow_stops']} | {f['landing_stops']} ({f['stops_before_pull']}) "
            f"| {f['landed']}/{f['seeds']} | {_s(f['stop_after_pull_s'])} "
            f"| {z_at} |"
        )
    L.append("")
    return L


def _render_envelope(res: dict[str, Any]) -> list[str]:
    L = [
        "## Uncalibrated: which error costs how many cm",
        "",
        "Calibration `none`; vibration 1.0 m/s^2 on in every row, plus the one error class "
        f"named; hover at {res['envelope_spots']} spots, error from {STEADY_FROM_S:.0f} s.",
        "",
        "| error class | median | p95 |",
        "| --- | --- | --- |",
    ]
    for e in res["envelope"]:
        L.append(f"| {e['class']} | {_cm(e['median_m'])} | {_cm(e['p95_m'])} |")
    L.append("")
    return L


_BEFORE_SLOW_STAGE = {
    "commit": "b6d0e7c",
    "hover_median_cm": {0.5: 4.6, 1.0: 8.7, 2.0: 17.4},
    "hover_p95_cm": {0.5: 10.5, 1.0: 20.0, 2.0: 39.2},
    "tug_t90_s": {0.5: 0.31, 1.0: 1.98},
    "envelope_median_cm": {"misalignment": 23.2, "accel_scale": 24.2, "accel_bias": 10.5},
}
"""The page's figures before the slow accelerometer stage (the run at b6d0e7c,
``--tug-seeds 8``): what the first bullet of the reading compares with."""


def _render_slow_stage(res: dict[str, Any]) -> list[str]:
    """The first bullet of the reading: this run against the estimator before the slow stage."""
    b = _BEFORE_SLOW_STAGE
    parts = []
    hover = {h["noise"]: h for h in res.get("hover", [])}
    if any(n in b["hover_median_cm"] for n in hover):  # a level the run before was made at
        meds = ", ".join(
            f"{_cm(h['ours_median_m'])} / {_cm(h['ours_p95_m'])} at {n:g} m/s^2 (was "
            f"{b['hover_median_cm'][n]:.1f} / {b['hover_p95_cm'][n]:.1f} cm)"
            for n, h in hover.items()
            if n in b["hover_median_cm"]
        )
        levels = [n for n in hover if n in b["hover_median_cm"]]

        def where(up: bool, key: str, before: dict[float, float]) -> str:
            at = [n for n in levels if (100.0 * hover[n][key] > before[n]) == up]
            return ", ".join(f"{n:g}" for n in at) + " m/s^2" if at else "no level"

        text = (
            f"hover median / p95 {meds}: the median is lower at "
            f"{where(False, 'ours_median_m', b['hover_median_cm'])}, the p95 higher at "
            f"{where(True, 'ours_p95_m', b['hover_p95_cm'])}"
        )
        if any(100.0 * hover[n]["ours_p95_m"] > b["hover_p95_cm"][n] for n in levels):
            text += (
                " (where the hover crossover switches on and off and the near-plumb spot "
                "(0.5, -0.6, 1.0) holds the tail: an open problem, "
                "docs/estimator_design.md)"
            )
        parts.append(text)
    tug = {t["noise"]: t for t in res.get("tug", [])}
    t90s = [
        f"{tug[n]['t90_s']:.2f} s at {n:g} m/s^2 (was {was:.2f} s)"
        for n, was in b["tug_t90_s"].items()
        if n in tug and tug[n].get("t90_s") is not None
    ]
    if t90s:
        parts.append(
            f"the tug's t90 {', '.join(t90s)}: the filter observes the accelerometer model "
            "throughout and takes the hover's thrust balance through the drone's velocity "
            "(tension_kalman.HoverVelocity), so a tug shows in its own innovations at once; "
            "a detection ends the hover (docs/estimator_design.md, *The hover's thrust "
            "balance, an equation of the filter*)"
        )
    env = {e["class"]: e for e in res.get("envelope", [])}
    gone = [
        f"{c} {_cm(env[c]['median_m'])} (was {was:.1f} cm)"
        for c, was in b["envelope_median_cm"].items()
        if c in env
    ]
    if gone:
        none = env.get("none")
        as_none = none is not None and all(
            env[c]["median_m"] <= 1.05 * none["median_m"]
            for c in b["envelope_median_cm"]
            if c in env
        )
        parts.append(
            f"uncalibrated, the accelerometer's own errors cost {', '.join(gone)}"
            + (
                f", within 5 % of vibration alone ({_cm(none['median_m'])}): learnt in flight "
                "at each power-on"
                if as_none and none is not None
                else ""
            )
            + "; the thrust axis and the thrust map are the airframe's constants that "
            "`calibrate` fits"
        )
    if not parts:
        return []
    return [
        f"- **The slow accelerometer stage and the airframe calibration** "
        f"(docs/estimator_design.md) against this page's previous run at "
        f"{b['commit']}, before it: " + "; ".join(parts) + "."
    ]


def _render_reading(res: dict[str, Any]) -> list[str]:
    L = ["## Reading", ""]
    L += _render_slow_stage(res)
    if "tug" in res:
        L += [
            "- The step oracle's t90 is 0 by construction (the mean of the samples since a "
            "known step is unbiased from the first one); its settle time is the information "
            "limit the per-seed settle times compare with.",
            "- Tug detection: the change test (innovation sums, its threshold from the "
            f"filter's false-alarm rate, {TensionFilterParams().false_alarms_per_h:g} per hour "
            "(noise known), 49.7 at 100 Hz, times the noise level's scatter factor, 1.19 at "
            "95 Hz), on the accelerometer model's innovations, finds a 30 mN step at 0.5 m/s^2 "
            "near the information limit in the table. Its longest window is where a 20 mN "
            "step reaches the threshold at the measured noise (at most 8 s; groundstation/"
            "tension.py, TensionFilter docstring). At 1-2 m/s^2 a 30 mN step adds only "
            "(30 mN)^2 / r = 0.5 and 0.125 per sample (r = 2 s2 for this noise), and in a "
            "hover the thrust balance, fused through the velocity state, takes part of the "
            "step in before the threshold is reached, so the innovations no longer show it: "
            "fewer detections there, while the t90 is the estimate's whichever way it "
            "followed. 10 s into a flight the noise estimate is young, and the youth factor "
            "(1.25 there) delays a detection by about that factor.",
        ]
    if "follow" in res:
        rows = res["follow"]
        declared = [f for f in rows if f["calibration"] == "declared"]
        refused = [f for f in rows if f["calibration"] == "none" and not f["mocap"]]
        truth = [f for f in rows if f["calibration"] == "truth" and not f["mocap"]]
        z_hi = [f["z_at_stop_range_m"][1] for f in declared if f["z_at_stop_range_m"]]
        z_truth = [f["z_at_stop_range_m"][1] for f in truth if f["z_at_stop_range_m"]]
        n_ref = sum(f["follow_refused"] for f in refused)
        n_fl = sum(f["flights"] for f in refused)
        L += [
            "- Following without motion capture on an uncalibrated drone is what the "
            "*declared* rows show: the tether-based height is off by most of a metre, so the "
            "first tug's Stop came while the drone was still high (true z at the Stop up to "
            f"{_cm(max(z_hi) if z_hi else None)}; land_below_m is 25 cm). With the calibration "
            f"= truth the highest Stop was at {_cm(max(z_truth) if z_truth else None)}. "
            f"Uncalibrated, the service refused follow in {n_ref} of {n_fl} flights (the rows "
            "*none*, tether); with motion capture the calibration does not matter to it (the "
            "biases read as a steady tension, which the tether's own tension absorbs).",
        ]
    if "hover" in res:
        L += [
            "- Near plumb (the spot (0.5, -0.6, 1.0), H ~ 9 mN) the azimuth is poorly "
            "determined at 2 m/s^2 for ours and the oracle alike; the pooled p95 follows that "
            "spot. There the localization blends the position toward the base as the "
            "filter's P grows, so the position error depends on the filter's memory more "
            "than elsewhere: with a fixed 6 s hover time constant ours reached (before the "
            "slow stage) 2.0x the oracle's p95 on seed 200 (the oracle's best "
            "was 20-40 s); the time constant "
            "now follows the noise (groundstation/tension.py, *Process noise in seconds*).",
            "- With calibration = truth a flight's vertical tension error is its noise's "
            "window mean: at 2 m/s^2 the raw observation's T_z error, averaged over the "
            "hover window, scatters by 2.4 mN (sd over 24 flights, -4.5 to +4.5 mN, e.g. "
            "+3.9 mN at (0.5, -0.6, 1.0), seed 104), and all but -0.04 to +0.13 mN of it is "
            "the vibration noise the simulator drew (`python -m benchmarks.vertical_bias`). "
            "Until this run calibration = truth was the equivalent calibration at the first "
            "spot's attitude for every spot, which added -0.5 to +0.8 mN where the hover "
            "tilt differs (a constant accelerometer bias stands for the per-boot "
            "misalignment at one attitude only, in a real calibration too); each flight now "
            "gets its own.",
        ]
    if "tug" in res:
        L.append(
            "- (Measured before the slow stage.) The hover time constant against "
            "the tug (measured with `--only tug --levels L "
            "--tug-seeds 8 --fixed-tau` at b70b80a: the same flights with the earlier fixed 6"
            " s): detections were those of a long-window step test the filter had then, and did "
            "not depend on it (the same first detections per seed at 2 m/s^2). t90 at 1 m/s^2 "
            "was 2.34 s with 6 s against 1.98 s n"
            "ow; at 2 m/s^2 **3.67 s with 6 s, beyond the 5 s pull now**: in the seeds with n"
            "o detection within the pull the estimate follows the step only at the hover gain"
            ", and a 40 s memory takes 30 mN in more slowly than 6 s. That is the price of th"
            "e hover target at 2 m/s^2 (and of the near-plumb p95): an undetected step's slow"
            "er uptake. The same memory costs a drone that moves from spot to spot without a "
            "detected change: with calibration = truth the calibration benchmark's 12 s dwell"
            "s at 1 m/s^2 read 14.8 cm against 11.4 cm with 6 s (docs/calibration.md). Agains"
            "t the page at 83e6afa (7 of 8 detected at 2 m/s^2) seeds 304 and 305 now go unde"
            "tected with either time constant: a change elsewhere since, not isolated."
        )
    L.append("")
    return L


SECTIONS = ("hover", "false_tugs", "tug", "move", "follow", "envelope")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short run; do not write docs")
    ap.add_argument("--json", type=Path, help="also write the raw results here")
    ap.add_argument(
        "--only",
        help=f"comma-separated sections to run, of {', '.join(SECTIONS)}; prints them and "
        "does not write docs (e.g. --only tug,false_tugs)",
    )
    ap.add_argument(
        "--false-minutes", type=float, help="hover minutes per level in false_tugs (10; quick 1)"
    )
    ap.add_argument("--tug-seeds", type=int, help="seeds per level in tug (4; quick 2)")
    ap.add_argument(
        "--hover-seeds", type=int, help="seeds per spot and level in hover (3; quick 1)"
    )
    ap.add_argument(
        "--fixed-tau",
        action="store_true",
        help="the service's filter with a fixed 6 s hover time constant (hover_wander_n2_per_s "
        "= 0, before it followed the noise), for comparison; with --only",
    )
    ap.add_argument(
        "--levels",
        help="comma-separated accelerometer noise levels, m/s^2 (0.5,1.0,2.0); with --only",
    )
    args = ap.parse_args(argv)
    quick = args.quick
    only = set(SECTIONS) if args.only is None else {x.strip() for x in args.only.split(",")}
    unknown = only - set(SECTIONS)
    if unknown:
        ap.error(f"--only: unknown section(s) {sorted(unknown)}; choose from {SECTIONS}")
    levels = NOISE_LEVELS_MPS2
    if args.levels is not None:
        if args.only is None:
            ap.error("--levels needs --only (a full run writes every level)")
        levels = tuple(float(x) for x in args.levels.split(","))
    if args.fixed_tau:
        if args.only is None:
            ap.error("--fixed-tau needs --only (the page is the default filter's)")
        import groundstation.estimator.drone as drone_mod

        drone_mod.TensionFilterParams = functools.partial(  # type: ignore[misc,assignment]
            TensionFilterParams, hover_wander_n2_per_s=0.0
        )
    t0 = time.time()
    spots = [0, 3] if quick else list(range(6))
    hover_s = 14.0 if quick else 20.0
    log: Callable[[str], None] = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    n_hover = args.hover_seeds or (1 if quick else 3)
    hover_seeds = [HOVER_SEED_BASE + 100 * j for j in range(n_hover)]
    res: dict[str, Any] = {"spots": len(spots), "hover_seconds": hover_s}
    res["commit"] = git_commit()
    if "hover" in only:
        res["hover"] = []
        for noise in levels:
            res["hover"].append(hover(noise, spots, hover_s, hover_seeds))
            log(f"hover {noise}: {res['hover'][-1]}")
    if "false_tugs" in only:
        minutes = args.false_minutes or (1.0 if quick else 10.0)
        res["false"] = []
        for n in levels:
            res["false"].append(false_tugs(n, 60.0 * minutes, 200))
            log(f"false: {res['false'][-1]}")
    if "tug" in only:
        n_seeds = args.tug_seeds or (2 if quick else 4)
        seeds = [300 + i for i in range(n_seeds)]
        res["tug"] = []
        tug_levels = list(levels)
        if args.levels is None:
            tug_levels.append(TUG_ACCEPTANCE_MPS2)  # last: the other levels keep their index
        for n in tug_levels:
            res["tug"].append(tug(n, seeds))
            log(f"tug: {res['tug'][-1]}")
    if "move" in only:
        res["move"] = []
        for n in levels:
            res["move"].append(move(n, [900] if quick else [900, 901, 902, 903]))
            log(f"move: {res['move'][-1]}")
    if "follow" in only:
        follow_seeds = [500, 501, 502, 503] if not quick else [500]
        res["follow"] = []
        rows = ((True, "truth"), (True, "none"), (False, "truth"), (False, "none"))
        rows += ((False, "declared"),)
        for n in levels:
            for mocap, cal in rows:
                res["follow"].append(follow_flights(n, follow_seeds, mocap, cal))
                log(f"follow: {res['follow'][-1]}")
    if "envelope" in only:
        env_spots = [0, 3] if quick else list(range(6))
        res["envelope_spots"] = len(env_spots)
        res["envelope"] = envelope(env_spots, 12.0 if quick else 16.0, 400)
        log(f"envelope: {res['envelope']}")
    cmd = ".venv/bin/python -m benchmarks.bench_realistic" + (" --quick" if quick else "")
    if args.only is not None:
        cmd += f" --only {args.only}"
    if args.false_minutes is not None:
        cmd += f" --false-minutes {args.false_minutes:g}"
    if args.tug_seeds is not None:
        cmd += f" --tug-seeds {args.tug_seeds}"
    if args.hover_seeds is not None:
        cmd += f" --hover-seeds {args.hover_seeds}"
    if args.fixed_tau:
        cmd += " --fixed-tau"
    if args.levels is not None:
        cmd += f" --levels {args.levels}"
    text = render(res, cmd, time.time() - t0)
    print(text)
    if args.json:
        args.json.write_text(json.dumps(res, indent=1, default=str))
    if not quick and args.only is None:
        DOC_PATH.write_text(text)
        figures = {**res, "levels": list(levels)}
        figures["envelope"] = {row["class"]: row for row in res["envelope"]}
        write_figures(DOC_PATH.stem, figures, cmd.split()[3:])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
