"""Reading files safely: the core's only I/O (docs/how-it-works.md).

Every file the core or a service reads on request (models, properties, systems,
bindings, definitions, goals, missions) is opened once with ``O_NOFOLLOW`` and
``O_NONBLOCK``, checked on the open descriptor (a regular file, inside the jail
``root`` when one is given, under the size limit) and read from that descriptor,
so a link or a FIFO swapped in between a check and an open is never followed.
Cost: one ``open``, one ``fstat`` and one read of at most ``limit`` bytes.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from skinet.errors import SkinetError, SourceError
from skinet.lang.larkerrors import MAX_SOURCE_CHARS


class FileRefused(SkinetError):
    """A file :func:`read_bytes` would not read; ``reason`` is one line without the path."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


_OPEN_FLAGS = (os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))


def read_bytes(path: str | Path, limit: int | None = None, root: Path | None = None) -> tuple[bytes, os.stat_result]:
    """A regular file's bytes and status, opened once and checked on the open descriptor.

    The path is resolved (links followed) and the resolved name opened with
    ``O_NOFOLLOW`` (a link swapped in since is refused, not followed) and
    ``O_NONBLOCK`` (a FIFO cannot block the opening); ``fstat`` of that
    descriptor must show a regular file within ``limit`` bytes, and, with
    ``root`` (a resolved folder), the descriptor's own path
    (``/proc/self/fd/N``) must lie inside it, so a folder of the path swapped
    for a link between resolving and opening is caught too.  Everything is then
    read from that descriptor (docs/deployment.md, "Files read and secrets written
    through no link").
    :class:`FileRefused` otherwise, never an ``OSError``.  Cost: one
    ``realpath``, one ``open``, one ``fstat``, the read.
    """
    try:
        resolved = os.path.realpath(path)
        if root is not None and not Path(resolved).is_relative_to(root):
            raise FileRefused(f"it lies outside {root}")
        fd = os.open(resolved, _OPEN_FLAGS)
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        raise FileRefused(f"cannot read file: {_reason(exc)}") from None
    try:
        if root is not None and not _opened_inside(fd, resolved, root):
            raise FileRefused(f"it lies outside {root}")
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise FileRefused(f"cannot read file: {os.strerror(errno.EISDIR)}")
        if not stat.S_ISREG(st.st_mode):
            raise FileRefused("not a regular file")
        if limit is not None and st.st_size > limit:
            raise FileRefused(f"file too large: {st.st_size} bytes (the limit is {limit})")
        chunks, total = [], 0
        while chunk := os.read(fd, 1 << 20 if limit is None else min(1 << 20, limit + 1 - total)):
            chunks.append(chunk)
            total += len(chunk)
            if limit is not None and total > limit:  # a file growing while read is bounded too
                raise FileRefused(f"file too large: {total} bytes (the limit is {limit})")
        return b"".join(chunks), st
    except OSError as exc:
        raise FileRefused(f"cannot read file: {_reason(exc)}") from None
    finally:
        os.close(fd)


def _opened_inside(fd: int, resolved: str, root: Path) -> bool:
    """Whether the open ``fd`` is a file inside ``root``: by its ``/proc/self/fd`` name,
    else (no ``/proc``) by device and inode against ``resolved``, re-resolved."""
    try:
        return Path(os.readlink(f"/proc/self/fd/{fd}")).is_relative_to(root)
    except OSError:
        st, again = os.fstat(fd), os.path.realpath(resolved)
        try:
            named = os.stat(again, follow_symlinks=False)
        except OSError:
            return False
        return Path(again).is_relative_to(root) and (st.st_dev, st.st_ino) == (named.st_dev, named.st_ino)


def _reason(exc: BaseException) -> str:
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)


def read_text(path: str | Path, limit: int | None = None, root: Path | None = None) -> str:
    """UTF-8 text of a file read by :func:`read_bytes`, or a :class:`SourceError`
    naming the file and the reason.

    A file larger than ``limit`` bytes is refused before it is read, so a huge
    file costs no memory.
    """
    try:
        data, _ = read_bytes(path, limit, root)
    except FileRefused as exc:
        raise SourceError.at(str(path), None, exc.reason) from None
    return utf8_text(data, str(path))


def read_source(path: str | Path, root: Path | None = None) -> str:
    """A model, properties, system or state file: at most MAX_SOURCE_CHARS bytes."""
    return read_text(path, MAX_SOURCE_CHARS, root)


def utf8_text(data: bytes, source: str) -> str:
    """``data`` as UTF-8 text, or a :class:`SourceError` naming ``source`` and the byte (never its content)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:  # its text quotes the byte: no content in an error
        raise SourceError.at(source, None, f"cannot read file: not UTF-8 text (byte {exc.start})") from None
