"""The envelope: position error against what a user gets wrong or cannot choose.

Section (d) of the results page. One sweep per factor, everything else nominal (the
simulator's defaults: accelerometer noise 0.3 m/s², thrust noise 3 mN, no thrust bias,
ω = 0.05 N/m known exactly, L = 1.6 m, base at (0, 0, 0.754) m), no motion capture:

* accelerometer noise σ (the service is configured with the same σ, as a user who
  measured it would be);
* thrust bias (the thrust the drone reports is (1 + b) times what its rotors give);
* ω error: the service is configured with ω·(1 + e) while the simulated tether weighs ω
  (:class:`~benchmarks.results_sim.SimJob` ``pipeline`` settings);
* tether length (both sides know it; long tethers rest on the floor);
* horizontal distance from the base at z = 1 m (several azimuths).

The first four sweeps hover at three of the paper's six spots (quick: one); each point pools
the runs' errors from ``steady_from_s`` on.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.results_sim import PAPER_SPOT_SCENARIOS, ErrorTrace, SimJob, hover_scenario

NOMINAL_WEIGHT_N_PER_M = 0.05
TRUST_P95_M = 0.10  # "trust the estimate" when the 95th percentile error is within this


@dataclass(frozen=True)
class Sweep:
    """One factor: its values and how a value becomes a job's settings."""

    name: str
    label: str  # axis label with unit
    values: tuple[float, ...]
    nominal: float
    settings: Callable[[float], dict[str, Any]]
    by_distance: bool = False


def _accel(v: float) -> dict[str, Any]:
    return {"sim": {"accel_noise_mps2": v}, "shared": {"drone": {"accel_noise_mps2": v}}}


def _bias(v: float) -> dict[str, Any]:
    return {"sim": {"thrust_bias_ratio": v / 100.0}}


def _omega(v: float) -> dict[str, Any]:
    return {"pipeline": {"tether": {"weight_n_per_m": NOMINAL_WEIGHT_N_PER_M * (1 + v / 100)}}}


def _length(v: float) -> dict[str, Any]:
    return {"shared": {"tether": {"length_m": v}}}


def _distance(v: float) -> dict[str, Any]:
    return {}


def sweeps(quick: bool) -> tuple[Sweep, ...]:
    if quick:
        return (
            Sweep("accel_noise", "accelerometer noise σ (m/s²)", (0.3, 1.0), 0.3, _accel),
            Sweep("thrust_bias", "thrust bias (%)", (0.0, 3.0), 0.0, _bias),
            Sweep("omega_error", "ω configured vs true (%)", (-10.0, 0.0, 10.0), 0.0, _omega),
            Sweep("length", "tether length L (m)", (1.6, 3.0), 1.6, _length),
            Sweep(
                "distance",
                "horizontal distance from the base r (m)",
                (0.0, 1.0),
                1.0,
                _distance,
                by_distance=True,
            ),
        )
    return (
        Sweep(
            "accel_noise", "accelerometer noise σ (m/s²)", (0.1, 0.3, 0.6, 1.0, 2.0), 0.3, _accel
        ),
        Sweep("thrust_bias", "thrust bias (%)", (0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0), 0.0, _bias),
        Sweep(
            "omega_error",
            "ω configured vs true (%)",
            (-20.0, -10.0, -5.0, -2.0, 0.0, 2.0, 5.0, 10.0, 20.0),
            0.0,
            _omega,
        ),
        Sweep("length", "tether length L (m)", (1.3, 1.6, 2.0, 2.25, 2.5, 3.0, 4.0), 1.6, _length),
        Sweep(
            "distance",
            "horizontal distance from the base r (m)",
            (0.0, 0.1, 0.2, 0.3, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4),
            1.0,
            _distance,
            by_distance=True,
        ),
    )


@dataclass(frozen=True)
class EnvelopePlan:
    quick: bool
    seconds: float
    steady_from_s: float
    spots: tuple[int, ...]  # which of the paper's spots (indices) each point flies
    azimuths: int  # distance sweep: azimuths per point


def plan(quick: bool) -> EnvelopePlan:
    if quick:
        return EnvelopePlan(True, 4.0, 1.5, (0,), 1)
    # The far spot, the low one and the one at the widest azimuth: three geometries.
    return EnvelopePlan(False, 8.0, 2.0, (0, 3, 4), 2)


def jobs(p: EnvelopePlan) -> list[SimJob]:
    out: list[SimJob] = []
    for sw in sweeps(p.quick):
        for vi, v in enumerate(sw.values):
            extra = sw.settings(v)
            if sw.by_distance:
                scenarios = []
                for a in range(p.azimuths):
                    az = 2.0 * math.pi * a / p.azimuths + 0.3
                    pos = (round(v * math.cos(az), 6), round(v * math.sin(az), 6), 1.0)
                    scenarios.append(hover_scenario(f"results_r{vi}_{a}", pos))
            else:
                scenarios = [PAPER_SPOT_SCENARIOS[i] for i in p.spots]
            for k, sc in enumerate(scenarios):
                out.append(
                    SimJob(
                        key=f"env/{sw.name}/{vi}/{k}",
                        scenario=sc,
                        seconds=p.seconds,
                        sim={"mocap": False, "seed": 1000 + 37 * vi + k, **extra.get("sim", {})},
                        shared=extra.get("shared", {}),
                        pipeline=extra.get("pipeline"),
                        reduce="error",
                    )
                )
    return out


@dataclass(frozen=True)
class Point:
    value: float
    median_m: float
    p95_m: float
    horizontal_median_m: float
    vertical_median_m: float  # median |Δz|
    availability: float  # fraction of steady-window samples with a position
    azimuth_determined: float
    floor_contact: float  # fraction of samples with tether on the floor (truth)


@dataclass(frozen=True)
class SweepResult:
    sweep: Sweep
    points: tuple[Point, ...]

    def trusted_range(self) -> tuple[float, float] | None:
        """The contiguous range of values around the nominal with p95 ≤ TRUST_P95_M."""
        vals = [pt.value for pt in self.points]
        ok = [pt.p95_m <= TRUST_P95_M and pt.availability > 0.5 for pt in self.points]
        if self.sweep.nominal not in vals:
            return None
        i = vals.index(self.sweep.nominal)
        if not ok[i]:
            return None
        lo = hi = i
        while lo > 0 and ok[lo - 1]:
            lo -= 1
        while hi < len(vals) - 1 and ok[hi + 1]:
            hi += 1
        return vals[lo], vals[hi]


def summarize(results: dict[str, Any], p: EnvelopePlan) -> tuple[SweepResult, ...]:
    out = []
    for sw in sweeps(p.quick):
        points = []
        for vi, v in enumerate(sw.values):
            runs: list[ErrorTrace] = [
                results[k] for k in sorted(results) if k.startswith(f"env/{sw.name}/{vi}/")
            ]
            errs, herrs, zerrs, avail, az, floor = [], [], [], [], [], []
            for tr in runs:
                m = tr.t_s >= p.steady_from_s
                e = tr.pos_error_m[m]
                ok = np.isfinite(e)
                errs.append(e[ok])
                herrs.append(tr.pos_error_h_m[m][ok])
                zerrs.append(np.abs(tr.pos_error_z_m[m][ok]))
                avail.append(float(np.isfinite(e).mean()))
                az.append(float(tr.azimuth_determined[m].mean()))
                floor.append(float(tr.floor_contact[m].mean()))
            e = np.concatenate(errs) if errs else np.zeros(0)
            h = np.concatenate(herrs) if herrs else np.zeros(0)
            z = np.concatenate(zerrs) if zerrs else np.zeros(0)
            points.append(
                Point(
                    value=v,
                    median_m=float(np.median(e)) if e.size else math.inf,
                    p95_m=float(np.percentile(e, 95)) if e.size else math.inf,
                    horizontal_median_m=float(np.median(h)) if h.size else math.inf,
                    vertical_median_m=float(np.median(z)) if z.size else math.inf,
                    availability=float(np.mean(avail)),
                    azimuth_determined=float(np.mean(az)),
                    floor_contact=float(np.mean(floor)),
                )
            )
        out.append(SweepResult(sw, tuple(points)))
    return tuple(out)
