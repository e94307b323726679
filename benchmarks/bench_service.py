"""Service capacity: N drones × 250 Hz through a router into ``groundstation serve``.

Run:  python -m benchmarks.bench_service [--drones 1 8 16 32] [--seconds 30] [--quick]
      [--dashboard] [--foxglove]

Topology (as deployed): a router, ``groundstation serve --headless`` as its client (or with
the dashboard: ``--dashboard``; with Foxglove's WebSocket server and a client subscribed to
every channel: ``--foxglove``), and this process as a second client that publishes
realistic hover telemetry for N drones at 250 Hz each and subscribes to the estimates; the
rig is :mod:`benchmarks.service_rig`. Latency is publish → estimate received, both stamped
with this process's monotonic clock; delivery is estimates received / telemetry sent.

Each drone count also runs against the bare echo (:mod:`benchmarks.echo_service`), the
floor, in the same run. Windows are 30 s or longer (``--quick`` excepted, marked as such):
a 10 s window used to end just before the client's first full garbage collection; now the
client's collector is off in the window (collections that still happen are counted), and
ticks the client published late are reported. The service's CPU time (per thread) and RSS
are read from /proc. Prints a page (``--out PATH`` also writes it); the published figures
are section (c) of docs/RESULTS.md, which ``python -m benchmarks.results`` measures with
the same rig.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path
from typing import Any

from benchmarks import service_rig as sr

REPO = sr.REPO
RATE_HZ = sr.RATE_HZ
MIN_WINDOW_S = 30.0


def _telemetry_payloads(n_drones: int, seconds: float, seed: int) -> list[list[bytes]]:
    """Pre-encoded hover telemetry, ``[step][drone]`` (``bench_pipeline`` reuses it)."""
    return sr.telemetry_payloads(n_drones, int(seconds * RATE_HZ), seed)


def run_case(
    n_drones: int,
    seconds: float,
    dashboard: bool = False,
    sut: str = "service",
    foxglove: bool = False,
    foxglove_topics: tuple[str, ...] = (),
) -> dict[str, Any]:
    """One steady window of ``n_drones`` × 250 Hz against ``sut`` (``service`` or ``echo``);
    ``foxglove``: with ``--foxglove-port`` and a Foxglove client subscribed to everything
    (or to the topics starting with one of ``foxglove_topics``)."""
    schedule = sr.Schedule.steady(seconds)
    payloads = sr.telemetry_payloads(n_drones, len(schedule.release_s), seed=n_drones)
    with sr.rig(
        sut, dashboard=dashboard, foxglove=foxglove, foxglove_topics=foxglove_topics
    ) as rig:
        row = sr.drive(rig.endpoint, n_drones, schedule, payloads, rig.pid)
    row["generator_late_ticks"] = row["late_ticks"]
    row["dashboard"] = dashboard
    row["foxglove"] = foxglove
    row["foxglove_topics"] = list(foxglove_topics)
    row["sut"] = sut
    return row


def to_markdown(rows: list[dict[str, Any]], seconds: float, command: str) -> str:
    load = os.getloadavg()[0]
    lines = [
        "# Service capacity",
        "",
        f"Command: `{command}` ({seconds:.0f} s per case). Machine: {platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, load average "
        f"{load:.1f} at the end (the machine is shared: compare the service with the echo "
        "floor of the same run).",
        "",
        "Router + system under test + a load client, each its own process over TCP on "
        "127.0.0.1. Latency: the client's publish → the estimate's arrival back at the client. "
        "*echo* is the floor (`benchmarks/echo_service.py`: transport, router and one Python "
        "callback). Method: `benchmarks/service_rig.py` (the client's garbage collector off in "
        "the window; late ticks: published more than 4 ms after their time).",
        "",
        "| drones × 250 Hz | system | offered msg/s | delivered | p50 ms | p99 ms | max ms "
        "| CPU µs/msg | worker µs/msg | CPU share | child process CPU | RSS MB "
        "| queue overflow | late ticks | client GCs |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        system = r.get("sut", "service") + (" + dashboard" if r["dashboard"] else "")
        if r.get("foxglove"):
            topics = ", ".join(r.get("foxglove_topics") or []) or "every channel"
            system += f" + Foxglove (a client on {topics})"
        worker = f"{r['worker_us_per_msg']:.0f}" if r.get("sut") != "echo" else "—"
        lines.append(
            f"| {r['drones']} | {system} | {r['offered_hz']:.0f} "
            f"| {100 * r['delivered']:.2f} % | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} "
            f"| {r['max_ms']:.1f} | {r['cpu_us_per_msg']:.0f} | {worker} "
            f"| {100 * r['cpu_share']:.0f} % "
            f"| {100 * r['dashboard_process_cpu_share']:.0f} % "
            f"| {r['rss_mb']:.0f} | {r['queue_overflow']} | {r['late_ticks']} "
            f"| {r['client_gc_collections']} |"
        )
    lines.append("")
    svc = [
        r
        for r in rows
        if r.get("sut", "service") == "service" and not r["dashboard"] and not r.get("foxglove")
    ]
    floors = {r["drones"]: r for r in rows if r.get("sut") == "echo"}
    ratios = [
        f"{r['drones']} drones {r['p99_ms'] / floors[r['drones']]['p99_ms']:.1f}×"
        for r in svc
        if r["drones"] in floors
    ]
    if ratios:
        lines += ["p99 service / echo floor: " + ", ".join(ratios) + ".", ""]
    sat = [r for r in svc if r["delivered"] < 0.999 or r["p99_ms"] > 10.0]
    if sat:
        first = sat[0]
        lines.append(
            f"Saturation: first case missing a target (≥ 99.9 % delivered, p99 ≤ 10 ms) is "
            f"{first['drones']} drones ({first['rate_hz']:.0f} msg/s): "
            f"{100 * first['delivered']:.2f} % delivered, p99 {first['p99_ms']:.1f} ms."
        )
    else:
        lines.append("Every case met the targets (≥ 99.9 % delivered, p99 ≤ 10 ms).")
    lines += [
        "",
        "Bursts (the upstream pausing 100 ms once a second) and the sustained capacity with a "
        "backlog: `python -m benchmarks.bench_bursts` → docs/service_bursts.md.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", type=int, nargs="+", default=[1, 8, 16, 32])
    parser.add_argument("--seconds", type=float, default=MIN_WINDOW_S, help="≥ 30")
    parser.add_argument("--dashboard", action="store_true", help="also run with the dashboard")
    parser.add_argument(
        "--foxglove",
        action="store_true",
        help="also run with --foxglove-port and a Foxglove client subscribed to every channel",
    )
    parser.add_argument(
        "--foxglove-topics",
        nargs="+",
        default=[],
        metavar="PREFIX",
        help="with --foxglove: the client subscribes to topics with these prefixes only "
        "(the layout's: scene tf tether/cf1/estimate)",
    )
    parser.add_argument("--no-floor", action="store_true", help="skip the echo floor")
    parser.add_argument("--quick", action="store_true", help="8 drones, 10 s (prints only)")
    parser.add_argument("--out", help="also write the page here (published: docs/RESULTS.md (c))")
    args = parser.parse_args()
    if args.quick:
        args.drones, args.seconds = [8], 10.0
    elif args.seconds < MIN_WINDOW_S:
        parser.error(f"--seconds {args.seconds:g}: windows shorter than 30 s need --quick")
    rows = []
    for n in args.drones:
        suts = ("service",) if args.no_floor else ("echo", "service")
        for sut in suts:
            row = run_case(n, args.seconds, sut=sut)
            print(json.dumps(row), flush=True)
            rows.append(row)
    if args.dashboard:
        for n in args.drones:
            row = run_case(n, args.seconds, dashboard=True)
            print(json.dumps(row), flush=True)
            rows.append(row)
    if args.foxglove:
        for n in args.drones:
            row = run_case(
                n, args.seconds, foxglove=True, foxglove_topics=tuple(args.foxglove_topics)
            )
            print(json.dumps(row), flush=True)
            rows.append(row)
    command = "python -m benchmarks.bench_service " + " ".join(sys.argv[1:])
    text = to_markdown(rows, args.seconds, command.strip())
    if args.out and not args.quick:
        Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
