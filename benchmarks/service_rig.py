"""The rig shared by the service load benchmarks (``bench_service``, ``bench_bursts``).

Topology, as deployed: a router (``tests/integration/router.py``), the system under test as
its client (``groundstation serve --headless``, or the bare echo of
:mod:`benchmarks.echo_service` as the floor), and this process as a second client that
publishes pre-encoded hover telemetry and subscribes to the estimates. Latency is publish →
estimate received, both stamped with this process's monotonic clock.

What the rig does so that it measures the service and not itself:

* The client's garbage collector is out of the window: the payloads are built first, then
  ``gc.collect(); gc.freeze(); gc.disable()`` until the window ends. Collections that still
  happen (none should) are counted and timed with ``gc.callbacks`` and reported.
* Send and receive times go into preallocated lists (no dict or lock per message); the
  estimate's ``seq`` is read from the payload's prefix (``{"seq":N,`` as both the service and
  the echo write it), with ``json.loads`` as the fallback.
* Late ticks are reported: a tick published more than one period (4 ms) after its schedule
  is late; the count and the worst lateness are in every row.
* The service's CPU is read per thread from ``/proc/PID/task``: the worker (the Python
  thread that is not the main thread) apart from zenoh's threads (named by the runtime),
  where the bus callbacks (validation) run.

The echo floor runs through the same router, the same client code, in the same run.
"""

from __future__ import annotations

import gc
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.bus import Sample
from groundstation.config import ZenohSection
from groundstation.sim import quat_wxyz_from_z_axis
from groundstation.tension import rotation_world_body
from groundstation.zenoh_bus import ZenohBus

REPO = Path(__file__).resolve().parents[1]
ROUTER = REPO / "tests" / "integration" / "router.py"
MASS_KG = 0.030
"""The drone's mass in :func:`telemetry_payloads`' hover telemetry."""
RATE_HZ = 250.0
PERIOD_S = 1.0 / RATE_HZ
SUTS = ("service", "echo", "floor", "baseline")
"""Systems under test: ``groundstation serve --headless``, the bare echo floor, the contract
floor (:mod:`benchmarks.floor_service`: validation, observation, one Kalman step and the
Estimate per message, nothing else), and ``serve``
from another source tree (``BENCH_BASELINE_TREE``: e.g. ``git archive <commit>`` unpacked),
for a before/after comparison in one run."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_port(port: int, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"port {port}")


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def thread_cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds per thread group of a process: ``main``, ``python`` (the other Python
    threads: the service's worker), and zenoh's runtime threads by name (digits dropped)."""
    ticks = os.sysconf("SC_CLK_TCK")
    out: dict[str, float] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            stat = (task / "stat").read_text()
        except OSError:
            continue
        comm = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat.rsplit(")", 1)[1].split()
        name = "main" if int(task.name) == pid else comm.rstrip("0123456789-_")
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / ticks
    return out


def children(pid: int) -> list[int]:
    """Direct child processes of ``pid`` (the dashboard process that `serve` starts)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def telemetry_payloads(n_drones: int, steps: int, seed: int) -> list[list[bytes]]:
    """Pre-encoded hover telemetry, ``[step][drone]`` (so the client's own CPU stays small)."""
    rng = np.random.default_rng(seed)
    mass = MASS_KG
    tension = np.array([-0.02, 0.0, -0.06])
    thrust_vec = -(tension + mass * np.array([0.0, 0.0, -9.81]))
    thrust = float(np.linalg.norm(thrust_vec))
    q = quat_wxyz_from_z_axis(thrust_vec / thrust).tolist()
    # Hover: p'' = 0, so the IMU reads f = R'(-g).
    f_body = rotation_world_body(np.array(q)).T @ np.array([0.0, 0.0, 9.81])
    out: list[list[bytes]] = []
    for step in range(steps):
        row = []
        noise = rng.normal(0.0, 0.3, (n_drones, 3))
        for d in range(n_drones):
            row.append(
                json.dumps(
                    {
                        "seq": step,
                        "stamp_s": step / RATE_HZ,
                        "accel_mps2": (f_body + noise[d]).tolist(),
                        "quat_wxyz": q,
                        "thrust_n": thrust + float(rng.normal(0.0, 0.003)),
                    }
                ).encode()
            )
        out.append(row)
    return out


# ---------------------------------------------------------------------------- processes


@dataclass
class Rig:
    """A router and one system under test (``service`` or ``echo``) on a fresh port."""

    sut: str
    dashboard: bool = False
    profile: str | None = None  # py-spy output path (env BENCH_PYSPY names the binary)
    foxglove: bool = False
    """With Foxglove's WebSocket server (``--foxglove-port``) and a client subscribed to
    every channel (:mod:`benchmarks.foxglove_client`)."""
    foxglove_topics: tuple[str, ...] = ()
    """Topic prefixes that client subscribes to (empty: every channel)."""
    endpoint: str = ""
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)
    pid: int = 0

    def start(self) -> None:
        port = free_port()
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self.procs.append(
            subprocess.Popen(
                [sys.executable, str(ROUTER), self.endpoint],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        wait_port(port)
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        cwd = REPO  # `python -m` puts the working directory first on sys.path
        if self.sut in ("service", "baseline"):
            args = [sys.executable, "-m", "groundstation", "serve", "--connect", self.endpoint]
            args += ["--web-port", str(free_port())] if self.dashboard else ["--headless"]
            if self.foxglove:
                fox_port = free_port()
                args += ["--foxglove-port", str(fox_port)]
            if self.sut == "baseline":
                cwd = Path(os.environ["BENCH_BASELINE_TREE"])
                env["PYTHONPATH"] = str(cwd)
        elif self.sut == "echo":
            args = [sys.executable, "-m", "benchmarks.echo_service", self.endpoint]
        elif self.sut == "floor":
            args = [sys.executable, "-m", "benchmarks.floor_service", self.endpoint]
        else:
            raise ValueError(f"sut must be one of {SUTS}, got {self.sut!r}")
        if self.profile:
            pyspy = os.environ.get("BENCH_PYSPY", "py-spy")
            spy = [pyspy, "record", "--nonblocking", "--threads", "--format", "raw"]
            args = [*spy, "--rate", "200", "-o", self.profile, "--", *args]
        proc = subprocess.Popen(
            args,
            stdout=subprocess.DEVNULL,
            stderr=None if self.profile else subprocess.DEVNULL,
            env=env,
            cwd=cwd,
        )
        self.procs.append(proc)
        self.pid = proc.pid
        if self.foxglove and self.sut in ("service", "baseline"):
            wait_port(fox_port)
            self.procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "benchmarks.foxglove_client",
                        str(fox_port),
                        *self.foxglove_topics,
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    cwd=REPO,
                )
            )
        if self.profile:  # the SUT is py-spy's child
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and not children(proc.pid):
                time.sleep(0.05)
            self.pid = children(proc.pid)[0]

    def stop(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT if self.profile else signal.SIGTERM)
                try:
                    proc.wait(15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        self.procs.clear()


@contextmanager
def rig(
    sut: str,
    dashboard: bool = False,
    profile: str | None = None,
    foxglove: bool = False,
    foxglove_topics: tuple[str, ...] = (),
) -> Iterator[Rig]:
    r = Rig(sut, dashboard, profile, foxglove, foxglove_topics=foxglove_topics)
    try:
        r.start()
        yield r
    finally:
        r.stop()


# ---------------------------------------------------------------------------- the client


@dataclass(frozen=True)
class Schedule:
    """When each tick is published: ``release_s[k]`` after the start, all drones at once.

    Steady load releases tick k at k/250 s. A burst schedule holds every tick whose time
    falls in the first ``pause_s`` of each ``every_s`` and releases them together at the
    end of the pause, back to back (the upstream paused: Wi-Fi, a router flush, a bridge's
    garbage collection).
    """

    release_s: tuple[float, ...]
    pause_s: float = 0.0
    every_s: float = 0.0

    @classmethod
    def steady(cls, seconds: float) -> Schedule:
        return cls(tuple(k * PERIOD_S for k in range(int(seconds * RATE_HZ))))

    @classmethod
    def bursts(cls, seconds: float, pause_s: float = 0.1, every_s: float = 1.0) -> Schedule:
        out = []
        for k in range(int(seconds * RATE_HZ)):
            t = k * PERIOD_S
            phase = t % every_s
            # the first tick of each second goes at the end of its pause too
            out.append(t - phase + pause_s if phase < pause_s else t)
        return cls(tuple(out), pause_s, every_s)


def _seq_of(payload: bytes) -> int:
    if payload.startswith(b'{"seq":'):
        end = payload.find(b",", 7)
        if end > 0:
            return int(payload[7:end])
    return int(json.loads(payload)["seq"])


def _prime(bus: ZenohBus, key: str, payload: bytes, first: threading.Event, endpoint: str) -> None:
    """Publish ``payload`` until the SUT's first estimate sets ``first`` (at most 30 s)."""
    deadline = time.monotonic() + 30
    while not first.is_set() and time.monotonic() < deadline:
        bus.publish(key, payload)
        first.wait(0.2)
    if not first.is_set():
        raise TimeoutError(f"no estimate from the SUT on {endpoint}")


def drive(
    endpoint: str,
    n_drones: int,
    schedule: Schedule,
    payloads: Sequence[Sequence[bytes]],
    sut_pid: int,
    drain_s: float = 2.0,
) -> dict[str, Any]:
    """Publish ``payloads`` to the SUT on ``schedule``; return latencies and costs.

    Tick 0 is a warm-up (published until the SUT answers drone 0), not timed.
    """
    steps = len(schedule.release_s)
    assert len(payloads) >= steps
    sent: list[list[int]] = [[0] * steps for _ in range(n_drones)]
    recv: list[list[int]] = [[0] * steps for _ in range(n_drones)]
    index = {f"tether/d{d}/estimate": d for d in range(n_drones)}
    first = threading.Event()
    clock = time.monotonic_ns

    def on_estimate(sample: Sample) -> None:
        now = clock()
        d = index.get(sample.key)
        if d is None:
            return
        seq = _seq_of(sample.payload)
        if 0 <= seq < steps:
            recv[d][seq] = now
            if seq == 0:
                first.set()

    gc_pauses_ns: list[int] = []
    gc_t0 = [0]

    def on_gc(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            gc_t0[0] = time.perf_counter_ns()
        else:
            gc_pauses_ns.append(time.perf_counter_ns() - gc_t0[0])

    bus = ZenohBus(ZenohSection(mode="client", connect=(endpoint,)))
    try:
        bus.subscribe("tether/*/estimate", on_estimate)
        keys = [f"tether/d{d}/telemetry" for d in range(n_drones)]
        _prime(bus, keys[0], payloads[0][0], first, endpoint)
        time.sleep(0.5)  # late warm-up replies out of the way
        publish = bus.publish
        threads0 = thread_cpu_s(sut_pid)
        child_pids = children(sut_pid)
        child0 = sum(cpu_s(c) for c in child_pids)
        late = 0
        worst_late_ns = 0
        gc.collect()
        gc.freeze()
        gc.disable()
        gc.callbacks.append(on_gc)
        try:
            t_start = clock()
            release_ns = [t_start + int(r * 1e9) for r in schedule.release_s]
            for k in range(1, steps):
                target = release_ns[k]
                now = clock()
                if target > now:
                    time.sleep((target - now) / 1e9)
                lateness = clock() - target
                if lateness > PERIOD_S * 1e9:
                    late += 1
                worst_late_ns = max(worst_late_ns, lateness)
                row = payloads[k]
                for d in range(n_drones):
                    sent[d][k] = clock()
                    publish(keys[d], row[d])
            elapsed_s = (clock() - t_start) / 1e9
            time.sleep(drain_s)
        finally:
            gc.callbacks.remove(on_gc)
            gc.enable()
            gc.unfreeze()
        threads1 = thread_cpu_s(sut_pid)
        child_cpu = sum(cpu_s(c) for c in child_pids) - child0
        rss = rss_mb(sut_pid)
        status = bus.query("tether/*/status", timeout_s=3.0)
        overflow = sum(json.loads(s.payload).get("queue_overflow", 0) for s in status)
    finally:
        bus.close()

    s = np.array([row[1:] for row in sent], dtype=np.int64)
    r = np.array([row[1:] for row in recv], dtype=np.int64)
    got = r > 0
    lat_ms = (r[got] - s[got]) / 1e6
    n_sent = int(s.size)
    threads = {k: threads1.get(k, 0.0) - threads0.get(k, 0.0) for k in threads1}
    cpu = sum(threads.values())
    worker = threads.get("python", 0.0)
    return {
        "drones": n_drones,
        "rate_hz": n_drones * RATE_HZ,
        "seconds": elapsed_s,
        "offered_hz": n_sent / elapsed_s,
        "sent": n_sent,
        "delivered": float(got.sum()) / n_sent,
        "p50_ms": _pct(lat_ms, 50),
        "p99_ms": _pct(lat_ms, 99),
        "p999_ms": _pct(lat_ms, 99.9),
        "max_ms": float(lat_ms.max()) if lat_ms.size else float("nan"),
        "cpu_us_per_msg": cpu / n_sent * 1e6,
        "worker_us_per_msg": worker / n_sent * 1e6,
        "cpu_share": cpu / elapsed_s,
        "threads_cpu_s": {k: round(v, 3) for k, v in sorted(threads.items()) if v > 0},
        "dashboard_process_cpu_share": child_cpu / elapsed_s,
        "rss_mb": rss,
        "queue_overflow": overflow,
        "late_ticks": late,
        "worst_late_ms": worst_late_ns / 1e6,
        "client_gc_collections": len(gc_pauses_ns),
        "client_gc_max_ms": max(gc_pauses_ns, default=0) / 1e6,
    }


def _pct(x: np.ndarray, q: float) -> float:
    return float(np.percentile(x, q)) if x.size else float("nan")


def capacity(
    endpoint: str,
    sut_pid: int,
    n_drones: int,
    backlog: int,
    warmup_steps: int = 125,
    seed: int = 0,
) -> dict[str, Any]:
    """Drain rate while a backlog exists.

    Each drone first gets ``warmup_steps`` ticks at 250 Hz (its filter converges, so the
    backlog runs the whole path: filter, localization, follow, Estimate); then ``backlog``
    messages over the ``n_drones`` are published back to back. Rate = estimates of the
    backlog / (last − first one's arrival at the client); CPU per message over the same span
    from ``/proc``. ``backlog`` must stay below the service's queue (8192 by default).
    """
    steps_b = backlog // n_drones
    steps = warmup_steps + steps_b
    payloads = telemetry_payloads(n_drones, steps, seed)
    recv: list[list[int]] = [[0] * steps for _ in range(n_drones)]
    index = {f"tether/d{d}/estimate": d for d in range(n_drones)}
    first = threading.Event()
    clock = time.monotonic_ns

    def on_estimate(sample: Sample) -> None:
        now = clock()
        d = index.get(sample.key)
        if d is not None:
            seq = _seq_of(sample.payload)
            if 0 <= seq < steps:
                recv[d][seq] = now
                if seq == 0 and d == 0:
                    first.set()

    def arrived() -> int:
        return sum(1 for row in recv for v in row[warmup_steps:] if v)

    bus = ZenohBus(ZenohSection(mode="client", connect=(endpoint,)))
    try:
        bus.subscribe("tether/*/estimate", on_estimate)
        keys = [f"tether/d{d}/telemetry" for d in range(n_drones)]
        _prime(bus, keys[0], payloads[0][0], first, endpoint)
        t_start = time.monotonic()
        for k in range(warmup_steps):
            delay = t_start + k * PERIOD_S - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            for d in range(n_drones):
                bus.publish(keys[d], payloads[k][d])
        time.sleep(1.0)
        threads0 = thread_cpu_s(sut_pid)
        gc.collect()
        gc.freeze()
        gc.disable()
        try:
            t0 = clock()
            for k in range(warmup_steps, steps):
                row = payloads[k]
                for d in range(n_drones):
                    bus.publish(keys[d], row[d])
            t_published = clock()
            # until every estimate is in, or none came for 3 s (a starved machine can stall
            # the service for a second), at most 120 s
            want = steps_b * n_drones
            last, last_change = -1, time.monotonic()
            deadline = last_change + 120.0
            while (count := arrived()) < want and time.monotonic() < deadline:
                if count != last:
                    last, last_change = count, time.monotonic()
                elif time.monotonic() - last_change > 3.0:
                    break
                time.sleep(0.1)
        finally:
            gc.enable()
            gc.unfreeze()
        threads1 = thread_cpu_s(sut_pid)
    finally:
        bus.close()
    times = np.array([v for row in recv for v in row[warmup_steps:] if v], dtype=np.int64)
    n = int(times.size)
    sent = steps_b * n_drones
    span_s = float(times.max() - times.min()) / 1e9 if n > 1 else float("nan")
    threads = {k: threads1.get(k, 0.0) - threads0.get(k, 0.0) for k in threads1}
    cpu = sum(threads.values())
    return {
        "drones": n_drones,
        "backlog": sent,
        "delivered": n / sent,
        "publish_ms": (t_published - t0) / 1e6,
        "drain_s": span_s,
        "msgs_per_s": (n - 1) / span_s if n > 1 else float("nan"),
        "wall_us_per_msg": span_s / max(n - 1, 1) * 1e6,
        "cpu_us_per_msg": cpu / max(n, 1) * 1e6,
        "worker_us_per_msg": threads.get("python", 0.0) / max(n, 1) * 1e6,
        "threads_cpu_s": {k: round(v, 3) for k, v in sorted(threads.items()) if v > 0},
    }


def offline_us_per_msg(n_drones: int, messages: int = 4000, seed: int = 0) -> dict[str, float]:
    """The same messages through :meth:`Pipeline.handle` in this process, no bus: CPU µs per
    message after each drone's filter has converged (the maths alone, for comparison with
    the service's worker in the same run)."""
    from groundstation.evaluation import settings_for
    from groundstation.pipeline import Pipeline

    warm = 125
    steps = warm + messages // n_drones
    payloads = telemetry_payloads(n_drones, steps, seed)
    keys = [f"tether/d{d}/telemetry" for d in range(n_drones)]
    samples = [Sample(keys[d], payloads[k][d]) for k in range(steps) for d in range(n_drones)]
    pipe = Pipeline(settings_for())
    for sample in samples[: warm * n_drones]:
        pipe.handle(sample, 0.0)
    timed = samples[warm * n_drones :]
    gc.collect()
    gc.disable()
    try:
        c0, t0 = time.thread_time(), time.perf_counter()
        for sample in timed:
            pipe.handle(sample, 0.0)
        c1, t1 = time.thread_time(), time.perf_counter()
    finally:
        gc.enable()
    n = len(timed)
    out = {"cpu_us_per_msg": (c1 - c0) / n * 1e6, "wall_us_per_msg": (t1 - t0) / n * 1e6}
    out["batched_cpu_us_per_msg"] = _offline_batched_us(samples, warm * n_drones)
    return out


def _offline_batched_us(samples: list[Sample], n_warm: int) -> float:
    """The same messages validated, then stepped as the service's worker steps a backlog
    (``Pipeline.process_batch`` in batches of ``service._MAX_BATCH``, grouped by drone): CPU
    µs per message, validation included; NaN for a tree without ``process_batch``."""
    from groundstation import service
    from groundstation.evaluation import settings_for
    from groundstation.pipeline import Pipeline

    pipe = Pipeline(settings_for())
    if not hasattr(pipe, "process_batch"):
        return math.nan
    for sample in samples[:n_warm]:
        pipe.handle(sample, 0.0)
    timed = samples[n_warm:]
    size = service._MAX_BATCH
    gc.collect()
    gc.disable()
    try:
        c0 = time.thread_time()
        parsed = [p for s in timed if (p := pipe.validate(s, 0.0)) is not None]
        for i in range(0, len(parsed), size):
            pipe.process_batch(service.group_by_drone(parsed[i : i + size]))
        c1 = time.thread_time()
    finally:
        gc.enable()
    return (c1 - c0) / len(timed) * 1e6
