"""A stand-in for the service, for the dashboard's tests, screenshot and benchmark.

It speaks the contract on a bus: Estimates and telemetry (with motion capture) for a few
drones circling a base, the ``tether/*/status`` queryable, and it answers commands the way
the service does: a FollowCommand shows up in the next Estimates' ``follow``, a params
message in the status, a Stop in ``follow.stopped``; with :attr:`FakeService.refuse_follow`
set it refuses FollowCommands instead, with that reason on ``tether/{drone}/events``. It holds
a service's liveliness token. Drone 0 pulls with a fixed tension of |T| = 0.250 N
(H = 0.150 N, T_v = 0.200 N) so a test can look for that number.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

from groundstation.bus import Bus, Sample, Subscription
from groundstation.messages import Event

BASE_M = (0.0, 0.0, 0.754)
FIXED_H_N = 0.150
FIXED_TV_N = 0.200
FIXED_NORM_N = 0.250


@dataclass
class _FollowState:
    enabled: bool = False
    threshold_n: float = 0.15
    land_below_m: float | None = None
    stopped: bool = False
    reason: str = ""

    def as_json(self) -> dict[str, Any]:
        return {
            "enabled": self.enabled,
            "active": False,
            "threshold_n": self.threshold_n,
            "land_below_m": self.land_below_m,
            "landing_armed": False,
            "stopped": self.stopped,
            "reason": self.reason,
        }


@dataclass
class _DroneState:
    follow: _FollowState = field(default_factory=_FollowState)
    weight_n_per_m: float = 0.05
    length_m: float = 1.6
    seq: int = 0
    armed: bool = True


class FakeService:
    """Publishes a plausible feed for ``drones`` at ``rate_hz`` and records the commands."""

    def __init__(
        self,
        bus: Bus,
        drones: tuple[str, ...] = ("cf1",),
        *,
        rate_hz: float = 50.0,
        mocap: bool | Collection[str] = True,
        obey_stop: bool = True,
        peers: int | None = 1,
        alone_ok: bool | None = None,
        bases: Mapping[str, tuple[float, float, float]] | None = None,
        estimate_error_m: tuple[float, float, float] = (0.02, -0.015, 0.01),
    ) -> None:
        self.bus = bus
        self.drones = drones
        self.rate_hz = rate_hz
        self.mocap = set(drones) if mocap is True else set() if mocap is False else set(mocap)
        """Drones whose telemetry carries a motion-capture position."""
        self.obey_stop = obey_stop
        """A Stop disarms the drone (its telemetry then says armed: false, thrust 0)."""
        self.peers = peers
        """The status' ``peers`` (None: not reported, as an older service)."""
        self.alone_ok = alone_ok
        """The status' ``alone_ok`` (None: not reported)."""
        self.bases = {d: tuple((bases or {}).get(d, BASE_M)) for d in drones}
        """Each drone's base exit point (BASE_M unless given); it circles its base."""
        self.estimate_error_m = estimate_error_m
        """The Estimate's position minus the true (motion-capture) one."""
        self.refuse_follow: str | None = None
        """When set, FollowCommands are refused with this reason (an Event), not applied."""
        self.follow_commands: list[tuple[str, dict[str, Any]]] = []
        self.params: list[tuple[str, dict[str, Any]]] = []
        self.stops: list[tuple[str, dict[str, Any]]] = []
        self.changed = threading.Condition()
        self._state = {d: _DroneState() for d in drones}
        self._lock = threading.Lock()
        self._t0_s = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._subs: list[Subscription] = [
            bus.subscribe("tether/*/follow", self._on_follow),
            bus.subscribe("tether/*/params", self._on_params),
            bus.subscribe("tether/*/cmd/stop", self._on_stop),
            bus.queryable("tether/*/status", self._on_status_query),
            bus.liveliness_token("groundstation/service/fake"),
        ]

    # ------------------------------------------------------------------ commands in

    def _record(self, log: list[tuple[str, dict[str, Any]]], sample: Sample) -> tuple[str, dict]:
        drone = sample.key.split("/")[1]
        cmd = json.loads(sample.payload)
        with self.changed:
            log.append((drone, cmd))
            self.changed.notify_all()
        return drone, cmd

    def _on_follow(self, sample: Sample) -> None:
        drone, cmd = self._record(self.follow_commands, sample)
        reason = self.refuse_follow
        if reason is not None:
            event = Event(stamp_s=time.time(), kind="rejected", input="follow", reason=reason)
            self.bus.publish(f"tether/{drone}/events", event.to_json())
            return
        with self._lock:
            state = self._state.get(drone)
            if state is None:
                return
            follow = state.follow
            follow.enabled = bool(cmd["enabled"])
            if "threshold_n" in cmd:
                follow.threshold_n = float(cmd["threshold_n"])
            if cmd.get("land") is False:
                follow.land_below_m = None
            elif "land_below_m" in cmd:
                follow.land_below_m = float(cmd["land_below_m"])
            elif cmd.get("land") is True and follow.land_below_m is None:
                follow.land_below_m = 0.2
            follow.reason = "operator"

    def _on_params(self, sample: Sample) -> None:
        drone, cmd = self._record(self.params, sample)
        with self._lock:
            state = self._state.get(drone)
            if state is None:
                return
            state.weight_n_per_m = float(cmd.get("weight_n_per_m", state.weight_n_per_m))
            state.length_m = float(cmd.get("length_m", state.length_m))

    def _on_stop(self, sample: Sample) -> None:
        drone, _cmd = self._record(self.stops, sample)
        with self._lock:
            state = self._state.get(drone)
            if state is not None:
                state.follow.stopped = True
                state.follow.enabled = False
                state.follow.reason = "stop"
                if self.obey_stop:
                    state.armed = False

    def rearm(self, drone: str) -> None:
        """Arm ``drone`` again (what the operator does on the drone after a Stop)."""
        with self._lock:
            self._state[drone].armed = True

    def wait_for(self, predicate: Any, timeout_s: float = 10.0) -> bool:
        """Wait until ``predicate(self)`` holds (evaluated on every recorded command)."""
        with self.changed:
            return self.changed.wait_for(lambda: predicate(self), timeout=timeout_s)

    # ------------------------------------------------------------------ feed out

    def _on_status_query(self, _selector: str) -> list[Sample]:
        replies = []
        with self._lock:
            for drone, state in self._state.items():
                status = {
                    "drone": drone,
                    "stale": False,
                    "telemetry_hz": self.rate_hz,
                    "estimate_hz": self.rate_hz,
                    "last_seen_age_s": 0.01,
                    "received": state.seq,
                    "accepted": state.seq,
                    "drops": {"invalid": 2, "bad_key": 1},
                    "queue_overflow": 0,
                    "follow": state.follow.as_json(),
                    "length_m": state.length_m,
                    "base_m": list(self.bases[drone]),
                    "weight_n_per_m": state.weight_n_per_m,
                    "length_source": "config",
                }
                if self.peers is not None:
                    status["peers"] = self.peers
                if self.alone_ok is not None:
                    status["alone_ok"] = self.alone_ok
                replies.append(Sample(f"tether/{drone}/status", json.dumps(status).encode()))
        return replies

    def poses(self, t_s: float) -> dict[str, tuple[tuple[float, float, float], float]]:
        """True position and azimuth of each drone at time ``t_s``."""
        out = {}
        n = len(self.drones)
        for k, drone in enumerate(self.drones):
            azimuth_rad = 2.0 * math.pi * k / n + 0.15 * t_s
            radius_m = 0.9 + 0.1 * k
            z_m = 1.0 + 0.1 * math.sin(0.5 * t_s + k)
            bx, by, _ = self.bases[drone]
            pos = (
                bx + radius_m * math.cos(azimuth_rad),
                by + radius_m * math.sin(azimuth_rad),
                z_m,
            )
            out[drone] = (pos, azimuth_rad)
        return out

    def publish_once(self, t_s: float | None = None) -> None:
        """Publish one telemetry and one Estimate per drone."""
        t_s = time.monotonic() - self._t0_s if t_s is None else t_s
        for k, (drone, (pos, azimuth_rad)) in enumerate(self.poses(t_s).items()):
            with self._lock:
                state = self._state[drone]
                state.seq += 1
                seq = state.seq
                follow = state.follow.as_json()
                length_m = state.length_m
                armed = state.armed
            if k == 0:
                h_n, tv_n = FIXED_H_N, FIXED_TV_N
            else:
                h_n, tv_n = 0.12 + 0.02 * math.sin(t_s), 0.18
            tension = (-h_n * math.cos(azimuth_rad), -h_n * math.sin(azimuth_rad), -tv_n)
            half_yaw = 0.5 * (azimuth_rad + math.pi)
            quat = (math.cos(half_yaw), 0.0, 0.0, math.sin(half_yaw))
            ex, ey, ez = self.estimate_error_m
            estimate_pos = (pos[0] + ex, pos[1] + ey, pos[2] + ez)
            telemetry = {
                "seq": seq,
                "stamp_s": t_s,
                "accel_mps2": [0.0, 0.0, 9.81],
                "quat_wxyz": list(quat),
                "thrust_n": 0.5 if armed else 0.0,
                "position_m": list(pos) if drone in self.mocap else None,
                "armed": armed,
            }
            estimate = {
                "seq": seq,
                "stamp_s": t_s,
                "tension_n": list(tension),
                "tension_std_n": [0.004, 0.004, 0.003],
                "horizontal_n": h_n,
                "vertical_n": tv_n,
                "position_m": list(estimate_pos),
                "position_std_m": [0.03, 0.03, 0.02],
                "radial_m": math.hypot(
                    estimate_pos[0] - self.bases[drone][0], estimate_pos[1] - self.bases[drone][1]
                ),
                "radial_interval_m": [0.85, 0.95],
                "azimuth_determined": True,
                "floor_contact": False,
                "on_ground": False,
                "converged": True,
                "length_m": length_m,
                "base_m": list(self.bases[drone]),
                "follow": follow,
            }
            self.bus.publish(f"tether/{drone}/telemetry", json.dumps(telemetry).encode())
            self.bus.publish(f"tether/{drone}/estimate", json.dumps(estimate).encode())

    def _run(self) -> None:
        period_s = 1.0 / self.rate_hz
        next_s = time.monotonic()
        while not self._stop.is_set():
            self.publish_once()
            next_s += period_s
            delay_s = next_s - time.monotonic()
            if delay_s < -1.0:  # fell far behind (loaded machine): do not burst
                next_s = time.monotonic()
            self._stop.wait(max(0.0, delay_s))

    def start(self) -> FakeService:
        self._thread = threading.Thread(target=self._run, name="fake-service", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        for sub in self._subs:
            sub.close()
