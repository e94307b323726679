"""Recorder throughput: is recording lossless at ≥ 5,000 samples/s? Writes a Markdown report.

Two measurements:

1. *Writer capacity*: the :class:`~groundstation.recording.Recorder` fed straight from a
   fake bus on this thread (no transport), as fast as it takes samples: the ceiling.
2. *End to end over Zenoh*: a publisher process puts telemetry-sized JSON samples round-robin
   on three drones' keys at a fixed rate; this process records them from a real zenoh
   session (peer, listening on tcp/127.0.0.1, multicast scouting off). Lossless means every
   published sample is in the file, byte-equal, in order.

Usage::

    python -m benchmarks.bench_recorder [--rates 5000 10000] [--duration 5]
        [--out docs/recorder_benchmark.md]
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import platform
import resource
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from groundstation.bus import Sample, SampleHandler, Subscription
from groundstation.config import ZenohSection
from groundstation.recording import Recorder, RecorderStats, iter_messages
from groundstation.zenoh_bus import ZenohBus

REPO = Path(__file__).resolve().parents[1]
DRONES = ("cf1", "cf2", "cf3")

PUBLISHER = r"""
import json, sys, time
import zenoh

endpoint, count, rate = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
drones = sys.argv[4].split(",")
conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
try:
    pubs = [session.declare_publisher(f"tether/{d}/telemetry",
                                      congestion_control=zenoh.CongestionControl.BLOCK)
            for d in drones]
    deadline = time.monotonic() + 20.0
    while not all(p.matching_status.matching for p in pubs):
        if time.monotonic() > deadline:
            sys.exit("no subscriber")
        time.sleep(0.01)
    start = time.monotonic()
    for i in range(count):
        due = start + i / rate
        delay = due - time.monotonic()
        if delay > 0.002:
            time.sleep(delay)
        pubs[i % len(drones)].put(payload(i))
    print(f"{time.monotonic() - start:.4f}", flush=True)
    sys.stdin.read()
finally:
    session.close()
"""


def payload(i: int) -> bytes:
    """Telemetry-sized JSON for sample ``i`` (also sent to the publisher as source)."""
    return json.dumps(
        {
            "seq": i // 3,
            "stamp_s": i * 0.0002,
            "accel_mps2": [0.01 * (i % 17), -0.02, 9.81 + 0.001 * (i % 101)],
            "quat_wxyz": [0.9999, 0.001, -0.002, 0.0004],
            "thrust_n": 0.3124 + 1e-5 * (i % 997),
            "gyro_rps": [0.001, 0.002, -0.001],
            "position_m": [0.512, -0.031, 1.204],
            "armed": True,
            "i": i,
        },
        separators=(",", ":"),
    ).encode()


class _FakeBus:
    """Hands the recorder's handler back so samples can be pushed from this thread."""

    def __init__(self) -> None:
        self.handlers: list[SampleHandler] = []

    def subscribe(self, keyexpr: str, handler: SampleHandler) -> Subscription:
        self.handlers.append(handler)
        return self

    def close(self) -> None:
        pass


def writer_capacity(n: int, tmp: Path) -> dict[str, float]:
    bus = _FakeBus()
    samples = [Sample(f"tether/{DRONES[i % 3]}/telemetry", payload(i)) for i in range(n)]
    recorder = Recorder(bus, tmp / "capacity.mcap")  # type: ignore[arg-type]
    handler = bus.handlers[0]
    start = time.perf_counter()
    for sample in samples:
        handler(sample)
    enqueued_s = time.perf_counter() - start
    stats = recorder.close()
    total_s = time.perf_counter() - start
    size = (tmp / "capacity.mcap").stat().st_size
    return {
        "samples": n,
        "enqueue_per_s": n / enqueued_s,
        "written_per_s": n / total_s,
        "bytes_per_sample": size / n,
        "max_queue": stats.max_queue_depth,
    }


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait(pred: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def end_to_end(rate: float, duration_s: float, tmp: Path) -> dict[str, float | int | bool]:
    count = int(rate * duration_s)
    port = _free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    path = tmp / f"e2e_{int(rate)}.mcap"
    script = tmp / "publisher.py"
    script.write_text("import json\n\n" + inspect.getsource(payload) + PUBLISHER)
    bus = ZenohBus(ZenohSection(mode="peer", listen=(endpoint,)))
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    recorder = Recorder(bus, path)
    stats: RecorderStats | None = None
    env = dict(os.environ, PYTHONPATH=str(REPO))
    pub = subprocess.Popen(
        [sys.executable, str(script), endpoint, str(count), str(rate), ",".join(DRONES)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert pub.stdout is not None
        line = pub.stdout.readline()
        pub_s = float(line)
        _wait(lambda: recorder.samples_received >= count, 30.0)
    finally:
        stats = recorder.close()
        cpu1 = resource.getrusage(resource.RUSAGE_SELF)
        if pub.stdin is not None:
            pub.stdin.close()
        pub.wait(timeout=30)
        if pub.stdout is not None:
            pub.stdout.close()
        bus.close()
    got = [(m.key, m.payload) for m in iter_messages(path)]
    want = [(f"tether/{DRONES[i % 3]}/telemetry", payload(i)) for i in range(count)]
    cpu_s = (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime)
    return {
        "rate": rate,
        "published": count,
        "achieved_rate": count / pub_s,
        "recorded": len(got),
        "lossless": got == want,
        "max_queue": stats.max_queue_depth,
        "dropped": stats.dropped,
        "cpu_us_per_sample": cpu_s / max(1, count) * 1e6,
        "bytes_per_sample": path.stat().st_size / max(1, count),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[5000.0, 10000.0])
    parser.add_argument("--duration", type=float, default=5.0, help="seconds per rate")
    parser.add_argument("--capacity-samples", type=int, default=100_000)
    parser.add_argument("--out", type=Path, help="write the Markdown report here")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        cap = writer_capacity(args.capacity_samples, tmp)
        rows = [end_to_end(rate, args.duration, tmp) for rate in args.rates]

    lines = [
        "# Recorder benchmark",
        "",
        f"`python -m benchmarks.bench_recorder --rates {' '.join(f'{r:g}' for r in args.rates)}"
        f" --duration {args.duration:g}` on {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, {time.strftime('%Y-%m-%d')}.",
        f"Samples are telemetry-sized JSON ({len(payload(12345))} bytes) on three drones' keys; "
        "chunks are",
        "zstd-compressed, 256 KiB, flushed at least every second.",
        "",
        "## Writer capacity (no transport)",
        "",
        f"{cap['samples']:,} samples pushed into the recorder's callback on one thread: "
        f"enqueued at {cap['enqueue_per_s']:,.0f}/s, all written and the file finished at "
        f"{cap['written_per_s']:,.0f}/s; {cap['bytes_per_sample']:.0f} bytes per sample on "
        f"disk; largest backlog {cap['max_queue']:,}.",
        "",
        "## End to end over Zenoh (publisher process → recorder, tcp/127.0.0.1)",
        "",
        "| target /s | achieved /s | published | recorded | lossless, in order | "
        "max backlog | dropped | recorder CPU µs/sample | bytes/sample |",
        "| ---: | ---: | ---: | ---: | :---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        lines.append(
            f"| {r['rate']:,.0f} | {r['achieved_rate']:,.0f} | {r['published']:,} | "
            f"{r['recorded']:,} | {'yes' if r['lossless'] else '**NO**'} | {r['max_queue']:,} | "
            f"{r['dropped']} | {r['cpu_us_per_sample']:.1f} | {r['bytes_per_sample']:.0f} |"
        )
    lines += [
        "",
        "The recorder CPU column is this whole process (zenoh runtime, callbacks, writer thread)",
        "divided by the samples; the publisher runs in its own process on the same two cores.",
        "",
    ]
    report = "\n".join(lines)
    print(report)
    if args.out:
        args.out.write_text(report)
    return 0 if all(r["lossless"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
