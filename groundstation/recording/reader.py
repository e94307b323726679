"""Reading recordings: finished files through their index, truncated ones up to the cut."""

from __future__ import annotations

import contextlib
import heapq
import logging
import struct
from collections.abc import Iterable, Iterator
from itertools import pairwise
from pathlib import Path
from typing import IO, NamedTuple, cast

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, ChunkIndex, Message, MessageIndex
from mcap.stream_reader import StreamReader, breakup_chunk

from groundstation.outputs import NewFile, OutputError, check_output
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


def iter_messages(
    path: str | Path, *, allow_truncated: bool = True, require_messages: bool = False
) -> Iterator[RecordedMessage]:
    """The messages of a recording in log-time order, what is readable of a damaged one.

    A finished file is read chunk by chunk through its index (as the reference reader,
    ``mcap.reader.make_reader``, would: in log-time order). A file without a footer
    (recorder killed) is read sequentially up to its last complete record; what follows the
    cut is skipped with a warning. Files written by :class:`Recorder` keep log times
    non-decreasing, so file order is log-time order. A chunk that cannot be decoded (flipped
    bits: a decompression or CRC error) is skipped with a warning that names it (its number
    and byte offset) and says how many messages it held (from its message index, when that
    is readable); the others are read.

    Args:
        path: the recording.
        allow_truncated: read an unfinished file (else refuse it).
        require_messages: raise when nothing at all could be read (for the commands that
            have nothing to do then: ``replay``, ``calibrate``).

    Raises:
        RecordingError: the file cannot be opened or is not MCAP, or it is truncated and
            ``allow_truncated`` is False, or ``require_messages`` and it holds no readable
            message (raised after the iteration, naming what was lost).
    """
    path = Path(path)
    losses = _Losses(path)
    if is_complete(path):
        yield from _iter_finished(path, losses)
    else:
        if not allow_truncated:
            raise RecordingError(f"recording {str(path)!r} is not finished (no footer)")
        yield from _iter_truncated(path, losses)
    losses.report()
    if require_messages and losses.read == 0:
        raise RecordingError(f"{str(path)!r} holds no readable message{losses.why_empty()}")


class _Losses:
    """What could not be read of one recording: told once, at the end of the reading."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.read = 0
        self.bad: list[tuple[str, str, int | None]] = []  # (which chunk, why, messages lost)
        self.truncated: str | None = None
        self.size = path.stat().st_size if path.exists() else 0

    def bad_chunk(self, which: str, exc: BaseException, lost: int | None) -> None:
        self.bad.append((which, f"{type(exc).__name__}: {exc}", lost))

    def lost(self) -> str:
        counts = [n for _, _, n in self.bad]
        if any(n is None for n in counts):
            return "an unknown number of messages"
        return f"{sum(n for n in counts if n is not None)} messages"

    def report(self) -> None:
        for which, why, lost in self.bad[:5]:
            n = "an unknown number of" if lost is None else str(lost)
            _log.warning("%s: %s is corrupt (%s): %s messages lost", self.path, which, why, n)
        if self.bad:
            _log.warning(
                "%s: %d messages read; %d corrupt chunk(s) skipped, %s lost",
                self.path,
                self.read,
                len(self.bad),
                self.lost(),
            )
        if self.truncated is not None:
            _log.warning(
                "%s is truncated after %d messages (%s); the rest is lost",
                self.path,
                self.read,
                self.truncated,
            )

    def why_empty(self) -> str:
        if self.bad:
            return f": every chunk is corrupt ({len(self.bad)}, {self.lost()} lost)"
        if self.truncated is not None:
            return (
                f": it ends after {self.size} bytes, before its first complete chunk "
                f"({self.truncated})"
            )
        return ": the recording is empty"


_DECODE_ERRORS: tuple[type[BaseException], ...] = (McapError, struct.error, ValueError, EOFError)


def _decode_errors() -> tuple[type[BaseException], ...]:
    import zstandard  # mcap's own dependency, for its chunk decompression error

    return (*_DECODE_ERRORS, zstandard.ZstdError)


def _chunk_messages(chunk: Chunk, topics: dict[int, str], *, sort: bool) -> list[RecordedMessage]:
    """The messages of one chunk (channels defined in it are added to ``topics``)."""
    out = []
    for record in breakup_chunk(chunk, validate_crc=True):
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message):
            topic = topics.get(record.channel_id)
            if topic is None:
                raise McapError(f"message on unknown channel {record.channel_id}")
            out.append(RecordedMessage(topic, record.data, record.log_time, record.publish_time))
    if sort:
        out.sort(key=lambda m: m.log_time_ns)  # stable: file order among equal times
    return out


def _indexed_count(fh: IO[bytes], index: ChunkIndex) -> int | None:
    """How many messages the chunk held, from its message index records (None: unreadable)."""
    try:
        total = 0
        for offset in index.message_index_offsets.values():
            fh.seek(offset)
            stream = ReadDataStream(fh)
            if stream.read1() != Opcode.MESSAGE_INDEX:
                return None
            stream.read8()
            total += len(MessageIndex.read(stream).records)
        return total
    except _decode_errors():
        return None


def _iter_finished(path: Path, losses: _Losses) -> Iterator[RecordedMessage]:
    errors = _decode_errors()
    with path.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        if summary is None or not summary.chunk_indexes:
            for _schema, channel, message in reader.iter_messages(log_time_order=True):
                losses.read += 1
                yield RecordedMessage(
                    channel.topic, message.data, message.log_time, message.publish_time
                )
            return
        topics = {cid: ch.topic for cid, ch in summary.channels.items()}
        by_offset = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        n = len(by_offset)

        def chunk(k: int, index: ChunkIndex) -> list[RecordedMessage]:
            try:
                fh.seek(index.chunk_start_offset + 1 + 8)
                return _chunk_messages(Chunk.read(ReadDataStream(fh)), topics, sort=True)
            except errors as exc:
                end = index.chunk_start_offset + index.chunk_length
                which = f"chunk {k + 1} of {n} (bytes {index.chunk_start_offset}-{end})"
                losses.bad_chunk(which, exc, _indexed_count(fh, index))
                return []

        in_time = sorted(by_offset, key=lambda c: (c.message_start_time, c.chunk_start_offset))
        overlapping = any(a.message_end_time > b.message_start_time for a, b in pairwise(in_time))
        number = {index.chunk_start_offset: k for k, index in enumerate(by_offset)}
        if not overlapping:
            for index in in_time:
                for m in chunk(number[index.chunk_start_offset], index):
                    losses.read += 1
                    yield m
            return
        # Chunks overlap in time (not a Recorder's file): merge them, ties in file order.
        lists = [chunk(k, index) for k, index in enumerate(by_offset)]
        for m in heapq.merge(*lists, key=lambda m: m.log_time_ns):
            losses.read += 1
            yield m


def _iter_truncated(path: Path, losses: _Losses) -> Iterator[RecordedMessage]:
    errors = _decode_errors()
    topics: dict[int, str] = {}
    chunks = 0
    counting_lost = False  # after a corrupt chunk: its message index records follow it
    try:
        fh = path.open("rb")
    except OSError as exc:
        raise RecordingError(f"cannot open recording {str(path)!r}: {exc.strerror}") from None
    with fh:
        # Chunk CRCs are checked chunk by chunk (breakup_chunk): a corrupt chunk is skipped;
        # the data section's CRC would only say that one was.
        reader = StreamReader(cast(IO[bytes], _StrictRead(fh)), emit_chunks=True)
        records = reader.records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except errors as exc:
                if losses.read == 0 and fh.tell() <= len(MAGIC) and isinstance(exc, McapError):
                    raise RecordingError(f"{str(path)!r} is not an MCAP file: {exc}") from None
                losses.truncated = str(exc)
                return
            if isinstance(record, Chunk):
                chunks += 1
                counting_lost = False
                try:
                    msgs = _chunk_messages(record, topics, sort=False)
                except errors as exc:
                    losses.bad_chunk(f"chunk {chunks} (ending at byte {fh.tell()})", exc, 0)
                    counting_lost = True
                    continue
                for m in msgs:
                    losses.read += 1
                    yield m
            elif isinstance(record, MessageIndex):
                if counting_lost:
                    which, why, lost = losses.bad[-1]
                    losses.bad[-1] = (which, why, (lost or 0) + len(record.records))
            elif isinstance(record, Message):
                topic = topics.get(record.channel_id)
                if topic is None:
                    raise RecordingError(
                        f"{str(path)!r}: message on unknown channel {record.channel_id}"
                    )
                losses.read += 1
                yield RecordedMessage(topic, record.data, record.log_time, record.publish_time)
            elif isinstance(record, Channel):
                topics[record.id] = record.topic


def recover(src: str | Path, dst: str | Path, *, force: bool = False) -> int:
    """Rewrite the readable part of a (possibly truncated) recording as a finished file.

    Args:
        src: the recording to read.
        dst: the file to write (never ``src``; an existing one only with ``force``).
        force: replace an existing ``dst``.

    Returns:
        The number of messages written to ``dst``.

    Raises:
        RecordingError: ``src`` is unreadable, ``dst`` is ``src``, exists (without
            ``force``) or cannot be created.
    """
    try:
        check_output(dst, inputs=(src,), force=force, flag="recover's output")
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
    return copy_messages(iter_messages(src), Path(dst), force=force)


def copy_messages(msgs: Iterable[RecordedMessage], dst: Path, *, force: bool = False) -> int:
    """Write ``msgs`` to a new MCAP file ``dst``, whole or not at all.

    Returns:
        The number of messages written.

    Raises:
        RecordingError: ``dst`` exists (without ``force``) or cannot be written; a reading
            error of ``msgs`` leaves no file behind.
    """
    out, writer = open_writer(dst, 1024 * 1024, force=force)
    channels = ChannelTable(writer)
    count = 0
    with _committed(out):
        for m in msgs:
            writer.add_message(
                channels.channel_id(m.key), m.log_time_ns, m.payload, m.publish_time_ns
            )
            count += 1
        writer.finish()
    return count


@contextlib.contextmanager
def _committed(out: NewFile) -> Iterator[None]:
    """Commit ``out`` when the block succeeds, discard it when it raises."""
    try:
        yield
    except BaseException:
        out.discard()
        raise
    try:
        out.commit()
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
