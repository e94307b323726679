"""The first view of the two-drone set-up frames every drone in the part of the 3D view the
control panel leaves free: config/sim.toml's bases 3 m apart, each drone
with a motion-capture marker about a metre from its estimate (an uncalibrated position), so
the motion-capture error line's far end must be in view too.

Checked from the camera the browser reports back (position, orientation, field of view,
canvas size) and the panel's box on the page, not from pixels: every base, drawn body and
motion-capture marker projects inside the canvas and left of the panel, and the two drones
stand side by side on the screen (150 px apart at least), not one behind the other.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import viser.transforms as vtf

from groundstation.bus import InMemoryBus
from groundstation.config import load_settings
from groundstation.dashboard import Dashboard
from tests.browser.conftest import RequestLog, open_page, scene_canvas_box
from tests.dashboard_fake import FakeService

pytestmark = [pytest.mark.browser, pytest.mark.slow]

TIMEOUT_S = 120.0
"""Software WebGL on a shared 2-core machine: the first camera report can take a while."""
SIM_TOML_BASES = {"cf1": (0.0, 0.0, 0.754), "cf2": (0.0, 3.0, 0.754)}
"""config/sim.toml's two drones."""
MOCAP_ERROR_M = (0.3, -0.9, 0.35)
"""Estimate minus motion capture: about a metre, as uncalibrated on the realistic profile."""
PANEL_BOX_JS = """() => {
    // The floating control panel: the widest ancestor of its Emergency stop button that
    // is still narrower than half the window.
    const button = [...document.querySelectorAll('button')]
        .find((b) => b.textContent.includes('Emergency stop'));
    if (!button) return null;
    let box = null;
    for (let e = button; e && e !== document.body; e = e.parentElement) {
        const r = e.getBoundingClientRect();
        if (r.width > window.innerWidth / 2) break;
        box = {x: r.x, y: r.y, width: r.width, height: r.height};
    }
    return box;
}"""


class StillFake(FakeService):
    """The fake feed frozen at t = 0: the drones stay where the camera was framed on them."""

    def publish_once(self, t_s: float | None = None) -> None:
        super().publish_once(0.0)


def wait_until(predicate: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    tick = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.1)
    return True


def css_pixels(camera: Any, points_m: np.ndarray, canvas: dict[str, float]) -> np.ndarray:
    """Page coordinates (k, 2), CSS px, of world points seen by a viser camera as reported
    by the browser (OpenCV convention: x right, y down, z forward)."""
    R_world_camera = vtf.SO3(np.asarray(camera.wxyz)).as_matrix()
    p_camera = (points_m - np.asarray(camera.position)) @ R_world_camera
    assert np.all(p_camera[:, 2] > 0.0), "a point is behind the camera"
    focal_px = 0.5 * camera.image_height / math.tan(0.5 * camera.fov)
    u_px = 0.5 * camera.image_width + focal_px * p_camera[:, 0] / p_camera[:, 2]
    v_px = 0.5 * camera.image_height + focal_px * p_camera[:, 1] / p_camera[:, 2]
    scale = canvas["width"] / camera.image_width  # the buffer's device px → CSS px
    return np.stack([canvas["x"] + scale * u_px, canvas["y"] + scale * v_px], axis=1)


@pytest.mark.parametrize("viewport", [(1280, 800), (1100, 800)])
def test_two_drones_are_framed_left_of_the_panel(browser: Any, viewport: tuple[int, int]) -> None:
    settings = load_settings(use_env=False, cli_overrides={"web": {"port": 0}})
    bus = InMemoryBus()
    fake = StillFake(
        bus,
        ("cf1", "cf2"),
        rate_hz=20.0,
        bases=SIM_TOML_BASES,
        estimate_error_m=MOCAP_ERROR_M,
    ).start()
    dashboard = Dashboard(settings, bus, port=0)
    page = None
    try:
        dashboard.start()

        def drones_drawn() -> bool:
            drones = [dashboard.drone(d) for d in ("cf1", "cf2")]
            return all(
                d is not None and d.body_position() is not None and d.telemetry is not None
                for d in drones
            )

        # Both drones known before the page connects: it is framed on both at once.
        assert wait_until(drones_drawn, 30.0), dashboard.drones
        page = open_page(browser, dashboard.url, RequestLog(), viewport=viewport)
        server = dashboard.server

        def camera_applied() -> Any:
            # The browser applied the framing when the camera it reports looks where the
            # dashboard pointed it.
            for client_id, client in server.get_clients().items():
                framed = dashboard.framed.get(client_id)
                if framed is None:
                    continue
                position, look_at = framed
                if np.allclose(client.camera.look_at, look_at, atol=1e-3) and np.allclose(
                    client.camera.position, position, atol=1e-3
                ):
                    return client
            return None

        assert wait_until(lambda: camera_applied() is not None, TIMEOUT_S), (
            "the browser never reported the framed camera"
        )
        client = camera_applied()
        canvas = scene_canvas_box(page)
        # The camera may come before the panel has mounted: wait for it too.
        assert wait_until(lambda: page.evaluate(PANEL_BOX_JS) is not None, TIMEOUT_S), (
            "no control panel on the page"
        )
        panel = page.evaluate(PANEL_BOX_JS)
        # The panel floats over the right of the canvas (else the test checks nothing).
        assert canvas["x"] < panel["x"] < canvas["x"] + canvas["width"]

        named: list[tuple[str, tuple[float, float, float]]] = []
        for drone_id in ("cf1", "cf2"):
            drone = dashboard.drone(drone_id)
            assert drone is not None and drone.telemetry is not None
            body = drone.body_position()
            mocap = drone.telemetry.position_m
            assert body is not None and mocap is not None
            named += [
                (f"{drone_id} base", drone.base_m(SIM_TOML_BASES[drone_id])),
                (f"{drone_id} body", body),
                (f"{drone_id} motion capture", mocap),
            ]
        # The scene really has the set-up: bases 3 m apart, ~1 m motion-capture errors.
        assert math.dist(named[0][1], named[3][1]) == pytest.approx(3.0)
        assert math.dist(named[1][1], named[2][1]) > 0.9

        uv = css_pixels(client.camera, np.array([p for _, p in named]), canvas)
        outside = [
            f"{name} at ({u:.0f}, {v:.0f})"
            for (name, _), (u, v) in zip(named, uv, strict=True)
            if not (
                canvas["x"] <= u < panel["x"] and canvas["y"] <= v <= canvas["y"] + canvas["height"]
            )
        ]
        assert not outside, (
            f"not in the free view (canvas {canvas}, panel from x = {panel['x']:.0f}): "
            + "; ".join(outside)
        )
        # Side by side, not one behind the other (their labels would overlap).
        cf1_body, cf2_body = uv[1], uv[4]
        assert abs(cf1_body[0] - cf2_body[0]) > 150.0, (cf1_body, cf2_body)
    finally:
        if page is not None:
            page.context.close()
        dashboard.close()
        fake.close()
        bus.close()
