"""Closed-loop runs for the results page: simulator ⇄ pipeline, one run per job.

A :class:`SimJob` names a scenario, a duration, the simulator's settings and, optionally,
different settings for the pipeline (the ω-error sweep: the service believes one weight per
metre, the simulated tether has another). :func:`run_job` runs it through
:func:`groundstation.evaluation.closed_loop` (deterministic, no bus, no clock) and returns a
:class:`Trace`: the estimates beside the ground truth, sample by sample, plus what the
service commanded. Jobs are plain data, so a process pool can run them
(:func:`run_jobs`). Each job registers its own scenario in the worker, so this works with
any multiprocessing start method.

Besides what the service publishes, a trace carries the raw tension observation
``T = m·R·f − R·e3·F`` of every telemetry sample *without* ground detection, and the same
tension filter run on those raw observations (``naive``): what an estimator that does not
detect ground contact reports, i.e. the paper's behaviour before lift-off.
"""

from __future__ import annotations

import json
import math
import multiprocessing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from groundstation.bus import Sample
from groundstation.config import Settings, load_settings
from groundstation.evaluation import closed_loop
from groundstation.pipeline import Pipeline
from groundstation.sim import PAPER_HOVER_SPOTS_M, SCENARIOS, Scenario, Waypoint
from groundstation.tension import TensionFilter, rotation_world_body

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "SimJob",
    "Trace",
    "convergence_time_s",
    "hover_scenario",
    "run_job",
    "run_jobs",
]


def hover_scenario(name: str, position_m: tuple[float, float, float]) -> Scenario:
    """Hover at ``position_m`` from t = 0 (the simulator starts it in equilibrium)."""
    return Scenario(
        name,
        f"hover at ({position_m[0]:g}, {position_m[1]:g}, {position_m[2]:g}) m",
        start_m=position_m,
        waypoints=(Waypoint(0.0, position_m),),
    )


PAPER_SPOT_SCENARIOS = tuple(
    hover_scenario(f"results_spot{i}", spot) for i, spot in enumerate(PAPER_HOVER_SPOTS_M)
)


@dataclass(frozen=True)
class SimJob:
    """One closed-loop run.

    Attributes:
        key: identifier of the run in the results (unique per job).
        scenario: the scenario (registered in :data:`groundstation.sim.SCENARIOS` by name).
        seconds: simulated duration, s.
        sim: ``[sim]`` overrides (``seed``, ``mocap``, noise, thrust bias, ...).
        shared: other tables applied to both the simulator and the pipeline
            (``{"tether": {"length_m": 2.0}}``).
        pipeline: tables applied to the pipeline only (``{"tether": {"weight_n_per_m": …}}``).
        naive: also run the tension filter on the raw observations without ground detection.
        reduce: ``"trace"`` keeps every sample; ``"error"`` keeps only what the envelope
            needs (time, position error, availability), to keep the transfer small.
    """

    key: str
    scenario: Scenario
    seconds: float
    sim: Mapping[str, Any] = field(default_factory=dict)
    shared: Mapping[str, Any] = field(default_factory=dict)
    pipeline: Mapping[str, Any] | None = None
    naive: bool = False
    reduce: str = "trace"


@dataclass(frozen=True)
class Trace:
    """Estimates and truth of one run, aligned per telemetry sample (n samples).

    Arrays are float64 with NaN where the service published no value (e.g. ``est_pos_m``
    before convergence or on the ground). Tension is the force on the drone, world frame, N;
    positions are world frame, m.
    """

    key: str
    t_s: FloatArray  # (n,)
    est_tension_n: FloatArray  # (n, 3)
    est_std_n: FloatArray  # (n, 3)
    est_pos_m: FloatArray  # (n, 3)
    est_pos_std_m: FloatArray  # (n, 3)
    est_on_ground: BoolArray  # (n,)
    azimuth_determined: BoolArray  # (n,)
    follow_active: BoolArray  # (n,)
    true_pos_m: FloatArray  # (n, 3)
    true_tension_n: FloatArray  # (n, 3)
    true_on_ground: BoolArray  # (n,)
    true_floor_contact: BoolArray  # (n,)
    raw_tension_n: FloatArray  # (n, 3) raw observation, no ground detection
    naive_tension_n: FloatArray  # (n, 3) filter on raw observations (NaN unless job.naive)
    setpoints: FloatArray  # (k, 4): stamp_s, x, y, z
    stops: tuple[tuple[float, str], ...]
    final_armed: bool
    final_pos_m: FloatArray  # (3,)
    weight_n_per_m: float  # the simulated tether's ω

    @property
    def pos_error_m(self) -> FloatArray:
        """3D position error per sample, m (NaN where no position was published)."""
        return np.asarray(np.linalg.norm(self.est_pos_m - self.true_pos_m, axis=1))


def _deep_merge(base: Mapping[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in patch.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = v
    return out


def _settings(job: SimJob, for_pipeline: bool) -> Settings:
    layered = _deep_merge(job.shared, {"sim": {**job.sim, "scenario": job.scenario.name}})
    if for_pipeline and job.pipeline:
        layered = _deep_merge(layered, job.pipeline)
    return load_settings(None, layered, use_env=False)


class _TapPipeline(Pipeline):
    """The service's pipeline, also keeping each telemetry payload (for the raw observation)."""

    def __init__(self, settings: Settings) -> None:
        super().__init__(settings)
        self.telemetry: dict[float, dict[str, Any]] = {}

    def handle(self, sample: Sample, now_s: float) -> list[Sample]:
        if sample.key.endswith("/telemetry"):
            msg = json.loads(sample.payload)
            self.telemetry[round(float(msg["stamp_s"]), 6)] = msg
        return super().handle(sample, now_s)


def _raw_observation(msg: Mapping[str, Any], mass_kg: float) -> FloatArray:
    # eq:NE_tether without ground detection: T = R (m f − e3 F)
    R_world_body = rotation_world_body(msg["quat_wxyz"])
    force_body_n = mass_kg * np.asarray(msg["accel_mps2"], dtype=float)
    force_body_n[2] -= float(msg["thrust_n"])
    return np.asarray(R_world_body @ force_body_n)


def _vec(value: Any) -> list[float]:
    return [math.nan] * 3 if value is None else [float(v) for v in value]


def run_job(job: SimJob) -> Trace:
    """Run one job in this process (registers its scenario first)."""
    SCENARIOS[job.scenario.name] = job.scenario
    sim_settings = _settings(job, for_pipeline=False)
    pipe = _TapPipeline(_settings(job, for_pipeline=True))
    run, _, sim = closed_loop(sim_settings, job.scenario.name, job.seconds, pipeline=pipe)
    drone = next(iter(sim.drones.values()))
    mass_kg = pipe.settings.drone.mass_kg

    ests = run.estimates
    n = len(ests)
    t = np.array([e["stamp_s"] for e in ests], dtype=float)
    truths = [run.truth_at(e["stamp_s"]) for e in ests]
    tele = [pipe.telemetry[round(e["stamp_s"], 6)] for e in ests]
    raw = np.array([_raw_observation(m, mass_kg) for m in tele]).reshape(n, 3)
    naive = np.full((n, 3), math.nan)
    if job.naive:
        filt = TensionFilter()
        last: float | None = None
        for i, m in enumerate(tele):
            dt = 0.0 if last is None else float(m["stamp_s"]) - last
            last = float(m["stamp_s"])
            naive[i] = filt.update(raw[i], dt, m["quat_wxyz"]).tension_world_n
    setpoints = np.array(
        [[s["stamp_s"], *s["position_m"]] for s in run.setpoints], dtype=float
    ).reshape(-1, 4)
    return Trace(
        key=job.key,
        t_s=t,
        est_tension_n=np.array([e["tension_n"] for e in ests], dtype=float).reshape(n, 3),
        est_std_n=np.array([e["tension_std_n"] for e in ests], dtype=float).reshape(n, 3),
        est_pos_m=np.array([_vec(e["position_m"]) for e in ests]).reshape(n, 3),
        est_pos_std_m=np.array([_vec(e.get("position_std_m")) for e in ests]).reshape(n, 3),
        est_on_ground=np.array([bool(e["on_ground"]) for e in ests]),
        azimuth_determined=np.array([bool(e.get("azimuth_determined")) for e in ests]),
        follow_active=np.array([bool(e["follow"]["active"]) for e in ests]),
        true_pos_m=np.array([tr["position_m"] for tr in truths], dtype=float).reshape(n, 3),
        true_tension_n=np.array([tr["tension_n"] for tr in truths], dtype=float).reshape(n, 3),
        true_on_ground=np.array([bool(tr["on_ground"]) for tr in truths]),
        true_floor_contact=np.array([bool(tr["floor_contact"]) for tr in truths]),
        raw_tension_n=raw,
        naive_tension_n=naive,
        setpoints=setpoints,
        stops=tuple((float(s["stamp_s"]), str(s["reason"])) for s in run.stops),
        final_armed=bool(drone.armed),
        final_pos_m=np.array(drone.position_world_m, dtype=float),
        weight_n_per_m=float(sim_settings.tether.weight_n_per_m),
    )


@dataclass(frozen=True)
class ErrorTrace:
    """What an envelope point needs from a run (see ``SimJob.reduce``)."""

    key: str
    t_s: FloatArray
    pos_error_m: FloatArray  # 3D, NaN where no position
    pos_error_h_m: FloatArray  # horizontal
    pos_error_z_m: FloatArray  # vertical (signed: estimate − truth)
    airborne: BoolArray
    azimuth_determined: BoolArray
    floor_contact: BoolArray
    tension_error_n: FloatArray  # |T_est − T_true|


class RunnableJob(Protocol):
    """A job of another kind (e.g. a realistic-profile flight of the envelope): a key, a
    simulated duration for the ordering, and its own ``run`` in the worker."""

    @property
    def key(self) -> str: ...

    @property
    def seconds(self) -> float: ...

    def run(self) -> Any: ...


def _run_reduced(job: SimJob | RunnableJob) -> Any:
    if not isinstance(job, SimJob):
        return job.run()
    trace = run_job(job)
    if job.reduce != "error":
        return trace
    return ErrorTrace(
        key=job.key,
        t_s=trace.t_s,
        pos_error_m=trace.pos_error_m,
        pos_error_h_m=np.hypot(*(trace.est_pos_m - trace.true_pos_m)[:, :2].T),
        pos_error_z_m=trace.est_pos_m[:, 2] - trace.true_pos_m[:, 2],
        airborne=~trace.est_on_ground,
        azimuth_determined=trace.azimuth_determined,
        floor_contact=trace.true_floor_contact,
        tension_error_n=np.linalg.norm(trace.est_tension_n - trace.true_tension_n, axis=1),
    )


def run_jobs(
    jobs: Iterable[SimJob | RunnableJob],
    workers: int,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run jobs (longest first) on ``workers`` processes; results by ``key``."""
    ordered = sorted(jobs, key=lambda j: -j.seconds)
    results: dict[str, Any] = {}
    if workers <= 1:
        for job in ordered:
            results[job.key] = _run_reduced(job)
            if progress:
                progress(job.key)
        return results
    # fork: the workers inherit the imports; the caller runs this before anything starts
    # threads (zenoh, viser), and each job registers its own scenario anyway.
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(workers) as pool:
        for out in pool.imap_unordered(_run_reduced, ordered, chunksize=1):
            results[out.key] = out
            if progress:
                progress(out.key)
    return results


def convergence_time_s(
    t_s: FloatArray, error: FloatArray, tolerance: float, start_s: float = 0.0
) -> float | None:
    """Time from ``start_s`` until ``|error|`` stays within ``tolerance`` to the end.

    NaN errors (no estimate yet) count as outside. Returns None if it never settles.
    """
    mask = t_s >= start_s
    tt = t_s[mask]
    bad = ~(np.abs(error[mask]) <= tolerance)
    if tt.size == 0 or bad[-1]:
        return None
    idx = np.flatnonzero(bad)
    first_ok = 0 if idx.size == 0 else int(idx[-1]) + 1
    return float(tt[first_ok] - start_s)
