"""The recorder: every sample of a bus into an MCAP file (layout: ``format.py``).

Threading: bus callbacks only stamp the sample and put it on a queue; one writer thread owns
the :class:`mcap.writer.Writer` and the file (STYLE.md: nothing heavy on zenoh's threads).
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from groundstation.bus import Bus, Sample, Subscription, keyexpr_matches
from groundstation.recording.format import (
    DEFAULT_KEYEXPRS,
    ChannelTable,
    RecordingError,
    open_writer,
)

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class RecorderStats:
    """What a :class:`Recorder` wrote."""

    path: str
    messages: int
    """Samples written to the file."""
    payload_bytes: int
    channels: int
    dropped: int
    """Samples dropped because the queue exceeded ``max_queue`` (0 unless the disk stalls)."""
    max_queue_depth: int
    """Largest backlog seen between the bus callbacks and the writer thread, in samples."""
    duration_s: float
    chunks_flushed: int
    """Chunks closed by the periodic flush (the others closed on reaching ``chunk_size``)."""


_STOP = object()


class Recorder:
    """Records every sample of a :class:`~groundstation.bus.Bus` into an MCAP file.

    Args:
        bus: the bus to record (its callbacks only enqueue).
        path: the output ``.mcap`` file, created at once so that it grows as samples arrive
            (an existing file is refused unless ``force``).
        keyexprs: key expressions to record; a sample matching several is written once.
        chunk_size: bytes after which a chunk is closed (before compression).
        flush_interval_s: a chunk holding messages is closed and flushed to the OS at least
            this often, bounding what a killed recorder loses.
        max_queue: backlog, in samples, beyond which new samples are dropped and counted
            (a memory bound for a stalled disk; never reached at the rates measured in
            ``docs/recorder_benchmark.md``).
        force: replace an existing ``path``: the recording goes to a temporary file beside
            it, moved into place when the recorder closes (the old file stays until then).

    Raises:
        RecordingError: the file cannot be created, or exists and ``force`` is false.
    """

    def __init__(
        self,
        bus: Bus,
        path: str | Path,
        keyexprs: Sequence[str] = DEFAULT_KEYEXPRS,
        *,
        chunk_size: int = 256 * 1024,
        flush_interval_s: float = 1.0,
        max_queue: int = 1_000_000,
        force: bool = False,
    ) -> None:
        if not keyexprs:
            raise ValueError("Recorder needs at least one key expression, got none")
        if flush_interval_s <= 0:
            raise ValueError(f"flush_interval_s must be > 0, got {flush_interval_s!r}")
        self.path = Path(path)
        self.keyexprs = tuple(keyexprs)
        self._flush_interval_s = flush_interval_s
        self._max_queue = max_queue
        self._file, self._writer = open_writer(
            self.path, chunk_size, force=force, grow_in_place=True
        )
        self._channels = ChannelTable(self._writer)
        self._writer.add_metadata(
            "groundstation.recording",
            {"keyexprs": json.dumps(self.keyexprs), "started_unix_ns": str(time.time_ns())},
        )
        self._writer.flush()  # a valid, empty recording is on disk from the start
        # Receive clock: monotonic, anchored once to the wall clock (ns since the epoch).
        self._t0_wall_ns = time.time_ns()
        self._t0_mono_ns = time.monotonic_ns()
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._enqueue_lock = threading.Lock()
        self._queued = 0
        self._processed = 0
        self._written = 0
        self._payload_bytes = 0
        self._dropped = 0
        self._max_depth = 0
        self._chunks_flushed = 0
        self._error: BaseException | None = None
        self._closed = False
        self._stats: RecorderStats | None = None
        self._started_s = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)
        self._thread.start()
        self._subs: list[Subscription] = []
        try:
            for index, keyexpr in enumerate(self.keyexprs):
                self._subs.append(bus.subscribe(keyexpr, self._handler(index)))
        except Exception:
            self.close()
            raise

    def _now_ns(self) -> int:
        return self._t0_wall_ns + (time.monotonic_ns() - self._t0_mono_ns)

    def _handler(self, index: int) -> Callable[[Sample], None]:
        earlier = self.keyexprs[:index]

        def on_sample(sample: Sample) -> None:
            # A key matched by an earlier key expression is that subscriber's to record.
            if earlier and any(keyexpr_matches(k, sample.key) for k in earlier):
                return
            # Stamp and enqueue under one lock: queue order is then time order even when
            # zenoh calls back from several threads.
            with self._enqueue_lock:
                if self._queued - self._processed >= self._max_queue:
                    self._dropped += 1
                    return
                self._queued += 1
                self._queue.put((sample, self._now_ns()))

        return on_sample

    @property
    def messages_written(self) -> int:
        """Samples written so far (approximate while recording)."""
        return self._written

    @property
    def samples_received(self) -> int:
        """Samples the bus has delivered so far (queued or dropped)."""
        return self._queued + self._dropped

    def _run(self) -> None:
        last_flush = time.monotonic()
        dirty = False
        while True:
            timeout = max(0.0, self._flush_interval_s - (time.monotonic() - last_flush))
            try:
                item = self._queue.get(timeout=timeout)
            except queue.Empty:
                item = None
            if item is _STOP:
                return
            if item is not None and self._error is None:
                sample, log_time_ns = item
                try:
                    self._writer.add_message(
                        channel_id=self._channels.channel_id(sample.key),
                        log_time=log_time_ns,
                        data=sample.payload,
                        publish_time=log_time_ns,
                    )
                except Exception as exc:  # disk full, I/O error: keep draining, report at close
                    self._error = exc
                    _log.error("recording to %s failed: %s", self.path, exc)
                else:
                    dirty = True
                    self._written += 1
                    self._payload_bytes += len(sample.payload)
                    depth = self._queued - self._processed
                    if depth > self._max_depth:
                        self._max_depth = depth
            if item is not None:
                self._processed += 1
            now = time.monotonic()
            if now - last_flush >= self._flush_interval_s:
                last_flush = now
                if dirty and self._error is None:
                    try:
                        self._writer.flush()
                    except Exception as exc:
                        self._error = exc
                        _log.error("recording to %s failed: %s", self.path, exc)
                    else:
                        self._chunks_flushed += 1
                        dirty = False

    def close(self) -> RecorderStats:
        """Unsubscribe, write every queued sample, finish the file (summary and footer).

        Idempotent: later calls return the same stats.

        Raises:
            RecordingError: writing the file failed (disk full, I/O error).
        """
        if self._stats is not None:
            return self._stats
        if not self._closed:
            self._closed = True
            for sub in self._subs:
                sub.close()
            self._subs.clear()
            # Samples a callback stamped before the unsubscribe returned are already queued
            # ahead of the sentinel; take the lock so none is mid-put.
            with self._enqueue_lock:
                self._queue.put(_STOP)
            self._thread.join()
            try:
                if self._error is None:
                    self._writer.finish()
            except Exception as exc:
                self._error = exc
            finally:
                # Even after a failure the file holds what was recorded up to it (readable,
                # and recoverable with ``recover``): keep it.
                try:
                    self._file.commit()
                except Exception as exc:
                    self._error = self._error or exc
        if self._error is not None:
            raise RecordingError(f"recording {str(self.path)!r} failed: {self._error}")
        self._stats = RecorderStats(
            path=str(self.path),
            messages=self._written,
            payload_bytes=self._payload_bytes,
            channels=len(self._channels),
            dropped=self._dropped,
            max_queue_depth=self._max_depth,
            duration_s=time.monotonic() - self._started_s,
            chunks_flushed=self._chunks_flushed,
        )
        return self._stats

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
