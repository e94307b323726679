"""MCAP recording, recovery, replay and offline re-estimation (an edge)."""

from groundstation.recording.mcap_io import (
    DEFAULT_KEYEXPRS,
    RecordedMessage,
    Recorder,
    RecorderStats,
    RecordingError,
    ReplayStats,
    is_complete,
    iter_messages,
    recover,
    replay,
    replay_offline,
    run_record,
    run_replay,
    run_replay_offline,
    schema_for_key,
    write_figures,
)

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
