"""The service on the in-memory bus: follow commands validated and explained, the operator
action log on ``tether/{drone}/events`` and in the log, peers in ``status``."""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from groundstation.bus import InMemoryBus, PeerWatch, Sample
from groundstation.config import Settings, load_settings
from groundstation.messages import Event, Status
from groundstation.service import EVENTS_PER_S, Service, never_capped

MASS_KG = 0.030
THRUST_N = 0.33


def _telemetry(seq: int, pull_down_n: float = 0.0) -> bytes:
    # Level, at rest: m·a_z − F = −pull (eq:NE_tether), so |T| = pull_down_n.
    accel_z = (THRUST_N - pull_down_n) / MASS_KG
    return json.dumps(
        {
            "seq": seq,
            "stamp_s": seq * 0.004,
            "accel_mps2": [0.0, 0.0, accel_z],
            "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "thrust_n": THRUST_N,
            # motion capture: the service follows only a position it can trust
            "position_m": [1.0, 0.0, 1.0],
        }
    ).encode()


def _wait(predicate: Callable[[], bool], timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    tick = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            return False
        tick.wait(0.02)  # polling a condition, not synchronising on time
    return True


class Harness:
    def __init__(self, settings: Settings) -> None:
        self.bus = InMemoryBus()
        self.service = Service(settings, self.bus)
        self.events: list[Event] = []
        self.bus.subscribe("tether/*/events", self._on_event)
        self.service.start()
        self.seq = 0

    def _on_event(self, sample: Sample) -> None:
        self.events.append(Event.model_validate_json(sample.payload))

    def fly(self, drone: str, n: int, pull_down_n: float = 0.05) -> None:
        """Publish ``n`` telemetry samples and wait until the service has processed them."""
        target = self.seq + n
        for _ in range(n):
            self.bus.publish(f"tether/{drone}/telemetry", _telemetry(self.seq, pull_down_n))
            self.seq += 1
        assert _wait(lambda: (self.status(drone) or {}).get("accepted", 0) >= target)

    def command(self, drone: str, payload: dict[str, Any] | bytes, kind: str = "follow") -> Event:
        """Publish a command and return the next event about it."""
        n = len(self.events)
        raw = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        self.bus.publish(f"tether/{drone}/{kind}", raw)
        assert _wait(lambda: len(self.events) > n), f"no event for {raw!r}"
        return self.events[n]

    def status(self, drone: str) -> dict[str, Any] | None:
        replies = self.bus.query(f"tether/{drone}/status")
        return json.loads(replies[0].payload) if replies else None

    def close(self) -> None:
        self.service.close()
        self.bus.close()


@pytest.fixture
def h() -> Iterator[Harness]:
    harness = Harness(load_settings(None, use_env=False))
    yield harness
    harness.close()


def test_follow_for_an_unknown_drone_is_refused_and_stays_off(h: Harness) -> None:
    event = h.command("cf9", {"enabled": True})
    assert event.kind == "rejected" and event.input == "follow" and event.field == "enabled"
    assert "no telemetry" in event.reason and "not applied" in event.reason
    h.fly("cf9", 300)
    status = h.status("cf9")
    assert status is not None
    assert status["follow"]["enabled"] is False, "cf9 must not start flying in follow mode"
    assert status["drops"]["follow_refused"] == 1
    # Once it is heard, the same command is applied.
    event = h.command("cf9", {"enabled": True})
    assert event.kind == "follow" and event.changes["enabled"] is True
    assert event.reason == "follow on"
    assert _wait(lambda: (h.status("cf9") or {})["follow"]["enabled"] is True)


def test_follow_for_a_stale_drone_is_refused(h: Harness) -> None:
    h.fly("cf1", 50)
    assert _wait(lambda: (h.status("cf1") or {}).get("stale") is True, 3.0)
    event = h.command("cf1", {"enabled": True})
    assert event.kind == "rejected" and "stale" in event.reason


@pytest.mark.parametrize(
    ("payload", "field", "needle"),
    [
        ({"enabled": True, "threshold_n": -1}, "threshold_n", "greater than 0"),
        ({"enabled": True, "threshold_n": 0.01}, "threshold_n", "below the service's floor"),
        ({"enable": True}, "enabled", "'enable'"),
        ({"enabled": "yes"}, "enabled", "valid boolean"),
        (b"not json", None, "JSON"),
        # Tug-to-land heights outside (floor 0 m, base 0.754 m + tether 1.6 m): above the
        # reach the first tug stops the motors at any height, at the floor or below never.
        ({"enabled": True, "land_below_m": 50.0}, "land_below_m", "outside the tether's reach"),
        ({"enabled": True, "land_below_m": -5.0}, "land_below_m", "above the floor (0 m"),
        ({"enabled": False, "land_below_m": 0.0}, "land_below_m", "outside the tether's reach"),
        ({"enabled": True, "land_below_m": 2.354}, "land_below_m", "below base + tether"),
    ],
)
def test_bad_follow_commands_are_rejected_with_the_reason(
    h: Harness, payload: dict[str, Any] | bytes, field: str | None, needle: str
) -> None:
    h.fly("cf1", 300)
    before = h.status("cf1")
    assert before is not None
    for _ in range(2):  # every one is told, not only the first of its kind
        event = h.command("cf1", payload)
        assert event.kind == "rejected" and event.input == "follow"
        assert event.field == field
        assert needle in event.reason, event.reason
        assert event.who == "unknown"  # the in-memory bus carries no source id
    after = h.status("cf1")
    assert after is not None
    assert after["follow"] == before["follow"], "a rejected command changes nothing"
    assert after["follow"]["threshold_n"] == 0.10


def test_a_land_height_within_reach_is_applied(h: Harness) -> None:
    h.fly("cf1", 300)
    event = h.command("cf1", {"enabled": False, "land_below_m": 0.25})
    assert event.kind == "follow" and event.changes["land_below_m"] == 0.25


def test_a_valid_threshold_is_applied_and_told(h: Harness) -> None:
    h.fly("cf1", 300, pull_down_n=0.05)
    event = h.command("cf1", {"enabled": True, "threshold_n": 0.07})
    assert event.kind == "follow" and event.changes == {"enabled": True, "threshold_n": 0.07}
    assert event.reason == "follow on"
    event = h.command("cf1", {"enabled": True, "threshold_n": 0.02})  # the floor itself
    assert event.kind == "follow" and event.changes == {"enabled": True, "threshold_n": 0.02}
    assert event.reason == "re-tuned", "already on: only the threshold changed"


def test_unknown_fields_of_an_accepted_command_are_told(h: Harness) -> None:
    h.fly("cf1", 10)
    warning = h.command("cf1", {"enabled": False, "treshold_n": 0.3})
    assert warning.kind == "warning" and warning.field == "treshold_n"
    assert "'treshold_n'" in warning.reason and "threshold_n" in warning.reason
    assert _wait(lambda: len(h.events) >= 2)
    applied = h.events[1]
    assert applied.kind == "follow" and applied.reason == "no change"


def test_params_and_stops_are_logged_with_who_what_when(
    h: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="groundstation.actions")
    h.fly("cf1", 10)
    t0 = time.time()
    event = h.command("cf1", {"weight_n_per_m": 0.06}, kind="params")
    assert event.kind == "params" and event.changes == {"weight_n_per_m": 0.06}
    assert t0 - 1.0 <= event.stamp_s <= time.time() + 1.0, "when: UNIX seconds"
    event = h.command("cf1", {"stamp_s": 1.0, "reason": "operator"}, kind="cmd/stop")
    assert event.kind == "stop" and event.input == "cmd/stop" and event.reason == "operator"
    lines = [r.getMessage() for r in caplog.records if r.name == "groundstation.actions"]
    assert len(lines) == 2, lines
    assert lines[0].startswith("cf1 params on params from unknown: applied")
    assert lines[1].startswith("cf1 stop on cmd/stop from unknown: operator")


def test_the_services_own_stop_is_logged_once(h: Harness) -> None:
    h.fly("cf1", 10)
    own = json.dumps({"stamp_s": 2.0, "reason": "tug-to-land"}).encode()
    h.service._publish([Sample("tether/cf1/cmd/stop", own)])
    event = h.command("cf1", {"stamp_s": 3.0, "reason": "operator"}, kind="cmd/stop")
    assert event.reason == "operator", "the service's own Stop is not told twice"
    assert [e.reason for e in h.events] == ["operator"]


def test_a_silent_drone_switches_follow_off_and_says_so(h: Harness) -> None:
    h.fly("cf1", 300)
    assert h.command("cf1", {"enabled": True}).kind == "follow"
    assert _wait(lambda: any(e.input == "service" for e in h.events), 3.0)
    (stale,) = [e for e in h.events if e.input == "service"]
    assert stale.kind == "follow" and stale.changes == {"enabled": False}
    assert "silent" in stale.reason and stale.who == h.service.pipeline.self_id


def test_rejected_telemetry_is_told_once_per_kind(h: Harness) -> None:
    h.fly("cf1", 10)
    for _ in range(5):
        h.bus.publish("tether/cf1/telemetry", b'{"seq": 1}')
    event = h.command("cf1", {"enabled": False})
    kinds = [(e.kind, e.input) for e in h.events]
    assert kinds == [("rejected", "telemetry"), ("follow", "follow")], kinds
    assert event.kind == "rejected" and "further ones counted" in event.reason


def test_a_flood_of_bad_commands_is_capped(h: Harness) -> None:
    h.fly("cf1", 1)
    for _ in range(300):
        h.bus.publish("tether/cf1/follow", b'{"enabled": 1}')
    assert h.bus.flush()
    assert _wait(lambda: h.service.events + sum(h.service.events_suppressed.values()) >= 300)
    assert h.service.events <= 2 * EVENTS_PER_S + 20  # the burst, plus what refilled meanwhile
    status = h.status("cf1")
    assert status is not None and status["events_suppressed"] >= 200


def test_a_flood_never_hides_a_stop_or_a_follow_switch(
    h: Harness, caplog: pytest.LogCaptureFixture
) -> None:
    # The cap drops events of a flood of bad commands, but never a Stop or follow switched
    # on/off: those stay in the action log (and on the bus, hence in a recording).
    caplog.set_level(logging.INFO, logger="groundstation.actions")
    h.fly("cf1", 300)
    for _ in range(300):
        h.bus.publish("tether/cf1/follow", b'{"enabled": 1}')
    h.bus.publish("tether/cf1/follow", b'{"enabled": true}')
    h.bus.publish("tether/cf1/cmd/stop", b'{"stamp_s": 1.0, "reason": "operator"}')
    assert h.bus.flush()
    assert _wait(lambda: any(e.kind == "stop" for e in h.events))
    assert sum(h.service.events_suppressed.values()) >= 200, "the flood was capped"
    kinds = [e.kind for e in h.events]
    assert "follow" in kinds and "stop" in kinds
    lines = [r.getMessage() for r in caplog.records if r.name == "groundstation.actions"]
    assert any(line.startswith("cf1 follow on follow from unknown: follow on") for line in lines)
    assert any(line.startswith("cf1 stop on cmd/stop from unknown: operator") for line in lines)


def test_which_events_are_never_capped() -> None:
    def event(kind: Any, reason: str = "", input_kind: str = "follow") -> Event:
        return Event(stamp_s=0.0, kind=kind, input=input_kind, reason=reason)

    assert never_capped(event("stop", "operator", "cmd/stop"))
    assert never_capped(event("stop", "tug-to-land", "service"))
    assert never_capped(event("follow", "follow on")) and never_capped(
        event("follow", "follow off")
    )
    assert never_capped(event("follow", "cf1 silent for 0.60 s: follow off", "service"))
    assert not never_capped(event("follow", "re-tuned"))
    assert not never_capped(event("follow", "no change"))
    assert not never_capped(event("rejected", "threshold_n ..."))
    assert not never_capped(event("warning", "unknown fields ignored"))


def test_status_matches_its_documented_model(h: Harness) -> None:
    h.fly("cf1", 10)
    status = h.status("cf1")
    assert status is not None
    Status.model_validate(status)
    undocumented = set(status) - set(Status.model_fields)
    assert not undocumented, f"status fields missing from messages.Status: {undocumented}"
    assert status["peers"] is None, "an in-memory bus has no peers to count"
    assert status["alone_ok"] is False


def test_status_says_when_being_alone_is_expected() -> None:
    bus = InMemoryBus()
    service = Service(load_settings(None, use_env=False), bus, alone_ok=True)
    service.start()
    try:
        bus.publish("tether/cf1/telemetry", _telemetry(0))
        assert _wait(lambda: bool(bus.query("tether/cf1/status")))
        status = json.loads(bus.query("tether/cf1/status")[0].payload)
        assert status["alone_ok"] is True
        assert bus.alive("groundstation/service/*") == [f"groundstation/service/{service.instance}"]
    finally:
        service.close()
        bus.close()


def test_events_are_recorded(tmp_path: Path) -> None:
    from groundstation.recording import Recorder, iter_messages

    harness = Harness(load_settings(None, use_env=False))
    recorder = Recorder(harness.bus, tmp_path / "r.mcap")
    try:
        harness.fly("cf1", 5)
        harness.command("cf1", {"enabled": True, "threshold_n": -1})
        assert harness.bus.flush()
    finally:
        recorder.close()
        harness.close()
    events = [m for m in iter_messages(tmp_path / "r.mcap") if m.key == "tether/cf1/events"]
    assert len(events) == 1
    assert Event.model_validate_json(events[0].payload).field == "threshold_n"


def test_peer_watch_says_no_peer_then_each_change(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="test.peers")
    counts = iter([0, 0, 0, 2, 2, 0, 1])
    where = "no peer / no router reachable at tcp/x:1"
    watch = PeerWatch(lambda: next(counts), where, "serve", logging.getLogger("test.peers"), 1.0)
    for t in (0.0, 0.5, 1.2, 2.0, 3.0, 4.0, 5.0):
        watch.poll(t)
    assert [(r.levelname, r.getMessage()) for r in caplog.records] == [
        ("WARNING", f"serve: {where}"),
        ("INFO", "serve: connected to 2 zenoh peer(s)/router(s)"),
        ("WARNING", f"serve: lost every zenoh peer and router; {where}"),
        ("INFO", "serve: connected to 1 zenoh peer(s)/router(s)"),
    ]
    assert watch.peers == 1 and watch.ever_connected


def test_an_operators_stop_switches_follow_off(h: Harness) -> None:
    h.fly("cf1", 300)
    assert h.command("cf1", {"enabled": True}).changes["enabled"] is True
    event = h.command("cf1", {"stamp_s": 1.0, "reason": "operator"}, kind="cmd/stop")
    assert event.kind == "stop" and event.changes == {"enabled": False}
    h.fly("cf1", 10)
    status = h.status("cf1")
    assert status is not None and status["follow"]["enabled"] is False
    assert "Stop (operator)" in status["follow"]["reason"]
    unreadable = h.command("cf1", b'{"reason": 3}', kind="cmd/stop")
    assert unreadable.kind == "stop" and "nobody can read" in unreadable.reason
    rearm = h.command("cf1", b"{}", kind="cmd/rearm")
    assert rearm.kind == "rearm" and rearm.input == "cmd/rearm"


def _settings_for_drones(drones: str) -> Settings:
    settings = load_settings(None, use_env=False)
    service = settings.service.model_copy(update={"drones": drones})
    return settings.model_copy(update={"service": service})


def test_a_service_refuses_drones_another_service_owns() -> None:
    from groundstation.service import OwnershipConflict

    bus = InMemoryBus()
    a = Service(_settings_for_drones("lab-a-*"), bus, instance="a")
    b = Service(_settings_for_drones("lab-b-*"), bus, instance="b")
    everyone = Service(_settings_for_drones("*"), bus, instance="all")
    labs = Service(_settings_for_drones("lab-*"), bus, instance="labs")
    estimates: list[str] = []
    bus.subscribe("tether/*/estimate", lambda s: estimates.append(s.key))
    try:
        a.start()
        b.start()  # disjoint slices: both run
        for late in (everyone, labs):
            with pytest.raises(OwnershipConflict, match="instance a owns 'tether/lab-a-"):
                late.start()
        # The refused services hold no token and subscribed to nothing: each drone's
        # telemetry is estimated once, by its owner.
        assert sorted(bus.alive("groundstation/service/*")) == [
            "groundstation/service/a",
            "groundstation/service/b",
        ]
        for seq in range(3):
            bus.publish("tether/lab-a-1/telemetry", _telemetry(seq))
            bus.publish("tether/lab-b-1/telemetry", _telemetry(seq))
        assert _wait(lambda: len(estimates) >= 6)
        assert bus.flush()
        assert (
            sorted(estimates) == ["tether/lab-a-1/estimate"] * 3 + ["tether/lab-b-1/estimate"] * 3
        )
        # Once an owner is gone its slice is free again.
        a.close()
        b.close()
        labs.start()
        assert bus.alive("groundstation/owner/*/*") == ["groundstation/owner/labs/lab-$*"]
    finally:
        for s in (a, b, everyone, labs):
            s.close()
        bus.close()
