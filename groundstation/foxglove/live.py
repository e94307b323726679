"""Foxglove's WebSocket server fed from the bus: the contract's messages as JSON channels and
each drone's 3D scene at a rate of its own.

An edge: it talks to the service over the bus only, like the dashboard (``serve`` runs it in
a child process, ``groundstation foxglove``, so that nothing here takes the interpreter from
estimation; ``demo`` keeps it in its one process).

Threads: the bus callbacks relay each payload unchanged to its channel (one call into the
SDK, which queues it per client in Rust) and keep the latest estimate, telemetry and truth
per drone as bytes, unparsed. One scene thread, at ``[foxglove] scene_rate_hz``, parses what
changed, builds the scenes (:mod:`groundstation.foxglove.scene`) and logs one
``foxglove.SceneUpdate`` and one ``foxglove.FrameTransforms``; with no client subscribed to
either it builds nothing.

Channels: ``tether/{drone}/{kind}`` for every key of the bus under ``tether/`` (the key is the
topic, the payload the message, ``json`` with the contract model's JSON schema, as in a
recording), :data:`SCENE_TOPIC` and :data:`TRANSFORMS_TOPIC`.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import foxglove
from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel
from pydantic import BaseModel

from groundstation import messages
from groundstation.bus import Bus, Sample, Subscription
from groundstation.config import Settings
from groundstation.foxglove.schemas import (
    SCENE_TOPIC,
    TRANSFORMS_TOPIC,
    frame_transforms,
    scene_update,
)
from groundstation.foxglove.state import DroneBoard

__all__ = [
    "SCENE_TOPIC",
    "TRANSFORMS_TOPIC",
    "FoxgloveLive",
    "ServerBindError",
    "json_schema_for_key",
]

_log = logging.getLogger(__name__)

SERVER_NAME = "groundstation"
DEFAULT_PORT = 8765
"""Foxglove's usual WebSocket port (the SDK's default), used when no port is configured."""


class ServerBindError(RuntimeError):
    """Foxglove's WebSocket server could not listen where it was told (names host and port)."""


_MODELS: dict[str, type[BaseModel]] = {
    "telemetry": messages.Telemetry,
    "reel": messages.Reel,
    "estimate": messages.Estimate,
    "follow": messages.FollowCommand,
    "params": messages.TetherParams,
    "setpoint": messages.Setpoint,
    "stop": messages.Stop,
    "truth": messages.Truth,
    "events": messages.Event,
}
"""The model of a key's last part (as the recorder's schemas)."""


def json_schema_for_key(key: str) -> foxglove.Schema:
    """The JSON schema of the channel of ``key``: its contract model's (inbound payloads as
    validated, outbound ones as serialised), else any object."""
    model = _MODELS.get(key.rsplit("/", 1)[-1])
    if model is None:
        return foxglove.Schema(name="json", encoding="jsonschema", data=b'{"type": "object"}')
    if issubclass(model, messages._In):
        schema = model.model_json_schema(mode="validation")
    else:
        schema = model.model_json_schema(mode="serialization")
    data = json.dumps(schema, sort_keys=True).encode()
    return foxglove.Schema(name=f"groundstation.{model.__name__}", encoding="jsonschema", data=data)


class FoxgloveLive:
    """Foxglove's WebSocket server with the bus's messages and the drones' scenes.

    Args:
        settings: the root configuration (``[foxglove]``; per-drone base, floor, tether).
        bus: where the messages come from (subscribes to ``tether/**``).
        clock: wall clock, seconds since the epoch (log times of the scene messages).
    """

    def __init__(
        self, settings: Settings, bus: Bus, *, clock: Callable[[], float] = time.time
    ) -> None:
        self._settings = settings
        self._bus = bus
        self._clock = clock
        self._context = foxglove.Context()
        self._server: Any = None
        self._scene = SceneUpdateChannel(SCENE_TOPIC, context=self._context)
        self._tf = FrameTransformsChannel(TRANSFORMS_TOPIC, context=self._context)
        self._channels: dict[str, foxglove.Channel] = {}
        self._channel_lock = threading.Lock()
        self.board = DroneBoard(settings)
        self._sub: Subscription | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._failed = False
        self.scenes_sent = 0
        """Scene updates logged (for tests and the log)."""

    # ---------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Bind the server, subscribe to the bus, start the scene thread.

        Raises:
            ServerBindError: the server could not bind (a port in use), naming host and port.
        """
        cfg = self._settings.foxglove
        port = cfg.port if cfg.port is not None else DEFAULT_PORT
        try:
            self._server = foxglove.start_server(
                name=SERVER_NAME, host=cfg.host, port=port, context=self._context
            )
        except RuntimeError as exc:
            raise ServerBindError(
                f"Foxglove's WebSocket server cannot listen on {cfg.host}:{port}: {exc}"
            ) from None
        self._sub = self._bus.subscribe("tether/**", self._on_sample)
        self._thread = threading.Thread(target=self._run, name="foxglove-scene", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self._server.port) if self._server is not None else 0

    @property
    def url(self) -> str:
        """``ws://host:port`` for Foxglove's "Open connection"."""
        return f"ws://{self._settings.foxglove.host}:{self.port}"

    def close(self) -> None:
        """Stop the scene thread, unsubscribe, stop the server (idempotent)."""
        self._stop.set()
        if self._sub is not None:
            self._sub.close()
            self._sub = None
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        if self._server is not None:
            self._server.stop()
            self._server = None

    # ---------------------------------------------------------------- bus callbacks

    def _channel(self, key: str) -> foxglove.Channel:
        with self._channel_lock:
            channel = self._channels.get(key)
            if channel is None:
                channel = foxglove.Channel(
                    key,
                    schema=json_schema_for_key(key),
                    message_encoding="json",
                    context=self._context,
                )
                self._channels[key] = channel
            return channel

    def _on_sample(self, sample: Sample) -> None:
        key = sample.key
        channel = self._channels.get(key)
        if channel is None:
            if key.count("/") < 2:
                return  # not tether/{drone}/...
            channel = self._channel(key)
        channel.log(sample.payload, log_time=time.time_ns())
        parts = key.split("/")
        if len(parts) == 3:
            self.board.put(parts[1], parts[2], sample.payload)

    # ---------------------------------------------------------------- scene thread

    def _run(self) -> None:
        period_s = 1.0 / self._settings.foxglove.scene_rate_hz
        next_s = time.monotonic()
        while not self._stop.wait(max(0.0, next_s - time.monotonic())):
            next_s += period_s
            if next_s <= time.monotonic():  # fell behind (a pause): no catching up in a burst
                next_s = time.monotonic() + period_s
            if not (self._scene.has_sinks() or self._tf.has_sinks()):
                continue
            try:
                scenes = self.board.build()
                if not scenes:
                    continue
                now_ns = int(self._clock() * 1e9)
                self._tf.log(frame_transforms(scenes, now_ns), log_time=now_ns)
                self._scene.log(scene_update(scenes, now_ns), log_time=now_ns)
                self.scenes_sent += 1
            except Exception as exc:  # a scene that cannot be drawn must not end the thread
                if not self._failed:
                    self._failed = True
                    _log.warning("foxglove: drawing the scene failed: %r", exc)
