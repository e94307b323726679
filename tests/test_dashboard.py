"""Dashboard without a browser: reading payloads, commands, follow checks, throttling, and the
update pass on fake data.

The Dashboard runs with ``update_thread=False`` so each test drives :meth:`Dashboard.update`
with its own clock; the viser server binds an ephemeral port on 127.0.0.1. With no browser
connected there is no per-tab panel, so these tests use ``[web] panel = "shared"`` (the
per-tab panels are driven by the browser tests).
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
from groundstation.dashboard import scene as scene_mod
from groundstation.dashboard.app import Dashboard
from groundstation.dashboard.commands import (
    FollowLimits,
    check_tether,
    follow_blocker,
    follow_command,
    params_command,
    stop_command,
)
from groundstation.dashboard.model import (
    DroneState,
    History,
    Inbox,
    Pending,
    StopSeen,
    Throttle,
    fill_gaps,
    reconcile,
)
from groundstation.dashboard.panel import PENDING_HOLD_S, Panel
from groundstation.dashboard.readouts import (
    BusView,
    LinkStats,
    follow_html,
    health_html,
    link_warning_html,
    stop_html,
    tension_html,
)
from groundstation.dashboard.scene import (
    ARROW_M_PER_N,
    LABEL_CLEARANCE_M,
    LABEL_STEP_M,
    PANEL_PX,
    camera_framing,
    label_tiers,
    load_quadrotor_mesh,
    panel_fraction,
    polyline_segments,
    project,
    tension_arrow,
    tether_points,
)
from groundstation.evaluation import settings_for
from groundstation.messages import (
    Estimate,
    Event,
    FollowCommand,
    FollowInfo,
    InvalidMessage,
    Status,
    StopIn,
    TetherParams,
    Truth,
)
from groundstation.pipeline import Pipeline
from tests.dashboard_fake import FIXED_NORM_N, FakeService

# ------------------------------------------------------------------------------ reading


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


def _truth(**overrides: Any) -> Truth:
    fields: dict[str, Any] = {
        "stamp_s": 1.0,
        "position_m": (0.8, 0.1, 1.05),
        "velocity_mps": (0.0, 0.0, 0.0),
        "tension_n": (0.0, 0.0, -0.3),
        "length_m": 1.6,
        "base_m": (0.0, 0.0, 0.754),
        "floor_contact": True,
        "taut": False,
        "armed": True,
        "on_ground": False,
    }
    fields.update(overrides)
    return Truth(**fields)


def test_estimate_read_round_trips_and_ignores_unknown_fields_at_every_level() -> None:
    est = _estimate()
    assert Estimate.read(est.to_json()) == est
    body = json.loads(est.to_json())
    body["added_by_a_newer_service"] = {"x": 1}
    body["follow"]["added_too"] = True
    read = Estimate.read(json.dumps(body).encode())
    assert read == est
    with pytest.raises(ValueError):  # what this process publishes stays forbidding extras
        Estimate.model_validate_json(json.dumps(body))


@pytest.mark.parametrize(
    "payload",
    [
        b"not json",
        b"[1, 2]",
        b'{"seq": 1}',
        json.dumps({**json.loads(_estimate().to_json()), "tension_n": [0.0, 1.0]}).encode(),
        json.dumps({**json.loads(_estimate().to_json()), "seq": "7"}).encode(),
        json.dumps({**json.loads(_estimate().to_json()), "horizontal_n": "0.15"}).encode(),
        json.dumps({**json.loads(_estimate().to_json()), "follow": []}).encode(),
        b'{"seq": 1, "stamp_s": NaN}',
    ],
)
def test_estimate_read_rejects_malformed(payload: bytes) -> None:
    with pytest.raises(InvalidMessage):
        Estimate.read(payload)


def test_the_services_own_estimate_and_status_are_read() -> None:
    """The dashboard's readers accept what the real pipeline publishes (no drift)."""
    pipe = Pipeline(settings_for())
    telemetry = {
        "seq": 0,
        "stamp_s": 0.0,
        "accel_mps2": [0.0, 0.0, 10.81],
        "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
        "thrust_n": 0.33,
    }
    out = pipe.handle(Sample("tether/cf1/telemetry", json.dumps(telemetry).encode()), 0.0)
    assert len(out) == 1
    est = Estimate.read(out[0].payload)
    assert est.seq == 0
    status_dict = pipe.status("cf1", 0.0)
    assert status_dict is not None
    status = Status.read(json.dumps(status_dict).encode())
    assert status.drone == "cf1" and status.accepted == 1
    assert status.follow is not None and status.follow.enabled is False


def _drone(**inbox: Any) -> DroneState:
    box = Inbox()
    for key, value in inbox.items():
        setattr(box, key, value)
    return DroneState("cf1", box, (0, 0, 0), capacity=16, weight_n=0.03 * 9.81)


def _log_sink() -> tuple[list[str], Any]:
    kinds: list[str] = []
    return kinds, lambda kind, *_args: kinds.append(kind)


def test_ingest_reads_each_kind_and_counts_what_does_not_validate() -> None:
    telemetry = {
        "seq": 3,
        "stamp_s": 0.1,
        "accel_mps2": [0, 0, 9.81],
        "quat_wxyz": [2.0, 0.0, 0.0, 0.0],
        "thrust_n": 0.3,
        "position_m": [1.0, 2.0, 3.0],
        "field_from_the_future": 1,
    }
    drone = _drone(
        estimate=_estimate().to_json(),
        n_estimate=1,
        telemetry=json.dumps(telemetry).encode(),
        n_telemetry=1,
        telemetry_rx_s=1.0,
        truth=_truth().to_json(),
        n_truth=1,
        reel=b'{"stamp_s": 0.0, "length_m": 1.2, "base_m": [0, 0, 0.5]}',
        n_reel=1,
    )
    kinds, log = _log_sink()
    changed, stop = drone.ingest(1.0, log)
    assert changed and stop is None and kinds == [] and drone.invalid == {}
    assert drone.quat_wxyz == (1.0, 0.0, 0.0, 0.0)  # normalised for drawing
    assert drone.telemetry is not None and drone.telemetry.position_m == (1.0, 2.0, 3.0)
    assert drone.truth is not None and drone.truth.tension_n == (0.0, 0.0, -0.3)
    assert drone.reel is not None and drone.reel.base_m == (0.0, 0.0, 0.5)
    assert drone.estimate == _estimate()

    drone.inbox.telemetry = b'{"seq": 4, "quat_wxyz": [0, 0, 0, 0]}'
    drone.inbox.n_telemetry += 1
    drone.inbox.reel = b'{"stamp_s": 0.0, "length_m": 0.0}'
    drone.inbox.n_reel += 1
    drone.ingest(1.1, log)
    assert drone.invalid == {"telemetry": 1, "reel": 1}
    assert drone.reel.base_m == (0.0, 0.0, 0.5)  # the last good one stays
    bad_quat = dict(telemetry, seq=5, quat_wxyz=[0.0, 0.0, 0.0, 0.0])
    drone.inbox.telemetry = json.dumps(bad_quat).encode()
    drone.inbox.n_telemetry += 1
    drone.ingest(1.2, log)
    assert drone.invalid["telemetry"] == 2
    assert sorted(set(kinds)) == ["invalid-reel", "invalid-telemetry"]


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
    assert parsed.threshold_n == 0.2 and parsed.land is True
    with pytest.raises(ValueError):
        follow_command(True, threshold_n=0.0)
    with pytest.raises(ValueError):
        follow_command(True, threshold_n=-1.0)
    with pytest.raises(ValueError):
        follow_command(True, land_below_m=math.nan)


def test_params_and_stop_commands() -> None:
    assert json.loads(params_command(weight_n_per_m=0.04)) == {"weight_n_per_m": 0.04}
    both = params_command(weight_n_per_m=0.04, length_m=1.8)
    assert TetherParams.parse(both) == TetherParams(weight_n_per_m=0.04, length_m=1.8)
    with pytest.raises(ValueError):
        params_command()
    with pytest.raises(ValueError):
        params_command(length_m=-1.0)
    stop = StopIn.parse(stop_command(1234.5))
    assert stop.stamp_s == 1234.5 and stop.reason == "operator"


def test_follow_limits_refuse_with_a_reason_and_never_clamp() -> None:
    # sigma_T = |(8, 8, 6)| mN = 12.8 mN -> floor 3 sigma = 38.4 mN, above the service's 0.02 N.
    limits = FollowLimits.for_drone((0.008, 0.008, 0.006), 0.0, 0.754, 1.6, min_threshold_n=0.02)
    assert limits.threshold_floor_n == pytest.approx(3.0 * math.hypot(0.008, 0.008, 0.006))
    assert limits.check_threshold(0.10) is None
    for bad in (-1.0, 0.0, math.nan):
        message = limits.check_threshold(bad)
        assert message is not None and "> 0" in message
    low = limits.check_threshold(0.03)
    assert low is not None and "0.038 N" in low and "σ" in low
    # The service's floor ([service] follow_threshold_min_n) is the panel's: 0.015 N is refused
    # here, not sent to be refused there (3 sigma = 19.2 mN is below it).
    quiet = FollowLimits.for_drone((0.004, 0.004, 0.003), 0.0, 0.754, 1.6, min_threshold_n=0.02)
    assert quiet.threshold_floor_n == 0.02
    refused = quiet.check_threshold(0.015)
    assert refused is not None and "follow_threshold_min_n" in refused
    unknown = FollowLimits.for_drone(None, 0.0, 0.754, 1.6, min_threshold_n=0.05)
    assert unknown.threshold_floor_n == 0.05
    # Land height: above the floor, below base + tether (0.754 + 1.6 m).
    assert limits.check_land_height(0.25) is None
    for bad in (0.0, -0.1, 2.36, 5.0, math.inf):
        message = limits.check_land_height(bad)
        assert message is not None and "refused" in message


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


def test_tether_points_fall_back_to_the_chord(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_curve(*_args: Any, **_kwargs: Any) -> np.ndarray:
        raise ValueError("no curve for these inputs")

    monkeypatch.setattr(scene_mod, "catenary_tether_points", no_curve)
    pts = tether_points((0.0, 0.0, 0.0), (1.0, 0.0, 1.0), 2.0, n=5)
    np.testing.assert_allclose(pts[:, 0], pts[:, 2])
    np.testing.assert_allclose(pts[-1], (1.0, 0.0, 1.0))
    # A bad length (the catenary's own error) is drawn as the chord too, not an exception.
    np.testing.assert_allclose(tether_points((0, 0, 0), (1, 0, 1), -1.0, n=3)[1], (0.5, 0, 0.5))


def test_polyline_segments_and_arrow() -> None:
    segs = polyline_segments(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]]))
    assert segs.shape == (2, 2, 3)
    np.testing.assert_allclose(segs[1], [[1, 0, 0], [1, 1, 0]])
    arrow = tension_arrow((1.0, 0.0, 1.0), (-0.1, 0.0, -0.2), m_per_n=2.0)
    np.testing.assert_allclose(arrow[0], [[1.0, 0.0, 1.0], [0.8, 0.0, 0.6]], atol=1e-6)


@pytest.mark.parametrize("covered_right", [0.0, 0.31, 0.5])
@pytest.mark.parametrize("aspect", [1.0, 1.6, 2.2])
def test_camera_framing_sees_every_point_left_of_the_panel(
    covered_right: float, aspect: float
) -> None:
    # config/sim.toml's two drones (bases 3 m apart), motion-capture markers 1 m off.
    points = np.array(
        [
            [0.0, 0.0, 0.754],
            [1.2, -0.3, 1.0],
            [0.2, 0.6, 1.4],
            [0.0, 3.0, 0.754],
            [-0.5, 3.9, 0.4],
            [0.5, 2.1, 1.1],
            [0.0, 0.0, 0.0],
        ]
    )
    fov_rad = math.radians(60.0)
    position, look_at = camera_framing(
        points, fov_rad, aspect=aspect, covered_right=covered_right, margin=0.1
    )
    ndc = project(points, position, look_at, fov_rad, aspect)
    free_right = 1.0 - 2.0 * covered_right
    assert np.all(ndc[:, 0] >= -0.9 - 1e-6) and np.all(ndc[:, 0] <= free_right - 0.1 + 1e-6)
    assert np.all(np.abs(ndc[:, 1]) <= 0.9 + 1e-6)
    # Not absurdly far: the points fill a fair share of the free window.
    span_x = ndc[:, 0].max() - ndc[:, 0].min()
    span_y = ndc[:, 1].max() - ndc[:, 1].min()
    assert span_x > 0.3 * (free_right - 0.1 + 0.9) or span_y > 0.3 * 1.8
    # Centred in the free window, not in the whole view.
    assert 0.5 * (ndc[:, 0].max() + ndc[:, 0].min()) == pytest.approx(
        0.5 * (free_right - 1.0), abs=0.2
    )
    assert position[2] > look_at[2]  # from above


def test_panel_fraction_is_bounded() -> None:
    assert panel_fraction(1280.0) == pytest.approx(PANEL_PX / 1280.0)
    assert panel_fraction(3840.0) == 0.3  # a HiDPI buffer: the panel's share is not less
    assert panel_fraction(600.0) == 0.5
    assert 0.3 <= panel_fraction(None) <= 0.5


def test_label_tiers_separate_neighbours_only() -> None:
    far = label_tiers({"cf1": (0.0, 0.0, 1.0), "cf2": (3.0, 0.0, 1.0)})
    assert far == {"cf1": 0, "cf2": 0}
    close = {"cf1": (0.0, 0.0, 1.0), "cf2": (0.2, 0.1, 1.02), "cf3": (0.1, -0.2, 0.98)}
    tiers = label_tiers(close)
    heights = sorted(close[d][2] + tiers[d] * LABEL_STEP_M for d in close)
    assert len(set(tiers.values())) == 3
    assert min(np.diff(heights)) >= LABEL_STEP_M - 0.05  # at least about one step apart
    # Neighbours at clearly different heights need no stacking.
    assert label_tiers({"cf1": (0.0, 0.0, 0.5), "cf2": (0.1, 0.0, 1.2)}) == {"cf1": 0, "cf2": 0}
    assert LABEL_CLEARANCE_M > 0.2


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
    est = _estimate()
    text = tension_html(est)
    assert "|T|" in text and "<b>0.250 N</b>" in text  # |(0.09, -0.12, -0.2)| = 0.25
    assert "0.150 N" in text and "0.200 N" in text
    evil = FollowInfo(enabled=True, active=False, threshold_n=0.1, reason="<script>x</script>")
    out = follow_html(evil)
    assert "<script>" not in out and "&lt;script&gt;" in out
    stop = stop_html(StopSeen(0.0, "<img src=x>"), 1.0, 0.01)
    assert "<img" not in stop and "Stop sent" in stop


def test_readouts_say_which_calibration_and_when_the_battery_leaves_it() -> None:
    plain = tension_html(_estimate())
    assert "uncalibrated" in plain and "battery outside calibration" not in plain
    inside = tension_html(_estimate(calibration="cal.toml", calibration_extrapolated=False))
    assert "cal.toml" in inside and "uncalibrated" not in inside
    assert "battery outside calibration" not in inside
    outside = tension_html(
        _estimate(calibration="<b>cal</b>", calibration_extrapolated=True, azimuth_source="reel")
    )
    assert "battery outside calibration" in outside and "<b>cal</b>" not in outside
    assert "azimuth from" in outside and "reel" in outside


def test_readouts_compare_with_simulator_truth() -> None:
    text = tension_html(_estimate(position_m=(0.8, 0.1, 1.0)), _truth())
    assert "0.300 N" in text and "5.0 cm" in text and "tether on floor (sim)" in text


def test_stop_readout_says_sent_then_acknowledged() -> None:
    sent = stop_html(StopSeen(10.0, "operator"), 11.0, telemetry_age_s=0.01)
    assert "Stop sent 1.0 s ago" in sent and "waiting for telemetry" in sent
    assert "acknowledged" not in sent
    lost = stop_html(StopSeen(10.0, "operator"), 13.0, telemetry_age_s=3.5)
    assert "no telemetry since" in lost and "acknowledged" not in lost
    done = stop_html(StopSeen(10.0, "operator", 10.3, "disarmed"), 12.0, 0.01)
    assert "Stop acknowledged: disarmed 0.3 s after" in done


def test_health_html_with_and_without_status() -> None:
    local = LinkStats(telemetry_hz=250.0, estimate_hz=249.0, telemetry_age_s=0.01)
    assert "no reply" in health_html(None, local, 0.5)
    status = Status(
        drone="cf1",
        stale=False,
        telemetry_hz=250.0,
        received=10,
        accepted=8,
        drops={"invalid": 2, "<b>": 1},
        queue_overflow=0,
        peers=2,
    )
    out = health_html(status, local, 0.5)
    assert "live" in out and "10 / 8" in out and "3 (" in out and "<b>" not in out
    assert "peers (service)" in out and ">2<" in out
    stale = health_html(status.model_copy(update={"stale": True}), local, 0.5)
    assert "STALE" in stale
    assert "STALE" in health_html(None, LinkStats(0.0, 0.0, 2.0), 0.5)


def test_link_warning_for_no_service_and_no_peers() -> None:
    answered = BusView(any_status=True, services=("groundstation/service/a",))
    assert link_warning_html(answered, Status(drone="cf1", peers=3)) == ""
    assert link_warning_html(answered, Status(drone="cf1")) == ""
    assert link_warning_html(answered) == ""
    nobody = link_warning_html(BusView(any_status=False, own_peers=0))
    assert "No service answers" in nobody and "connected to 0 zenoh peer" in nobody
    assert "0 peers" in link_warning_html(answered, Status(drone="cf1", peers=0))
    # demo: service, simulator and dashboard share one session; 0 peers is no fault there.
    demo = Status(drone="cf1", peers=0, alone_ok=True)
    assert link_warning_html(answered, demo) == ""
    local = LinkStats(250.0, 250.0, 0.01)
    assert "in-process" in health_html(demo, local, 0.5)
    # A service is running (its liveliness token) but no drone has reported to it yet.
    waiting = link_warning_html(BusView(any_status=False, services=("groundstation/service/a",)))
    assert "Service running (instance a)" in waiting and "alert" not in waiting


def test_follow_blocker_says_why_the_service_would_refuse() -> None:
    def blocked(**kw: Any) -> str | None:
        args = {
            "telemetry_age_s": 0.01,
            "stale_after_s": 0.5,
            "has_mocap": False,
            "calibration": "none",
        }
        return follow_blocker("cf2", **(args | kw))

    no_position = blocked()
    assert no_position is not None and "no motion capture" in no_position
    assert "groundstation calibrate" in no_position
    assert blocked(has_mocap=True) is None
    assert blocked(calibration="lab 2026-11-30") is None
    assert blocked(has_mocap=None) is None  # no telemetry read here: the service decides
    stale = blocked(has_mocap=True, telemetry_age_s=2.0)
    assert stale is not None and "stale" in stale
    assert blocked(has_mocap=True, telemetry_age_s=None) is None


def test_tether_parameters_are_checked_with_a_reason() -> None:
    assert check_tether(0.05, 1.6) is None
    assert check_tether(0.05, None) is None
    for weight in (-1.0, 0.0, math.nan):
        message = check_tether(weight, 1.6)
        assert message is not None and "ω" in message and "> 0" in message
    length = check_tether(0.05, -0.5)
    assert length is not None and "Length -0.5 m refused" in length


# ------------------------------------------------------------------------------ the dashboard


@pytest.fixture
def settings() -> Settings:
    return load_settings(use_env=False, cli_overrides={"web": {"port": 0, "panel": "shared"}})


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


def _panel(dashboard: Dashboard) -> Panel:
    (panel,) = dashboard.panels
    return panel


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


def _feed(dash: Dashboard, bus: InMemoryBus, fake: FakeService, t_s: float, now_s: float) -> None:
    fake.publish_once(t_s)
    assert bus.flush()
    dash.update(now_s)


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


def test_framing_takes_in_the_motion_capture_markers(dash: Dashboard, bus: InMemoryBus) -> None:
    # An estimate a metre off motion capture: the error line's far end must be framed too.
    fake = FakeService(bus, ("cf1", "cf2"), estimate_error_m=(0.3, -0.9, 0.35))
    try:
        fake.publish_once(0.0)
        assert bus.flush()
        dash.update(time.monotonic())
        drones = [d for d in (dash.drone("cf1"), dash.drone("cf2")) if d is not None]
        points = dash.scene.framing_points(drones)
        for drone in drones:
            assert drone.telemetry is not None and drone.telemetry.position_m is not None
            assert drone.telemetry.position_m in points
            assert drone.body_position() in points
            mocap_m, body_m = drone.telemetry.position_m, drone.body_position()
            assert body_m is not None and math.dist(mocap_m, body_m) > 0.9
        label = _node(dash, "/drones/cf1/body/label").text
        # One value a line: the label stays narrow.
        assert label.splitlines()[1:] == [
            "|T| 0.250 N",
            f"mocap Δ {100.0 * math.dist((0.0, 0.0, 0.0), (0.3, -0.9, 0.35)):.1f} cm",
        ]
    finally:
        fake.close()


def test_update_draws_the_scene_and_fills_the_panel(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    fake.publish_once(0.0)
    assert bus.flush()
    assert dash.poll_status() == 2
    dash.update(time.monotonic())
    panel = _panel(dash)
    assert dash.drones == ["cf1", "cf2"]
    assert panel.selected == "cf1"

    arrow = _node(dash, "/drones/cf1/tension")
    length_m = float(np.linalg.norm(arrow.points[0, 1] - arrow.points[0, 0]))
    assert length_m == pytest.approx(FIXED_NORM_N * ARROW_M_PER_N, rel=1e-5)
    label = _node(dash, "/drones/cf1/body/label").text
    assert label.startswith("cf1\n") and "|T| 0.250 N" in label and "mocap Δ" in label
    tether = _node(dash, "/drones/cf1/tether")
    np.testing.assert_allclose(tether.points[0, 0], (0.0, 0.0, 0.754), atol=1e-6)
    body = _node(dash, "/drones/cf1/body")
    np.testing.assert_allclose(tether.points[-1, 1], body.position, atol=1e-5)
    assert _node(dash, "/drones/cf1/mocap").visible
    assert _node(dash, "/drones/cf1/body/quad") is not None
    assert _node(dash, "/drones/cf2/tension").visible
    assert _node(dash, "/world_axes") is not None
    assert _node(dash, "/world_axes/x_label").text == "x"

    assert "0.250 N" in panel.tension_html.content
    assert "bad_key: 1" in panel.health_html.content
    assert "peers (service)" in panel.health_html.content
    assert panel.warning.content == ""
    assert panel.follow.handle.value is False
    assert not panel.follow.handle.disabled


def test_callbacks_only_store_and_parsing_happens_at_the_scene_rate(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    _feed(dash, bus, fake, 0.0, 100.0)
    for seq in range(500):  # a burst of garbage: callbacks must just store it
        bus.publish("tether/cf1/telemetry", b"{garbage %d" % seq)
    bus.publish("tether/not a drone!/telemetry", b"{}")
    assert bus.flush()
    period_s = 1.0 / dash._scene_rate_hz
    dash.update(100.0 + 0.5 * period_s)  # throttled: nothing parsed yet
    assert dash.stats().ticks == 1
    cf1 = dash.drone("cf1")
    assert cf1 is not None and cf1.invalid == {}
    dash.update(100.0 + 1.1 * period_s)
    assert dash.stats().ticks == 2
    assert cf1.invalid == {"telemetry": 1}  # only the latest was parsed
    assert dash.drones == ["cf1", "cf2"]


def test_follow_checkbox_shows_the_report_and_publishes_on_click(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    follow_seen = _record(bus, "tether/*/follow")
    t0 = time.monotonic()
    _feed(dash, bus, fake, 0.0, t0)
    checkbox = _panel(dash).follow.handle

    # A browser ticks the box: one FollowCommand, and the box holds the request.
    checkbox.value = True  # what viser does on the client's message (our sync ignores it)
    assert bus.flush() and follow_seen == []  # programmatic set: nothing published
    _panel(dash)._on_follow_toggled(_client_event())
    assert bus.flush()
    assert [json.loads(s.payload) for s in follow_seen] == [{"enabled": True}]
    assert follow_seen[0].key == "tether/cf1/follow"

    # The service has not caught up yet: still shows the request...
    dash.update(t0 + 0.5)
    assert checkbox.value is True
    # ...then the fake service echoes it in the next Estimates.
    _feed(dash, bus, fake, 0.1, t0 + 1.0)
    assert checkbox.value is True and _panel(dash).follow.pending is None

    # Switched off elsewhere (another browser / CLI): every dashboard follows the report.
    bus.publish("tether/cf1/follow", follow_command(False))
    assert bus.flush()
    _feed(dash, bus, fake, 0.2, t0 + 1.5)
    assert checkbox.value is False


def test_follow_request_nobody_answers_reverts_and_says_so(
    dash: Dashboard, bus: InMemoryBus
) -> None:
    # A service that ignores the command: the box shows the report again after the hold, and
    # the panel says that nothing confirmed it (never a silent revert).
    estimate = _estimate(follow=FollowInfo(enabled=False, active=False, threshold_n=0.15))
    bus.publish("tether/cf9/estimate", estimate.to_json())
    assert bus.flush()
    t0 = time.monotonic()
    dash.update(t0)
    panel = _panel(dash)
    panel.follow.handle.value = True
    panel._on_follow_toggled(_client_event())
    bus.publish("tether/cf9/estimate", estimate.to_json())
    assert bus.flush()
    dash.update(t0 + 0.2)
    assert panel.follow.handle.value is True
    bus.publish("tether/cf9/estimate", estimate.to_json())
    assert bus.flush()
    dash.update(t0 + PENDING_HOLD_S + 1.0)
    assert panel.follow.handle.value is False
    message = panel.follow_message.content
    assert "Not confirmed" in message and "follow mode" in message
    assert "tether/cf9/events" in message


def _telemetry_with_mocap(seq: int) -> bytes:
    return json.dumps(
        {
            "seq": seq,
            "stamp_s": seq * 0.004,
            "accel_mps2": [0.0, 0.0, (0.33 - 0.05) / 0.030],
            "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "thrust_n": 0.33,
            "position_m": [1.0, 0.0, 1.0],
        }
    ).encode()


def test_a_refusal_by_the_service_is_said_where_the_operator_typed(bus: InMemoryBus) -> None:
    from groundstation.service import Service

    # The real service, configured with a higher threshold floor than this dashboard knows:
    # the panel lets 0.07 N through, the service refuses it and says why on its events.
    strict = load_settings(
        use_env=False, cli_overrides={"service": {"follow_threshold_min_n": 0.09}}
    )
    service = Service(strict, bus)
    dash_settings = load_settings(
        use_env=False, cli_overrides={"web": {"port": 0, "panel": "shared"}}
    )
    dashboard = Dashboard(dash_settings, bus, port=0, update_thread=False)
    service.start()
    dashboard.start()
    try:
        for seq in range(30):
            bus.publish("tether/cf1/telemetry", _telemetry_with_mocap(seq))
        assert _wait_until(lambda: dashboard.poll_status() == 1, 5.0)
        assert bus.flush()
        t0 = time.monotonic()
        dashboard.update(t0)
        panel = _panel(dashboard)
        assert panel.selected == "cf1" and panel.warning.content == ""
        follow_seen = _record(bus, "tether/cf1/follow")
        panel.threshold.handle.value = 0.07
        panel._on_follow_submit(None)
        assert bus.flush() and len(follow_seen) == 1, panel.follow_message.content
        assert "answer follows" in panel.follow_message.content
        inbox = dashboard._inboxes["cf1"]
        assert _wait_until(lambda: inbox.n_events >= 1, 5.0), "the service did not answer"
        dashboard.update(t0 + 0.2)
        message = panel.follow_message.content
        assert "The service refused the follow command" in message
        assert "follow_threshold_min_n" in message and 'role="alert"' in message
        # Nothing of the command was applied: the inputs show the report again at once.
        assert panel.threshold.pending is None
        assert panel.threshold.handle.value == pytest.approx(strict.follow.threshold_n)
        # An event never creates a drone (the service answers for drones that never flew).
        bus.publish(
            "tether/cf7/events", Event(stamp_s=0.0, kind="rejected", input="follow").to_json()
        )
        assert bus.flush()
        dashboard.update(t0 + 0.4)
        assert dashboard.drones == ["cf1"]
    finally:
        dashboard.close()
        service.close()


def test_the_fake_services_refusal_is_said_once_then_applied_answers(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    t0 = time.monotonic()
    _feed(dash, bus, fake, 0.0, t0)
    panel = _panel(dash)
    fake.refuse_follow = "cf1 is busy; not applied"
    panel.follow.handle.value = True
    panel._on_follow_toggled(_client_event())
    assert bus.flush()
    _feed(dash, bus, fake, 0.1, t0 + 0.2)
    assert "cf1 is busy" in panel.follow_message.content
    assert panel.follow.handle.value is False and panel.follow.pending is None
    fake.refuse_follow = None
    bus.publish(
        "tether/cf1/events",
        Event(stamp_s=0.0, kind="follow", input="follow", reason="follow on").to_json(),
    )
    assert bus.flush()
    _feed(dash, bus, fake, 0.2, t0 + 0.4)
    assert "The service: follow on." in panel.follow_message.content


def test_follow_mode_without_a_trusted_position_is_refused_on_the_panel(
    settings: Settings, bus: InMemoryBus
) -> None:
    # cf2 has no motion capture and no calibration in force: the service would refuse
    # follow, so the panel says why and sends nothing (instead of a box that unticks itself).
    service = FakeService(bus, ("cf1", "cf2"), mocap=("cf1",))
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        follow_seen = _record(bus, "tether/*/follow")
        _feed(dashboard, bus, service, 0.0, time.monotonic())
        dashboard.select("cf2")
        panel = _panel(dashboard)
        dashboard.update(time.monotonic() + 1.0)
        assert "cannot be switched on now" in panel.follow_help.content
        panel.follow.handle.value = True
        panel._on_follow_toggled(_client_event())
        assert bus.flush()
        assert follow_seen == [], "follow went out for a drone the service would refuse"
        assert panel.follow.handle.value is False
        message = panel.follow_message.content
        assert "Follow mode not switched on" in message and "no motion capture" in message
        dashboard.select("cf1")  # with motion capture: allowed
        panel.follow.handle.value = True
        panel._on_follow_toggled(_client_event())
        assert bus.flush()
        assert [json.loads(s.payload) for s in follow_seen] == [{"enabled": True}]
    finally:
        dashboard.close()
        service.close()


def test_settings_forms_publish_follow_and_params(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    follow_seen = _record(bus, "tether/*/follow")
    params_seen = _record(bus, "tether/*/params")
    fake.publish_once(0.0)
    assert bus.flush()
    dash.poll_status()
    dash.update(time.monotonic())
    panel = _panel(dash)

    panel.threshold.handle.value = 0.3
    panel._on_follow_submit(None)
    panel.land.handle.value = True
    panel.land_height.handle.value = 0.4
    panel._on_land_toggled(_client_event())
    panel.weight.handle.value = 0.04
    panel.length.handle.value = 1.9
    panel._on_tether_submit(None)
    assert bus.flush()
    assert [json.loads(s.payload) for s in follow_seen] == [
        {"enabled": False, "threshold_n": 0.3, "land": False},
        {"enabled": False, "land_below_m": 0.4, "land": True},
    ]
    assert [json.loads(s.payload) for s in params_seen] == [
        {"weight_n_per_m": 0.04, "length_m": 1.9}
    ]
    assert fake.params == [("cf1", {"weight_n_per_m": 0.04, "length_m": 1.9})]


def test_tether_parameters_out_of_range_are_refused_on_the_panel(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    # No browser minimum on ω and length: a typed -1 is said and not sent, never clamped.
    params_seen = _record(bus, "tether/*/params")
    _feed(dash, bus, fake, 0.0, time.monotonic())
    panel = _panel(dash)
    panel.weight.handle.value = -1.0
    panel._tether_typed(panel.weight)(_client_event())
    assert "ω -1 N/m refused" in panel.tether_message.content
    panel._on_tether_submit(None)
    panel.weight.handle.value = 0.05
    panel.length.handle.value = 0.0
    panel._on_tether_submit(None)
    assert bus.flush()
    assert params_seen == [], "refused tether parameters went out"
    assert "Length 0 m refused" in panel.tether_message.content
    assert "Nothing was sent" in panel.tether_message.content
    assert panel.length.handle.value == 0.0  # not clamped behind the operator's back


@pytest.mark.parametrize(
    ("threshold_n", "expect"),
    [(-1.0, "&gt; 0"), (0.0, "&gt; 0"), (0.005, "below"), (0.015, "below")],
)
def test_follow_threshold_below_the_floor_is_refused_on_the_panel(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService, threshold_n: float, expect: str
) -> None:
    follow_seen = _record(bus, "tether/*/follow")
    _feed(dash, bus, fake, 0.0, time.monotonic())
    panel = _panel(dash)
    panel.threshold.handle.value = threshold_n
    panel._on_threshold_typed(_client_event())  # said while typing...
    assert expect in panel.follow_message.content and "refused" in panel.follow_message.content
    panel._on_follow_submit(None)  # ...and refused on Apply
    assert bus.flush()
    assert follow_seen == [], "a refused threshold went out"
    assert "Nothing was sent" in panel.follow_message.content
    assert panel.threshold.handle.value == threshold_n  # not clamped behind the operator's back
    assert "beyond the tether's own tension" in panel.follow_help.content


def test_land_height_out_of_reach_is_refused(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    follow_seen = _record(bus, "tether/*/follow")
    _feed(dash, bus, fake, 0.0, time.monotonic())
    panel = _panel(dash)
    panel.land_height.handle.value = 3.0  # base 0.754 m + tether 1.6 m = 2.354 m
    panel.land.handle.value = True
    panel._on_land_toggled(_client_event())
    assert bus.flush()
    assert follow_seen == []
    assert "outside the tether's reach" in panel.follow_message.content
    assert panel.land.handle.value is False  # the box shows the report again
    panel.land_height.handle.value = 0.0  # at the floor: never below it
    panel._on_land_height_typed(_client_event())
    assert "refused" in panel.follow_message.content


def test_length_is_not_editable_when_a_reel_reports_it(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    params_seen = _record(bus, "tether/*/params")
    fake.publish_once(0.0)
    bus.publish("tether/cf1/reel", b'{"stamp_s": 0.0, "length_m": 1.25}')
    assert bus.flush()
    dash.update(time.monotonic())
    panel = _panel(dash)
    assert panel.length.handle.disabled
    assert "reel" in panel.tether_html.content
    panel.weight.handle.value = 0.06
    panel._on_tether_submit(None)
    assert bus.flush()
    assert [json.loads(s.payload) for s in params_seen] == [{"weight_n_per_m": 0.06}]


def test_stop_is_sent_then_acknowledged_by_telemetry(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    t0 = time.monotonic()
    _feed(dash, bus, fake, 0.0, t0)
    payload = dash.request_stop("cf1")
    assert bus.flush()
    assert fake.stops and fake.stops[0][0] == "cf1"
    stop = StopIn.parse(payload)
    assert stop.reason == "operator" and abs(stop.stamp_s - time.time()) < 5.0
    dash.update(t0 + 1.0)  # the Stop seen, no telemetry since
    panel = _panel(dash)
    assert "Stop sent" in panel.stop_html.content
    assert "acknowledged" not in panel.stop_html.content
    assert "STOPPED" in _node(dash, "/drones/cf1/body/label").text
    _feed(dash, bus, fake, 0.1, t0 + 2.0)  # the fake obeys: its telemetry says disarmed
    assert "Stop acknowledged: disarmed" in panel.stop_html.content
    # Re-armed and flying again: the stop is over.
    fake.rearm("cf1")
    _feed(dash, bus, fake, 0.2, t0 + 3.0)
    assert panel.stop_html.content == ""


def test_stop_not_obeyed_is_never_acknowledged(settings: Settings, bus: InMemoryBus) -> None:
    service = FakeService(bus, ("cf1",), obey_stop=False)
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        t0 = time.monotonic()
        _feed(dashboard, bus, service, 0.0, t0)
        dashboard.request_stop("cf1")
        for k in range(1, 6):  # telemetry keeps coming, armed and with thrust
            _feed(dashboard, bus, service, 0.1 * k, t0 + k)
        content = _panel(dashboard).stop_html.content
        assert "Stop sent" in content and "waiting for telemetry" in content
        assert "acknowledged" not in content
    finally:
        dashboard.close()
        service.close()


def test_stop_all_stops_every_drone_stale_ones_too(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    _feed(dash, bus, fake, 0.0, time.monotonic())
    cf2 = dash.drone("cf2")
    assert cf2 is not None and cf2.inbox.telemetry_rx_s is not None
    cf2.inbox.telemetry_rx_s -= 10.0  # lost telemetry: may still be flying
    assert dash.stop_all() == ["cf1", "cf2"]
    assert bus.flush()
    assert sorted(d for d, _ in fake.stops) == ["cf1", "cf2"]


def test_stale_drones_fade_then_are_forgotten(
    settings: Settings, bus: InMemoryBus, fake: FakeService
) -> None:
    short = settings.model_copy(
        update={"web": settings.web.model_copy(update={"forget_after_s": 30.0})}
    )
    dashboard = Dashboard(short, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        t0 = time.monotonic()
        _feed(dashboard, bus, fake, 0.0, t0)
        cf2 = dashboard.drone("cf2")
        assert cf2 is not None and cf2.inbox.telemetry_rx_s is not None
        # cf2 went quiet 5 s ago (arrival times moved back instead of waiting).
        cf2.inbox.telemetry_rx_s -= 5.0
        cf2.inbox.last_rx_s -= 5.0
        fake.drones = ("cf1",)
        _feed(dashboard, bus, fake, 0.1, t0 + 1.5)
        label = _node(dashboard, "/drones/cf2/body/label").text
        assert "stale" in label and "|T|" not in label
        assert _node(dashboard, "/drones/cf2/body/quad").opacity == pytest.approx(0.25)
        assert not _node(dashboard, "/drones/cf2/tension").visible
        assert _node(dashboard, "/drones/cf1/body/quad").opacity is None
        assert dashboard.drones == ["cf1", "cf2"]
        # ...and 40 s ago: past forget_after_s, dropped from scene and selector. The service
        # still answers for it (its status table keeps every drone): that keeps no one alive.
        cf2.inbox.last_rx_s -= 35.0
        assert dashboard.poll_status() == 2
        _feed(dashboard, bus, fake, 0.2, t0 + 3.0)
        assert dashboard.drones == ["cf1"]
        assert dashboard.poll_status() == 1, "a status reply brought a forgotten drone back"
        _feed(dashboard, bus, fake, 0.3, t0 + 4.0)
        assert dashboard.drones == ["cf1"]
        assert dashboard.server.scene.get_handle_by_name("/drones/cf2/body") is None
        assert tuple(_panel(dashboard).drone_select.options) == ("cf1",)
    finally:
        dashboard.close()


def test_forget_stale_on_request_and_a_forgotten_drone_comes_back(
    dash: Dashboard, bus: InMemoryBus, fake: FakeService
) -> None:
    t0 = time.monotonic()
    _feed(dash, bus, fake, 0.0, t0)
    panel = _panel(dash)
    dash.select("cf2")
    assert panel.selected == "cf2"
    cf2 = dash.drone("cf2")
    assert cf2 is not None and cf2.inbox.telemetry_rx_s is not None
    cf2.inbox.telemetry_rx_s -= 5.0
    assert dash.forget_stale() == ["cf2"]
    assert dash.drones == ["cf1"] and panel.selected == "cf1"
    _feed(dash, bus, fake, 0.1, t0 + 1.0)  # cf2 speaks again
    assert dash.drones == ["cf1", "cf2"]
    assert tuple(panel.drone_select.options) == ("cf1", "cf2")


def test_labels_of_neighbouring_drones_are_stacked(settings: Settings, bus: InMemoryBus) -> None:
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        for k, drone in enumerate(("cf1", "cf2")):
            est = _estimate(position_m=(0.5 + 0.1 * k, 0.0, 1.0), position_std_m=None)
            bus.publish(f"tether/{drone}/estimate", est.to_json())
        assert bus.flush()
        dashboard.update(time.monotonic())
        heights = dashboard.scene.label_heights_m()
        assert abs(heights["cf1"] - heights["cf2"]) >= LABEL_STEP_M - 1e-9
        label = _node(dashboard, "/drones/cf2/body/label")
        assert label.position[2] == pytest.approx(heights["cf2"])
    finally:
        dashboard.close()


def test_no_status_reply_shows_a_warning(dash: Dashboard, bus: InMemoryBus) -> None:
    bus.publish("tether/cf1/estimate", _estimate().to_json())
    assert bus.flush()
    assert dash.poll_status() == 0  # nobody answers
    dash.update(time.monotonic())
    assert "No service answers" in _panel(dash).warning.content


def test_a_running_service_without_drones_is_not_called_missing(
    dash: Dashboard, bus: InMemoryBus
) -> None:
    token = bus.liveliness_token("groundstation/service/abc")
    assert dash.poll_status() == 0  # no drone: no status to give
    dash.update(time.monotonic())
    content = _panel(dash).warning.content
    assert "No service answers" not in content
    assert "Service running (instance abc)" in content
    token.close()
    dash.poll_status()
    dash.update(time.monotonic() + 1.0)
    assert "No service answers" in _panel(dash).warning.content


def test_zero_peers_in_the_demo_is_no_alarm(settings: Settings, bus: InMemoryBus) -> None:
    service = FakeService(bus, ("cf1",), peers=0, alone_ok=True)
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        service.publish_once(0.0)
        assert bus.flush()
        assert dashboard.poll_status() == 1
        dashboard.update(time.monotonic())
        panel = _panel(dashboard)
        assert panel.warning.content == ""
        assert "in-process" in panel.health_html.content
    finally:
        dashboard.close()
        service.close()


def test_zero_peers_shows_a_warning(settings: Settings, bus: InMemoryBus) -> None:
    service = FakeService(bus, ("cf1",), peers=0)
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        service.publish_once(0.0)
        assert bus.flush()
        assert dashboard.poll_status() == 1
        dashboard.update(time.monotonic())
        assert "0 peers" in _panel(dashboard).warning.content
    finally:
        dashboard.close()
        service.close()


def test_charts_hold_20_s_and_switch_with_motion_capture(
    settings: Settings, bus: InMemoryBus
) -> None:
    service = FakeService(bus, ("cf1", "cf2"), mocap=("cf1",))
    dashboard = Dashboard(settings, bus, port=0, update_thread=False)
    dashboard.start()
    try:
        t0 = 1000.0
        period_s = 1.0 / dashboard._scene_rate_hz
        for k in range(int(30.0 / period_s)):
            _feed(dashboard, bus, service, k * period_s, t0 + k * period_s)
        charts = _panel(dashboard).charts
        tension = charts.tension.data
        assert len(tension) == 6
        t = tension[0]
        assert t[0] >= -20.0 - 1e-9 and t[-1] <= 0.0
        assert t[-1] - t[0] > 19.0
        np.testing.assert_allclose(tension[4], FIXED_NORM_N, rtol=1e-6)
        np.testing.assert_allclose(tension[5], 0.15)  # threshold
        assert charts.position_mocap.visible and not charts.position.visible
        assert len(charts.position_mocap.data) == 7
        assert all(np.all(np.isfinite(col)) for col in charts.position_mocap.data)
        # cf2 has no motion capture: the other chart, with a full window, never re-seriesed.
        dashboard.select("cf2")
        now_s = t0 + 30.0
        _feed(dashboard, bus, service, 30.0, now_s)
        assert charts.position.visible and not charts.position_mocap.visible
        data = charts.position.data
        assert len(data) == 4 and data[0][0] < -19.0 and data[0][-1] <= 0.0
        assert [len(c.series) for c in (charts.position, charts.position_mocap)] == [4, 7]
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


def test_an_uncalibrated_position_says_its_error_where_it_is_shown() -> None:
    """167 cm off, on the wrong side of the base, with only a small orange badge.
    The position row and a warning under the table say it, with the expected size."""
    text = tension_html(_estimate(calibration="none"))
    position_row = text.split("position</td>")[1].split("</tr>")[0]
    assert "± ~1 m uncalibrated" in position_row
    assert 'role="alert"' in text and "median 95 cm" in text and "groundstation calibrate" in text
    calibrated = tension_html(_estimate(calibration="cal.toml"))
    assert "± ~1 m" not in calibrated and "median 95 cm" not in calibrated
    undetermined = tension_html(_estimate(calibration="none", position_m=None))
    assert "(undetermined)" in undetermined and "median 95 cm" not in undetermined


def test_follow_checkboxes_have_no_tooltip_over_the_stop_buttons(dash: Dashboard) -> None:
    """The Follow mode tooltip once stayed over Emergency stop / Stop all drones after a
    click. What the two boxes do is a note below them instead."""
    panel = _panel(dash)
    assert panel.follow.handle.hint is None and panel.land.handle.hint is None
    assert "Follow mode: the drone yields when the tether is pulled" in panel.follow_help.content
    assert panel.stop_button.hint is not None  # the stop buttons keep theirs
