"""Dashboard without a browser: parsing, commands, throttling, and the update pass on fake data.

The Dashboard runs with ``update_thread=False`` so each test drives :meth:`Dashboard.update`
with its own clock; the viser server binds an ephemeral port on 127.0.0.1.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from groundstation.bus import InMemoryBus, Sample
from groundstation.config import Settings, load_settings
from groundstation.dashboard import app as dash_mod
from groundstation.dashboard.app import (
    Dashboard,
    FollowView,
    History,
    LinkStats,
    Pending,
    Throttle,
    camera_framing,
    fill_gaps,
    follow_command,
    follow_html,
    health_html,
    load_quadrotor_mesh,
    params_command,
    parse_estimate,
    parse_reel,
    parse_telemetry,
    parse_truth,
    polyline_segments,
    reconcile,
    stop_command,
    tension_arrow,
    tension_html,
    tether_points,
)
from groundstation.messages import (
    Estimate,
    FollowCommand,
    FollowInfo,
    StopIn,
    Truth,
)
from tests.dashboard_fake import FIXED_NORM_N, FakeService

# ------------------------------------------------------------------------------ parsing


def _estimate(**overrides: Any) -> Estimate:
    fields: dict[str, Any] = {
        "seq": 7,
        "stamp_s": 1.5,
        "tension_n": (0.09, -0.12, -0.2),
        "tension_std_n": (0.01, 0.01, 0.005),
        "horizontal_n": 0.15,
        "vertical_n": 0.2,
        "position_m": (0.8, 0.1, 1.0),
        "follow": FollowInfo(enabled=True, active=False, threshold_n=0.15, land_below_m=0.3),
        "position_std_m": (0.02, 0.03, 0.01),
        "radial_m": 0.81,
        "radial_interval_m": (0.8, 0.82),
        "azimuth_determined": True,
        "floor_contact": False,
        "converged": True,
        "length_m": 1.6,
        "base_m": (0.0, 0.0, 0.754),
    }
    fields.update(overrides)
    return Estimate(**fields)


def test_parse_estimate_reads_the_contract_model() -> None:
    view = parse_estimate(_estimate().to_json())
    assert view.seq == 7
    assert view.tension_n == pytest.approx((0.09, -0.12, -0.2))
    assert view.tension_norm_n == pytest.approx(math.sqrt(0.09**2 + 0.12**2 + 0.2**2))
    assert view.position_m == pytest.approx((0.8, 0.1, 1.0))
    assert view.position_std_m == pytest.approx((0.02, 0.03, 0.01))
    assert view.radial_interval_m == pytest.approx((0.8, 0.82))
    assert view.follow == FollowView(enabled=True, active=False, threshold_n=0.15, land_below_m=0.3)
    assert view.base_m == pytest.approx((0.0, 0.0, 0.754))
    assert view.converged and not view.on_ground


def test_parse_estimate_with_only_contract_fields() -> None:
    payload = json.dumps(
        {
            "seq": 1,
            "stamp_s": 0.0,
            "tension_n": [0.0, 0.0, -0.1],
            "tension_std_n": [0.01, 0.01, 0.01],
            "horizontal_n": 0.0,
            "vertical_n": 0.1,
            "position_m": None,
            "follow": {"enabled": False, "active": False, "threshold_n": 0.2},
            "unknown_extra": {"ignored": True},
        }
    ).encode()
    view = parse_estimate(payload)
    assert view.position_m is None
    assert view.position_std_m is None
    assert view.follow.land_below_m is None
    assert view.follow.threshold_n == 0.2


@pytest.mark.parametrize(
    "payload",
    [
        b"not json",
        b"[1, 2]",
        b'{"seq": 1}',
        json.dumps({**json.loads(_estimate().to_json()), "tension_n": [0.0, 1.0]}).encode(),
        json.dumps({**json.loads(_estimate().to_json()), "seq": "7"}).encode(),
        json.dumps({**json.loads(_estimate().to_json()), "follow": []}).encode(),
        b'{"seq": 1, "stamp_s": NaN}',
    ],
)
def test_parse_estimate_rejects_malformed(payload: bytes) -> None:
    with pytest.raises(ValueError):
        parse_estimate(payload)


def test_parse_telemetry_normalises_the_quaternion() -> None:
    view = parse_telemetry(
        json.dumps(
            {
                "seq": 3,
                "stamp_s": 0.1,
                "accel_mps2": [0, 0, 9.81],
                "quat_wxyz": [2.0, 0.0, 0.0, 0.0],
                "thrust_n": 0.3,
                "position_m": [1.0, 2.0, 3.0],
            }
        ).encode()
    )
    assert view.quat_wxyz == (1.0, 0.0, 0.0, 0.0)
    assert view.position_m == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError):
        parse_telemetry(b'{"quat_wxyz": [0, 0, 0, 0]}')
    no_mocap = parse_telemetry(b'{"seq": 1, "quat_wxyz": [1, 0, 0, 0]}')
    assert no_mocap.position_m is None


def test_parse_truth_and_reel() -> None:
    truth = Truth(
        stamp_s=1.0,
        position_m=(1.0, 0.0, 1.0),
        velocity_mps=(0.0, 0.0, 0.0),
        tension_n=(-0.1, 0.0, -0.2),
        length_m=1.6,
        base_m=(0.0, 0.0, 0.754),
        floor_contact=False,
        taut=False,
        armed=True,
        on_ground=False,
    )
    view = parse_truth(truth.to_json())
    assert view.position_m == (1.0, 0.0, 1.0)
    assert view.tension_n == (-0.1, 0.0, -0.2)
    reel = parse_reel(b'{"stamp_s": 0.0, "length_m": 1.2, "base_m": [0, 0, 0.5]}')
    assert reel.length_m == 1.2 and reel.base_m == (0.0, 0.0, 0.5)
    with pytest.raises(ValueError):
        parse_reel(b'{"stamp_s": 0.0, "length_m": 0.0}')


# ------------------------------------------------------------------------------ commands


def test_follow_command_is_a_valid_contract_follow_command() -> None:
    only_enable = follow_command(True)
    assert json.loads(only_enable) == {"enabled": True}
    full = follow_command(False, threshold_n=0.2, land=True, land_below_m=0.25)
    assert json.loads(full) == {
        "enabled": False,
        "threshold_n": 0.2,
        "land": True,
        "land_below_m": 0.25,
    }
    parsed = FollowCommand.parse(full)
    assert isinstance(parsed, FollowCommand)
    assert parsed.threshold_n == 0.2 and parsed.land is True
    with pytest.raises(ValueError):
        follow_command(True, threshold_n=0.0)
    with pytest.raises(ValueError):
        follow_command(True, land_below_m=math.nan)


def test_params_and_stop_commands() -> None:
    assert json.loads(params_command(weight_n_per_m=0.04)) == {"weight_n_per_m": 0.04}
    assert json.loads(params_command(weight_n_per_m=0.04, length_m=1.8)) == {
        "weight_n_per_m": 0.04,
        "length_m": 1.8,
    }
    with pytest.raises(ValueError):
        params_command()
    with pytest.raises(ValueError):
        params_command(length_m=-1.0)
    stop = StopIn.parse(stop_command(1234.5))
    assert isinstance(stop, StopIn)
    assert stop.stamp_s == 1234.5 and stop.reason == "operator"


# ------------------------------------------------------------------------------ helpers


def test_throttle_lets_through_at_most_the_rate() -> None:
    throttle = Throttle(20.0)
    times = np.arange(0.0, 1.0, 0.001)  # asked 1000 times in one second
    passed = [t for t in times if throttle.due(float(t))]
    assert 19 <= len(passed) <= 21
    assert np.all(np.diff(passed) >= 0.05 - 1e-9)
    with pytest.raises(ValueError):
        Throttle(0.0)


def test_throttle_does_not_burst_after_a_stall() -> None:
    throttle = Throttle(10.0)
    assert throttle.due(0.0)
    assert throttle.due(5.0)  # long stall
    assert not throttle.due(5.05)


def test_reconcile_holds_a_request_until_reported_or_expired() -> None:
    pending = Pending(True, until_s=10.0)
    assert reconcile(False, pending, 9.0) == (True, pending)
    assert reconcile(True, pending, 9.0) == (True, None)
    assert reconcile(False, pending, 10.0) == (False, None)
    assert reconcile(False, None, 0.0) == (False, None)


def test_fill_gaps_holds_values_and_flags_empty_columns() -> None:
    col, ok = fill_gaps(np.array([np.nan, 1.0, np.nan, np.nan, 3.0]))
    assert ok
    assert col.tolist() == [1.0, 1.0, 1.0, 1.0, 3.0]
    col, ok = fill_gaps(np.full(4, np.nan))
    assert not ok and np.all(np.isfinite(col))
    col, ok = fill_gaps(np.array([1.0, 2.0]))
    assert ok and col.tolist() == [1.0, 2.0]


def test_history_ring_and_window() -> None:
    history = History(n_cols=2, capacity=5)
    for t in range(8):
        history.append((float(t), 10.0 * t))
    assert len(history) == 5
    rows = history.window(since_s=5.0)
    assert rows[:, 0].tolist() == [5.0, 6.0, 7.0]
    assert history.window(since_s=-1.0)[:, 0].tolist() == [3.0, 4.0, 5.0, 6.0, 7.0]


def test_tether_points_end_at_base_and_drone() -> None:
    base, drone = (0.0, 0.0, 0.754), (1.0, 0.2, 1.0)
    pts = tether_points(base, drone, 1.6, floor_z_m=0.0, n=32)
    assert pts.shape == (32, 3)
    np.testing.assert_allclose(pts[0], base, atol=1e-6)
    np.testing.assert_allclose(pts[-1], drone, atol=1e-6)
    assert np.all(pts[:, 2] >= -1e-9)  # never below the floor


def test_tether_points_draw_the_floor_run_and_clamp_to_the_floor() -> None:
    # A slack tether from a raised base to a drone near the floor: part lies on the floor.
    pts = tether_points((0.0, 0.0, 0.754), (0.6, 0.0, 0.1), 1.6, floor_z_m=0.0)
    assert np.count_nonzero(np.abs(pts[:, 2]) < 1e-3) >= 2
    below = tether_points((0.0, 0.0, 0.754), (0.6, 0.0, -0.01), 1.6, floor_z_m=0.0)
    assert below[-1, 2] == pytest.approx(0.0) and np.all(below[:, 2] >= -1e-9)


def test_tether_points_fall_back_to_a_straight_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dash_mod, "_catenary_checked", True)
    monkeypatch.setattr(dash_mod, "_catenary_points", None)
    pts = tether_points((0.0, 0.0, 0.0), (1.0, 0.0, 1.0), 2.0, n=5)
    np.testing.assert_allclose(pts[:, 0], pts[:, 2])

    def no_curve(*_args: Any, **_kwargs: Any) -> np.ndarray:
        raise ValueError("length shorter than the chord")

    monkeypatch.setattr(dash_mod, "_catenary_points", no_curve)
    pts = tether_points((0.0, 0.0, 0.0), (1.0, 0.0, 1.0), 1.0, n=5)
    np.testing.assert_allclose(pts[-1], (1.0, 0.0, 1.0))


def test_polyline_segments_and_arrow() -> None:
    segs = polyline_segments(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]]))
    assert segs.shape == (2, 2, 3)
    np.testing.assert_allclose(segs[1], [[1, 0, 0], [1, 1, 0]])
    arrow = tension_arrow((1.0, 0.0, 1.0), (-0.1, 0.0, -0.2), m_per_n=2.0)
    np.testing.assert_allclose(arrow[0], [[1.0, 0.0, 1.0], [0.8, 0.0, 0.6]], atol=1e-6)


def test_camera_framing_sees_every_point() -> None:
    points = np.array([[0.0, 0.0, 0.754], [1.2, -0.3, 1.0], [-0.5, 0.9, 0.4]])
    fov_rad = math.radians(60.0)
    position, look_at = camera_framing(points, fov_rad)
    view = (look_at - position) / np.linalg.norm(look_at - position)
    for p in points:
        ray = (p - position) / np.linalg.norm(p - position)
        assert math.degrees(math.acos(np.clip(view @ ray, -1, 1))) < math.degrees(fov_rad / 2)
    assert position[2] > look_at[2]  # from above


def test_quadrotor_mesh_from_web_and_fallback(tmp_path: Path) -> None:
    vertices, faces = load_quadrotor_mesh()
    assert vertices.shape[1] == 3 and faces.shape[1] == 3
    assert faces.max() < len(vertices)
    span_m = vertices.max(axis=0) - vertices.min(axis=0)
    assert 0.08 < span_m[0] < 0.15  # a 92 mm micro quad
    fallback_v, fallback_f = load_quadrotor_mesh(tmp_path / "missing.stl")
    assert fallback_f.max() < len(fallback_v)
    (tmp_path / "bad.stl").write_bytes(b"solid ascii\n" * 10)
    bad_v, _ = load_quadrotor_mesh(tmp_path / "bad.stl")
    assert len(bad_v) == len(fallback_v)


def test_readouts_escape_text_from_the_bus() -> None:
    view = parse_estimate(_estimate().to_json())
    text = tension_html(view)
    assert "|T|" in text and f"{view.tension_norm_n:.3f} N" in text
    assert "0.150 N" in text and "0.200 N" in text
    evil = FollowView(enabled=True, reason="<script>alert(1)</script>")
    out = follow_html(evil, (0.0, "<img src=x>"), 1.0)
    assert "<script>" not in out and "<img" not in out
    assert "&lt;script&gt;" in out


def test_readouts_compare_with_simulator_truth() -> None:
    view = parse_estimate(_estimate(position_m=(0.8, 0.1, 1.0)).to_json())
    truth = dash_mod.TruthView(
        position_m=(0.8, 0.1, 1.05),
        tension_n=(0.0, 0.0, -0.3),
        length_m=1.6,
        base_m=None,
        floor_contact=True,
    )
    text = tension_html(view, truth)
    assert "0.300 N" in text and "5.0 cm" in text and "tether on floor (sim)" in text


def test_health_html_with_and_without_status() -> None:
    local = LinkStats(telemetry_hz=250.0, estimate_hz=249.0, telemetry_age_s=0.01)
    assert "no reply" in health_html(None, local, 0.5)
    status = {
        "stale": False,
        "telemetry_hz": 250.0,
        "received": 10,
        "accepted": 8,
        "drops": {"invalid": 2, "<b>": 1},
        "queue_overflow": 0,
    }
    out = health_html(status, local, 0.5)
    assert "live" in out and "10 / 8" in out and "3 (" in out and "<b>" not in out
    stale = health_html({**status, "stale": True}, local, 0.5)
    assert "STALE" in stale
    assert "STALE" in health_html(None, LinkStats(0.0, 0.0, 2.0), 0.5)


# ------------------------------------------------------------------------------ the dashboard


@pytest.fixture
def settings() -> Settings:
    return load_settings(use_env=False, cli_overrides={"web": {"port": 0}})


@pytest.fixture
def bus() -> Iterator[InMemoryBus]:
    bus = InMemoryBus()
    yield bus
    bus.close()


@pytest.fixture
def dash(settings: Settings, bus: InMemoryBus) -> Iterator[Dashboard]:
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    yield dashboard
    dashboard.close()


@pytest.fixture
def fake(bus: InMemoryBus) -> Iterator[FakeService]:
    service = FakeService(bus, ("cf1", "cf2"))
    yield service
    service.close()


def _record(bus: InMemoryBus, keyexpr: str) -> list[Sample]:
    seen: list[Sample] = []
    bus.subscribe(keyexpr, seen.append)
    return seen


def _client_event() -> Any:
    """What viser passes to a callback when a browser changed the input."""
    return SimpleNamespace(client_id=1, client=None, target=None)


def _wait_until(predicate: Any, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    tick = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.05)  # polling a condition, not synchronising on time
    return True


def _node(dashboard: Dashboard, name: str) -> Any:
    handle = dashboard.server.scene.get_handle_by_name(name)
    assert handle is not None, name
    return handle


def test_url_binds_loopback_and_close_is_idempotent(settings: Settings, bus: InMemoryBus) -> None:
    dashboard = Dashboard(settings, bus, port=0, update_thread=True)
    with pytest.raises(RuntimeError):
        _ = dashboard.url
    dashboard.start()
    assert dashboard.url.startswith("http://127.0.0.1:")
    assert not dashboard.url.endswith(":0")
    with pytest.raises(RuntimeError):
        dashboard.start()
    t0 = time.monotonic()
    dashboard.close()
    dashboard.close()
    assert time.monotonic() - t0 < 2.0


def test_update_draws_the_scene_and_fills_the_panel(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    fake.publish_once(0.0)
    assert bus.flush()
    assert dash.poll_status() == 2
    now_s = time.monotonic()
    dash.update(now_s)
    assert dash.drones == ["cf1", "cf2"]
    assert dash.selected == "cf1"

    arrow = _node(dash, "/drones/cf1/tension")
    length_m = float(np.linalg.norm(arrow.points[0, 1] - arrow.points[0, 0]))
    assert length_m == pytest.approx(FIXED_NORM_N * dash_mod.ARROW_M_PER_N, rel=1e-5)
    assert _node(dash, "/drones/cf1/tension_label").text == "|T| 0.250 N"
    tether = _node(dash, "/drones/cf1/tether")
    np.testing.assert_allclose(tether.points[0, 0], (0.0, 0.0, 0.754), atol=1e-6)
    body = _node(dash, "/drones/cf1/body")
    np.testing.assert_allclose(tether.points[-1, 1], body.position, atol=1e-5)
    assert _node(dash, "/drones/cf1/mocap").visible
    assert _node(dash, "/drones/cf1/mocap_label").text.startswith("mocap Δ")
    assert _node(dash, "/drones/cf1/body/quad") is not None
    assert _node(dash, "/drones/cf2/tension").visible

    assert "0.250 N" in dash._tension_html.content
    assert "bad_key: 1" in dash._health_html.content
    assert dash._follow.handle.value is False
    assert not dash._follow.handle.disabled


def test_callbacks_only_store_and_parsing_happens_at_the_scene_rate(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    fake.publish_once(0.0)
    assert bus.flush()
    dash.update(100.0)
    for seq in range(500):  # a burst of garbage: callbacks must just store it
        bus.publish("tether/cf1/telemetry", b"{garbage %d" % seq)
    bus.publish("tether/not a drone!/telemetry", b"{}")
    assert bus.flush()
    period_s = 1.0 / dash._scene_rate_hz
    dash.update(100.0 + 0.5 * period_s)  # throttled: nothing parsed yet
    assert dash.stats().ticks == 1
    assert "unparsable" not in dash._health_html.content
    dash.update(100.0 + 1.1 * period_s)
    assert dash.stats().ticks == 2
    assert dash._drones["cf1"].invalid == {"telemetry": 1}  # only the latest was parsed
    assert dash.drones == ["cf1", "cf2"]


def test_follow_checkbox_shows_the_report_and_publishes_on_click(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    follow_seen = _record(bus, "tether/*/follow")
    fake.publish_once(0.0)
    assert bus.flush()
    t0 = time.monotonic()
    dash.update(t0)
    checkbox = dash._follow.handle

    # A browser ticks the box: one FollowCommand, and the box holds the request.
    checkbox.value = True  # what viser does on the client's message (our sync ignores it)
    assert bus.flush() and follow_seen == []  # programmatic set: nothing published
    dash._on_follow_toggled(_client_event())
    assert bus.flush()
    assert [json.loads(s.payload) for s in follow_seen] == [{"enabled": True}]
    assert follow_seen[0].key == "tether/cf1/follow"

    # The service has not caught up yet: still shows the request...
    dash.update(t0 + 0.5)
    assert checkbox.value is True
    # ...then the fake service echoes it in the next Estimates.
    fake.publish_once(0.1)
    assert bus.flush()
    dash.update(t0 + 1.0)
    assert checkbox.value is True and dash._follow.pending is None

    # Switched off elsewhere (another browser / CLI): every dashboard follows the report.
    bus.publish("tether/cf1/follow", follow_command(False))
    assert bus.flush()
    fake.publish_once(0.2)
    assert bus.flush()
    dash.update(t0 + 1.5)
    assert checkbox.value is False


def test_follow_request_not_confirmed_reverts_to_the_report(
    dash: Dashboard, bus: InMemoryBus
) -> None:
    # A service that ignores the command: the box shows the report again after the hold.
    estimate = _estimate(follow=FollowInfo(enabled=False, active=False, threshold_n=0.15))
    bus.publish("tether/cf9/estimate", estimate.to_json())
    assert bus.flush()
    t0 = time.monotonic()
    dash.update(t0)
    dash._follow.handle.value = True
    dash._on_follow_toggled(_client_event())
    bus.publish("tether/cf9/estimate", estimate.to_json())
    assert bus.flush()
    dash.update(t0 + 0.2)
    assert dash._follow.handle.value is True
    bus.publish("tether/cf9/estimate", estimate.to_json())
    assert bus.flush()
    dash.update(t0 + dash_mod.PENDING_HOLD_S + 1.0)
    assert dash._follow.handle.value is False


def test_settings_forms_publish_follow_and_params(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    follow_seen = _record(bus, "tether/*/follow")
    params_seen = _record(bus, "tether/*/params")
    fake.publish_once(0.0)
    assert bus.flush()
    dash.poll_status()
    dash.update(time.monotonic())

    dash._threshold.handle.value = 0.3
    dash._on_follow_submit(None)
    dash._land.handle.value = True
    dash._land_height.handle.value = 0.4
    dash._on_land_toggled(_client_event())
    dash._weight.handle.value = 0.04
    dash._length.handle.value = 1.9
    dash._on_tether_submit(None)
    assert bus.flush()
    assert [json.loads(s.payload) for s in follow_seen] == [
        {"enabled": False, "threshold_n": 0.3, "land": False},
        {"enabled": False, "land": True, "land_below_m": 0.4},
    ]
    assert [json.loads(s.payload) for s in params_seen] == [
        {"weight_n_per_m": 0.04, "length_m": 1.9}
    ]
    assert fake.params == [("cf1", {"weight_n_per_m": 0.04, "length_m": 1.9})]


def test_length_is_not_editable_when_a_reel_reports_it(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    params_seen = _record(bus, "tether/*/params")
    fake.publish_once(0.0)
    bus.publish("tether/cf1/reel", b'{"stamp_s": 0.0, "length_m": 1.25}')
    assert bus.flush()
    dash.update(time.monotonic())
    assert dash._length.handle.disabled
    assert "reel" in dash._tether_html.content
    dash._weight.handle.value = 0.06
    dash._on_tether_submit(None)
    assert bus.flush()
    assert [json.loads(s.payload) for s in params_seen] == [{"weight_n_per_m": 0.06}]


def test_stop_is_published_and_shown(dash: Dashboard, bus: InMemoryBus, fake: FakeService) -> None:
    fake.publish_once(0.0)
    assert bus.flush()
    t0 = time.monotonic()
    dash.update(t0)
    payload = dash.request_stop("cf1")
    assert bus.flush()
    assert fake.stops and fake.stops[0][0] == "cf1"
    stop = StopIn.parse(payload)
    assert isinstance(stop, StopIn)
    assert stop.reason == "operator" and abs(stop.stamp_s - time.time()) < 5.0
    fake.publish_once(0.1)
    assert bus.flush()
    dash.update(t0 + 1.0)
    assert "Stop sent" in dash._follow_html.content
    assert "STOPPED" in _node(dash, "/drones/cf1/body/label").text


def test_charts_hold_20_s_and_hide_missing_mocap(settings: Settings, bus: InMemoryBus) -> None:
    service = FakeService(bus, ("cf1",), mocap=False)
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        t0 = 1000.0
        period_s = 1.0 / dashboard._scene_rate_hz
        for k in range(int(30.0 / period_s)):
            service.publish_once(k * period_s)
            assert bus.flush()
            dashboard.update(t0 + k * period_s)
        tension = dashboard._tension_chart.data
        assert len(tension) == 6
        t = tension[0]
        assert t[0] >= -dash_mod.HISTORY_S - 1e-9 and t[-1] <= 0.0
        assert t[-1] - t[0] > dash_mod.HISTORY_S - 1.0
        np.testing.assert_allclose(tension[4], FIXED_NORM_N, rtol=1e-6)
        np.testing.assert_allclose(tension[5], 0.15)  # threshold
        position = dashboard._position_chart.data
        assert all(np.all(np.isfinite(col)) for col in position)
        assert [s.get("show", True) for s in dashboard._position_chart.series[4:]] == [False] * 3
    finally:
        dashboard.close()
        service.close()


def test_update_thread_stays_within_the_scene_rate(settings: Settings, bus: InMemoryBus) -> None:
    service = FakeService(bus, ("cf1",), rate_hz=250.0).start()
    dashboard = Dashboard(settings, bus, port=0)
    dashboard.start()
    try:
        assert _wait_until(lambda: dashboard.stats().ticks >= 10, timeout_s=10.0)
        stats = dashboard.stats()
        assert stats.ticks >= 10
        assert stats.ticks <= settings.web.scene_rate_hz * stats.wall_s + 2
    finally:
        dashboard.close()
        service.close()
