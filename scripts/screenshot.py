"""Refresh ``docs/dashboard.png``: a screenshot of the dashboard on a live feed.

    .venv/bin/python scripts/screenshot.py [--out docs/dashboard.png] [--seconds 22] [--fake]

Runs the simulator (scenario ``hover_spots``, drones cf1 and cf2), the service and the
dashboard in this process on an in-memory bus, lets the charts fill, opens Debian's Chromium
(``/usr/bin/chromium``, headless, software WebGL), waits for a rendered frame and writes the
PNG. Without an importable service/simulator, or with ``--fake``, the feed is the test fake
(``tests/dashboard_fake.py``). Nothing is fetched from outside the machine.
"""

from __future__ import annotations

import argparse
import io
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

from groundstation.bus import InMemoryBus  # noqa: E402
from groundstation.config import load_settings  # noqa: E402
from groundstation.dashboard import Dashboard  # noqa: E402
from tests.browser.conftest import CHROMIUM, CHROMIUM_ARGS  # noqa: E402  (one set of flags)


def _start_feed(bus: InMemoryBus, settings: Any, fake: bool) -> tuple[str, list[Any]]:
    if not fake:
        try:
            from groundstation.service import Service
            from groundstation.sim import Simulator
        except ImportError as exc:
            print(f"screenshot: service/simulator not importable ({exc}); using the fake feed")
        else:
            service = Service(settings, bus)
            sim = Simulator(settings, bus)
            service.start()
            sim.start()
            return "simulator + service", [sim, service]
    from tests.dashboard_fake import FakeService

    return "fake feed", [FakeService(bus, ("cf1", "cf2"), rate_hz=100.0).start()]


def _scene_drawn(page: Any) -> bool:
    box = page.evaluate(
        """() => {
            let best = null;
            for (const c of document.querySelectorAll('canvas')) {
                const r = c.getBoundingClientRect();
                if (!best || r.width * r.height > best.width * best.height)
                    best = {x: r.x, y: r.y, width: r.width, height: r.height};
            }
            return best;
        }"""
    )
    if not box:
        return False
    pixels = np.asarray(Image.open(io.BytesIO(page.screenshot(clip=box))).convert("L"))
    return float(pixels.std()) > 5.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "dashboard.png")
    parser.add_argument("--seconds", type=float, default=22.0, help="feed time before the shot")
    parser.add_argument("--fake", action="store_true", help="use the test fake, not the sim")
    args = parser.parse_args()

    from playwright.sync_api import sync_playwright

    settings = load_settings(
        use_env=False,
        cli_overrides={
            "web": {"port": 0},
            "sim": {"scenario": "hover_spots", "drones": ["cf1", "cf2"]},
        },
    )
    bus = InMemoryBus()
    source, parts = _start_feed(bus, settings, args.fake)
    dashboard = Dashboard(settings, bus, port=0)
    dashboard.start()
    print(f"screenshot: {source}, dashboard at {dashboard.url}")
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(
                executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS
            )
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            foreign: list[str] = []
            page.on(
                "request",
                lambda r: (
                    None
                    if r.url.startswith(("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:"))
                    else foreign.append(r.url)
                ),
            )
            page.set_default_timeout(120_000)
            page.goto(dashboard.url)
            page.get_by_text("|T|", exact=True).first.wait_for()
            deadline = time.monotonic() + 120.0
            tick = threading.Event()
            while not _scene_drawn(page):
                if time.monotonic() > deadline:
                    raise SystemExit("screenshot: the 3D view stayed blank")
                tick.wait(0.5)
            # The "software WebGL" notice is true but not what the picture is about.
            close = page.locator(".mantine-Notification-root button")
            for i in range(close.count()):
                close.nth(i).click()
            # Let the 20 s charts fill (the clock started with the dashboard), then make sure
            # the browser has drawn them.
            tick.wait(max(2.0, args.seconds - dashboard.stats().wall_s))
            page.wait_for_function(
                """() => {
                    const charts = Object.values(window.__viserTestpoints?.uplots ?? {});
                    return charts.length >= 2 && charts.every(
                        (c) => c.chart.data[0].length > 50 && c.chart.scales.x.min < -5);
                }"""
            )
            tick.wait(1.0)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            browser.close()
            if foreign:
                raise SystemExit(f"screenshot: requests left the machine: {foreign}")
    finally:
        dashboard.close()
        for part in parts:
            part.close()
        bus.close()
    print(f"screenshot: wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
