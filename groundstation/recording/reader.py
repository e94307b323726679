"""Reading recordings: finished files through their index, truncated ones up to the cut."""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, NamedTuple, cast

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

from groundstation.recording.format import (
    MAGIC,
    ChannelTable,
    RecordingError,
    open_writer,
)

_log = logging.getLogger(__name__)


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
            if fh.tell() < 2 * len(MAGIC):
                return False
            fh.seek(-len(MAGIC), 2)
            if fh.read(len(MAGIC)) != MAGIC:
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
                if count == 0 and fh.tell() <= len(MAGIC) and isinstance(exc, McapError):
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
    return copy_messages(iter_messages(src), Path(dst))


def copy_messages(msgs: Iterable[RecordedMessage], dst: Path) -> int:
    stream, writer = open_writer(dst, 1024 * 1024)
    channels = ChannelTable(writer)
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
