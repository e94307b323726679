"""Playing a recording back on a bus, and re-running estimation on one offline."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from groundstation.bus import Bus, Sample, keyexpr_matches
from groundstation.config import Settings
from groundstation.foxglove.offline import SceneTap
from groundstation.outputs import OutputError, check_output
from groundstation.recording.figures import write_figures
from groundstation.recording.format import (
    INPUT_KEY_RE,
    ORIGINAL_PREFIX,
    OUTPUT_KEY_RE,
    ChannelTable,
    RecordingError,
    open_writer,
)
from groundstation.recording.reader import iter_messages
from groundstation.recording.smoothed import SmoothingTap

_log = logging.getLogger(__name__)


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
    smooth: bool = True,
    force: bool = False,
    scenes: SceneTap | None = None,
) -> int:
    """Re-run estimation on a recording as fast as possible and write inputs plus outputs.

    Every recorded message is copied to ``out_path`` at its log time, except the recording's
    own estimates and commands (``tether/*/estimate``, ``tether/*/cmd/*``), which move under
    ``replay/original/`` so the new outputs can take their keys. Inputs
    (``tether/*/telemetry|reel|follow|params``) go through ``pipeline.handle`` with
    ``now_s`` = log time in seconds; ``pipeline.tick`` runs every ``tick_period_s`` of log
    time (as the live service's staleness check does). Outputs are written at the log time of
    the input that produced them. With ``smooth`` (and the service's Pipeline) each Estimate the
    tension filter stepped for also gets its forward-backward smoothed tension and position,
    ``tether/{drone}/estimate_smoothed`` at the same log time (docs/smoother.md). With
    ``scenes``, the 3D scene of every drone at the tap's rate of log time: ``scene``
    (``foxglove.SceneUpdate``) and ``tf`` (``foxglove.FrameTransforms``), protobuf with their
    schemas, so the file opens in Foxglove in 3D (docs/foxglove.md).

    The output is written beside ``out_path`` and moved into place when complete: a failure
    leaves no output and an existing file as it was. ``out_path`` may not be ``path``, and an
    existing ``out_path`` is replaced only with ``force``.

    Returns:
        The number of output samples the pipeline produced.

    Raises:
        RecordingError: unreadable input, an output that is the input, exists (without
            ``force``) or cannot be created.
    """
    try:
        check_output(out_path, inputs=(path,), force=force)
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
    out_file, writer = open_writer(Path(out_path), 1024 * 1024, force=force)
    channels = ChannelTable(writer)
    produced = 0
    next_tick_s: float | None = None
    tap = SmoothingTap(pipeline) if smooth else None
    drawing = scenes is not None

    def write(key: str, payload: bytes, t_ns: int) -> None:
        writer.add_message(channels.channel_id(key), t_ns, payload, t_ns)
        if drawing and scenes is not None:
            for m in scenes.after(key, payload, t_ns):
                cid = channels.typed_channel_id(
                    m.topic, m.schema.name, m.schema.encoding, m.schema.data, "protobuf"
                )
                writer.add_message(cid, m.log_time_ns, m.data, m.log_time_ns)

    try:
        for msg in iter_messages(path, require_messages=True):
            now_s = msg.log_time_ns / 1e9
            if next_tick_s is None:
                next_tick_s = now_s + tick_period_s
            while now_s >= next_tick_s:
                tick_ns = int(next_tick_s * 1e9)
                for out in pipeline.tick(next_tick_s):
                    write(out.key, out.payload, tick_ns)
                    produced += 1
                next_tick_s += tick_period_s
            if OUTPUT_KEY_RE.fullmatch(msg.key):
                write(ORIGINAL_PREFIX + msg.key, msg.payload, msg.log_time_ns)
                continue
            write(msg.key, msg.payload, msg.log_time_ns)
            if INPUT_KEY_RE.fullmatch(msg.key):
                outs = pipeline.handle(Sample(msg.key, msg.payload), now_s)
                for out in outs:
                    write(out.key, out.payload, msg.log_time_ns)
                    produced += 1
                if tap is not None:
                    tap.after(msg.key, outs, msg.log_time_ns)
        drawing = False  # the smoothed samples go back in time: no scene from them
        for key, payload, t_ns in tap.samples() if tap is not None else ():
            write(key, payload, t_ns)  # after the pass: smoothing needs the whole of it
        writer.finish()
    except BaseException:
        # Nothing usable in the input, or it cannot be read: no half-written output.
        out_file.discard()
        raise
    try:
        out_file.commit()
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
    return produced


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
    first = next(iter_messages(path, require_messages=True), None)
    if first is None:  # pragma: no cover - require_messages raises first
        return 1
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
    force: bool = False,
) -> int:
    """Body of ``groundstation replay --offline``: re-run estimation, write OUT (and figures).

    Both outputs are checked before the recording is read: ``out_path`` may not be ``path``
    nor exist, and ``figures_dir`` may not be a file nor already hold figures (``*.png``),
    unless ``force``.

    Args:
        settings: configuration for the pipeline (as the live service would have).
        path: the recording.
        out_path: the MCAP file to write (see :func:`replay_offline`).
        figures_dir: also draw PNGs there (see :func:`write_figures`).
        pipeline: the estimator to run; default ``groundstation.pipeline.Pipeline(settings)``.
        force: replace an existing ``out_path`` and existing figures.

    Returns:
        0 on success.

    Raises:
        RecordingError: unreadable input, an output refused (see above) or uncreatable,
            matplotlib missing for figures.
    """
    try:
        check_output(out_path, inputs=(path,), force=force)
        if figures_dir is not None:
            figs = check_output(figures_dir, inputs=(path,), flag="--figures", directory=True)
            held = sorted(p.name for p in figs.glob("*.png")) if figs.is_dir() else []
            if held and not force:
                shown = ", ".join(held[:4]) + (", ..." if len(held) > 4 else "")
                raise OutputError(
                    f"--figures {str(figures_dir)!r} already holds figures ({shown}): "
                    "refusing to replace them (pass --force, or choose another directory)"
                )
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
    if pipeline is None:
        from groundstation.pipeline import Pipeline

        pipeline = Pipeline(settings)
    produced = replay_offline(path, out_path, pipeline, force=force, scenes=SceneTap(settings))
    _log.info("offline replay of %s: %d outputs written to %s", path, produced, out_path)
    if figures_dir is not None:
        for png in write_figures(out_path, figures_dir):
            _log.info("wrote %s", png)
    return 0
