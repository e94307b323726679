"""Sections (b) and (c) of the results page: the catenary solver against its peers, and the
service at scale.

Nothing here re-implements a benchmark: the case set, the peers (the paper's recipe, scipy
``fsolve`` on the five equations, a plain vectorised Newton), the 50-digit reference and the
error measures are :mod:`benchmarks.bench_catenary`'s; the service load run is
:func:`benchmarks.bench_service.run_case` (with the echo floor, bursts and the drain rate of
:mod:`benchmarks.service_rig`); the dashboard's cost is measured with
:mod:`benchmarks.bench_dashboard`'s ``callback_cost_us`` and ``run_once``. This module only
chooses the sizes (quick or full) and keeps the numbers as data for tables and figures.
"""

from __future__ import annotations

import inspect
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from benchmarks import bench_catenary as bc
from groundstation.catenary import solve

CATENARY_NAMES = {
    "ours, vectorised": "ours, vectorised",
    "ours, scalar": "ours, scalar",
    "paper recipe": "paper recipe, scalar",
    "fsolve": "scipy fsolve (5 equations), scalar",
    "plain Newton, vectorised": "plain Newton, vectorised",
}
"""bench_catenary's method keys → names on the results page (the page's order)."""
SERVICE_TARGET_DELIVERY = 0.999  # bench_service's targets
SERVICE_TARGET_P99_MS = 10.0
SERVICE_TARGET_BURST_RATIO = 3.0  # p99 under bursts ≤ 3× the echo floor's
SERVICE_TARGET_CAPACITY_HZ = 20_000.0  # msgs/s on one core with a backlog


# ---------------------------------------------------------------------------- (b) catenary


@dataclass(frozen=True)
class MethodResult:
    name: str
    us_per_solve: float
    solves_per_s: float
    timed_cases: int
    raised: int  # exceptions over the timed cases
    returned: float  # fraction of reference cases with a finite answer
    ok: float  # fraction within 1e-9 (a, x0 and curve) of the 50-digit reference
    worst_a: float
    worst_x0: float
    worst_curve: float
    ok_by_category: dict[str, float]


@dataclass(frozen=True)
class CatenaryResult:
    n_vectorised: int
    n_scalar: int
    n_fsolve: int
    n_reference: int
    methods: tuple[MethodResult, ...]
    seconds: float


def _seconds(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _time_scalar(
    fns: Sequence[Callable[..., Any]], rows: Sequence[tuple[float, ...]], repeats: int
) -> list[tuple[float, int]]:
    """bench_catenary.time_scalar per function: (µs per call, calls that raised).

    Its signature moved from one function to a sequence (timed interleaved); accept both so
    this page does not break while that benchmark evolves.
    """
    if "fns" in inspect.signature(bc.time_scalar).parameters:
        return [(float(us), int(n)) for us, n in bc.time_scalar(fns, rows, repeats)]
    return [bc.time_scalar(fn, rows, repeats) for fn in fns]  # type: ignore[arg-type, misc]


def catenary(quick: bool) -> CatenaryResult:
    """Time and accuracy of every method on bench_catenary's mixed case set."""
    t0 = time.perf_counter()
    n_vec = 200_000 if quick else 1_000_000
    n_scalar = 2_000 if quick else 20_000
    n_fsolve = 200 if quick else 2_000
    n_ref = 100 if quick else 1_000
    cases = bc.make_cases(n_vec)
    cols = (cases.x1, cases.y1, cases.x2, cases.y2, cases.length)

    t_ours = t_newton = math.inf
    for _ in range(3 if quick else 8):  # interleaved, best of: the machine is shared
        t_ours = min(t_ours, _seconds(lambda: solve(*cols)))
        t_newton = min(t_newton, _seconds(lambda: bc.newton_baseline(*cols)))
    ours_vec = solve(*cols)
    newton = bc.newton_baseline(*cols)

    rows = [cases.row(i) for i in range(n_scalar)]
    (us_scalar, raised_scalar), (us_paper, raised_paper) = _time_scalar(
        [solve, bc.paper_recipe_solve], rows, 3
    )
    ((us_fsolve, raised_fsolve),) = _time_scalar([bc.fsolve_solve], rows[:n_fsolve], 1)
    acc, acc_cat = bc.measure_accuracy(cases, n_ref, ours_vec, newton)

    timing = {
        "ours, vectorised": (t_ours / n_vec * 1e6, n_vec, 0),  # µs, cases timed, raised
        "plain Newton, vectorised": (t_newton / n_vec * 1e6, n_vec, 0),
        "ours, scalar": (us_scalar, n_scalar, raised_scalar),
        "paper recipe": (us_paper, n_scalar, raised_paper),
        "fsolve": (us_fsolve, n_fsolve, raised_fsolve),
    }
    methods = []
    for key, name in CATENARY_NAMES.items():
        us, n, raised = timing[key]
        a = acc[key]
        methods.append(
            MethodResult(
                name=name,
                us_per_solve=float(us),
                solves_per_s=1e6 / float(us),
                timed_cases=n,
                raised=int(raised),
                returned=a.finite / a.total,
                ok=a.ok / a.total,
                worst_a=a.worst_a,
                worst_x0=a.worst_x0,
                worst_curve=a.worst_y,
                ok_by_category={
                    c: acc_cat[(key, c)].ok / max(acc_cat[(key, c)].total, 1) for c in bc.CATEGORIES
                },
            )
        )
    return CatenaryResult(
        n_vec, n_scalar, n_fsolve, n_ref, tuple(methods), time.perf_counter() - t0
    )


# ---------------------------------------------------------------------------- (c) service


@dataclass(frozen=True)
class ServiceResult:
    seconds: float
    rows: tuple[dict[str, Any], ...]  # bench_service.run_case outputs
    dashboard_rows: tuple[dict[str, Any], ...]  # run_case(..., dashboard=True)
    load_before: float  # 1-minute load average when the section started
    floor_rows: tuple[dict[str, Any], ...] = ()  # run_case(..., sut="echo"): the echo floor
    bursts: dict[str, dict[str, Any]] = field(default_factory=dict)  # sut -> service_rig.drive
    capacity: dict[str, dict[str, Any]] = field(default_factory=dict)  # sut -> rig.capacity
    offline_us_per_msg: float = float("nan")  # Pipeline.handle in-process, same run (CPU)
    load_after: float = float("nan")

    def meets(self, row: dict[str, Any]) -> bool:
        return bool(
            row["delivered"] >= SERVICE_TARGET_DELIVERY and row["p99_ms"] <= SERVICE_TARGET_P99_MS
        )

    def delivered_ok(self, row: dict[str, Any]) -> bool:
        return bool(row["delivered"] >= SERVICE_TARGET_DELIVERY and row["queue_overflow"] == 0)

    def floor(self, drones: int) -> dict[str, Any] | None:
        return next((r for r in self.floor_rows if r["drones"] == drones), None)


def service(
    drone_counts: tuple[int, ...],
    seconds: float,
    dashboard_drones: tuple[int, ...],
    extend_to: int = 0,
    progress: Callable[[str], None] | None = None,
    floor_drones: tuple[int, ...] = (8,),
    burst_drones: int = 8,
    backlog: int = 6000,
    capacity_suts: tuple[str, ...] = ("echo", "floor", "service"),
) -> ServiceResult:
    """``run_case`` per drone count; then, if every count delivered, larger counts (doubling
    up to ``extend_to``) to find where it saturates; then the dashboard cases; the echo
    floor at ``floor_drones``; bursts (100 ms pauses once a second) against the service, the
    echo floor and the contract floor (:mod:`benchmarks.floor_service`); the drain rate with a
    ``backlog`` (all :mod:`benchmarks.service_rig`)."""
    from benchmarks import service_rig as sr  # imports zenoh: only when needed
    from benchmarks.bench_service import run_case

    load = os.getloadavg()[0]
    offline = sr.offline_us_per_msg(8)["cpu_us_per_msg"]
    rows: list[dict[str, Any]] = []
    for n in drone_counts:
        rows.append(run_case(n, seconds))
        if progress:
            progress(f"service {n} drones: {_row_brief(rows[-1])}")
    n = max(drone_counts)
    while extend_to and all(r["delivered"] >= SERVICE_TARGET_DELIVERY for r in rows):
        n *= 2
        if n > extend_to:
            break
        rows.append(run_case(n, seconds))
        if progress:
            progress(f"service {n} drones: {_row_brief(rows[-1])}")
    floors = []
    for n in floor_drones:
        floors.append(run_case(n, seconds, sut="echo"))
        if progress:
            progress(f"echo floor {n} drones: {_row_brief(floors[-1])}")
    dash = []
    for n in dashboard_drones:
        dash.append(run_case(n, seconds, dashboard=True))
        if progress:
            progress(f"service {n} drones + dashboard: {_row_brief(dash[-1])}")
    schedule = sr.Schedule.bursts(seconds)
    payloads = sr.telemetry_payloads(burst_drones, len(schedule.release_s), seed=burst_drones)
    bursts, capacity = {}, {}
    for sut in ("echo", "floor", "service"):
        with sr.rig(sut) as rig:
            bursts[sut] = sr.drive(rig.endpoint, burst_drones, schedule, payloads, rig.pid)
        if progress:
            progress(f"bursts, {sut}: {_row_brief(bursts[sut])}")
    for sut in capacity_suts:
        with sr.rig(sut) as rig:
            capacity[sut] = sr.capacity(rig.endpoint, rig.pid, burst_drones, backlog)
        if progress:
            progress(f"capacity, {sut}: {capacity[sut]['msgs_per_s']:.0f} msg/s")
    offline = min(offline, sr.offline_us_per_msg(8)["cpu_us_per_msg"])
    return ServiceResult(
        seconds,
        tuple(rows),
        tuple(dash),
        load,
        tuple(floors),
        bursts,
        capacity,
        offline,
        os.getloadavg()[0],
    )


def _row_brief(r: dict[str, Any]) -> str:
    return (
        f"delivered {100 * r['delivered']:.2f} %, p50 {r['p50_ms']:.1f} ms, "
        f"p99 {r['p99_ms']:.1f} ms, {r['cpu_us_per_msg']:.0f} µs/msg"
    )


@dataclass(frozen=True)
class DashboardResult:
    callback_us: float
    seconds: float
    # drones -> (process CPU/s without the dashboard, with it, update-thread CPU/s, passes/s)
    runs: dict[int, tuple[float, float, float, float]]


def dashboard(drone_counts: tuple[int, ...], seconds: float) -> DashboardResult:
    """bench_dashboard's in-process measurement, without a browser."""
    from benchmarks import bench_dashboard as bd  # imports viser: only when needed

    per_cb = bd.callback_cost_us(50_000)
    runs = {}
    for n in drone_counts:
        base = bd.run_once(n, seconds, dashboard_on=False, browser=None)
        dash = bd.run_once(n, seconds, dashboard_on=True, browser=None)
        runs[n] = (
            base.process_cpu_per_s,
            dash.process_cpu_per_s,
            float(dash.update_cpu_per_s or 0.0),
            float(dash.ticks_per_s or 0.0),
        )
    return DashboardResult(per_cb, seconds, runs)


def saturation(svc: ServiceResult) -> tuple[int | None, int | None]:
    """(largest drone count meeting both targets, smallest count missing one), by count."""
    rows = sorted(svc.rows, key=lambda r: r["drones"])
    passing = [r["drones"] for r in rows if svc.meets(r)]
    failing = [r["drones"] for r in rows if not svc.meets(r)]
    return (max(passing) if passing else None), (min(failing) if failing else None)


def capacity_msgs_per_s(svc: ServiceResult) -> float:
    """Messages per second the service processed in the most loaded case (delivered rate)."""
    return float(max(r["offered_hz"] * r["delivered"] for r in svc.rows))
