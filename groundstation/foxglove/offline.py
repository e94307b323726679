"""The scene channels of a re-estimated recording (``replay --offline``).

:class:`SceneTap` sees every message the offline replay writes, in log-time order, and every
``1 / scene_rate_hz`` seconds of log time returns a ``foxglove.SceneUpdate`` and a
``foxglove.FrameTransforms`` of the drones whose messages changed, protobuf-encoded by
foxglove-sdk, with the schema (a FileDescriptorSet) the file must carry for each.
"""

from __future__ import annotations

from typing import NamedTuple

import foxglove
from foxglove.messages import FrameTransforms, SceneUpdate

from groundstation.config import Settings
from groundstation.foxglove.schemas import (
    SCENE_TOPIC,
    TRANSFORMS_TOPIC,
    frame_transforms,
    scene_update,
)
from groundstation.foxglove.state import DroneBoard

__all__ = ["SceneMessage", "SceneTap"]


class SceneMessage(NamedTuple):
    """One message to write: its topic, schema, protobuf bytes and log time."""

    topic: str
    schema: foxglove.Schema
    """``foxglove.SceneUpdate`` or ``foxglove.FrameTransforms``, encoding ``protobuf``."""
    data: bytes
    log_time_ns: int


class SceneTap:
    """Turns a recording's messages into scene and transform messages at the scene rate.

    Args:
        settings: per-drone configuration and ``[foxglove] scene_rate_hz``.
    """

    def __init__(self, settings: Settings) -> None:
        self._board = DroneBoard(settings)
        self._period_ns = int(1e9 / settings.foxglove.scene_rate_hz)
        self._next_ns: int | None = None
        self._counts: dict[str, int] = {}
        self._scene_schema = SceneUpdate.get_schema()
        self._tf_schema = FrameTransforms.get_schema()
        self.written = 0
        """Scene updates returned so far."""

    def after(self, key: str, payload: bytes, log_time_ns: int) -> list[SceneMessage]:
        """Take one written message; return the scene messages due at its log time (after it).

        Args:
            key: its key (``tether/{drone}/{kind}``; others are ignored).
            payload: its bytes (JSON).
            log_time_ns: its log time, ns since the epoch (non-decreasing from call to call).
        """
        parts = key.split("/")
        if len(parts) == 3 and parts[0] == "tether":
            self._board.put(parts[1], parts[2], payload)
        if self._next_ns is None:
            self._next_ns = log_time_ns
        if log_time_ns < self._next_ns:
            return []
        self._next_ns += self._period_ns
        if self._next_ns <= log_time_ns:  # a gap in the recording: restart the rhythm here
            self._next_ns = log_time_ns + self._period_ns
        drones = self._board.changed_since(self._counts)
        if not drones:
            return []
        scenes = self._board.build(drones)
        if not scenes:
            return []
        self.written += 1
        return [
            SceneMessage(
                TRANSFORMS_TOPIC,
                self._tf_schema,
                frame_transforms(scenes, log_time_ns).encode(),
                log_time_ns,
            ),
            SceneMessage(
                SCENE_TOPIC,
                self._scene_schema,
                scene_update(scenes, log_time_ns).encode(),
                log_time_ns,
            ),
        ]
