"""The dashboard in a real Chromium: it renders, shows |T|, and its buttons put commands on
the bus (Follow mode at once; Stop only after the confirmation). Nothing it loads comes from
outside the machine.

The feed is :class:`tests.dashboard_fake.FakeService` on an in-memory bus (it echoes a
FollowCommand into the next Estimates, as the service does); one test drives the real
:class:`groundstation.service.Service` fed by the simulator.
"""

from __future__ import annotations

import io
import json
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from PIL import Image

from groundstation.bus import InMemoryBus, Sample
from groundstation.config import Settings, load_settings
from groundstation.dashboard import Dashboard
from tests.browser.conftest import (
    FIRST_FRAME_TIMEOUT_MS,
    RequestLog,
    open_page,
    scene_canvas_box,
)
from tests.dashboard_fake import FakeService

pytestmark = [pytest.mark.browser, pytest.mark.slow]

COMMAND_TIMEOUT_S = 30.0


def wait_until(predicate: Callable[[], bool], timeout_s: float) -> bool:
    """Poll ``predicate`` until it holds or ``timeout_s`` passes."""
    deadline = time.monotonic() + timeout_s
    tick = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.1)
    return True


def canvas_pixels(page: Any) -> np.ndarray:
    box = scene_canvas_box(page)
    png = page.screenshot(clip=box)
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def scene_drawn(page: Any) -> bool:
    """The 3D view shows more than a blank canvas: varied pixels and some red (arrow, x axes)."""
    pixels = canvas_pixels(page)
    gray = pixels.mean(axis=2)
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    reddish = int(np.count_nonzero((r > 150) & (g < 110) & (b < 110)))
    return float(gray.std()) > 5.0 and reddish > 20


@dataclass
class Feed:
    bus: InMemoryBus
    fake: FakeService
    dashboard: Dashboard
    page: Any
    requests: RequestLog


def _settings() -> Settings:
    return load_settings(use_env=False, cli_overrides={"web": {"port": 0}})


@pytest.fixture(scope="module")
def feed(browser: Any) -> Iterator[Feed]:
    bus = InMemoryBus()
    fake = FakeService(bus, ("cf1", "cf2"), rate_hz=50.0).start()
    dashboard = Dashboard(_settings(), bus, port=0)
    dashboard.start()
    requests = RequestLog()
    page = open_page(browser, dashboard.url, requests)
    try:
        yield Feed(bus, fake, dashboard, page, requests)
    finally:
        page.context.close()
        dashboard.close()
        fake.close()
        bus.close()


def test_scene_renders(feed: Feed) -> None:
    page = feed.page
    page.locator("canvas").first.wait_for(state="visible", timeout=FIRST_FRAME_TIMEOUT_MS)
    assert wait_until(lambda: scene_drawn(page), FIRST_FRAME_TIMEOUT_MS / 1000.0), (
        "the 3D canvas stayed blank"
    )


def test_tension_readout_shows_the_value(feed: Feed) -> None:
    from playwright.sync_api import expect

    page = feed.page
    expect(page.get_by_text("|T|", exact=True).first).to_be_visible()
    # Drone cf1 of the fake pulls with |T| = 0.250 N.
    expect(page.get_by_text("0.250 N", exact=True).first).to_be_visible()
    expect(page.get_by_text("Tension (N)").first).to_be_visible()


def test_follow_mode_click_publishes_and_reflects_the_report(feed: Feed) -> None:
    from playwright.sync_api import expect

    page, fake = feed.page, feed.fake
    checkbox = page.get_by_label("Follow mode", exact=True)
    expect(checkbox).to_be_enabled()
    expect(checkbox).not_to_be_checked()
    checkbox.click()
    assert fake.wait_for(
        lambda f: any(d == "cf1" and c.get("enabled") is True for d, c in f.follow_commands),
        COMMAND_TIMEOUT_S,
    ), f"no FollowCommand enabled=true on the bus: {fake.follow_commands}"
    assert fake.follow_commands[-1] == ("cf1", {"enabled": True})
    # Held by the report (not only by the click): still checked once the hold expired.
    assert wait_until(lambda: feed.dashboard._follow.pending is None, COMMAND_TIMEOUT_S)
    expect(checkbox).to_be_checked()

    # A change made elsewhere shows up in the browser.
    feed.bus.publish("tether/cf1/follow", b'{"enabled": false}')
    expect(checkbox).not_to_be_checked(timeout=COMMAND_TIMEOUT_S * 1000)


def test_stop_needs_confirmation(feed: Feed) -> None:
    from playwright.sync_api import expect

    page, fake, bus = feed.page, feed.fake, feed.bus
    stop_button = page.get_by_role("button", name="Emergency stop")
    confirm = page.get_by_role("button", name="Confirm stop")

    stop_button.click()
    expect(confirm).to_be_visible()
    assert bus.flush()
    assert fake.stops == [], "a Stop went out before the confirmation"
    page.get_by_role("button", name="Cancel").click()
    expect(confirm).to_be_hidden()
    assert bus.flush()
    assert fake.stops == [], "Cancel sent a Stop"

    stop_button.click()
    t_click_s = time.time()
    confirm.click()
    assert fake.wait_for(lambda f: len(f.stops) == 1, COMMAND_TIMEOUT_S), "no Stop on the bus"
    drone, stop = fake.stops[0]
    assert drone == "cf1" and stop["reason"] == "operator"
    assert abs(stop["stamp_s"] - t_click_s) < 30.0
    expect(confirm).to_be_hidden()
    expect(page.get_by_text("Stop sent", exact=False).first).to_be_visible()


def test_nothing_is_fetched_from_outside(feed: Feed) -> None:
    assert feed.requests.urls, "no request recorded at all"
    assert feed.requests.foreign() == []


def test_follow_mode_with_the_real_service(browser: Any) -> None:
    service_mod = pytest.importorskip(
        "groundstation.service",
        reason="groundstation.service does not import yet",
        exc_type=ImportError,
    )
    from playwright.sync_api import expect

    from groundstation.sim import Simulator

    settings = load_settings(
        use_env=False,
        cli_overrides={
            "web": {"port": 0},
            "sim": {"scenario": "hover", "drones": ["cf1"], "rate_hz": 100.0},
            # Software WebGL can starve the in-process simulator for a moment; this test
            # is about the GUI → service path, not about staleness (tested elsewhere).
            "service": {"stale_after_s": 5.0},
            "follow": {"stale_after_s": 5.0},
        },
    )
    bus = InMemoryBus()
    follow_reports: list[bool] = []

    def on_estimate(sample: Sample) -> None:
        follow = json.loads(sample.payload).get("follow", {})
        follow_reports.append(bool(follow.get("enabled")))

    bus.subscribe("tether/cf1/estimate", on_estimate)
    service = service_mod.Service(settings, bus)
    sim = Simulator(settings, bus)
    dashboard = Dashboard(settings, bus, port=0)
    requests = RequestLog()
    page = None
    try:
        service.start()
        sim.start()
        dashboard.start()
        page = open_page(browser, dashboard.url, requests)
        checkbox = page.get_by_label("Follow mode", exact=True)
        expect(checkbox).to_be_enabled()
        assert wait_until(lambda: len(follow_reports) > 0, COMMAND_TIMEOUT_S)
        assert follow_reports[-1] is False
        n_before = len(follow_reports)
        checkbox.click()
        assert wait_until(lambda: True in follow_reports[n_before:], COMMAND_TIMEOUT_S), (
            "the service's Estimates never reported follow.enabled = true"
        )
        expect(checkbox).to_be_checked()
        assert requests.foreign() == []
    finally:
        if page is not None:
            page.context.close()
        dashboard.close()
        sim.close()
        service.close()
        bus.close()
