"""MCAP recording, recovery, replay and offline re-estimation (an edge).

Parts: ``format`` (the file layout, schemas per channel), ``writer`` (the recorder),
``reader`` (finished and truncated files, recovery), ``replay`` (on a bus, and offline
through the pipeline), ``figures`` (PNGs from a recording), ``record`` (the CLI body),
``calibrate`` (``groundstation calibrate``: fits ``[calibration]`` from recordings).
"""

from groundstation.recording.figures import write_figures
from groundstation.recording.format import DEFAULT_KEYEXPRS, RecordingError, schema_for_key
from groundstation.recording.reader import RecordedMessage, is_complete, iter_messages, recover
from groundstation.recording.record import run_record
from groundstation.recording.replay import (
    ReplayStats,
    replay,
    replay_offline,
    run_replay,
    run_replay_offline,
)
from groundstation.recording.writer import Recorder, RecorderStats

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
