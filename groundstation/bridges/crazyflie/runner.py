"""The bridge at run time: one loop between a :class:`Link` and the bus.

Link and bus callbacks only validate and queue; one thread (the caller's, in :meth:`run`)
aligns log blocks, publishes Telemetry, streams setpoints and handles Stop, so the order of
events is the order they are acted on. Setpoints go out every :data:`SETPOINT_PERIOD_S`,
whatever the log rate. Bus keys (``{drone}`` is the drone id):

* publishes ``tether/{drone}/telemetry`` (contract) and ``tether/{drone}/bridge`` (added:
  status, once per ``status_period_s`` and on every change of connection or latch);
* reads ``tether/{drone}/cmd/setpoint`` and ``tether/{drone}/cmd/stop`` (contract; a Stop of
  ``kind`` ``land`` lands without the latch), ``tether/{drone}/estimate`` (contract: only as
  the ground station's heartbeat),
  ``tether/{drone}/cmd/rearm`` (added: lifts the stop latch and asks the supervisor to arm,
  any JSON object),
  ``tether/{drone}/cmd/takeoff`` ``{"height_m": h, "speed_mps": v}`` and
  ``tether/{drone}/cmd/land`` ``{"speed_mps": v}`` (added: straight vertical ramps of position
  setpoints from the motion-capture position; landing ends with the motors off) and the
  configured motion-capture key.

Safety (docs/real-lab.md, "what the bridge does when something goes wrong"): the ground station
is heard when a Setpoint, an Estimate or a command for this drone *arrives* (timed on the bus's
thread); silence holds, then lands (:class:`~.bridge.CommandGate`). Log data is timed when it
arrives (cflib's thread), so a stalled bridge thread is no link loss; and a silent link is
never closed as a recovery while the bridge commands the drone (cflib's ``close_link`` sends a
zero setpoint: motors off in flight).
"""

from __future__ import annotations

import json
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from groundstation.bridges.crazyflie.bridge import (
    NOT_LOGGED_CONSEQUENCE,
    VELOCITY_VAR,
    Aligner,
    CommandGate,
    MissingVariables,
    MocapPose,
    Phase,
    Reach,
    SetpointCommand,
    SettleWatch,
    Skip,
    VariablePlan,
    build_telemetry,
    plan_variables,
    yaw_deg_from_quat,
)
from groundstation.bridges.crazyflie.link import Link, LinkError, LogBlockRefused
from groundstation.bus import Bus, Sample, Subscription
from groundstation.config import CrazyflieSection
from groundstation.messages import (
    InvalidMessage,
    LandIn,
    MocapPoseIn,
    SetpointIn,
    StopIn,
    TakeoffIn,
)

__all__ = ["SETPOINT_PERIOD_S", "CrazyflieBridge", "bridge_keys", "run_bridges"]

_VERDICT_WHY = {
    "out_of_reach": ": beyond the tether's reach from the base",
    "too_fast": ": a jump faster than [crazyflie] max_setpoint_speed_mps",
    "landing": ": the drone is landing (a take-off or a Stop replaces a landing)",
    "stale": ": computed from old telemetry",
    "clock": ": not stamped on the drone's clock",
}
"""Why a setpoint was dropped, for the log (once per kind)."""

_log = logging.getLogger("groundstation.crazyflie")

_BACKOFF_START_S = 0.25
SETPOINT_PERIOD_S = 0.02
"""The setpoint in force is (re-)sent every 20 ms, whatever ``rate_hz``: the firmware's
commander watchdog levels the drone 0.5 s after the last setpoint and cuts the motors after
2 s, and a log period may be as long as 2 s (``rate_hz = 0.5``)."""
DATA_TIMEOUT_PERIODS = 3
"""An open link is taken as lost after ``data_timeout_s``, but never before this many of the
most frequent block's periods have passed without data (a slow log rate is not a loss)."""
REACH_MARGIN_M = 0.05
"""A take-off target stays this much inside the tether's length from the base."""
RESET_HOLD_S = 0.1
"""``kalman.resetEstimation`` is written 1, then 0 this much later (cflib's
``reset_estimator``; the firmware clears it itself once reset)."""
ONBOARD_SOURCES = ("lighthouse", "loco", "flow")


def bridge_keys(drone: str) -> dict[str, str]:
    """The bus keys of one drone's bridge."""
    base = f"tether/{drone}"
    return {
        "telemetry": f"{base}/telemetry",
        "status": f"{base}/bridge",
        "setpoint": f"{base}/cmd/setpoint",
        "stop": f"{base}/cmd/stop",
        "rearm": f"{base}/cmd/rearm",
        "takeoff": f"{base}/cmd/takeoff",
        "land": f"{base}/cmd/land",
        "estimate": f"{base}/estimate",
    }


@dataclass(frozen=True, slots=True)
class _Event:
    kind: str
    """``data``, ``lost``, ``setpoint``, ``stop``, ``rearm``, ``mocap``, ``wake``."""
    payload: Any = None
    epoch: int = 0
    """Connection number a link event belongs to (late events of an old link are ignored)."""


class CrazyflieBridge:
    """Runs the bridge for one drone until ``stop`` is set.

    Args:
        section: ``[crazyflie]``.
        bus: the bus (a :class:`~groundstation.zenoh_bus.ZenohBus` in the CLI).
        drone: the drone id used in the keys.
        link: the drone (:class:`~groundstation.bridges.crazyflie.link.CflibLink`, or the
            test fake).
        clock: monotonic host clock, s.
        floor_z_m: where a landing ramp ends, world z (``[base] floor_z_m``).
        reach: ``(base exit point, tether length)``, world frame, m: a take-off whose target
            lies beyond ``length - 0.05`` m of the base is refused. None: not checked.
    """

    def __init__(
        self,
        section: CrazyflieSection,
        bus: Bus,
        drone: str,
        link: Link,
        clock: Callable[[], float] = time.monotonic,
        floor_z_m: float = 0.0,
        reach: tuple[tuple[float, float, float], float] | None = None,
    ) -> None:
        self.section = section
        self.bus = bus
        self.drone = drone
        self.link = link
        self.keys = bridge_keys(drone)
        self.mocap_key = section.mocap_key.replace("{drone}", drone) if section.mocap_key else None
        self._clock = clock
        self.floor_z_m = floor_z_m
        self.reach = reach
        self._events: queue.Queue[_Event] = queue.Queue()
        self.gate = CommandGate(
            section.watchdog_s,
            section.yaw_deg,
            silence_s=section.silence_s,
            hold_s=section.hold_s,
            land_speed_mps=section.land_speed_mps,
            floor_z_m=floor_z_m,
            reach=Reach(reach[0], reach[1], REACH_MARGIN_M) if reach is not None else None,
            max_speed_mps=section.max_setpoint_speed_mps,
        )
        self._heard_s = -math.inf
        """Host clock when the ground station was last heard, written on the bus's thread."""
        self._unanswered_s: float | None = None
        """Host clock of the first Telemetry published after the ground station was last
        heard: silence counts from there (while the bridge publishes nothing, stalled, the
        ground station has nothing to answer)."""
        self._arrived_s = 0.0
        """Host clock when log data last arrived, written on the link's thread."""
        self._phase: Phase = "idle"
        self._motors_off = False
        self._link_silent = False
        self.seq = 0
        self.connected = False
        self.counts: dict[str, int] = {}
        self._logged: set[str] = set()
        self._epoch = 0
        self._plan: VariablePlan | None = None
        self._aligner: Aligner | None = None
        self._slow: dict[str, float] = {}
        self._mocap: MocapPose | None = None
        self._last_stamp_s: float | None = None
        self._connected_s = 0.0
        self._last_yaw_deg: float | None = None
        self._pending_stop = False
        self._commanding = False
        self._next_tick_s = 0.0
        self._data_timeout_s = section.data_timeout_s
        self._subs: list[Subscription] = []
        self._settle = SettleWatch(section.estimator_settle_s, section.estimator_settle_spread)
        self._estimator_pending = False
        """Reset the estimator at the first period with the motors off (never in flight)."""
        self._estimator_error = ""
        self._settled_told = False
        self._reset_clear_s: float | None = None
        self._onboard: tuple[tuple[float, float, float], float] | None = None
        """The last onboard-estimator position published and when (host clock)."""
        self._extpos_pending: MocapPose | None = None
        self._extpos_sent_s = -math.inf

    # ------------------------------------------------------------------ callbacks

    def _put(self, kind: str, payload: Any = None, epoch: int = 0) -> None:
        self._events.put(_Event(kind, payload, epoch))

    def _on_bus(self, sample: Sample) -> None:
        key = sample.key
        try:
            if key == self.keys["estimate"]:
                # The heartbeat only (one per accepted Telemetry): not parsed, at 100 Hz.
                if sample.payload[:1] == b"{":
                    self._heard_s = self._clock()
                return
            if key == self.keys["setpoint"]:
                self._put("setpoint", SetpointIn.parse(sample.payload))
            elif key == self.keys["stop"]:
                self._put("stop", StopIn.parse(sample.payload))
            elif key == self.keys["rearm"]:
                if not isinstance(json.loads(sample.payload), dict):
                    raise InvalidMessage("invalid", "rearm payload is not a JSON object")
                self._put("rearm")
            elif key == self.keys["takeoff"]:
                self._put("takeoff", TakeoffIn.parse(sample.payload))
            elif key == self.keys["land"]:
                self._put("land", LandIn.parse(sample.payload))
            elif key == self.mocap_key:
                self._put("mocap", MocapPoseIn.parse(sample.payload))
                return  # motion capture is not the ground station
            else:
                return
            self._heard_s = self._clock()  # timed on arrival: a busy bridge thread is no silence
        except (InvalidMessage, ValueError) as exc:
            self._put("bad_input", f"{key}: {exc}")

    # ------------------------------------------------------------------ lifecycle

    def run(self, stop: threading.Event) -> int:
        """Connect, bridge, reconnect after a loss, until ``stop``; then stop and disconnect.

        Returns:
            0, or 2 when the firmware lacks a needed log variable or refuses a log block (the
            message names them; retrying would not help).
        """
        for name in ("setpoint", "stop", "rearm", "takeoff", "land", "estimate"):
            self._subs.append(self.bus.subscribe(self.keys[name], self._on_bus))
        if self.mocap_key:
            self._subs.append(self.bus.subscribe(self.mocap_key, self._on_bus))
        backoff_s = _BACKOFF_START_S
        next_status = self._clock()
        try:
            while not stop.is_set():
                if not self.connected:
                    try:
                        self._connect()
                        backoff_s = _BACKOFF_START_S
                    except (MissingVariables, LogBlockRefused) as exc:
                        _log.error("%s", exc)
                        return 2
                    except LinkError as exc:
                        self._once(
                            "connect_failed",
                            "%s; retrying (back-off up to %.1f s)",
                            exc,
                            self.section.reconnect_max_s,
                        )
                        self._drain_commands()
                        if stop.wait(backoff_s):
                            break
                        backoff_s = min(2.0 * backoff_s, self.section.reconnect_max_s)
                        continue
                next_status = self._serve_tick(stop, next_status)
        finally:
            self._shutdown()
        return 0

    def _connect(self) -> None:
        self._epoch += 1
        epoch = self._epoch
        toc = self.link.open(
            lambda reason: self._put("lost", reason, epoch), self.section.connect_timeout_s
        )
        try:
            plan = plan_variables(self.section, toc, self.link.uri)
        except MissingVariables:
            self.link.close()
            raise
        self._plan = plan
        self._aligner = Aligner([b.name for b in plan.fast], self.section.log_period_ms)
        self._slow = {}
        self._last_stamp_s = None
        self._settle.forget()
        self._estimator_pending = plan.settle
        self._estimator_error = ""
        self._reset_clear_s = None
        self._settled_told = False
        self._onboard = None
        try:
            self.link.start_logging(
                [*plan.fast, *plan.slow], self._data_handler(epoch), self.section.connect_timeout_s
            )
        except LinkError:
            self.link.close()
            raise
        shortest_s = min(b.period_ms for b in (*plan.fast, *plan.slow)) / 1000.0
        self._data_timeout_s = max(self.section.data_timeout_s, DATA_TIMEOUT_PERIODS * shortest_s)
        # The service answers each Telemetry: at a slow log rate its silence is longer.
        self.gate.silence_s = max(
            self.section.silence_s, DATA_TIMEOUT_PERIODS * self.section.log_period_ms / 1000.0
        )
        self.connected = True
        self._link_silent = False
        self._arrived_s = self._connected_s = self._next_tick_s = self._clock()
        self._logged.discard("connect_failed")
        self._logged.discard("lost")
        if self._pending_stop:
            self._send("stop_motors")  # a Stop that arrived while the link was down
            self._pending_stop = False
        _log.info(
            "connected to %s: blocks %s every %d ms, %s; armed %s, vbat %s",
            self.link.uri,
            " | ".join(",".join(b.variables) for b in plan.fast),
            self.section.log_period_ms,
            " | ".join(",".join(b.variables) for b in plan.slow) or "no slow block",
            "supervisor.info" if plan.armed else "not reported",
            "pm.vbat" if plan.vbat else "not reported",
        )
        for var in plan.not_logged:
            self._once(
                f"not_logged:{var}",
                "%s: the firmware does not log %s: %s",
                self.link.uri,
                var,
                NOT_LOGGED_CONSEQUENCE[var],
            )
        self._publish_status()

    def _data_handler(self, epoch: int) -> Callable[[str, int, Mapping[str, float]], None]:
        """The link's data callback: time the arrival (the link's liveness), then queue."""

        def on_data(block: str, raw_ms: int, values: Mapping[str, float]) -> None:
            self._arrived_s = self._clock()
            self._put("data", (block, raw_ms, values), epoch)

        return on_data

    def _serve_tick(self, stop: threading.Event, next_status: float) -> float:
        """Handle events until the next setpoint tick, then send the setpoint in force.

        Ticks come every :data:`SETPOINT_PERIOD_S` on a fixed schedule, not once per log
        period: at a low ``rate_hz`` the firmware's watchdog would otherwise take over.
        """
        while not stop.is_set():
            remaining = self._next_tick_s - self._clock()
            if remaining <= 0:
                break
            try:
                event = self._events.get(timeout=remaining)
            except queue.Empty:
                break
            self._handle(event)
            if not self.connected:
                return next_status
        now = self._clock()
        self._next_tick_s += SETPOINT_PERIOD_S
        if self._next_tick_s <= now:  # fell behind (a busy host): keep the cadence from now
            self._next_tick_s = now + SETPOINT_PERIOD_S
        if self.connected:
            self._check_link(now)
        if self.connected:
            self._send_setpoint(now)
        if self.connected:
            self._estimator_tick(now)
            self._forward_extpos(now)
        if now >= next_status:
            self._publish_status()
            next_status = now + self.section.status_period_s
        return next_status

    def _check_link(self, now: float) -> None:
        """No log data for ``data_timeout_s`` (timed on arrival): a lost link, unless the
        bridge is commanding the drone. Then the link is not closed (cflib's ``close_link``
        sends a zero setpoint, which the firmware takes as motors off: a drop from height);
        the gate lands the drone on setpoints, which may still get through (a one-way loss), and
        the link is given up once the motors are off."""
        silent = now - self._arrived_s > self._data_timeout_s
        if silent and self._commanding:
            if not self._link_silent:
                self._link_silent = True
                self._count("link_silent")
                _log.warning(
                    "no log data from %s for %.2f s while flying: link kept open (closing it "
                    "would cut the motors); landing on setpoints, which may still get through",
                    self.link.uri,
                    now - self._arrived_s,
                )
                self.gate.land(now, f"no log data for {now - self._arrived_s:.2f} s")
                self._publish_status()
            return
        if silent:
            self._on_lost(f"no log data for {self._data_timeout_s:g} s")
        elif self._link_silent:
            self._link_silent = False
            _log.warning("log data from %s again", self.link.uri)
            self._publish_status()

    def _drain_commands(self) -> None:
        """While disconnected, still act on commands (a Stop latches; setpoints are dropped)."""
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                return
            if event.kind not in ("data", "lost"):
                self._handle(event)

    # ------------------------------------------------------------------ events

    def _handle(self, event: _Event) -> None:
        kind = event.kind
        if kind in ("data", "lost") and event.epoch != self._epoch:
            return  # from a link we already gave up
        if kind == "data":
            self._on_data(*event.payload)
        elif kind == "lost":
            self._on_lost(str(event.payload))
        elif kind == "setpoint":
            sp: SetpointIn = event.payload
            if not self.connected:
                self._count("setpoint_disconnected")
                return
            now = self._clock()
            current = self._measured_position(now)
            verdict = self.gate.on_setpoint(
                sp.position_m, sp.stamp_s, now, self._last_stamp_s, self._last_yaw_deg, current
            )
            if verdict != "accepted":
                self._count(f"setpoint_{verdict}")
                self._once(
                    f"setpoint_{verdict}",
                    "setpoint %s dropped (%s)%s",
                    [round(v, 3) for v in sp.position_m],
                    verdict,
                    _VERDICT_WHY.get(verdict, ""),
                )
                if verdict in ("out_of_reach", "too_fast"):
                    self._publish_status()  # a refusal the operator must see at once
        elif kind == "stop":
            stop_msg: StopIn = event.payload
            if stop_msg.landing:
                self._landing_stop(stop_msg.reason)
                return
            was_latched = self.gate.latched
            self.gate.on_stop(stop_msg.reason)
            self._commanding = False  # the stop is the last command
            self._motors_off = True
            self._count("stops")
            if self.connected:
                self._send("stop_motors")
            else:
                self._pending_stop = True
            _log.warning(
                "emergency Stop (%s): motors stopped, latched until tether/%s/cmd/rearm",
                stop_msg.reason,
                self.drone,
            )
            if not was_latched:
                self._publish_status()
        elif kind == "rearm":
            if self.gate.latched:
                _log.warning("re-armed by the operator: setpoints are accepted again")
            self.gate.rearm()
            if self.connected:
                self._send("arm")
            self._publish_status()
        elif kind in ("takeoff", "land"):
            self._ramp(kind, event.payload)
        elif kind == "mocap":
            pose: MocapPoseIn = event.payload
            self._mocap = MocapPose(pose.position_m, pose.quat_wxyz, self._clock())
            if self.section.send_extpos and self.connected:
                if self._extpos_pending is not None:
                    self._count("extpos_superseded")  # a newer pose within the rate's period
                self._extpos_pending = self._mocap
                self._forward_extpos(self._clock())
        elif kind == "bad_input":
            self._count("bad_input")
            self._once(f"bad_input:{str(event.payload).split(':')[0]}", "dropped %s", event.payload)

    def _landing_stop(self, reason: str) -> None:
        """A Stop of kind ``land``: down to the floor, motors off there, no latch."""
        self._count("landing_stops")
        outcome = self.gate.on_stop(reason, self._clock(), landing=True)
        if outcome == "latched":
            _log.warning("landing Stop (%s) ignored: an emergency stop is in force", reason)
        elif outcome == "landing":
            _log.warning(
                "landing Stop (%s): landing at %.2f m/s, motors off on the floor (no latch)",
                reason,
                self.gate.land_speed_mps,
            )
        else:
            # Nothing in force: the bridge is not flying the drone. Motors off, no lock.
            self._commanding = False
            self._motors_off = True
            if self.connected:
                self._send("send_stop_setpoint")
            _log.warning("landing Stop (%s): nothing in force, motors off (no latch)", reason)
        self._publish_status()

    def _measured_position(self, now_s: float) -> tuple[float, float, float] | None:
        """Where the drone is measured to be: a fresh motion-capture pose, else the onboard
        estimator's latest position (fresh, and the estimator settled since its reset)."""
        pose, stale_s = self._mocap, self.section.mocap_stale_s
        if pose is not None and now_s - pose.received_s <= stale_s:
            return pose.position_m
        onboard = self._onboard
        if onboard is not None and now_s - onboard[1] <= stale_s and self._settle.settled(now_s):
            return onboard[0]
        return None

    def _estimator_refusal(self, now_s: float) -> str | None:
        """Why the estimator is not ready for a take-off, or None (ready, or not needed)."""
        plan = self._plan
        if plan is None or not plan.settle or self._settle.settled(now_s):
            return None
        if self._estimator_error:
            return f"the estimator could not be reset ({self._estimator_error})"
        if self._settle.reset_s is None:
            return (
                "the estimator has not been reset on this connection (it is reset at the "
                "first log period with the motors off, never in flight)"
            )
        spreads = self._settle.spreads()
        spread = [round(x, 5) for x in spreads] if spreads is not None else "no sample yet"
        return (
            f"the estimator has not settled since its reset {now_s - self._settle.reset_s:.1f} s "
            f"ago (kalman.varPX/PY/PZ spread {spread} over "
            f"{self.section.estimator_settle_s:g} s, wanted each < "
            f"{self.section.estimator_settle_spread:g}; is the position measured: extpos "
            "streaming, the deck seeing its anchors or base stations?)"
        )

    def _ramp(self, kind: str, cmd: TakeoffIn | LandIn) -> None:
        now = self._clock()
        start = self.gate.position_in_force(now) if kind == "land" else None
        if start is None:
            start = self._measured_position(now)
        refusal = self._estimator_refusal(now) if kind == "takeoff" else None
        if not self.connected or refusal is not None or start is None:
            self._count(f"{kind}_refused")
            _log.warning(
                "%s refused: %s",
                kind,
                "link down"
                if not self.connected
                else refusal or "no fresh motion-capture pose or onboard position",
            )
            self._publish_status()
            return
        x, y, _ = start
        z = cmd.height_m if isinstance(cmd, TakeoffIn) else self.floor_z_m
        if kind == "takeoff" and self.reach is not None:
            base_m, length_m = self.reach
            if math.dist(base_m, (x, y, z)) > length_m - REACH_MARGIN_M:
                self._count("takeoff_refused")
                _log.warning(
                    "takeoff refused: (%.2f, %.2f, %.2f) m is beyond the tether's reach "
                    "(%.2f m from the base)",
                    x,
                    y,
                    z,
                    length_m,
                )
                return
        verdict = self.gate.ramp(
            start, (x, y, z), cmd.speed_mps, now, self._last_yaw_deg, land=kind == "land"
        )
        if verdict != "accepted":
            self._count(f"{kind}_refused")
            _log.warning("%s refused (%s)", kind, verdict)
        else:
            _log.info(
                "%s: from %s to z %.2f m at %.2f m/s",
                kind,
                [round(v, 3) for v in start],
                z,
                cmd.speed_mps,
            )

    def _on_data(self, block: str, raw_ms: int, values: Mapping[str, float]) -> None:
        plan, aligner = self._plan, self._aligner
        if plan is None or aligner is None:
            return
        if any(block == b.name for b in plan.slow):
            self._slow.update(values)
            if plan.settle:
                self._settle.push(self._clock(), [values.get(v, math.nan) for v in VELOCITY_VAR])
            return
        before = aligner.out_of_order
        # Until the slow block's first sample (armed, battery), a Telemetry would say "armed"
        # by the contract's default: wait for it, a few of its periods at most.
        waiting = (
            plan.slow
            and not self._slow
            and self._clock() - self._connected_s < 3 * self.section.slow_period_ms / 1000.0
        )
        for aligned in aligner.push(block, raw_ms, values):
            if waiting:
                self._count("before_slow_block")
                continue
            try:
                tel = build_telemetry(
                    aligned, plan, self.section, self.seq, self._slow, self._mocap, self._clock()
                )
            except Skip as exc:
                self._count(exc.kind)
                self._once(exc.kind, "no telemetry for this period: %s", exc)
                continue
            self.bus.publish(
                self.keys["telemetry"], tel.model_dump_json(exclude_none=True).encode()
            )
            if self._unanswered_s is None or self._unanswered_s <= self._heard_s:
                self._unanswered_s = self._clock()
            self.seq += 1
            self._last_stamp_s = tel.stamp_s
            self._last_yaw_deg = yaw_deg_from_quat(tel.quat_wxyz)
            if tel.position_m is not None and tel.position_source in ONBOARD_SOURCES:
                self._onboard = (tel.position_m, self._clock())
            motors_off = all(aligned.values.get(m, 1.0) == 0.0 for m in plan.motors)
            if self._estimator_pending and not self._commanding and motors_off:
                self._reset_estimator()
        if aligner.out_of_order > before:
            self._once("out_of_order", "log packet with an old timestamp dropped (%s)", block)

    def _reset_estimator(self) -> None:
        """Bitcraze's mocap example, on the floor: the Kalman estimator selected and
        ``locSrv.extQuatStdDev`` set (with ``send_extpos``), ``kalman.initialX/Y/Z`` (with
        ``estimator_initial_m``), then ``kalman.resetEstimation`` 1 and, 0.1 s later, 0; take-off
        waits for the variances to settle (:class:`~.bridge.SettleWatch`)."""
        self._estimator_pending = False
        section = self.section
        writes: list[tuple[str, float]] = []
        if section.send_extpos:
            writes.append(("stabilizer.estimator", 2.0))  # Kalman: it fuses extpos
            writes.append(("locSrv.extQuatStdDev", section.ext_quat_std_rad))
            if section.ext_pos_std_m is not None:
                writes.append(("locSrv.extPosStdDev", section.ext_pos_std_m))
        if section.estimator_initial_m is not None:
            writes.extend(
                (f"kalman.initial{axis}", float(v))
                for axis, v in zip("XYZ", section.estimator_initial_m, strict=True)
            )
        writes.append(("kalman.resetEstimation", 1.0))
        try:
            for name, value in writes:
                self.link.set_param(name, value)
        except LinkError as exc:
            self._estimator_error = str(exc)
            _log.error("estimator not reset: %s; take-off is refused", exc)
            self._publish_status()
            return
        now = self._clock()
        self._settle.reset(now)
        self._reset_clear_s = now + RESET_HOLD_S
        self._count("estimator_resets")
        _log.info(
            "estimator reset (%s); take-off once kalman.varPX/PY/PZ stay within %g over %g s",
            ", ".join(f"{n} = {v:g}" for n, v in writes),
            section.estimator_settle_spread,
            section.estimator_settle_s,
        )
        self._publish_status()

    def _estimator_tick(self, now_s: float) -> None:
        """Clear ``kalman.resetEstimation`` once due; report the estimator settling."""
        if self._reset_clear_s is not None and now_s >= self._reset_clear_s:
            self._reset_clear_s = None
            try:
                self.link.set_param("kalman.resetEstimation", 0.0)
            except LinkError as exc:
                _log.warning("kalman.resetEstimation not cleared: %s", exc)
        reset_s = self._settle.reset_s
        if reset_s is not None and self._settle.settled(now_s) and not self._settled_told:
            self._settled_told = True
            self._count("estimator_settled")
            _log.info("estimator settled %.1f s after its reset: take-off allowed", now_s - reset_s)
            self._publish_status()

    def _forward_extpos(self, now_s: float) -> None:
        """Send the pending motion-capture pose to the drone, at most ``extpos_rate_hz``."""
        pose = self._extpos_pending
        if pose is None or now_s - self._extpos_sent_s < 1.0 / self.section.extpos_rate_hz:
            return
        self._extpos_pending = None
        if self._send("send_extpos", pose.position_m, pose.quat_wxyz):
            self._extpos_sent_s = now_s
            self._count("extpos_sent")

    def _on_lost(self, reason: str) -> None:
        self.connected = False
        self.gate.on_link_lost()
        self._commanding = False
        self._once(
            "lost", "link to %s lost (%s): telemetry stops; reconnecting", self.link.uri, reason
        )
        self._count("link_lost")
        self.link.close()
        self._publish_status()

    def _send_setpoint(self, now_s: float) -> None:
        # Silent: Telemetry went out and nothing came back since. Nothing published (a stalled
        # thread, a silent link: _check_link) is no silence of the ground station's.
        unanswered = self._unanswered_s
        heard = self._heard_s
        self.gate.heard_s = now_s if unanswered is None or heard >= unanswered else unanswered
        cmd = self.gate.tick(now_s)
        self._report_phase(now_s, cmd)
        if cmd is None:
            return
        if cmd.motors_off:
            self._send("send_stop_setpoint")
            self._commanding = False
            self._motors_off = True
            self._count("landings")
            _log.warning(
                "landed (%s): motors off on the floor (no latch)", self.gate.landing_reason
            )
            self._publish_status()
            return
        x, y, z = cmd.position_m
        if not self._send("send_position_setpoint", x, y, z, cmd.yaw_deg):
            return
        self._commanding = True
        self._motors_off = False
        self._count("setpoints_sent")

    def _report_phase(self, now_s: float, cmd: SetpointCommand | None) -> None:
        """Log and publish each change of what the gate does (hold, landing, ...)."""
        phase = self.gate.phase(now_s)
        if phase == self._phase:
            return
        before, self._phase = self._phase, phase
        where = [round(v, 3) for v in cmd.position_m] if cmd is not None else None
        if phase == "holding":
            self._count("holds")
            _log.warning(
                "ground station silent for %.2f s: holding %s (landing after %.2f s more)",
                self.gate.silent_s(now_s),
                where,
                self.gate.hold_s,
            )
        elif phase == "landing":
            _log.warning(
                "landing (%s) from %s at %.2f m/s",
                self.gate.landing_reason,
                where,
                self.gate.land_speed_mps,
            )
        else:
            _log.info("bridge: %s -> %s", before, phase)
        self._publish_status()

    def _shutdown(self) -> None:
        for sub in self._subs:
            sub.close()
        self._subs.clear()
        if self.connected:
            try:
                if self._commanding:
                    self.link.send_stop_setpoint()
            finally:
                self.link.close()
                self.connected = False
        _log.info("bridge stopped: %d telemetry published, counts %s", self.seq, self.counts)

    def _send(self, method: str, *args: Any) -> bool:
        """Call a command of the link; a link that fails under it is a lost link."""
        try:
            getattr(self.link, method)(*args)
        except LinkError as exc:
            if self.connected:
                if method == "stop_motors":
                    self._pending_stop = True  # send it again once reconnected
                self._on_lost(f"{method} failed: {exc}")
            return False
        return True

    # ------------------------------------------------------------------ reporting

    def status(self) -> dict[str, Any]:
        """What ``tether/{drone}/bridge`` carries."""
        aligner, plan = self._aligner, self._plan
        return {
            "uri": self.link.uri,
            "connected": self.connected,
            "latched": self.gate.latched,
            "stop_reason": self.gate.stop_reason,
            "holding": self.gate.holding(self._clock()),
            "phase": self.gate.phase(self._clock()),
            "landing_reason": self.gate.landing_reason,
            "motors_off": self._motors_off,
            "link_silent": self._link_silent,
            "silent_s": round(min(self.gate.silent_s(self._clock()), 1e6), 3),
            "telemetry": self.seq,
            "counts": dict(self.counts),
            "dropped_setpoints": dict(self.gate.dropped),
            "out_of_order": aligner.out_of_order if aligner else 0,
            "unmatched": aligner.unmatched if aligner else 0,
            "not_logged": {v: NOT_LOGGED_CONSEQUENCE[v] for v in plan.not_logged} if plan else {},
            "estimator": self._estimator_status(),
        }

    def _estimator_status(self) -> dict[str, Any]:
        """Whether take-off waits for the estimator, and where it stands."""
        plan, now = self._plan, self._clock()
        if plan is None or not plan.settle:
            return {"required": False}
        spreads = self._settle.spreads()
        onboard = self._onboard
        return {
            "required": True,
            "reset": self._settle.reset_s is not None,
            "settled": self._settle.settled(now),
            "spread": [round(x, 6) for x in spreads] if spreads is not None else None,
            "error": self._estimator_error,
            "onboard_position_m": [round(v, 4) for v in onboard[0]] if onboard else None,
        }

    def _publish_status(self) -> None:
        self.bus.publish(self.keys["status"], json.dumps(self.status()).encode())

    def _count(self, kind: str) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1

    def _once(self, kind: str, msg: str, *args: Any) -> None:
        if kind not in self._logged:
            self._logged.add(kind)
            _log.warning(msg, *args)


def run_bridges(bridges: list[CrazyflieBridge], stop: threading.Event) -> int:
    """Run several bridges (one per link; cflib shares one Crazyradio between the links of a
    process) until ``stop``, each on its own thread.

    A bridge that ends on its own (a configuration error: exit code 2) leaves the others
    flying: stopping them would stop their drones' motors.

    Returns:
        The largest exit code of the bridges.
    """
    codes: dict[str, int] = {}

    def run_one(bridge: CrazyflieBridge) -> None:
        try:
            codes[bridge.drone] = bridge.run(stop)
        except Exception:
            _log.exception("bridge for %s failed", bridge.drone)
            codes[bridge.drone] = 1
        if codes[bridge.drone] and not stop.is_set():
            _log.error(
                "bridge for %s (%s) ended with code %d; the other links keep running",
                bridge.drone,
                bridge.link.uri,
                codes[bridge.drone],
            )

    threads = [
        threading.Thread(target=run_one, args=(b,), name=f"bridge-{b.drone}", daemon=True)
        for b in bridges
    ]
    for t in threads:
        t.start()
    for t in threads:
        while t.is_alive():
            t.join(0.5)
    return max(codes.values(), default=0)
