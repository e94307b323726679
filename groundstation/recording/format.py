"""The recording's file format: MCAP layout, a schema per channel, the writer setup shared
by recording, recovery and offline replay.

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
"""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

from mcap.writer import CompressionType, Writer
from pydantic import BaseModel

from groundstation import messages
from groundstation.outputs import NewFile, OutputError

_log = logging.getLogger(__name__)


DEFAULT_KEYEXPRS = ("tether/**",)
MAGIC = b"\x89MCAP0\r\n"
_LIBRARY = "groundstation-recorder"
ORIGINAL_PREFIX = "replay/original/"
"""Offline replay writes the recording's own estimates and commands under this prefix."""
INPUT_KEY_RE = re.compile(r"tether/[^/]+/(telemetry|reel|follow|params)")
OUTPUT_KEY_RE = re.compile(r"tether/[^/]+/(estimate|estimate_smoothed|cmd/setpoint|cmd/stop)")


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


class ChannelTable:
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

    def typed_channel_id(
        self, topic: str, schema_name: str, schema_encoding: str, schema_data: bytes, encoding: str
    ) -> int:
        """The channel of ``topic`` with a schema given here (a Foxglove protobuf schema, say)
        rather than chosen by key: registered on first use, as :meth:`channel_id` does."""
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(schema_name)
            if sid is None:
                sid = self._writer.register_schema(
                    name=schema_name, encoding=schema_encoding, data=schema_data
                )
                self._schemas[schema_name] = sid
            cid = self._writer.register_channel(
                topic=topic, message_encoding=encoding, schema_id=sid
            )
            self._channels[topic] = cid
        return cid


def open_writer(
    path: Path, chunk_size: int, *, force: bool = False, grow_in_place: bool = False
) -> tuple[NewFile, Writer]:
    """An MCAP writer on a new file (:class:`~groundstation.outputs.NewFile`).

    The caller finishes the writer, then commits the file (or discards it on failure). An
    existing ``path`` is refused unless ``force``; with ``grow_in_place`` the file is created
    under its name at once (a recording: what a killed recorder wrote stays readable there).

    Raises:
        RecordingError: the file cannot be created, or exists and ``force`` is false.
    """
    try:
        out = NewFile(path, force=force, grow_in_place=grow_in_place)
    except OutputError as exc:
        raise RecordingError(f"cannot create recording: {exc}") from None
    writer = Writer(out.stream, chunk_size=chunk_size, compression=CompressionType.ZSTD)
    writer.start(profile="", library=_LIBRARY)
    return out, writer
