"""Cost of the per-message path, stage by stage, for a converged hovering drone.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_pipeline            # writes docs/pipeline_benchmark.md
    .venv/bin/python -m benchmarks.bench_pipeline --quick    # a smoke run, prints only
    .venv/bin/python -m benchmarks.bench_pipeline --json /tmp/after.json --before /tmp/before.json

The telemetry is the service benchmark's (``benchmarks.bench_service``: one drone holding
still against a 63 mN tether pull, the simulator's IMU and thrust noise, 250 Hz), parsed
once. A pipeline takes ``--warmup`` messages first, so the filter has converged and every
message runs the whole path: observation, filter, localization, follow, Estimate.

* ``total``: :meth:`Pipeline.handle` (validation of the bytes included, the Estimate encoded
  to JSON), one call per message, each timed with ``perf_counter_ns``. Reported: the median
  and p90 over all timed messages, and the mean of the best repeat.
* Stages: each stage alone over the same converged messages (mean per call, best of the
  repeats): ``validate`` (key + JSON → Telemetry), ``observe_tension``,
  ``TensionFilter.update`` (a copy of the converged filter fed the stream),
  ``localize``, ``follow_step`` (follow is off: what the pipeline does instead of
  ``follow.follow_step``, whose own cost is the row below), ``estimate`` (the Estimate's
  JSON, ``messages.encode_estimate_ordered``).
* Rows in parentheses, not in the sum: the filter's Kalman step alone, in closed form
  (``tension.DiagonalKalman``, the floor under ``filter_update``) and as filterpy's
  ``KalmanFilter`` predict + update (what that step cost before it was written out),
  ``localize`` over batches (``localization.localize_batch``).
* ``follow on``: :meth:`Pipeline.handle`'s median for the same hover with a motion-capture
  position in every message and follow enabled (no pull: armed, the goal frozen; the whole
  follow step runs, the catenary's own force at that position included).
* What CPython executes: the bytecodes of one message (``sys.settrace`` opcode events, over
  200 messages) and, for scale, the time per bytecode of a loop of float arithmetic and one
  ``math`` call on local variables (CPython's best case with floats).
* The drone rows: 8 drones interleaved, ``Pipeline.process`` one message at a time against
  ``Pipeline.process_batch`` in batches of 32 grouped by drone (the service's drain while a
  backlog exists), CPU time per message, validation not included.

As :mod:`timeit` does, the garbage collector is off while timing. The machine is shared:
compare runs made close together, and trust the best repeat more than one run.
"""

from __future__ import annotations

import argparse
import copy
import gc
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from filterpy.kalman import KalmanFilter

from benchmarks import git
from benchmarks.bench_service import _telemetry_payloads
from benchmarks.figures import write_figures
from groundstation import follow as follow_mod
from groundstation.bus import Sample
from groundstation.evaluation import settings_for
from groundstation.localization import localize, localize_batch
from groundstation.messages import Telemetry
from groundstation.pipeline import Pipeline, _follow_stamped
from groundstation.service import group_by_drone
from groundstation.tension import DiagonalKalman, TensionFilter, observe_tension

DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "pipeline_benchmark.md"
KEY = "tether/d0/telemetry"
STAGES = (
    "validate",
    "observation",
    "gate",
    "contact",
    "slow_accel",
    "filter",
    "localize",
    "follow",
    "estimate",
    "glue",
)
"""The stages of one message, as :mod:`groundstation.estimator` composes them, each timed
inside the real path (:func:`_stage_split`); ``glue`` is what is left of the whole
message's time: the Pipeline's routing, the estimator's counters and rates, the frozen
records between the stages, the published Samples."""
EXTRA = ("kalman_bare", "filterpy_bare", "localize_batch", "follow_step_itself")
"""Not in the sum: the Kalman step alone, closed form and filterpy (the floor under
``filter_update``), and ``localize`` over the batch (``localization.localize_batch``, BATCH
cases per call)."""
BATCH = 32
"""Batch size of the batched rows (the service's ``_MAX_BATCH``)."""
DRONES = 8


def _inv3(S: np.ndarray) -> np.ndarray:
    """Inverse of a 3x3 matrix by its adjugate: S^-1 = adj(S) / det(S).

    Installed as ``KalmanFilter.inv`` for the filterpy row (it was the tension filter's until
    that became three scalar filters in closed form), filterpy's hook for the inverse it needs in
    ``update`` (K = P- C' (C P- C' + R)^-1). There S is symmetric positive definite with
    eigenvalues at least (m sigma_a)^2 = (9 mN)^2, so the adjugate form is as accurate as
    np.linalg.inv's LU (agreement to rounding). A singular or non-finite S takes
    np.linalg.inv, which decides what happens, as before.

    Args:
        S: Shape (3, 3).

    Returns:
        The inverse, shape (3, 3).
    """
    (a, b, c), (d, e, f), (g, h, i) = S.tolist()
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    det = a * c00 + d * c01 + g * c02
    if not (det != 0.0 and math.isfinite(det)):
        return np.asarray(np.linalg.inv(S), dtype=np.float64)
    return (
        np.array(
            [
                [c00, c01, c02],
                [f * g - d * i, a * i - c * g, c * d - a * f],
                [d * h - e * g, b * g - a * h, a * e - b * d],
            ]
        )
        / det
    )


def _best_mean_us(run: Callable[[], int], repeats: int) -> float:
    """Best over ``repeats`` of (time of ``run()``) / (calls it made), µs."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        n = run()
        best = min(best, (time.perf_counter_ns() - t0) / n / 1e3)
    return best


def measure(warmup: int, messages: int, repeats: int, seed: int = 0) -> dict[str, Any]:
    payloads = [row[0] for row in _telemetry_payloads(1, (warmup + messages) / 250.0, seed)]
    warm, timed = payloads[:warmup], payloads[warmup : warmup + messages]
    settings = settings_for()

    def warmed() -> Pipeline:
        pipe = Pipeline(settings)
        for p in warm:
            pipe.handle(Sample(KEY, p), 0.0)
        return pipe

    samples = [Sample(KEY, p) for p in timed]
    gc_was = gc.isenabled()
    gc.disable()
    try:
        # -- total: Pipeline.handle, each message timed
        per_msg: list[float] = []
        means: list[float] = []
        for _ in range(repeats):
            pipe = warmed()
            handle = pipe.handle
            clock = time.perf_counter_ns
            times = []
            for s in samples:
                t0 = clock()
                handle(s, 0.0)
                times.append(clock() - t0)
            assert pipe.drones["d0"].estimates == warmup + messages, "a message was dropped"
            per_msg.extend(times)
            means.append(sum(times) / len(times) / 1e3)
        per_msg_us = np.array(per_msg) / 1e3

        # -- stages, on the converged state
        pipe = warmed()
        rt = pipe.drones["d0"]
        mass_kg = rt.params.drone.mass_kg
        floor_z_m = rt.params.base.floor_z_m
        msgs = [Telemetry.parse(p) for p in timed]
        obs = [
            observe_tension(m.accel_mps2, m.quat_wxyz, m.thrust_n, mass_kg, armed=m.armed)
            for m in msgs
        ]
        filt0: TensionFilter = copy.deepcopy(rt.filter)
        ests = []
        f = copy.deepcopy(filt0)
        for m, o in zip(msgs, obs, strict=True):
            assert o.tension_world_n is not None
            ests.append(f.update(o.tension_world_n, 0.004, m.quat_wxyz))
        positions = [
            localize(
                e.tension_world_n,
                e.cov_n2,
                rt.weight_n_per_m,
                rt.length_m,
                rt.base_world_m,
                floor_z_m,
            )
            for e in ests
        ]
        assert all(p is not None for p in positions)

        def run_validate() -> int:
            for s in samples:
                pipe.validate(s, 0.0)
            return len(samples)

        def run_observe() -> int:
            for m in msgs:
                observe_tension(m.accel_mps2, m.quat_wxyz, m.thrust_n, mass_kg, armed=m.armed)
            return len(msgs)

        def run_localize() -> int:
            for e in ests:
                localize(
                    e.tension_world_n,
                    e.cov_n2,
                    rt.weight_n_per_m,
                    rt.length_m,
                    rt.base_world_m,
                    floor_z_m,
                )
            return len(ests)

        def run_follow() -> int:
            state, fp = rt.follow_state, rt.follow_params
            for m, e, p in zip(msgs, ests, positions, strict=True):
                assert p is not None
                follow_mod.follow_step(
                    state,
                    fp,
                    stamp_s=m.stamp_s,
                    tension_norm_n=float(np.linalg.norm(e.tension_world_n)),
                    position_world_m=p.position_world_m,
                    base_world_m=rt.base_world_m,
                    length_m=rt.length_m,
                    floor_z_m=floor_z_m,
                )
            return len(msgs)

        def run_follow_off() -> int:
            # What the pipeline does per message while follow is off (no follow_step).
            state = rt.follow_state
            assert not (state.enabled or state.active)
            for m in msgs:
                _follow_stamped(state, m.stamp_s)
            return len(msgs)

        def run_localize_batch() -> int:
            n = 0
            for i in range(0, len(ests) - BATCH + 1, BATCH):
                chunk = ests[i : i + BATCH]
                localize_batch(
                    np.array([e.tension_world_n for e in chunk]),
                    np.array([e.cov_n2 for e in chunk]),
                    rt.weight_n_per_m,
                    rt.length_m,
                    rt.base_world_m,
                    floor_z_m,
                )
                n += len(chunk)
            return n

        stages = _stage_split(warmed, samples, repeats)
        extra = {
            "kalman_bare": _kalman_us(filt0, obs, repeats),
            "filterpy_bare": _filterpy_us(filt0, msgs, obs, repeats),
            "follow_step_itself": _best_mean_us(run_follow, repeats),
            "localize_batch": _best_mean_us(run_localize_batch, repeats),
        }
        drones = _drones_us(warmup, messages, repeats, seed)
        follow_on = _follow_on_us(warmed, timed, repeats)
        bytecodes = _bytecodes_per_message(warmed, samples)
        loop_ns = _loop_ns_per_bytecode(repeats)
    finally:
        if gc_was:
            gc.enable()
    return {
        "warmup": warmup,
        "messages": messages,
        "repeats": repeats,
        "stages_us": stages,
        "stages_sum_us": sum(stages.values()),
        "extra_us": extra,
        **drones,
        "total_median_us": float(np.median(per_msg_us)),
        "total_p90_us": float(np.percentile(per_msg_us, 90)),
        "total_best_mean_us": min(means),
        "follow_on_median_us": follow_on,
        "bytecodes_per_message": bytecodes,
        "loop_ns_per_bytecode": loop_ns,
        "commit": _commit(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "loadavg": os.getloadavg(),
    }


def _split_targets() -> dict[str, tuple[tuple[Any, str], ...]]:
    from groundstation import contact as contact_mod
    from groundstation.estimator import drone as drone_mod
    from groundstation.estimator.filter_control import FilterControl

    return {
        "observation": ((drone_mod, "observe"),),
        "gate": ((drone_mod, "gate_step"),),
        "contact": ((contact_mod, "contact_step"), (contact_mod, "vertical_accel_mps2")),
        "slow_accel": ((drone_mod, "learn_slow"),),
        "filter": ((FilterControl, "step"),),
        "localize": ((drone_mod, "localize_one"),),
        "follow": ((drone_mod, "follow_stamped"), (drone_mod, "follow_decide")),
        "estimate": ((drone_mod.DroneEstimator, "_estimate"),),
    }


def _stage_split(
    warmed: Callable[[], Pipeline], samples: list[Sample], repeats: int
) -> dict[str, float]:
    """µs per message of each stage inside :meth:`Pipeline.handle` (best repeat).

    Each stage's functions are wrapped with a ``perf_counter_ns`` timer while a converged
    pipeline handles the messages; a wrapper's own cost (measured on an empty function) is
    taken off every call it timed. ``glue`` is the uninstrumented whole message's mean less
    the stages: everything between them.
    """
    clock = time.perf_counter_ns
    targets = _split_targets()
    acc: dict[str, int] = {}
    calls: dict[str, int] = {}

    def timed(fn: Callable[..., Any], key: str) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            t0 = clock()
            out = fn(*args, **kwargs)
            acc[key] += clock() - t0
            calls[key] += 1
            return out

        return wrapper

    # The wrapper's own cost per call, ns (around an empty function).
    acc["_"] = calls["_"] = 0
    empty = timed(lambda: None, "_")
    t0 = clock()
    for _ in range(20000):
        empty()
    overhead_ns = max(0.0, (clock() - t0 - acc["_"]) / 20000)

    best = {k: math.inf for k in STAGES}
    for _ in range(repeats):
        pipe = warmed()
        handle = pipe.handle
        t0 = clock()
        for smp in samples:
            handle(smp, 0.0)
        total_us = (clock() - t0) / len(samples) / 1e3

        pipe = warmed()
        saved = [(o, a, getattr(o, a)) for pairs in targets.values() for o, a in pairs]
        for key in (*targets, "validate"):
            acc[key] = calls[key] = 0
        try:
            for key, pairs in targets.items():
                for owner, attr in pairs:
                    setattr(owner, attr, timed(getattr(owner, attr), key))
            pipe.validate = timed(pipe.validate, "validate")  # type: ignore[method-assign]
            for smp in samples:
                pipe.handle(smp, 0.0)
        finally:
            for owner, attr, fn in saved:
                setattr(owner, attr, fn)
        split = {
            key: max(0.0, acc[key] - overhead_ns * calls[key]) / len(samples) / 1e3
            for key in (*targets, "validate")
        }
        split["glue"] = max(0.0, total_us - sum(split.values()))
        for key in STAGES:
            best[key] = min(best[key], split[key])
    return best


def _filter_us(filt0: TensionFilter, msgs: list[Telemetry], obs: list[Any], repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        f = copy.deepcopy(filt0)
        update = f.update
        t0 = time.perf_counter_ns()
        for m, o in zip(msgs, obs, strict=True):
            update(o.tension_world_n, 0.004, m.quat_wxyz)
        best = min(best, (time.perf_counter_ns() - t0) / len(msgs) / 1e3)
    return best


def _hover_qr(filt0: TensionFilter) -> tuple[list[float], list[float]]:
    """The converged filter's hover Q (one 4 ms step) and R, diagonals, N^2."""
    _, _, r = filt0.noise_model()
    tau = filt0.hover_time_constant(r, 0.004)
    return [ri * 0.004 / (tau * tau) * 0.004 for ri in r], list(r)


def _kalman_us(filt0: TensionFilter, obs: list[Any], repeats: int) -> float:
    """The closed-form Kalman step alone (``DiagonalKalman`` predict + update), with the
    converged filter's state, hover Q and R: the floor of ``filter_update``, which also
    sets Q and R and adds the noise estimate, the change test and the estimate."""
    est = filt0.estimate
    assert est is not None
    q, r = _hover_qr(filt0)
    zs = [o.tension_world_n.tolist() for o in obs]
    best = math.inf
    for _ in range(repeats):
        kf = DiagonalKalman()
        kf.set(est.tension_world_n.tolist(), np.diag(est.cov_n2).tolist())
        predict, update = kf.predict, kf.update
        t0 = time.perf_counter_ns()
        for z in zs:
            predict(q)
            update(z, r)
        best = min(best, (time.perf_counter_ns() - t0) / len(zs) / 1e3)
    return best


def _filterpy_us(
    filt0: TensionFilter, msgs: list[Telemetry], obs: list[Any], repeats: int
) -> float:
    """filterpy's KalmanFilter predict + update alone (its default inverse), with the
    converged filter's state, hover Q and R set once: the same step as ``kalman_bare``,
    as the tension filter took it before that was written out in closed form."""
    est = filt0.estimate
    assert est is not None
    q, r = _hover_qr(filt0)
    best = math.inf
    zs = [np.array(o.tension_world_n, dtype=float) for o in obs]
    for _ in range(repeats):
        kf = KalmanFilter(dim_x=3, dim_z=3)
        kf.F, kf.H, kf.Q, kf.R = np.eye(3), np.eye(3), np.diag(q), np.diag(r)
        kf.x, kf.P = est.tension_world_n.reshape(3, 1).copy(), est.cov_n2.copy()
        kf.inv = _inv3  # the adjugate hook the tension filter installed
        predict, update = kf.predict, kf.update
        t0 = time.perf_counter_ns()
        for z in zs:
            predict()
            update(z)
        best = min(best, (time.perf_counter_ns() - t0) / len(zs) / 1e3)
    return best


def bytecode_tracer(on_opcode: Callable[[], None]) -> Callable[[Any, str, Any], Any]:
    """A ``sys.settrace`` function that calls ``on_opcode`` once per bytecode CPython
    executes (opcode events on, line events off), in every frame entered while it is set.
    tests/test_work_budget.py budgets the counts it gives."""

    def trace(frame: Any, event: str, arg: Any) -> Any:
        frame.f_trace_opcodes = True
        frame.f_trace_lines = False
        return opcode

    def opcode(frame: Any, event: str, arg: Any) -> Any:
        if event == "opcode":
            on_opcode()
        return opcode

    return trace


def _bytecodes_per_message(warmed: Callable[[], Pipeline], samples: list[Sample]) -> float:
    """Bytecodes CPython executes per message in ``Pipeline.handle``
    (:func:`bytecode_tracer`; deterministic), over up to 200 of the timed messages."""
    count = [0]

    def one() -> None:
        count[0] += 1

    trace = bytecode_tracer(one)
    pipe = warmed()
    some = samples[:200]
    for s in some:
        sys.settrace(trace)
        try:
            pipe.handle(s, 0.0)
        finally:
            sys.settrace(None)
    return count[0] / len(some)


def _loop_ns_per_bytecode(repeats: int) -> float:
    """What a bytecode costs CPython here at its best with floats: a loop of float
    arithmetic and one ``math`` call on local variables (12 bytecodes an iteration, counted
    as above), best of ``repeats``."""

    def loop(n: int) -> float:
        x = 0.5
        for _ in range(n):
            x = math.hypot(x, 0.1) * 0.5
        return x

    n = 200_000
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        loop(n)
        best = min(best, (time.perf_counter_ns() - t0) / n / 12)
    return best


def _follow_on_us(warmed: Callable[[], Pipeline], timed: list[bytes], repeats: int) -> float:
    """``Pipeline.handle``'s median with follow on: the same hover, each message carrying a
    motion-capture position (where the warmed pipeline had localized the drone) and follow
    enabled after the first of them (no pull: following is armed, the goal frozen,
    the whole follow step runs, with the catenary's force at that position)."""
    clock = time.perf_counter_ns
    times: list[int] = []
    for _ in range(repeats):
        pipe = warmed()
        drone = pipe.drones["d0"]
        (estimate,) = pipe.handle(Sample(KEY, timed[0]), 0.0)
        mocap = json.loads(estimate.payload)["position_m"]
        assert mocap is not None, "the warmed pipeline has no position"
        samples = []
        for p in timed[1:]:
            body = json.loads(p)
            body["position_m"] = mocap
            samples.append(Sample(KEY, json.dumps(body).encode()))
        # Follow is refused for a drone whose last message had neither motion capture nor
        # a calibration behind it: one message with motion capture first.
        pipe.handle(samples[0], 0.0)
        pipe.handle(Sample("tether/d0/follow", b'{"enabled": true}'), 0.0)
        assert drone.follow_state.enabled, drone.follow_state.reason
        handle = pipe.handle
        for s in samples[1:]:
            t0 = clock()
            handle(s, 0.0)
            times.append(clock() - t0)
        assert drone.follow_state.enabled, drone.follow_state.reason
    return float(np.median(times)) / 1e3


def _drones_us(warmup: int, messages: int, repeats: int, seed: int) -> dict[str, float]:
    """DRONES drones interleaved (after ``warmup`` messages each, so that every filter has
    converged), per message: ``Pipeline.process`` one by one against
    ``Pipeline.process_batch`` in batches of BATCH grouped by drone (the service's drain
    with a backlog), on the same validated messages (CPU time, best repeat)."""
    steps = warmup + messages // DRONES + 1  # ``warmup`` messages per drone first
    rows = _telemetry_payloads(DRONES, steps / 250.0, seed)
    keys = [f"tether/d{d}/telemetry" for d in range(DRONES)]
    samples = [Sample(keys[d], row[d]) for row in rows for d in range(DRONES)]
    warm = samples[: warmup * DRONES]
    timed = samples[warmup * DRONES : warmup * DRONES + messages]
    settings = settings_for()
    best = {"drones_process_us": math.inf, "drones_batch_us": math.inf}
    for _ in range(repeats):
        for key in best:
            pipe = Pipeline(settings)
            for s in warm:
                pipe.handle(s, 0.0)
            parsed = [p for s in timed if (p := pipe.validate(s, 0.0)) is not None]
            t0 = time.process_time()
            if key == "drones_process_us":
                for p in parsed:
                    pipe.process(p, 0.0)
            else:
                for i in range(0, len(parsed), BATCH):
                    pipe.process_batch(group_by_drone(parsed[i : i + BATCH]))
            best[key] = min(best[key], (time.process_time() - t0) / len(parsed) * 1e6)
    return best


def _best(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Value-by-value minimum of several results (a shared machine only adds time)."""
    out = dict(results[0])
    # (A result from before the stage split has other stage names: its stages stay blank.)
    out["stages_us"] = {k: min(r["stages_us"].get(k, math.inf) for r in results) for k in STAGES}
    out["extra_us"] = {
        k: min(r.get("extra_us", {}).get(k, math.inf) for r in results) for k in EXTRA
    }
    keys = ("stages_sum_us", "total_median_us", "total_p90_us", "total_best_mean_us")
    for key in (*keys, "follow_on_median_us", "drones_process_us", "drones_batch_us"):
        out[key] = min(r.get(key, math.inf) for r in results)
    out["runs"] = sum(r.get("runs", 1) for r in results)
    return out


def _commit() -> str:
    commit = git("rev-parse", "--short", "HEAD").strip()
    if not commit:
        return "unknown"
    return commit + (" (modified)" if git("status", "--porcelain", "groundstation").strip() else "")


def _fmt(v: float | None) -> str:
    return "" if v is None or not math.isfinite(v) else f"{v:.1f}"


def render(result: dict[str, Any], before: dict[str, Any] | None, argv: list[str]) -> str:
    # Stages of a result from before the stage split were timed alone, another method:
    # only its totals are shown beside these.
    same_method = before is not None and all(
        math.isfinite(before["stages_us"].get(n, math.inf)) for n in STAGES
    )
    rows = [
        (n, result["stages_us"][n], before["stages_us"][n] if same_method else None)  # type: ignore[index]
        for n in STAGES
    ]
    rows.append(
        ("sum of stages", result["stages_sum_us"], before["stages_sum_us"] if same_method else None)  # type: ignore[index]
    )
    for key, label in (
        ("total_median_us", "**Pipeline.handle, median**"),
        ("total_p90_us", "Pipeline.handle, p90"),
        ("total_best_mean_us", "Pipeline.handle, mean (best repeat)"),
        (
            "follow_on_median_us",
            "Pipeline.handle, median, follow on (motion capture in each message, no pull)",
        ),
        ("drones_process_us", f"{DRONES} drones: Pipeline.process, one by one"),
        (
            "drones_batch_us",
            f"**{DRONES} drones: Pipeline.process_batch (the service's drain), batches of "
            f"{BATCH}**",
        ),
    ):
        rows.append((label, result.get(key), (before or {}).get(key)))
    extra_labels = {
        "kalman_bare": "(the Kalman step alone: DiagonalKalman predict + update)",
        "filterpy_bare": "(the same step on filterpy's KalmanFilter, as before)",
        "localize_batch": (
            f"(localize_batch, the smoother's vectorised call, {BATCH} cases per call, per case)"
        ),
        "follow_step_itself": "(follow_step itself, follow off: the pipeline skips it)",
    }
    for key, label in extra_labels.items():
        was = (before or {}).get("extra_us", {}).get(key)
        rows.append((label, result["extra_us"].get(key), was))
    head = "| stage | µs/msg |" + (" before µs/msg |" if before else "")
    sep = "| --- | --- |" + (" --- |" if before else "")
    lines = [
        "# Per-message pipeline cost",
        "",
        f"Generated by `.venv/bin/python -m benchmarks.bench_pipeline {' '.join(argv)}`".rstrip()
        + f" at commit {result['commit']} (Python {result['python']}, numpy {result['numpy']},"
        f" {result['machine']}, {result['cpus']} CPUs, load average "
        f"{', '.join(f'{x:.2f}' for x in result['loadavg'])}).",
        "",
        f"One converged hovering drone (after {result['warmup']} messages), "
        f"{result['messages']} messages x {result['repeats']} repeats, best of "
        f"{result['runs']} run(s); method in the module "
        "docstring of `benchmarks/bench_pipeline.py`. Stages are each timed alone (best "
        "repeat); the handle rows time whole messages; the drone rows time validated "
        f"messages of {DRONES} interleaved drones (CPU time, validation not included); rows "
        "in parentheses are not in the sum.",
        "",
        head,
        sep,
    ]
    for name, now, was in rows:
        lines.append(f"| {name} | {_fmt(now)} |" + (f" {_fmt(was)} |" if before else ""))
    if before:
        lines += [
            "",
            f"Before: {before['commit']}, best of {before.get('runs', 1)} run(s), load average "
            f"{', '.join(f'{x:.2f}' for x in before['loadavg'])} (first run).",
        ]
    median = result["total_median_us"]
    st = result["stages_us"]
    io = st["validate"] + st["estimate"]
    lines += [
        "",
        f"The target, ≤ 50 µs per message with validation and encoding: "
        f"**{'met' if median <= 50.0 else 'not met'}** (median {median:.0f} µs). Of it, "
        f"the contract's JSON in and out (validate + estimate) is {io:.0f} µs, the "
        f"localization's catenary solves (the drone and six sigma points) {st['localize']:.0f} "
        f"µs, the tension filter with its noise, change and drift tests "
        f"{st['filter']:.0f} µs. With follow on (and motion capture) a message costs "
        f"{result['follow_on_median_us']:.0f} µs. docs/service_profile.md, sections 6 and 7, "
        "say why this is about what CPython does with this work and what it would take to "
        "go further.",
    ]
    if "bytecodes_per_message" in result:
        n_bc = result["bytecodes_per_message"]
        lines += [
            "",
            f"What CPython executes: {n_bc:,.0f} bytecodes per message (counted, as "
            f"tests/test_work_budget.py counts them), {median * 1e3 / n_bc:.1f} ns each at the "
            f"median; a loop of float arithmetic and one math call on local variables runs at "
            f"{result['loop_ns_per_bytecode']:.1f} ns per bytecode here. 50 µs would take "
            f"{50e3 / n_bc:.1f} ns per bytecode with this much work, or less work.",
        ]
    lines += [
        "",
        "Budget: 8 drones x 250 Hz = 2000 msg/s on 2 cores, so every 100 µs of pipeline is "
        "20 % of a core (plus zenoh's share, measured by `benchmarks.bench_service`).",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--warmup", type=int, default=500, help="messages before timing")
    parser.add_argument("--messages", type=int, default=2000, help="timed messages per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--runs", type=int, default=1, help="whole runs; the best of each value")
    parser.add_argument("--quick", action="store_true", help="small run, print only")
    parser.add_argument("--json", type=Path, help="also write the raw result here")
    parser.add_argument(
        "--before",
        type=Path,
        nargs="+",
        help="--json results to show beside this one (the best of them, value by value)",
    )
    parser.add_argument("--label", help="what was measured (default: the git commit)")
    parser.add_argument("--no-doc", action="store_true", help=f"do not write {DOC_PATH.name}")
    args = parser.parse_args(argv)
    if args.quick:
        args.warmup, args.messages, args.repeats = 100, 200, 2
    result = _best([measure(args.warmup, args.messages, args.repeats) for _ in range(args.runs)])
    if args.label:
        result["commit"] = args.label
    before = _best([json.loads(p.read_text()) for p in args.before]) if args.before else None
    text = render(result, before, argv if argv is not None else sys.argv[1:])
    print(text)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    if not (args.quick or args.no_doc):
        DOC_PATH.write_text(text)
        print(f"wrote {DOC_PATH}")
        write_figures(DOC_PATH.stem, result, argv if argv is not None else sys.argv[1:])


if __name__ == "__main__":
    main()
