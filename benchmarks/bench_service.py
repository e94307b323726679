"""Service capacity: N drones × 250 Hz through a router into ``groundstation serve``.

Run:  .venv/bin/python -m benchmarks.bench_service [--drones 1 8 16 32] [--seconds 20] [--quick]

Topology (as deployed): a router (Python session in router mode, tests/integration/router.py),
``groundstation serve --headless`` as its client (or with the dashboard: ``--dashboard``), and
this process as a second client that publishes realistic hover telemetry for N drones at
250 Hz each and subscribes to the estimates. Latency is publish → estimate received, both
stamped with this process's monotonic clock; delivery is estimates received / telemetry sent.
The service's CPU time and RSS are read from /proc. Writes docs/service_benchmark.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import socket
import subprocess
import sys
import threading
import time
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
RATE_HZ = 250.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_port(port: int, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"port {port}")


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks


def _children(pid: int) -> list[int]:
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


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _telemetry_payloads(n_drones: int, seconds: float, seed: int) -> list[list[bytes]]:
    """Pre-encoded hover telemetry (so the generator's own CPU stays small)."""
    rng = np.random.default_rng(seed)
    steps = int(seconds * RATE_HZ)
    mass = 0.030
    tension = np.array([-0.02, 0.0, -0.06])
    thrust_vec = -(tension + mass * np.array([0.0, 0.0, -9.81]))
    thrust = float(np.linalg.norm(thrust_vec))
    q = quat_wxyz_from_z_axis(thrust_vec / thrust)
    # Hover: p'' = 0, so the IMU reads f = R'(-g).
    f_body = rotation_world_body(q).T @ np.array([0.0, 0.0, 9.81])
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
                        "quat_wxyz": q.tolist(),
                        "thrust_n": thrust + float(rng.normal(0.0, 0.003)),
                    }
                ).encode()
            )
        out.append(row)
    return out


def run_case(n_drones: int, seconds: float, dashboard: bool = False) -> dict[str, Any]:
    port = _free_port()
    ep = f"tcp/127.0.0.1:{port}"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    router = subprocess.Popen(
        [sys.executable, str(ROUTER), ep], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    service = None
    bus = None
    try:
        _wait_port(port)
        args = [sys.executable, "-m", "groundstation", "serve", "--connect", ep]
        if dashboard:
            args += ["--web-port", str(_free_port())]
        else:
            args.append("--headless")
        service = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        payloads = _telemetry_payloads(n_drones, seconds, seed=n_drones)
        bus = ZenohBus(ZenohSection(mode="client", connect=(ep,)))
        sent: dict[tuple[int, int], int] = {}
        latencies_ns: list[int] = []
        lock = threading.Lock()

        def on_estimate(sample: Sample) -> None:
            now = time.monotonic_ns()
            drone = int(sample.key.split("/")[1][1:])
            seq = json.loads(sample.payload)["seq"]
            with lock:
                t0 = sent.get((drone, seq))
                if t0 is not None:
                    latencies_ns.append(now - t0)

        bus.subscribe("tether/*/estimate", on_estimate)
        keys = [f"tether/d{d}/telemetry" for d in range(n_drones)]
        # Warm-up: wait until the service answers the first drone.
        first = threading.Event()
        bus.subscribe("tether/d0/estimate", lambda s: first.set())
        deadline = time.monotonic() + 20
        while not first.is_set() and time.monotonic() < deadline:
            bus.publish(keys[0], payloads[0][0])
            first.wait(0.2)
        with lock:
            latencies_ns.clear()
        cpu0 = _cpu_s(service.pid)
        children = _children(service.pid)
        child_cpu0 = sum(_cpu_s(c) for c in children)
        t_start = time.monotonic()
        period = 1.0 / RATE_HZ
        late_ticks = 0
        for step, row in enumerate(payloads[1:], start=1):
            target = t_start + step * period
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -period:
                late_ticks += 1
            for d, payload in enumerate(row):
                with lock:
                    sent[(d, step)] = time.monotonic_ns()
                bus.publish(keys[d], payload)
        elapsed = time.monotonic() - t_start
        time.sleep(2.0)  # drain
        cpu = _cpu_s(service.pid) - cpu0
        child_cpu = sum(_cpu_s(c) for c in children) - child_cpu0
        rss = _rss_mb(service.pid)
        status = bus.query("tether/*/status", timeout_s=3.0)
        overflow = sum(json.loads(s.payload).get("queue_overflow", 0) for s in status)
        with lock:
            lat = np.array(latencies_ns, dtype=float) / 1e6
            n_sent = len(sent)
        return {
            "drones": n_drones,
            "rate_hz": n_drones * RATE_HZ,
            "offered_hz": n_sent / elapsed,
            "sent": n_sent,
            "delivered": len(lat) / n_sent if n_sent else float("nan"),
            "p50_ms": float(np.percentile(lat, 50)) if len(lat) else float("nan"),
            "p99_ms": float(np.percentile(lat, 99)) if len(lat) else float("nan"),
            "max_ms": float(lat.max()) if len(lat) else float("nan"),
            "cpu_us_per_msg": cpu / n_sent * 1e6 if n_sent else float("nan"),
            "cpu_share": cpu / elapsed,
            "dashboard_process_cpu_share": child_cpu / elapsed,
            "rss_mb": rss,
            "queue_overflow": overflow,
            "generator_late_ticks": late_ticks,
            "dashboard": dashboard,
        }
    finally:
        if bus is not None:
            bus.close()
        for proc in (service, router):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(5)
                except subprocess.TimeoutExpired:
                    proc.kill()


def to_markdown(rows: list[dict[str, Any]], seconds: float, command: str) -> str:
    lines = [
        "# Service capacity",
        "",
        f"Command: `{command}` ({seconds:.0f} s per case). Machine: {platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}.",
        "",
        "Router + `groundstation serve` + a load client, each its own process over TCP on "
        "127.0.0.1. Latency: the client's publish → the estimate's arrival back at the client.",
        "",
        "| drones × 250 Hz | dashboard | offered msg/s | delivered | p50 ms | p99 ms | max ms "
        "| service CPU µs/msg | service CPU share | dashboard process CPU | RSS MB "
        "| queue overflow |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['drones']} | {'yes' if r['dashboard'] else 'no'} | {r['offered_hz']:.0f} "
            f"| {100 * r['delivered']:.2f} % | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} "
            f"| {r['max_ms']:.1f} | {r['cpu_us_per_msg']:.0f} | {100 * r['cpu_share']:.0f} % "
            f"| {100 * r['dashboard_process_cpu_share']:.0f} % "
            f"| {r['rss_mb']:.0f} | {r['queue_overflow']} |"
        )
    lines.append("")
    sat = [r for r in rows if r["delivered"] < 0.999 or r["p99_ms"] > 10.0]
    if sat:
        first = sat[0]
        lines.append(
            f"Saturation: first case missing a target (≥ 99.9 % delivered, p99 ≤ 10 ms) is "
            f"{first['drones']} drones ({first['rate_hz']:.0f} msg/s): "
            f"{100 * first['delivered']:.2f} % delivered, p99 {first['p99_ms']:.1f} ms."
        )
    else:
        lines.append("Every case met the targets (≥ 99.9 % delivered, p99 ≤ 10 ms).")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", type=int, nargs="+", default=[1, 8, 16, 32])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--dashboard", action="store_true", help="also run with the dashboard")
    parser.add_argument("--quick", action="store_true", help="8 drones, 5 s")
    parser.add_argument("--out", default=str(REPO / "docs" / "service_benchmark.md"))
    args = parser.parse_args()
    if args.quick:
        args.drones, args.seconds = [8], 5.0
    rows = []
    for n in args.drones:
        row = run_case(n, args.seconds)
        print(json.dumps(row), flush=True)
        rows.append(row)
    if args.dashboard:
        for n in args.drones:
            row = run_case(n, args.seconds, dashboard=True)
            print(json.dumps(row), flush=True)
            rows.append(row)
    command = "python -m benchmarks.bench_service " + " ".join(sys.argv[1:])
    text = to_markdown(rows, args.seconds, command.strip())
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
