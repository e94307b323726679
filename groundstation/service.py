"""The ground-station service: config + bus + :class:`~groundstation.pipeline.Pipeline`.

Bus callbacks only validate and hand over through a bounded queue (an overflow is counted
as the drop kind ``queue_overflow``); estimation runs on the service's own worker thread.
Health per drone is answered by the queryable ``tether/{drone}/status``; the service holds
the liveliness token ``groundstation/service/{instance}``.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

from groundstation.bus import Bus, Sample, Subscription, keyexpr_matches
from groundstation.config import Settings
from groundstation.pipeline import Parsed, Pipeline

__all__ = ["Service"]

_log = logging.getLogger("groundstation.service")
_INPUT_KINDS = ("telemetry", "reel", "follow", "params")


class Service:
    """Estimate per drone from telemetry on the bus; publish estimates and commands.

    Args:
        settings: the root configuration.
        bus: the bus to serve on (the service does not close it).
        clock: monotonic seconds (a parameter so tests can drive time).
    """

    def __init__(
        self,
        settings: Settings,
        bus: Bus,
        *,
        clock: Callable[[], float] = time.monotonic,
        instance: str | None = None,
    ) -> None:
        self.settings = settings
        self.bus = bus
        self.clock = clock
        self.instance = instance or uuid.uuid4().hex[:12]
        self.pipeline = Pipeline(settings, on_drop=self._on_drop)
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
        """Subscribe, declare the status queryable and the liveliness token, start the worker."""
        if self._worker is not None:
            return
        drones = self.settings.service.drones_keyexpr_chunk
        if self.settings.service.record:
            from groundstation.recording import Recorder

            self._recorder = Recorder(self.bus, self.settings.service.record)
        self._worker = threading.Thread(target=self._run, name="groundstation-worker", daemon=True)
        self._worker.start()
        for kind in _INPUT_KINDS:
            self._handles.append(self.bus.subscribe(f"tether/{drones}/{kind}", self._on_sample))
        self._handles.append(self.bus.queryable(f"tether/{drones}/status", self._on_status))
        self._handles.append(self.bus.liveliness_token(f"groundstation/service/{self.instance}"))
        _log.info(
            "serving drones tether/%s/* (instance %s, stale after %.2f s)",
            drones,
            self.instance,
            self.settings.service.stale_after_s,
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

    # ------------------------------------------------------------------ worker

    def _run(self) -> None:
        # Batches: the worker wakes once for whatever arrived meanwhile (a tick of 8 drones,
        # or a backlog after a pause upstream), steps it drone by drone under one lock
        # acquisition and then publishes it. Per message that saves a thread wake-up, a lock
        # round and, above all, a GIL hand-over to zenoh's callback thread between
        # estimating and publishing (docs/service_benchmark.md has the numbers).
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
                with self._lock:
                    outputs = self.pipeline.tick(now_s)
                self._publish(outputs)
                next_tick = now_s + tick_period_s
            if self._stop.is_set() and self._queue.empty():
                return

    def _step_batch(self, batch: list[Parsed]) -> None:
        outputs: list[Sample] = []
        with self._lock:
            for parsed in group_by_drone(batch):
                try:
                    outputs += self.pipeline.process(parsed, parsed.received_s)
                except Exception:  # the service must outlive any single bad step
                    _log.exception("processing a %s from %s failed", parsed.kind, parsed.drone)
                    self.pipeline.count_drop(parsed.drone, "internal_error", "see log")
        self._publish(outputs)

    def _step(self, parsed: Parsed) -> None:
        """One message, as :meth:`_step_batch` does it (the plain per-message path)."""
        self._step_batch([parsed])

    def _publish(self, outputs: list[Sample]) -> None:
        publish = self.bus.publish
        for out in outputs:
            publish(out.key, out.payload)
        self.published += len(outputs)


_MAX_BATCH = 16
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
