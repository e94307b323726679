"""Dashboard CPU cost: 1 and 8 drones, telemetry + Estimates at 250 Hz each.

Run:  .venv/bin/python -m benchmarks.bench_dashboard [--drones 1 8] [--seconds 8] [--no-browser]
      .venv/bin/python -m benchmarks.bench_dashboard --quick   (1 drone, 3 s, no browser,
      prints only: a smoke run, docs/dashboard_cost.md is left as it is)

In one process on an in-memory bus, a feeder thread publishes, per drone, a Telemetry (with
motion capture) and an Estimate every 4 ms (pre-encoded payloads, so the feeder is cheap).
Measured for each drone count:

- the bus callbacks' cost per sample (they only store the latest bytes and count), timed by
  calling the dashboard's handlers directly;
- the update thread: CPU seconds per wall second (``time.thread_time`` inside the update
  passes: parse the latest payloads, push the scene at the scene rate, readouts ≤ 10 Hz,
  charts 4 Hz);
- the whole process's CPU per second with the dashboard minus the same feed without it
  (callbacks + update thread + viser's server thread serialising and sending), once with no
  browser and once with one headless Chromium connected (its own process, not counted; the
  server's sending is). Panels are per browser tab (``[web] panel = "tab"``): with no browser
  there is no panel to refresh, with one there is one.

Writes docs/dashboard_cost.md.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from groundstation.bus import InMemoryBus, Sample
from groundstation.config import load_settings
from groundstation.dashboard import Dashboard

REPO = Path(__file__).resolve().parents[1]
RATE_HZ = 250.0
CHROMIUM = "/usr/bin/chromium"
FPS_JS = """() => new Promise((resolve) => {
    let frames = 0;
    const t0 = performance.now();
    const tick = (t) => {
        frames += 1;
        if (t - t0 < 3000) requestAnimationFrame(tick);
        else resolve(1000 * frames / (t - t0));
    };
    requestAnimationFrame(tick);
})"""


def _payloads(drone_index: int, n: int = 250) -> list[tuple[bytes, bytes]]:
    """n (telemetry, estimate) pairs of one drone circling its base."""
    out = []
    for k in range(n):
        azimuth_rad = 2.0 * math.pi * k / n + drone_index
        pos = [0.9 * math.cos(azimuth_rad), 0.9 * math.sin(azimuth_rad), 1.0]
        telemetry = {
            "seq": k,
            "stamp_s": k / RATE_HZ,
            "accel_mps2": [0.01, -0.02, 9.81],
            "quat_wxyz": [math.cos(azimuth_rad / 2), 0.0, 0.0, math.sin(azimuth_rad / 2)],
            "thrust_n": 0.47,
            "gyro_rps": [0.0, 0.0, 0.0],
            "position_m": pos,
        }
        estimate = {
            "seq": k,
            "stamp_s": k / RATE_HZ,
            "tension_n": [-0.15 * math.cos(azimuth_rad), -0.15 * math.sin(azimuth_rad), -0.2],
            "tension_std_n": [0.004, 0.004, 0.003],
            "horizontal_n": 0.15,
            "vertical_n": 0.2,
            "position_m": [pos[0] + 0.02, pos[1], pos[2] - 0.01],
            "follow": {"enabled": False, "active": False, "threshold_n": 0.15},
            "position_std_m": [0.03, 0.03, 0.02],
            "radial_m": 0.9,
            "radial_interval_m": [0.88, 0.92],
            "azimuth_determined": True,
            "floor_contact": False,
            "on_ground": False,
            "converged": True,
            "length_m": 1.6,
            "base_m": [0.0, 3.0 * drone_index, 0.754],
        }
        out.append((json.dumps(telemetry).encode(), json.dumps(estimate).encode()))
    return out


class Feeder:
    """Publishes every drone's telemetry and Estimate at RATE_HZ on a thread."""

    def __init__(self, bus: InMemoryBus, n_drones: int) -> None:
        self.bus = bus
        self.drones = [f"cf{i + 1}" for i in range(n_drones)]
        self.payloads = [_payloads(i) for i in range(n_drones)]
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="feeder", daemon=True)

    def _run(self) -> None:
        period_s = 1.0 / RATE_HZ
        next_s = time.monotonic()
        k = 0
        while not self._stop.is_set():
            for drone, payloads in zip(self.drones, self.payloads, strict=True):
                telemetry, estimate = payloads[k % len(payloads)]
                self.bus.publish(f"tether/{drone}/telemetry", telemetry)
                self.bus.publish(f"tether/{drone}/estimate", estimate)
            self.sent += 1
            k += 1
            next_s += period_s
            delay_s = next_s - time.monotonic()
            if delay_s < -0.5:
                next_s = time.monotonic()  # fell behind: do not burst
            elif delay_s > 0.0:
                self._stop.wait(delay_s)

    def start(self) -> Feeder:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)


@dataclass(frozen=True)
class Run:
    drones: int
    browser: bool
    seconds: float
    feed_rate_hz: float
    process_cpu_per_s: float
    update_cpu_per_s: float | None
    ticks_per_s: float | None
    browser_fps: float | None = None
    """Frames the page drew per second (requestAnimationFrame callbacks over 3 s)."""


def _settle(seconds: float) -> None:
    threading.Event().wait(seconds)


def run_once(n_drones: int, seconds: float, dashboard_on: bool, browser: Any | None) -> Run:
    settings = load_settings(use_env=False, cli_overrides={"web": {"port": 0}})
    bus = InMemoryBus()
    feeder = Feeder(bus, n_drones).start()
    dashboard = None
    page = None
    try:
        if dashboard_on:
            dashboard = Dashboard(settings, bus, port=0)
            dashboard.start()
            if browser is not None:
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.set_default_timeout(120_000)
                page.goto(dashboard.url)
                page.get_by_text("|T|", exact=True).first.wait_for()
        _settle(2.0)  # warm up: drones seen, scene nodes created, first frame sent
        sent0, cpu0, wall0 = feeder.sent, time.process_time(), time.monotonic()
        stats0 = dashboard.stats() if dashboard is not None else None
        _settle(seconds)
        wall_s = time.monotonic() - wall0
        cpu_s = time.process_time() - cpu0
        sent_s = (feeder.sent - sent0) / wall_s
        update_cpu = ticks = None
        if dashboard is not None and stats0 is not None:
            stats1 = dashboard.stats()
            update_cpu = (stats1.update_cpu_s - stats0.update_cpu_s) / wall_s
            ticks = (stats1.ticks - stats0.ticks) / wall_s
        fps = None
        if page is not None:
            # The 3D view renders in requestAnimationFrame: their rate is the frame rate.
            fps = page.evaluate(FPS_JS)
        return Run(
            n_drones, page is not None, wall_s, sent_s, cpu_s / wall_s, update_cpu, ticks, fps
        )
    finally:
        if page is not None:
            page.close()
        if dashboard is not None:
            dashboard.close()
        feeder.close()
        bus.close()


def callback_cost_us(n: int = 200_000) -> float:
    """Microseconds per telemetry callback (store latest bytes, count, stamp)."""
    settings = load_settings(use_env=False)
    dashboard = Dashboard(settings, InMemoryBus(), update_thread=False)
    sample = Sample("tether/cf1/telemetry", _payloads(0, 1)[0][0])
    dashboard._receive("telemetry", sample)  # first sample creates the drone's inbox
    t0 = time.perf_counter()
    for _ in range(n):
        dashboard._receive("telemetry", sample)
    return (time.perf_counter() - t0) / n * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", type=int, nargs="+", default=[1, 8])
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--no-browser", action="store_true")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "dashboard_cost.md")
    parser.add_argument("--quick", action="store_true", help="1 drone, 3 s, no browser, no file")
    args = parser.parse_args()
    if args.quick:
        args.drones, args.seconds, args.no_browser = [1], 3.0, True

    load_1min = os.getloadavg()[0]
    per_cb_us = callback_cost_us()
    print(f"telemetry callback: {per_cb_us:.2f} µs per sample")
    rows: list[tuple[Run, Run, Run | None]] = []
    use_browser = not args.no_browser and os.access(CHROMIUM, os.X_OK)
    pw = browser = None
    if use_browser:
        from playwright.sync_api import sync_playwright

        pw = sync_playwright().start()
        browser = pw.chromium.launch(
            executable_path=CHROMIUM,
            headless=True,
            args=["--no-sandbox", "--disable-gpu", "--disable-background-networking"],
        )
    try:
        for n in args.drones:
            base = run_once(n, args.seconds, dashboard_on=False, browser=None)
            dash = run_once(n, args.seconds, dashboard_on=True, browser=None)
            with_browser = (
                run_once(n, args.seconds, dashboard_on=True, browser=browser)
                if browser is not None
                else None
            )
            rows.append((base, dash, with_browser))
            for run in (base, dash, with_browser):
                if run is not None:
                    print(run)
    finally:
        if browser is not None:
            browser.close()
        if pw is not None:
            pw.stop()

    settings = load_settings(use_env=False)
    lines = [
        "# Dashboard cost",
        "",
        f"`python -m benchmarks.bench_dashboard --drones {' '.join(map(str, args.drones))} "
        f"--seconds {args.seconds:g}` on {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, {time.strftime('%Y-%m-%d')}; load average "
        f"{load_1min:.1f} at the start (the machine is shared: other work on the two cores "
        "makes these numbers noisy, by some tens of percent between runs).",
        "",
        f"Per drone: telemetry and an Estimate at {RATE_HZ:.0f} Hz each on an in-memory bus; "
        f"scene rate {settings.web.scene_rate_hz:g} Hz (readouts ≤ 10 Hz, charts 4 Hz, "
        "status polled at 1 Hz with no service answering). CPU is in seconds per second "
        "(1.0 = one core busy).",
        "",
        f"Bus callback (store the latest bytes, count, stamp): **{per_cb_us:.2f} µs per "
        "sample**, so 8 drones × 500 samples/s cost "
        f"{8 * 2 * RATE_HZ * per_cb_us / 1e6 * 100:.1f} % of a core on the bus thread.",
        "",
        "| drones | feed achieved (Hz per drone) | update thread CPU/s | scene passes/s "
        "| dashboard CPU/s, no browser | dashboard CPU/s, one browser "
        "| browser frames/s (software WebGL) |",
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for base, dash, with_browser in rows:
        extra = fps = "—"
        if with_browser is not None:
            extra = f"{with_browser.process_cpu_per_s - base.process_cpu_per_s:.3f}"
            if with_browser.browser_fps is not None:
                fps = f"{with_browser.browser_fps:.1f}"
        lines.append(
            f"| {dash.drones} | {dash.feed_rate_hz:.0f} | {dash.update_cpu_per_s or 0.0:.3f} "
            f"| {dash.ticks_per_s or 0.0:.1f} "
            f"| {dash.process_cpu_per_s - base.process_cpu_per_s:.3f} | {extra} | {fps} |"
        )
    lines += [
        "",
        '"Dashboard CPU/s" is this process\'s CPU per second with the dashboard minus the '
        "same feed without it: bus callbacks, the update thread and viser's server thread "
        "(serialising and, with a browser, sending). The browser renders in its own process "
        "(software WebGL here) and is not counted. Each browser tab has its own panel, so the "
        "no-browser column has no panel work and the one-browser column one panel's. "
        "Baseline (feed + bus alone): "
        + ", ".join(f"{b.drones} drone(s) {b.process_cpu_per_s:.3f}" for b, _, _ in rows)
        + ".",
        "",
    ]
    print("\n".join(lines))
    if not args.quick:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
