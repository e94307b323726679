"""Output files that never destroy a user's file: checked before anything runs, written whole.

Every command that writes a file (``record``, ``replay --offline``, ``calibrate``, the
figures) goes through here:

- :func:`check_output` refuses, before any input is read, an output that is one of the
  inputs (``replay j.mcap --offline --out j.mcap``), and an existing output unless the user
  passed ``--force``;
- :class:`NewFile` writes to a temporary file beside the target and moves it into place only
  when the whole output is written (a failure leaves the target as it was); without
  ``force`` the move is a hard link, which fails rather than replace a file that appeared
  meanwhile. A long recording (``record``) may instead grow the new file in place, so that
  what a killed recorder wrote is on disk under its name.
- Files get the mode the process's umask gives a new file (``0o666 & ~umask``), as ``open``
  would: ``tempfile.mkstemp`` alone makes them ``0o600``, unreadable to the deployment's
  service user.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path
from typing import IO, Any

__all__ = ["NewFile", "OutputError", "check_output", "expand_time", "file_mode"]


class OutputError(RuntimeError):
    """An output that would destroy a file, or that cannot be written (one line for the CLI)."""


def file_mode() -> int:
    """The mode ``open(path, "w")`` gives a new file under this process's umask."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def expand_time(path: str, now_unix_s: float) -> str:
    """``{time}`` in ``path`` replaced by the UTC time ``YYYYmmddTHHMMSSZ``: a recording name
    that a restarted service does not find taken (``session-{time}.mcap``)."""
    if "{time}" not in path:
        return path
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(now_unix_s))
    return path.replace("{time}", stamp)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): compare where they would be
        return a.resolve() == b.resolve()


def check_output(
    out: str | Path,
    *,
    inputs: Iterable[str | Path] = (),
    force: bool = False,
    flag: str = "--out",
    directory: bool = False,
) -> Path:
    """Refuse an output that would destroy a file, before anything is read or written.

    Args:
        out: the output's path.
        inputs: the files the command reads; the output may be none of them, even with
            ``force`` (it would be read and written at once).
        force: the user asked to replace an existing output (``--force``).
        flag: the option that named ``out``, for the message.
        directory: ``out`` is a directory to write files into (it may exist; a file there
            is refused).

    Returns:
        ``out`` as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``out`` is an input, exists (without ``force``), is of the wrong kind,
            or its directory does not exist.
    """
    path = Path(out)
    for inp in inputs:
        if _same_file(path, Path(inp)):
            raise OutputError(
                f"{flag} {str(path)!r} is also an input of this command ({str(inp)!r}): "
                "refusing to write over it; choose another name"
            )
    if directory:
        if path.exists() and not path.is_dir():
            raise OutputError(
                f"{flag} {str(path)!r} is a file, not a directory: refusing to replace it; "
                "name a directory (it is created if missing)"
            )
        return path
    if path.is_dir():
        raise OutputError(f"{flag} {str(path)!r} is a directory; name a file")
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputError(
            f"{flag} {str(path)!r} exists: refusing to replace it (pass --force to replace "
            "it, or choose another name)"
        )
    parent = path.parent
    if not parent.is_dir():
        raise OutputError(f"{flag} {str(path)!r}: the directory {str(parent)!r} does not exist")
    return path


class NewFile:
    """A file written whole or not at all (a temporary file beside it, moved into place).

    Use :meth:`commit` once everything is written, or :meth:`discard`; as a context manager
    it commits when the block succeeds and discards when it raises.

    Args:
        target: the file to create.
        force: replace ``target`` if it exists (else :meth:`commit` fails rather than
            replace a file that appeared while writing).
        text: open the stream in text mode (UTF-8) rather than binary.
        grow_in_place: create ``target`` itself at once (exclusively: an existing file is an
            error, unless ``force``, which then falls back to the temporary file) and write
            into it; for a recording, whose partial content is worth keeping when the process
            is killed.

    Raises:
        OutputError: the file cannot be created.
    """

    def __init__(
        self,
        target: str | Path,
        *,
        force: bool = False,
        text: bool = False,
        grow_in_place: bool = False,
    ) -> None:
        self.target = Path(target)
        self._force = force
        self._done = False
        mode = "w" if text else "wb"
        enc: dict[str, Any] = {"encoding": "utf-8"} if text else {}
        self._tmp: Path | None = None
        try:
            if grow_in_place and not (force and self.target.exists()):
                fd = os.open(self.target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            else:
                fd, tmp = tempfile.mkstemp(
                    prefix=f".{self.target.name}.", suffix=".partial", dir=self.target.parent
                )
                self._tmp = Path(tmp)
                os.fchmod(fd, file_mode())
        except FileExistsError:
            raise OutputError(
                f"{str(self.target)!r} exists: refusing to replace it (pass --force to replace "
                "it, or choose another name)"
            ) from None
        except OSError as exc:
            raise OutputError(f"cannot create {str(self.target)!r}: {exc.strerror}") from None
        self.stream: IO[Any] = os.fdopen(fd, mode, **enc)

    @property
    def writing_path(self) -> Path:
        """Where the bytes go until :meth:`commit` (the target itself when grown in place)."""
        return self._tmp if self._tmp is not None else self.target

    def commit(self) -> Path:
        """Flush, sync and move the file into place.

        Returns:
            The target path.

        Raises:
            OutputError: the target appeared meanwhile (without ``force``), or the move failed.
        """
        if self._done:
            return self.target
        self._done = True
        try:
            self.stream.flush()
            os.fsync(self.stream.fileno())
        finally:
            self.stream.close()
        if self._tmp is None:
            return self.target
        try:
            if self._force:
                os.replace(self._tmp, self.target)
            else:
                try:
                    os.link(self._tmp, self.target)
                except FileExistsError:
                    raise OutputError(
                        f"{str(self.target)!r} appeared while it was being written: left as "
                        "it is (pass --force to replace it)"
                    ) from None
                except OSError:  # a file system without hard links
                    if self.target.exists():
                        raise OutputError(
                            f"{str(self.target)!r} appeared while it was being written: left "
                            "as it is (pass --force to replace it)"
                        ) from None
                    os.replace(self._tmp, self.target)
        except OSError as exc:
            raise OutputError(f"cannot write {str(self.target)!r}: {exc.strerror}") from None
        finally:
            with contextlib.suppress(FileNotFoundError):
                self._tmp.unlink()
        return self.target

    def discard(self) -> None:
        """Close and remove what was written (a file grown in place is kept: it is the part
        of a recording that was made)."""
        if self._done:
            return
        self._done = True
        self.stream.close()
        if self._tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                self._tmp.unlink()

    def __enter__(self) -> NewFile:
        return self

    def __exit__(self, exc_type: object, *rest: object) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()
