"""The ground-station service: config + bus + :class:`~groundstation.pipeline.Pipeline`.

Bus callbacks only validate and hand over through a bounded queue (an overflow is counted
as the drop kind ``queue_overflow``); estimation runs on the service's own worker thread.
Health per drone is answered by the queryable ``tether/{drone}/status``; the service holds
the liveliness token ``groundstation/service/{instance}``.

One owner per drone: a service also holds ``groundstation/owner/{instance}/{drones}``
(``[service] drones`` as a key chunk, ``*`` for all), and refuses to start
(:class:`OwnershipConflict`) while another service on the bus holds a pattern that matches
a drone id of its own: two services estimating one drone would both command it (two
setpoint streams, two tug-to-land decisions).

The operator action log: every command the service refuses or applies (follow on/off,
thresholds, tether parameters), follow switched off by a silent drone, and every Stop (its
own and anyone's on ``tether/{drone}/cmd/stop``) is one line in the log and one
:class:`~groundstation.messages.Event` on ``tether/{drone}/events``, which the recorder
records with the rest of ``tether/**``. Events are capped per drone
(``EVENTS_PER_S``) so a flood of bad commands cannot flood the bus; a Stop and follow
switched on or off are never capped (:func:`never_capped`), so a flood cannot hide them from
the log or the recording.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from typing import Any

from groundstation.bus import (
    Bus,
    PeerWatch,
    Sample,
    Subscription,
    describe_endpoints,
    keyexpr_matches,
    patterns_overlap,
)
from groundstation.config import Settings
from groundstation.messages import Event, InvalidMessage, StopIn
from groundstation.pipeline import FOLLOW_OFF, FOLLOW_ON, Parsed, Pipeline

__all__ = ["EVENTS_PER_S", "OWNER_TOKENS", "OwnershipConflict", "Service", "never_capped"]

_log = logging.getLogger("groundstation.service")
_actions = logging.getLogger("groundstation.actions")
_INPUT_KINDS = ("telemetry", "reel", "follow", "params")
OWNER_TOKENS = "groundstation/owner/*/*"
"""Liveliness tokens ``groundstation/owner/{instance}/{drones}``: which service owns which
drone ids (``{drones}`` a key chunk such as ``lab-a-$*``, or ``*``)."""
OWNER_QUERY_S = 1.0
"""How long :meth:`Service.start` waits for the other services' owner tokens, s."""


class OwnershipConflict(RuntimeError):
    """Another service on the bus already owns drone ids that this one would own."""


EVENTS_PER_S = 20.0
"""Events published per drone and second at most (a burst of twice that is allowed); the
rest are counted in ``status`` as ``events_suppressed``."""


class Service:
    """Estimate per drone from telemetry on the bus; publish estimates and commands.

    Args:
        settings: the root configuration.
        bus: the bus to serve on (the service does not close it).
        clock: monotonic seconds (a parameter so tests can drive time).
        instance: the instance id (default: random).
        alone_ok: no peer is normal (``demo``: simulator, service and dashboard share one
            session): "no peer / no router" is only a debug line, and ``status`` says
            ``alone_ok: true`` so that ``peers: 0`` raises no alarm.
        replace_recording: ``[service] record`` may replace an existing file (``serve
            --record FILE --force``); otherwise an existing file is refused at start.
    """

    def __init__(
        self,
        settings: Settings,
        bus: Bus,
        *,
        clock: Callable[[], float] = time.monotonic,
        instance: str | None = None,
        alone_ok: bool = False,
        replace_recording: bool = False,
    ) -> None:
        self.settings = settings
        self._replace_recording = replace_recording
        self.bus = bus
        self.clock = clock
        self.instance = instance or uuid.uuid4().hex[:12]
        self.alone_ok = alone_ok
        self.pipeline = Pipeline(
            settings, on_drop=self._on_drop, on_event=self._on_event, wall_clock=time.time
        )
        zid = getattr(bus, "zid", None)
        self.pipeline.self_id = zid if isinstance(zid, str) else f"service {self.instance}"
        self._event_lock = threading.Lock()
        self._event_budget: dict[str, tuple[float, float]] = {}  # drone: (tokens, at_s)
        self.events_suppressed: dict[str, int] = {}
        self.events = 0
        self._own_stops: deque[bytes] = deque(maxlen=64)
        count = getattr(bus, "peer_count", None)
        z = settings.zenoh
        self.peer_watch = (
            PeerWatch(
                count,
                describe_endpoints(z.mode, z.connect, z.listen),
                "groundstation serve",
                _log,
                alone_ok=alone_ok,
            )
            if callable(count)
            else None
        )
        # SimpleQueue: a C queue, no lock or condition per message in Python; the bound is
        # kept by the (only) producers, the bus callbacks, through qsize().
        self._queue: queue.SimpleQueue[Parsed] = queue.SimpleQueue()
        self._queue_size = settings.service.queue_size
        self._lock = threading.Lock()  # pipeline state: worker vs status queries
        self._stop = threading.Event()
        self._worker: threading.Thread | None = None
        self._handles: list[Subscription] = []
        self._logged_kinds: set[str] = set()
        self._recorder: Any = None
        self.published = 0

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Subscribe, declare the status queryable and the liveliness tokens, start the worker.

        Raises:
            OwnershipConflict: another service on the bus owns drone ids this one would
                (``[service] drones`` patterns that overlap); nothing was started.
        """
        if self._worker is not None:
            return
        drones = self.settings.service.drones_keyexpr_chunk
        self._check_ownership(drones)
        if self.settings.service.record:
            from groundstation.recording import Recorder

            self._recorder = Recorder(
                self.bus, self.settings.service.record, force=self._replace_recording
            )
        self._worker = threading.Thread(target=self._run, name="groundstation-worker", daemon=True)
        self._worker.start()
        for kind in _INPUT_KINDS:
            self._handles.append(self.bus.subscribe(f"tether/{drones}/{kind}", self._on_sample))
        self._handles.append(self.bus.subscribe(f"tether/{drones}/cmd/stop", self._on_stop))
        self._handles.append(self.bus.subscribe(f"tether/{drones}/cmd/rearm", self._on_rearm))
        self._handles.append(self.bus.queryable(f"tether/{drones}/status", self._on_status))
        self._handles.append(self.bus.liveliness_token(f"groundstation/service/{self.instance}"))
        self._handles.append(
            self.bus.liveliness_token(f"groundstation/owner/{self.instance}/{drones}")
        )
        _log.info(
            "serving drones tether/%s/* (instance %s, stale after %.2f s)",
            drones,
            self.instance,
            self.settings.service.stale_after_s,
        )

    def _check_ownership(self, drones: str) -> None:
        """Refuse to start while another service owns any drone id ``drones`` matches.

        Reads the other services' owner tokens once (a service started at the same instant
        may not be seen yet; the later of two overlapping starts refuses)."""
        others = []
        for key in self.bus.alive(OWNER_TOKENS, timeout_s=OWNER_QUERY_S):
            parts = key.split("/")
            if len(parts) != 4 or parts[2] == self.instance:
                continue
            if patterns_overlap(parts[3], drones):
                others.append(f"instance {parts[2]} owns 'tether/{parts[3]}'")
        if others:
            raise OwnershipConflict(
                f"drones 'tether/{drones}' overlap another service on this bus: "
                + "; ".join(others)
                + ". Two services would both estimate and command those drones: give each "
                "service its own slice with --drones / [service] drones (e.g. 'lab-a-*', "
                "'lab-b-*'), or stop the other one."
            )

    def close(self) -> None:
        """Stop receiving, finish the queued work, stop the worker. Idempotent."""
        handles, self._handles = self._handles, []
        for handle in handles:
            handle.close()
        self._stop.set()
        if self._worker is not None:
            self._worker.join(timeout=2.0)
        if self._recorder is not None:
            recorder, self._recorder = self._recorder, None
            recorder.close()

    def __enter__(self) -> Service:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ bus side

    def _on_sample(self, sample: Sample) -> None:
        # Runs on a bus thread: validate and hand over, nothing else.
        now_s = self.clock()
        parsed = self.pipeline.validate(sample, now_s)
        if parsed is None:
            return
        if self._queue.qsize() >= self._queue_size:
            self.pipeline.count_drop(parsed.drone, "queue_overflow", "processing queue full")
            return
        self._queue.put(parsed)

    def _on_status(self, selector: str) -> list[Sample]:
        now_s = self.clock()
        replies = []
        with self._lock:
            for drone in self.pipeline.drone_ids():
                key = f"tether/{drone}/status"
                if not keyexpr_matches(selector, key):
                    continue
                status = self.pipeline.status(drone, now_s)
                if status is not None:
                    status["service"] = self.instance
                    status["peers"] = None if self.peer_watch is None else self.peer_watch.peers
                    status["alone_ok"] = self.alone_ok
                    status["events_suppressed"] = self.events_suppressed.get(drone, 0)
                    replies.append(Sample(key, json.dumps(status).encode()))
        return replies

    def _on_drop(self, drone: str | None, kind: str, detail: str) -> None:
        if kind in self._logged_kinds:
            return
        self._logged_kinds.add(kind)
        _log.warning(
            "dropped input (%s) from %s: %s (further drops of this kind are only counted)",
            kind,
            drone or "?",
            detail,
        )

    def _on_stop(self, sample: Sample) -> None:
        # Anyone's Stop (ours were logged when issued): the worker switches follow off for
        # that drone and logs it. A Stop nobody can read stops no drone either: only told.
        with self._event_lock:
            if sample.payload in self._own_stops:
                return
        drone = sample.key.split("/")[1]
        try:
            stop = StopIn.parse(sample.payload)
        except InvalidMessage as exc:
            reason = f"a Stop nobody can read ({exc.detail}): the drone ignores it too"
            self._tell(drone, "stop", "cmd/stop", sample.source, reason)
            return
        parsed = Parsed(drone, "cmd/stop", stop, self.clock(), sample.source)
        if self._queue.qsize() >= self._queue_size:
            self.pipeline.count_drop(drone, "queue_overflow", "processing queue full")
            return
        self._queue.put(parsed)

    def _on_rearm(self, sample: Sample) -> None:
        # ``cmd/rearm`` (the Crazyflie bridge's, added) lifts a drone's stop latch: logged.
        drone = sample.key.split("/")[1]
        self._tell(drone, "rearm", "cmd/rearm", sample.source, "re-arm requested")

    def _tell(self, drone: str, kind: str, input_kind: str, who: str | None, reason: str) -> None:
        event = Event(
            stamp_s=time.time(),
            kind=kind,
            input=input_kind,
            who=who or "unknown",
            reason=reason[:500],
        )
        self._on_event(drone, event)

    def _on_event(self, drone: str, event: Event) -> None:
        """Log one action line and publish the Event (any thread; capped per drone, but
        never a Stop or follow switched on/off: :func:`never_capped`)."""
        now_s = self.clock()
        keep = never_capped(event)
        with self._event_lock:
            tokens, at_s = self._event_budget.get(drone, (2 * EVENTS_PER_S, now_s))
            tokens = min(2 * EVENTS_PER_S, tokens + (now_s - at_s) * EVENTS_PER_S)
            if tokens < 1.0 and not keep:
                self._event_budget[drone] = (tokens, now_s)
                self.events_suppressed[drone] = self.events_suppressed.get(drone, 0) + 1
                return
            if drone in self._event_budget or len(self._event_budget) < 1024:
                # A kept event still spends the budget (not below zero), so what it lets
                # through is one event per Stop or switch, never more.
                self._event_budget[drone] = (max(0.0, tokens - 1.0), now_s)
            elif not keep:
                return  # bounded memory against a flood of drone ids
            self.events += 1
        level = logging.INFO if event.kind in ("follow", "params") else logging.WARNING
        _actions.log(
            level,
            "%s %s on %s from %s: %s%s%s",
            drone,
            event.kind,
            event.input,
            event.who,
            event.reason,
            f" [field {event.field}]" if event.field else "",
            f" {event.changes}" if event.changes else "",
        )
        self.bus.publish(f"tether/{drone}/events", event.to_json())

    # ------------------------------------------------------------------ worker

    def _run(self) -> None:
        # Batches: the worker wakes once for whatever arrived meanwhile (a tick of 8 drones,
        # or a backlog after a pause upstream), steps it drone by drone under one lock
        # acquisition and then publishes it. Per message that saves a thread wake-up, a lock
        # round and, above all, a GIL hand-over to zenoh's callback thread between
        # estimating and publishing (docs/service_profile.md has the numbers).
        tick_period_s = min(0.05, self.settings.service.stale_after_s / 5.0)
        next_tick = self.clock()
        get = self._queue.get
        get_nowait = self._queue.get_nowait
        while True:
            batch: list[Parsed] = []
            try:
                batch.append(get(timeout=tick_period_s))
                while len(batch) < _MAX_BATCH:
                    batch.append(get_nowait())
            except queue.Empty:
                pass
            if batch:
                self._step_batch(batch)
            now_s = self.clock()
            if now_s >= next_tick:
                if self.peer_watch is not None:
                    self.peer_watch.poll(now_s)
                with self._lock:
                    outputs = self.pipeline.tick(now_s)
                self._publish(outputs)
                next_tick = now_s + tick_period_s
            if self._stop.is_set() and self._queue.empty():
                return

    def _step_batch(self, batch: list[Parsed]) -> None:
        with self._lock:
            outputs = self.pipeline.process_batch(group_by_drone(batch), self._on_error)
        self._publish(outputs)

    def _on_error(self, parsed: Parsed) -> None:
        # Called inside the except of one input's processing: the service must outlive any
        # single bad step.
        _log.exception("processing a %s from %s failed", parsed.kind, parsed.drone)
        self.pipeline.count_drop(parsed.drone, "internal_error", "see log")

    def _step(self, parsed: Parsed) -> None:
        """One message, as :meth:`_step_batch` does it (the plain per-message path)."""
        self._step_batch([parsed])

    def _publish(self, outputs: list[Sample]) -> None:
        publish = self.bus.publish
        for out in outputs:
            if out.key.endswith("/cmd/stop"):
                with self._event_lock:
                    self._own_stops.append(out.payload)
            publish(out.key, out.payload)
        self.published += len(outputs)


def never_capped(event: Event) -> bool:
    """Whether ``event`` is logged and published whatever the per-drone cap says: a Stop
    (anyone's, or the service's own), and follow switched on or off (by a command, or off by
    a silent drone). An operator's Stop must be in the action log even while someone floods
    the drone with bad commands; each of these is one event per input, so keeping them
    cannot multiply a flood."""
    if event.kind == "stop":
        return True
    return event.kind == "follow" and (
        event.input == "service" or event.reason in (FOLLOW_ON, FOLLOW_OFF)
    )


_MAX_BATCH = 32
"""Messages stepped before their outputs are published (bounds the first one's wait)."""


def group_by_drone(batch: list[Parsed]) -> list[Parsed]:
    """The batch drone by drone, each drone's messages in their order of arrival.

    Drones share no state in the pipeline, so this changes no output, only the order in
    which different drones' outputs leave (each drone's state stays hot in the cache).
    """
    if len(batch) < 2:
        return batch
    order: dict[str, list[Parsed]] = {}
    for parsed in batch:
        group = order.get(parsed.drone)
        if group is None:
            order[parsed.drone] = [parsed]
        else:
            group.append(parsed)
    if len(order) == 1:
        return batch
    return [parsed for group in order.values() for parsed in group]
