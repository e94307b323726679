"""Record the bus to MCAP, play a recording back, and re-run estimation on one offline.

File layout (see ``docs/recording.md``):

- one MCAP channel per concrete key (``tether/cf1/telemetry``), ``message_encoding`` ``json``;
- a ``jsonschema`` schema per channel, generated from the contract's pydantic models by the
  key's last part (``telemetry`` → :class:`~groundstation.messages.Telemetry`, …), or
  ``{"type": "object"}`` for any other key, so the file opens in Foxglove;
- message ``data`` is the payload exactly as received (not re-encoded);
- ``log_time`` = ``publish_time`` = the receive time in ns since the Unix epoch, taken from a
  monotonic clock anchored once to the wall clock, so times never go backwards in a file and
  file order, receive order and log-time order are the same;
- chunked (zstd), a chunk closed when it reaches ``chunk_size`` bytes or at the latest every
  ``flush_interval_s``; a killed recorder therefore leaves a file readable up to its last
  closed chunk: :func:`iter_messages` reads such a file, :func:`recover` rewrites it whole.

Threading: bus callbacks only stamp the sample and put it on a queue; one writer thread owns
the :class:`mcap.writer.Writer` and the file (STYLE.md: nothing heavy on zenoh's threads).
"""

from __future__ import annotations

import contextlib
import json
import logging
import queue
import re
import struct
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, NamedTuple, Protocol, cast

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from pydantic import BaseModel

from groundstation import messages
from groundstation.bus import Bus, Sample, Subscription, keyexpr_matches
from groundstation.config import Settings

__all__ = [
    "DEFAULT_KEYEXPRS",
    "RecordedMessage",
    "Recorder",
    "RecorderStats",
    "RecordingError",
    "ReplayStats",
    "is_complete",
    "iter_messages",
    "recover",
    "replay",
    "replay_offline",
    "run_record",
    "run_replay",
    "run_replay_offline",
    "schema_for_key",
    "write_figures",
]

_log = logging.getLogger(__name__)

DEFAULT_KEYEXPRS = ("tether/**",)
_MAGIC = b"\x89MCAP0\r\n"
_LIBRARY = "groundstation-recorder"
_ORIGINAL_PREFIX = "replay/original/"
"""Offline replay writes the recording's own estimates and commands under this prefix."""
_INPUT_KEY_RE = re.compile(r"tether/[^/]+/(telemetry|reel|follow|params)")
_OUTPUT_KEY_RE = re.compile(r"tether/[^/]+/(estimate|cmd/setpoint|cmd/stop)")


class RecordingError(RuntimeError):
    """A recording cannot be written or read; the message names the file and the cause."""


# --------------------------------------------------------------------------- schemas


def _schema_models() -> dict[str, type[BaseModel]]:
    models: dict[str, type[BaseModel]] = {
        "telemetry": messages.Telemetry,
        "reel": messages.Reel,
        "estimate": messages.Estimate,
        "follow": messages.FollowCommand,
        "setpoint": messages.Setpoint,
        "stop": messages.Stop,
        "truth": messages.Truth,
    }
    # ``params`` (operator tether parameters) joined the messages after this module; look it
    # up by name so the recorder does not depend on when it lands.
    params = getattr(messages, "TetherParams", None)
    if isinstance(params, type) and issubclass(params, BaseModel):
        models["params"] = params
    events = getattr(messages, "Event", None)  # the operator action log, likewise
    if isinstance(events, type) and issubclass(events, BaseModel):
        models["events"] = events
    return models


_GENERIC_SCHEMA = ("json", b'{"type": "object"}')


def schema_for_key(key: str) -> tuple[str, bytes]:
    """The MCAP schema ``(name, jsonschema bytes)`` for the channel of a concrete ``key``.

    Chosen by the key's last part (``tether/cf1/cmd/setpoint`` → Setpoint); any other key gets
    ``("json", {"type": "object"})``.
    """
    if not key.startswith("tether/"):
        return _GENERIC_SCHEMA
    model = _schema_models().get(key.rsplit("/", 1)[-1])
    if model is None:
        return _GENERIC_SCHEMA
    # Inbound payloads are described as they are validated, outbound ones as serialised.
    if issubclass(model, messages._In):
        schema = model.model_json_schema(mode="validation")
    else:
        schema = model.model_json_schema(mode="serialization")
    return f"groundstation.{model.__name__}", json.dumps(schema, sort_keys=True).encode()


class _ChannelTable:
    """Registers one schema per model and one channel per key on a Writer (one thread)."""

    def __init__(self, writer: Writer) -> None:
        self._writer = writer
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self._channels)

    def channel_id(self, key: str) -> int:
        cid = self._channels.get(key)
        if cid is None:
            name, data = schema_for_key(key)
            sid = self._schemas.get(name)
            if sid is None:
                sid = self._writer.register_schema(name=name, encoding="jsonschema", data=data)
                self._schemas[name] = sid
            cid = self._writer.register_channel(topic=key, message_encoding="json", schema_id=sid)
            self._channels[key] = cid
        return cid


def _open_writer(path: Path, chunk_size: int) -> tuple[IO[bytes], Writer]:
    try:
        stream = path.open("wb")
    except OSError as exc:
        raise RecordingError(f"cannot create recording {str(path)!r}: {exc.strerror}") from None
    writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType.ZSTD)
    writer.start(profile="", library=_LIBRARY)
    return stream, writer


# --------------------------------------------------------------------------- recorder


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
        path: the output ``.mcap`` file (created or truncated).
        keyexprs: key expressions to record; a sample matching several is written once.
        chunk_size: bytes after which a chunk is closed (before compression).
        flush_interval_s: a chunk holding messages is closed and flushed to the OS at least
            this often, bounding what a killed recorder loses.
        max_queue: backlog, in samples, beyond which new samples are dropped and counted
            (a memory bound for a stalled disk; never reached at the rates measured in
            ``docs/recorder_benchmark.md``).

    Raises:
        RecordingError: the file cannot be created.
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
    ) -> None:
        if not keyexprs:
            raise ValueError("Recorder needs at least one key expression, got none")
        if flush_interval_s <= 0:
            raise ValueError(f"flush_interval_s must be > 0, got {flush_interval_s!r}")
        self.path = Path(path)
        self.keyexprs = tuple(keyexprs)
        self._flush_interval_s = flush_interval_s
        self._max_queue = max_queue
        self._stream, self._writer = _open_writer(self.path, chunk_size)
        self._channels = _ChannelTable(self._writer)
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
                self._stream.close()
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


# --------------------------------------------------------------------------- reading


class RecordedMessage(NamedTuple):
    """One message of a recording."""

    key: str
    payload: bytes
    log_time_ns: int
    publish_time_ns: int


class _StrictRead:
    """A file whose short reads raise, so a record cut by a kill is detected, not parsed."""

    def __init__(self, fh: IO[bytes]) -> None:
        self._fh = fh

    def read(self, size: int = -1) -> bytes:
        data = self._fh.read(size)
        if size > 0 and len(data) < size:
            raise _Truncated(f"needed {size} bytes, file ends after {len(data)}")
        return data


class _Truncated(McapError):
    pass


def is_complete(path: str | Path) -> bool:
    """Whether the recording at ``path`` was finished (it ends with a footer and magic)."""
    try:
        with Path(path).open("rb") as fh:
            fh.seek(0, 2)
            if fh.tell() < 2 * len(_MAGIC):
                return False
            fh.seek(-len(_MAGIC), 2)
            if fh.read(len(_MAGIC)) != _MAGIC:
                return False
            fh.seek(0)
            make_reader(fh).get_summary()
    except (OSError, McapError, struct.error, ValueError):
        return False
    return True


def iter_messages(path: str | Path, *, allow_truncated: bool = True) -> Iterator[RecordedMessage]:
    """The messages of a recording in log-time order.

    A finished file is read through its index with the reference reader
    (``mcap.reader.make_reader``). A file without a footer (recorder killed) is read
    sequentially up to its last complete chunk; what follows the cut is skipped with a
    warning. Files written by :class:`Recorder` keep log times non-decreasing, so file order
    is log-time order.

    Raises:
        RecordingError: the file cannot be opened or is not MCAP, or it is truncated and
            ``allow_truncated`` is False.
    """
    path = Path(path)
    if is_complete(path):
        with path.open("rb") as fh:
            for _schema, channel, message in make_reader(fh).iter_messages(log_time_order=True):
                yield RecordedMessage(
                    channel.topic, message.data, message.log_time, message.publish_time
                )
        return
    if not allow_truncated:
        raise RecordingError(f"recording {str(path)!r} is not finished (no footer)")
    yield from _iter_truncated(path)


def _iter_truncated(path: Path) -> Iterator[RecordedMessage]:
    import zstandard  # mcap's own dependency, for its chunk decompression error

    topics: dict[int, str] = {}
    count = 0
    try:
        fh = path.open("rb")
    except OSError as exc:
        raise RecordingError(f"cannot open recording {str(path)!r}: {exc.strerror}") from None
    with fh:
        reader = StreamReader(cast(IO[bytes], _StrictRead(fh)), validate_crcs=True)
        records = reader.records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except (McapError, struct.error, ValueError, zstandard.ZstdError) as exc:
                if count == 0 and fh.tell() <= len(_MAGIC) and isinstance(exc, McapError):
                    raise RecordingError(f"{str(path)!r} is not an MCAP file: {exc}") from None
                _log.warning(
                    "%s is truncated after %d messages (%s); the rest is lost", path, count, exc
                )
                return
            if isinstance(record, Message):
                topic = topics.get(record.channel_id)
                if topic is None:
                    raise RecordingError(
                        f"{str(path)!r}: message on unknown channel {record.channel_id}"
                    )
                count += 1
                yield RecordedMessage(topic, record.data, record.log_time, record.publish_time)
            elif isinstance(record, Channel):
                topics[record.id] = record.topic


def recover(src: str | Path, dst: str | Path) -> int:
    """Rewrite the readable part of a (possibly truncated) recording as a finished file.

    Returns:
        The number of messages written to ``dst``.

    Raises:
        RecordingError: ``src`` is unreadable or ``dst`` cannot be created.
    """
    return _copy_messages(iter_messages(src), Path(dst))


def _copy_messages(msgs: Iterable[RecordedMessage], dst: Path) -> int:
    stream, writer = _open_writer(dst, 1024 * 1024)
    channels = _ChannelTable(writer)
    count = 0
    try:
        for m in msgs:
            writer.add_message(
                channels.channel_id(m.key), m.log_time_ns, m.payload, m.publish_time_ns
            )
            count += 1
        writer.finish()
    finally:
        stream.close()
    return count


# --------------------------------------------------------------------------- replay


@dataclass(frozen=True, slots=True)
class ReplayStats:
    """What a replay published."""

    messages: int
    duration_s: float
    """Wall-clock time the replay took."""
    span_s: float
    """Log-time span of the published messages."""
    max_lag_s: float
    """Largest delay of a publication behind its scheduled time."""


def replay(
    bus: Bus,
    path: str | Path,
    *,
    speed: float = 1.0,
    stop_event: threading.Event | None = None,
    keyexprs: Sequence[str] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> ReplayStats:
    """Publish a recording on ``bus`` with its original timing.

    Message *i* goes out at ``start + (log_time_i − log_time_0) / speed``; a replay that falls
    behind publishes at once and never skips.

    Args:
        bus: where to publish (each message on its recorded key, payload unchanged).
        path: the recording (finished or truncated).
        speed: time scale; 2 plays twice as fast. ``inf`` publishes as fast as possible.
        stop_event: set it to stop early.
        keyexprs: publish only keys matching one of these (default: everything).
        clock: seconds, monotonic (tests may pass a fake).

    Raises:
        ValueError: ``speed`` is not > 0.
        RecordingError: the file is unreadable.
    """
    if not speed > 0:
        raise ValueError(f"replay speed must be > 0, got {speed!r}")
    stop = stop_event if stop_event is not None else threading.Event()
    count = 0
    first_ns: int | None = None
    last_ns = 0
    start_s = clock()
    max_lag_s = 0.0
    for msg in iter_messages(path):
        if keyexprs is not None and not any(keyexpr_matches(k, msg.key) for k in keyexprs):
            continue
        if first_ns is None:
            first_ns = msg.log_time_ns
            start_s = clock()
        due_s = start_s + (msg.log_time_ns - first_ns) / 1e9 / speed
        delay_s = due_s - clock()
        if delay_s <= 0:
            max_lag_s = max(max_lag_s, -delay_s)
        # Short waits keep the main thread responsive to signals across long gaps.
        while delay_s > 0 and not stop.wait(min(delay_s, 0.2)):
            delay_s = due_s - clock()
        if stop.is_set():
            break
        bus.publish(msg.key, msg.payload)
        count += 1
        last_ns = msg.log_time_ns
    span_s = 0.0 if first_ns is None else (last_ns - first_ns) / 1e9
    return ReplayStats(count, clock() - start_s, span_s, max_lag_s)


class PipelineLike(Protocol):
    """What offline replay needs of :class:`groundstation.pipeline.Pipeline`."""

    def handle(self, sample: Sample, now_s: float) -> list[Sample]: ...

    def tick(self, now_s: float) -> list[Sample]: ...


def replay_offline(
    path: str | Path,
    out_path: str | Path,
    pipeline: PipelineLike,
    *,
    tick_period_s: float = 0.05,
) -> int:
    """Re-run estimation on a recording as fast as possible and write inputs plus outputs.

    Every recorded message is copied to ``out_path`` at its log time, except the recording's
    own estimates and commands (``tether/*/estimate``, ``tether/*/cmd/*``), which move under
    ``replay/original/`` so the new outputs can take their keys. Inputs
    (``tether/*/telemetry|reel|follow|params``) go through ``pipeline.handle`` with
    ``now_s`` = log time in seconds; ``pipeline.tick`` runs every ``tick_period_s`` of log
    time (as the live service's staleness check does). Outputs are written at the log time of
    the input that produced them.

    Returns:
        The number of output samples the pipeline produced.

    Raises:
        RecordingError: unreadable input or uncreatable output.
    """
    stream, writer = _open_writer(Path(out_path), 1024 * 1024)
    channels = _ChannelTable(writer)
    produced = 0
    next_tick_s: float | None = None

    def write(key: str, payload: bytes, t_ns: int) -> None:
        writer.add_message(channels.channel_id(key), t_ns, payload, t_ns)

    try:
        for msg in iter_messages(path):
            now_s = msg.log_time_ns / 1e9
            if next_tick_s is None:
                next_tick_s = now_s + tick_period_s
            while now_s >= next_tick_s:
                tick_ns = int(next_tick_s * 1e9)
                for out in pipeline.tick(next_tick_s):
                    write(out.key, out.payload, tick_ns)
                    produced += 1
                next_tick_s += tick_period_s
            if _OUTPUT_KEY_RE.fullmatch(msg.key):
                write(_ORIGINAL_PREFIX + msg.key, msg.payload, msg.log_time_ns)
                continue
            write(msg.key, msg.payload, msg.log_time_ns)
            if _INPUT_KEY_RE.fullmatch(msg.key):
                for out in pipeline.handle(Sample(msg.key, msg.payload), now_s):
                    write(out.key, out.payload, msg.log_time_ns)
                    produced += 1
        writer.finish()
    finally:
        stream.close()
    return produced


# --------------------------------------------------------------------------- figures


def write_figures(path: str | Path, figures_dir: str | Path) -> list[Path]:
    """Draw tension and position over time per drone from a (replayed) recording.

    Per drone ``{drone}_tension.png`` (estimate ± 1 σ, and truth when recorded) and
    ``{drone}_position.png`` (tether-based estimate, truth and motion capture when recorded).
    Needs matplotlib (the ``dev`` extra); draws with the Agg backend, no display.

    Returns:
        The PNG files written.

    Raises:
        RecordingError: matplotlib is missing, or the recording is unreadable.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RecordingError("figures need matplotlib: pip install matplotlib") from None

    series: dict[str, dict[str, list[tuple[float, Any]]]] = defaultdict(lambda: defaultdict(list))
    t0_ns: int | None = None
    for msg in iter_messages(path):
        m = re.fullmatch(r"tether/([^/]+)/(estimate|truth|telemetry)", msg.key)
        if m is None:
            continue
        if t0_ns is None:
            t0_ns = msg.log_time_ns
        try:
            data = json.loads(msg.payload)
        except ValueError:
            continue
        if isinstance(data, dict):
            series[m.group(1)][m.group(2)].append(((msg.log_time_ns - t0_ns) / 1e9, data))

    out_dir = Path(figures_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    axes_names = ("x", "y", "z")
    for drone, kinds in sorted(series.items()):
        est = kinds.get("estimate", [])
        truth = kinds.get("truth", [])
        tele = kinds.get("telemetry", [])
        if not est and not truth:
            continue

        fig, axs = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
        for i, ax in enumerate(axs):
            if est:
                t = [s for s, _ in est]
                v = [d["tension_n"][i] for _, d in est]
                sd = [d.get("tension_std_n", [0, 0, 0])[i] for _, d in est]
                ax.plot(t, v, lw=1, label="estimate")
                ax.fill_between(
                    t,
                    [a - b for a, b in zip(v, sd, strict=True)],
                    [a + b for a, b in zip(v, sd, strict=True)],
                    alpha=0.25,
                    lw=0,
                    label="±1σ",
                )
            if truth:
                ax.plot(
                    [s for s, _ in truth],
                    [d["tension_n"][i] for _, d in truth],
                    "k--",
                    lw=1,
                    label="truth",
                )
            ax.set_ylabel(f"T{axes_names[i]} [N]")
        axs[0].legend(loc="upper right", fontsize=8)
        axs[0].set_title(f"{drone}: tether tension on the drone (world frame)")
        axs[-1].set_xlabel("time [s]")
        target = out_dir / f"{drone}_tension.png"
        fig.savefig(target, dpi=100)
        plt.close(fig)
        written.append(target)

        fig, axs = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
        for i, ax in enumerate(axs):
            pts = [(s, d["position_m"][i]) for s, d in est if d.get("position_m") is not None]
            if pts:
                ax.plot(*zip(*pts, strict=True), lw=1, label="tether estimate")
            mocap = [(s, d["position_m"][i]) for s, d in tele if d.get("position_m") is not None]
            if mocap:
                ax.plot(*zip(*mocap, strict=True), lw=1, alpha=0.7, label="motion capture")
            if truth:
                ax.plot(
                    [s for s, _ in truth],
                    [d["position_m"][i] for _, d in truth],
                    "k--",
                    lw=1,
                    label="truth",
                )
            ax.set_ylabel(f"{axes_names[i]} [m]")
        axs[0].legend(loc="upper right", fontsize=8)
        axs[0].set_title(f"{drone}: position (world frame)")
        axs[-1].set_xlabel("time [s]")
        target = out_dir / f"{drone}_position.png"
        fig.savefig(target, dpi=100)
        plt.close(fig)
        written.append(target)
    return written


# --------------------------------------------------------------------------- CLI bodies


def _linger(recorder: Recorder, *, quiet_s: float, max_s: float) -> None:
    # A stop often comes right after the publishers finish, with their last samples still in
    # flight (publisher batch, router, socket): keep listening until the bus has been quiet
    # for ``quiet_s``, for at most ``max_s``.
    deadline = time.monotonic() + max_s
    seen = recorder.samples_received
    while time.monotonic() < deadline:
        time.sleep(min(quiet_s, max(0.0, deadline - time.monotonic())))
        now_seen = recorder.samples_received
        if now_seen == seen:
            return
        seen = now_seen


def run_record(
    settings: Settings,
    out_path: str | Path,
    keyexprs: Sequence[str] = DEFAULT_KEYEXPRS,
    stop_event: threading.Event | None = None,
    *,
    linger_quiet_s: float = 0.25,
    linger_max_s: float = 1.5,
) -> int:
    """Body of ``groundstation record``: record the Zenoh bus until ``stop_event`` is set.

    Opens a session from ``settings.zenoh`` and records. When the event is set it keeps
    recording until the bus has been quiet for ``linger_quiet_s`` (at most ``linger_max_s``),
    so samples still in flight when SIGINT arrives are not lost, then finishes the file.

    Returns:
        0 once the file is finished.

    Raises:
        RecordingError: the file cannot be created or written.
    """
    from groundstation.bus import PeerWatch, describe_endpoints
    from groundstation.zenoh_bus import ZenohBus

    stop = stop_event if stop_event is not None else threading.Event()
    z = settings.zenoh
    with ZenohBus(z) as bus:
        watch = PeerWatch(
            bus.peer_count,
            describe_endpoints(z.mode, z.connect, z.listen),
            "groundstation record",
            _log,
        )
        recorder = Recorder(bus, out_path, keyexprs or DEFAULT_KEYEXPRS)
        try:
            _log.info("recording %s to %s", ", ".join(recorder.keyexprs), out_path)
            # Short waits keep the main thread responsive to the CLI's signal handlers.
            while not stop.wait(0.2):
                watch.poll(time.monotonic())
            _linger(recorder, quiet_s=linger_quiet_s, max_s=linger_max_s)
            watch.poll(time.monotonic())
        finally:
            stats = recorder.close()
    _log.info(
        "recorded %d messages on %d keys to %s (dropped %d, max backlog %d)",
        stats.messages,
        stats.channels,
        stats.path,
        stats.dropped,
        stats.max_queue_depth,
    )
    if not watch.ever_connected:
        _log.warning("nothing could reach the recorder: %s", watch.where)
    return 0


def run_replay(
    settings: Settings,
    path: str | Path,
    *,
    speed: float = 1.0,
    stop_event: threading.Event | None = None,
    wait_for_subscribers_s: float = 2.0,
) -> int:
    """Body of ``groundstation replay``: publish a recording on Zenoh with its timing.

    Before the first message it waits up to ``wait_for_subscribers_s`` for a subscriber to
    match the first key, so a replay into a network that is still connecting does not lose
    its beginning.

    Returns:
        0 when the recording has been played (or ``stop_event`` was set).

    Raises:
        ValueError: ``speed`` is not > 0.
        RecordingError: the file is unreadable.
    """
    from groundstation.zenoh_bus import ZenohBus

    stop = stop_event if stop_event is not None else threading.Event()
    first = next(iter_messages(path), None)
    if first is None:
        _log.warning("%s holds no message; nothing to replay", path)
        return 0
    with ZenohBus(settings.zenoh) as bus:
        _wait_for_match(bus, first.key, wait_for_subscribers_s, stop)
        stats = replay(bus, path, speed=speed, stop_event=stop)
    _log.info(
        "replayed %d messages (%.1f s of recording in %.1f s, max lag %.3f s)",
        stats.messages,
        stats.span_s,
        stats.duration_s,
        stats.max_lag_s,
    )
    return 0


def _wait_for_match(bus: Any, key: str, timeout_s: float, stop: threading.Event) -> bool:
    session = getattr(bus, "session", None)
    if session is None or timeout_s <= 0:
        return False
    publisher = session.declare_publisher(key)
    try:
        deadline = time.monotonic() + timeout_s
        while not publisher.matching_status.matching:
            if time.monotonic() >= deadline or stop.wait(0.02):
                return False
        return True
    finally:
        with contextlib.suppress(Exception):
            publisher.undeclare()


def run_replay_offline(
    settings: Settings,
    path: str | Path,
    out_path: str | Path,
    *,
    figures_dir: str | Path | None = None,
    pipeline: PipelineLike | None = None,
) -> int:
    """Body of ``groundstation replay --offline``: re-run estimation, write OUT (and figures).

    Args:
        settings: configuration for the pipeline (as the live service would have).
        path: the recording.
        out_path: the MCAP file to write (see :func:`replay_offline`).
        figures_dir: also draw PNGs there (see :func:`write_figures`).
        pipeline: the estimator to run; default ``groundstation.pipeline.Pipeline(settings)``.

    Returns:
        0 on success.

    Raises:
        RecordingError: unreadable input, uncreatable output, matplotlib missing for figures.
    """
    if pipeline is None:
        from groundstation.pipeline import Pipeline

        pipeline = Pipeline(settings)
    produced = replay_offline(path, out_path, pipeline)
    _log.info("offline replay of %s: %d outputs written to %s", path, produced, out_path)
    if figures_dir is not None:
        for png in write_figures(out_path, figures_dir):
            _log.info("wrote %s", png)
    return 0
