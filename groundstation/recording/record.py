"""Body of ``groundstation record``: the Zenoh bus into a file until stopped."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from groundstation.config import Settings
from groundstation.recording.format import (
    DEFAULT_KEYEXPRS,
)
from groundstation.recording.writer import Recorder

_log = logging.getLogger(__name__)


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
    force: bool = False,
) -> int:
    """Body of ``groundstation record``: record the Zenoh bus until ``stop_event`` is set.

    Opens a session from ``settings.zenoh`` and records. When the event is set it keeps
    recording until the bus has been quiet for ``linger_quiet_s`` (at most ``linger_max_s``),
    so samples still in flight when SIGINT arrives are not lost, then finishes the file.
    An existing ``out_path`` is refused unless ``force`` (then the new recording replaces
    it when finished; see :class:`~groundstation.recording.writer.Recorder`).

    Returns:
        0 once the file is finished.

    Raises:
        RecordingError: the file exists (without ``force``), cannot be created or written.
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
        recorder = Recorder(bus, out_path, keyexprs or DEFAULT_KEYEXPRS, force=force)
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
