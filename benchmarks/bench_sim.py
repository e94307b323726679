"""Speed of the simulator: simulated seconds per wall second, per profile, in lock-step.

Run from the repository root::

    .venv/bin/python -m benchmarks.bench_sim            # 30 s per case, prints a table
    .venv/bin/python -m benchmarks.bench_sim --quick    # 5 s per case
    .venv/bin/python -m benchmarks.bench_sim --tether   # lumped tether vs catenary at rest
    .venv/bin/python -m benchmarks.bench_sim --service  # today's service on both profiles

One drone (cf1), scenario ``hover`` and ``takeoff_ramp``, default settings; ``Simulator.step``
driven in a loop without a bus (the samples are built, JSON included, as when publishing).
The realistic profile integrates at ``[sim.realistic] physics_rate_hz`` (1 kHz) and publishes
~100 Hz IMU Telemetry; the ideal one publishes at ``[sim] rate_hz`` (250 Hz). The machine's
load matters: the wall-clock factor is what a user sees, the CPU-time factor what one free
core would give (the numbers say on what they were measured).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time

import numpy as np

from groundstation import catenary
from groundstation.config import load_settings
from groundstation.sim import Simulator
from groundstation.sim.tether import LumpedTether, TetherParams

BASE_M = np.array([0.0, 0.0, 0.754])
TETHER_SPOTS_M = (
    ("paper spot 1", (1.2, 0.0, 1.0)),
    ("below the base", (1.0, -0.3, 0.5)),
    ("95 % of L", (1.52 * math.cos(0.1), 0.0, 0.754 + 1.52 * math.sin(0.1))),
    ("97 % of L", (1.552 * math.cos(0.1), 0.0, 0.754 + 1.552 * math.sin(0.1))),
    ("touchdown", (0.9, 0.0, 0.3)),
    ("plumb", (0.0, 0.0, 1.2)),
    ("pile (slack on the floor)", (0.5, 0.0, 0.3)),
)


def tether_table(n_segments: int = 10) -> None:
    """Lumped tether at rest (10 s settled) against catenary.tether_force / tether_points."""
    print(f"# lumped tether, N = {n_segments}, EA = 100 N, L = 1.6 m, ω = 0.05 N/m, floor z = 0")
    print("| spot | drone (m) | shape max dev (% of L) | end force error (%) | floor contact |")
    print("|---|---|---|---|---|")
    for name, spot in TETHER_SPOTS_M:
        drone = np.array(spot)
        tether = LumpedTether(TetherParams(n_segments=n_segments), BASE_M, drone, 1.6, 0.0)
        tether.settle(5.0, extra_damping_per_s=3.0)
        tether.settle(5.0)
        ref = catenary.tether_force(BASE_M, drone, 1.6, 0.05, 0.0)
        curve = catenary.tether_points(BASE_M, drone, 1.6, 0.0, n=4001)
        dev = np.min(np.linalg.norm(tether.x_world_m[:, None] - curve[None], axis=2), axis=1)
        f_ref = np.asarray(ref.force_world_n)
        err = np.linalg.norm(tether.force_on_drone_world_n - f_ref) / np.linalg.norm(f_ref)
        xyz = ", ".join(f"{v:.3f}" for v in spot)
        print(
            f"| {name} | ({xyz}) | {100 * dev.max() / 1.6:.2f} | {100 * err:.1f} | "
            f"{tether.floor_contact} / {ref.floor_contact} |"
        )


class _NullBus:
    def publish(self, key: str, payload: bytes) -> None:
        pass


def measure(profile: str, scenario: str, seconds: float) -> tuple[float, float, float, int]:
    """(construction wall s, wall real-time factor, CPU real-time factor, telemetry count)."""
    settings = load_settings(None, {"sim": {"profile": profile}}, use_env=False)
    t0 = time.perf_counter()
    sim = Simulator(settings, _NullBus(), scenario=scenario)  # type: ignore[arg-type]
    t1, c1 = time.perf_counter(), time.process_time()
    telemetry = 0
    for _ in range(round(seconds / sim.dt_s)):
        telemetry += sum(1 for s in sim.step() if s.key.endswith("/telemetry"))
    wall, cpu = time.perf_counter() - t1, time.process_time() - c1
    return t1 - t0, seconds / wall, seconds / cpu, telemetry


def service_table(seconds: float = 12.0, after_s: float = 8.0) -> None:
    """The service (its defaults, no calibration, no motion capture) at the paper's six spots:
    median 3D position error after ``after_s``, per profile. The real tethered flights were
    0.9–1.4 m off per flight with the nominal configuration."""
    from benchmarks.results_sim import hover_scenario
    from groundstation.evaluation import closed_loop
    from groundstation.sim import PAPER_HOVER_SPOTS_M, SCENARIOS

    print(
        f"# service defaults, mocap off, {seconds:g} s per spot, median error after {after_s:g} s"
    )
    print("| spot | ideal: median error (m) | realistic: median error (m) |")
    print("|---|---|---|")
    for i, spot in enumerate(PAPER_HOVER_SPOTS_M):
        sc = hover_scenario(f"bench_sim_spot{i}", spot)
        SCENARIOS[sc.name] = sc
        row = []
        for profile in ("ideal", "realistic"):
            settings = load_settings(
                None, {"sim": {"profile": profile, "mocap": False, "seed": i}}, use_env=False
            )
            run, _, _ = closed_loop(settings, sc.name, seconds)
            errors = [
                float(
                    np.linalg.norm(
                        np.subtract(e["position_m"], run.truth_at(e["stamp_s"])["position_m"])
                    )
                )
                for e in run.estimates
                if e["stamp_s"] >= after_s and e["position_m"] is not None
            ]
            row.append(f"{np.median(errors):.3f}" if errors else "none")
        xyz = ", ".join(f"{v:g}" for v in spot)
        print(f"| ({xyz}) | {row[0]} | {row[1]} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--quick", action="store_true", help="5 s per case")
    ap.add_argument("--tether", action="store_true", help="lumped tether vs catenary instead")
    ap.add_argument("--service", action="store_true", help="the service's error on both profiles")
    args = ap.parse_args(argv)
    if args.tether:
        tether_table()
        return 0
    if args.service:
        service_table()
        return 0
    seconds = 5.0 if args.quick else 30.0
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load {load:.1f}, python {platform.python_version()}, {seconds:g} s per case"
    )
    print(
        "| profile | scenario | start-up s | × real time (wall) | × real time (CPU) "
        "| telemetry Hz |"
    )
    print("|---|---|---|---|---|---|")
    for profile in ("ideal", "realistic"):
        for scenario in ("hover", "takeoff_ramp"):
            setup_s, wall_x, cpu_x, n = measure(profile, scenario, seconds)
            print(
                f"| {profile} | {scenario} | {setup_s:.2f} | {wall_x:.1f} | {cpu_x:.1f} | "
                f"{n / seconds:.0f} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
