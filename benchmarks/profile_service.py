"""Where the service's worker spends its time online: py-spy on ``groundstation serve``.

Run:  python -m benchmarks.profile_service [--seconds 10] [--baseline TREE] [--pyspy PATH]

Needs py-spy (``pip install py-spy``; not a dependency of the project). The rig of
:mod:`benchmarks.service_rig` drives 8 drones × 250 Hz steady load into the service started
under ``py-spy record --threads --nonblocking`` (200 samples/s); then this prints, for the
service's worker thread, the share of its samples inside each of a few functions (inclusive),
the service's CPU per thread group from /proc, and the same messages' CPU cost offline
(``Pipeline.handle`` in this process) measured right before, for comparison.
``--baseline TREE`` profiles ``serve`` from another source tree (e.g. ``git archive`` of an
older commit) instead.

``--micro`` prints two costs without py-spy instead: a zenoh ``put`` in a tight loop through
a router (CPU and wall per put), and the Estimate's JSON with and without the model
(``messages.encode_estimate`` against ``Estimate(...).to_json()``, interleaved, 5 rounds).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import shutil
import tempfile
from pathlib import Path

from benchmarks import service_rig as sr

FUNCTIONS = (
    "Service._run",
    "Service._step",
    "Service._step_batch",
    "Pipeline.process",
    "Pipeline.process_batch",
    "DroneEstimator.step",
    "DroneEstimator.front",
    "DroneEstimator.back",
    "observe",
    "gate_step",
    "contact_step",
    "learn_slow",
    "FilterControl.step",
    "TensionFilter.update",
    "KalmanFilter.update",
    "KalmanFilter.predict",
    "localize",
    "localize_batch",
    "follow_decide",
    "follow_step",
    "DroneEstimator._estimate",
    "BaseModel.model_dump_json",
    "encode_estimate",
    "encode_estimate_ordered",
    "Service._publish",
    "ZenohBus.publish",
    "Queue.get",
    "SimpleQueue.get",
    "Condition.wait",
)


def summarize(raw: Path) -> tuple[dict[str, int], dict[str, float]]:
    """(samples per thread, worker's inclusive share per function) from py-spy's raw output."""
    per_thread: collections.Counter[str] = collections.Counter()
    inclusive: collections.Counter[str] = collections.Counter()
    for line in raw.read_text().splitlines():
        stack, _, count = line.rpartition(" ")
        frames = stack.split(";")
        n = int(count)
        thread = frames[0].split(":")[-1].strip()
        per_thread[thread] += n
        if thread == "groundstation-worker":
            for name in {f.split(" (")[0] for f in frames[1:]}:
                inclusive[name] += n
    total = max(per_thread["groundstation-worker"], 1)
    return dict(per_thread), {f: inclusive[f] / total for f in FUNCTIONS if inclusive[f]}


def put_cost_us(n: int = 20_000) -> dict[str, float]:
    """A publisher's ``put`` of a 700-byte payload in a tight loop, through a router to a
    subscriber in another process (the echo): µs of this thread's CPU and of wall time."""
    import time

    from groundstation.config import ZenohSection
    from groundstation.zenoh_bus import ZenohBus

    with sr.rig("echo") as rig:
        bus = ZenohBus(ZenohSection(mode="client", connect=(rig.endpoint,)))
        try:
            bus.subscribe("bench/**", lambda s: None)
            time.sleep(0.5)
            payload = b"x" * 700
            for _ in range(1000):
                bus.publish("bench/put", payload)
            c0, t0 = time.thread_time(), time.perf_counter()
            for _ in range(n):
                bus.publish("bench/put", payload)
            c1, t1 = time.thread_time(), time.perf_counter()
        finally:
            bus.close()
    return {"cpu_us": (c1 - c0) / n * 1e6, "wall_us": (t1 - t0) / n * 1e6}


def encoder_cost_us(rounds: int = 5, n: int = 20_000) -> list[tuple[float, float]]:
    """(model + to_json, encode_estimate) µs per Estimate, per round, interleaved."""
    import timeit

    from groundstation.messages import Estimate, FollowInfo, encode_estimate

    follow = FollowInfo(enabled=False, active=False, threshold_n=0.15)
    follow_dict = follow.model_dump()
    fields = {
        "seq": 123,
        "stamp_s": 12.345,
        "tension_n": (-0.0201234, 0.00012345, -0.0612345),
        "tension_std_n": (0.00031, 0.00032, 0.00029),
        "horizontal_n": 0.0201,
        "vertical_n": 0.0612,
        "position_m": (0.81234, 0.0123, 1.0123),
        "position_std_m": (0.01, 0.02, 0.03),
        "radial_m": 0.8123,
        "radial_interval_m": (0.8, 0.82),
        "azimuth_determined": True,
        "floor_contact": False,
        "on_ground": False,
        "converged": True,
        "length_m": 1.6,
        "base_m": (0.0, 0.0, 0.754),
    }
    assert Estimate(follow=follow, **fields).to_json() == encode_estimate(
        follow=follow_dict, **fields
    )
    out = []
    for _ in range(rounds):
        model = timeit.timeit(lambda: Estimate(follow=follow, **fields).to_json(), number=n)
        fast = timeit.timeit(lambda: encode_estimate(follow=follow_dict, **fields), number=n)
        out.append((model / n * 1e6, fast / n * 1e6))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--drones", type=int, default=8)
    parser.add_argument("--baseline", metavar="TREE", help="profile serve from this tree")
    parser.add_argument("--pyspy", default=shutil.which("py-spy") or "py-spy")
    parser.add_argument("--micro", action="store_true", help="put and encoder costs only")
    args = parser.parse_args()
    if args.micro:
        put = put_cost_us()
        print(f"load average {os.getloadavg()[0]:.1f}")
        print(f"zenoh put, tight loop: {put['cpu_us']:.1f} µs CPU, {put['wall_us']:.1f} µs wall")
        for model, fast in encoder_cost_us():
            print(f"Estimate JSON: model {model:.2f} µs, encode_estimate {fast:.2f} µs")
        return
    os.environ["BENCH_PYSPY"] = args.pyspy
    sut = "service"
    if args.baseline:
        os.environ["BENCH_BASELINE_TREE"] = str(Path(args.baseline).resolve())
        sut = "baseline"
    offline = sr.offline_us_per_msg(args.drones)
    schedule = sr.Schedule.steady(args.seconds)
    payloads = sr.telemetry_payloads(args.drones, len(schedule.release_s), seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "profile.txt"
        with sr.rig(sut, profile=str(raw)) as rig:
            row = sr.drive(rig.endpoint, args.drones, schedule, payloads, rig.pid)
        threads, shares = summarize(raw)
    print(
        f"load average {os.getloadavg()[0]:.1f}; {args.drones} drones × 250 Hz, "
        f"{args.seconds:g} s, {sut}"
    )
    print(f"offline Pipeline.handle: {offline['cpu_us_per_msg']:.0f} µs CPU/msg")
    print(
        f"online: process {row['cpu_us_per_msg']:.0f} µs CPU/msg, Python threads "
        f"{row['worker_us_per_msg']:.0f} µs/msg; by thread (s): {json.dumps(row['threads_cpu_s'])}"
    )
    print(f"p50 {row['p50_ms']:.2f} ms, p99 {row['p99_ms']:.2f} ms (under the profiler)")
    print(f"py-spy samples per thread: {json.dumps(threads)}")
    print("worker's samples inside (inclusive):")
    for name, share in shares.items():
        print(f"  {name:28s} {100 * share:5.1f} %")


if __name__ == "__main__":
    main()
