"""Fixtures for driving the dashboard in a real Chromium (Debian's, headless, software GL).

The browser tests skip only when ``/usr/bin/chromium`` is missing (CI installs it: ``./dev
test``). Every request the page makes is recorded so a test can check that nothing leaves
the machine.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
FRAME_PERIOD_MS = 250
"""The page's animation frames come at most every 250 ms (``FRAME_CAP_JS``).

Software GL draws one frame of the dashboard in ~0.1-0.4 s of CPU, and viser draws frames
for 250 ms after every scene update (20 Hz): left alone, Chromium's GPU process (at a
raised priority) takes every core it can get, for frames no test looks at, and starves the
page's own scripts and every other test of a parallel run. Capped, the browser tests take
~60 s of wall time and ~100 s of CPU alone instead of ~100 s and ~180 s (measured with
/proc/stat on this 2-core machine). What the tests check (the page's controls, readouts,
charts and a drawn scene) does not depend on the frame rate; Playwright's own waits run in
its isolated world, whose requestAnimationFrame is untouched."""
FRAME_CAP_JS = (
    "(() => {"
    f" const period = {FRAME_PERIOD_MS};"
    " window.requestAnimationFrame ="
    " (cb) => window.setTimeout(() => cb(performance.now()), period);"
    " window.cancelAnimationFrame = (id) => window.clearTimeout(id);"
    " })();"
)
LOCAL_HOSTS = {"127.0.0.1", "localhost", "[::1]", "::1"}
FIRST_FRAME_TIMEOUT_MS = 120_000
"""Software WebGL on a shared 2-core machine: the first frame can take many seconds."""


def _needs_chromium() -> None:
    if not os.access(CHROMIUM, os.X_OK):
        pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium); ./dev test installs it")


@dataclass
class RequestLog:
    """Every URL a page asked for (HTTP requests and WebSockets)."""

    urls: list[str] = field(default_factory=list)

    def foreign(self) -> list[str]:
        """URLs that are not loopback, ``data:`` or ``blob:``."""
        out = []
        for url in self.urls:
            parts = urlsplit(url)
            if parts.scheme in ("data", "blob"):
                continue
            host = parts.hostname or ""
            if host in LOCAL_HOSTS or f"[{host}]" in LOCAL_HOSTS:
                continue
            out.append(url)
        return out


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    # Module scope on purpose: while Playwright's sync API is alive its event loop counts
    # as running in this thread, and asyncio.run() in a later test module would fail.
    _needs_chromium()
    from playwright.sync_api import expect, sync_playwright

    # expect() has its own 5 s default, separate from the page's: software GL needs more.
    expect.set_options(timeout=FIRST_FRAME_TIMEOUT_MS)
    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS
        )
        try:
            yield chromium
        finally:
            chromium.close()


def open_page(
    browser: Any, url: str, log: RequestLog, viewport: tuple[int, int] = (1100, 800)
) -> Any:
    """A fresh page (its own browser context) on ``url`` recording every request into ``log``.

    Args:
        viewport: (width, height) in CSS pixels.
    """
    context = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
    context.add_init_script(FRAME_CAP_JS)
    context.on("request", lambda request: log.urls.append(request.url))
    page = context.new_page()
    page.on("websocket", lambda ws: log.urls.append(ws.url))
    page.set_default_timeout(FIRST_FRAME_TIMEOUT_MS)
    page.goto(url)
    return page


def scene_canvas_box(page: Any) -> dict[str, float]:
    """Bounding box of the largest canvas (the 3D view; uPlot charts are canvases too).

    Waits for the first canvas: a test may be the first on its page (its worker's first, or
    the only one asked for), before the dashboard has drawn anything.
    """
    page.locator("canvas").first.wait_for(state="visible", timeout=FIRST_FRAME_TIMEOUT_MS)
    box = page.evaluate(
        """() => {
            let best = null;
            for (const c of document.querySelectorAll('canvas')) {
                const r = c.getBoundingClientRect();
                if (!best || r.width * r.height > best.width * best.height) {
                    best = {x: r.x, y: r.y, width: r.width, height: r.height};
                }
            }
            return best;
        }"""
    )
    assert box is not None, "no canvas on the page"
    return dict(box)
