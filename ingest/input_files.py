"""Bounded reading of the motion files an import or an export is given: only regular
files (a FIFO, a device or a socket is refused by its type, before anything is read),
at most a size limit each, and error messages that quote at most `QUOTE_CHARS`
characters of what a file holds."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

from samba.base import InputError

MAX_FILE_BYTES = 100_000_000
"""Default largest file read (bytes, 100 MB: 25 times the largest CMU BVH file);
`samba db import --max-file-mb` raises it."""
QUOTE_CHARS = 80
"""Most characters of a file's content an error message quotes."""

_KINDS = {
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
    stat.S_IFDIR: "a directory",
}


def quoted(text: str | bytes) -> str:
    """`text` as an error message quotes it: its repr, cut to `QUOTE_CHARS` characters of
    content with the total length said when longer."""
    if len(text) <= QUOTE_CHARS:
        return repr(text)
    return f"{text[:QUOTE_CHARS]!r}... ({len(text):,} characters)"


def clipped(text: str) -> str:
    """`text` (a message that may hold a file's content) cut to `QUOTE_CHARS` characters,
    '...' marking a cut."""
    return text if len(text) <= QUOTE_CHARS else text[:QUOTE_CHARS] + "..."


def open_input(path: str | Path, max_bytes: int, error: type[InputError]) -> BinaryIO:
    """`path` opened for reading in binary, when it is a regular file (symbolic links
    followed) of at most `max_bytes` bytes; otherwise `error` naming it and why. Opening
    never blocks (a FIFO is refused, not waited on)."""
    source = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise error(source, f"cannot read file: {exc.strerror or exc}") from exc
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = _KINDS.get(stat.S_IFMT(info.st_mode), "not a file")
            raise error(source, f"cannot read file: {kind}, not a regular file")
        if info.st_size > max_bytes:
            raise error(source, _too_large(info.st_size, max_bytes))
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_input(path: str | Path, max_bytes: int, error: type[InputError]) -> bytes:
    """The bytes of the regular file `path` (see `open_input`), at most `max_bytes` of
    them: a file that grows past the limit while read is refused too."""
    with open_input(path, max_bytes, error) as stream:
        try:
            # Sized by the file, not the limit: reading into a buffer of the limit's size
            # takes twice as long as the read itself.
            size = os.fstat(stream.fileno()).st_size
            data = stream.read(size + 1)
            if len(data) > size:  # it grew since it was opened
                data += stream.read(max_bytes + 1 - len(data))
        except OSError as exc:
            raise error(str(path), f"cannot read file: {exc.strerror or exc}") from exc
    if len(data) > max_bytes:
        raise error(str(path), _too_large(len(data), max_bytes))
    return data


def _too_large(size: int, max_bytes: int) -> str:
    """The message of a file of `size` bytes over the limit `max_bytes`."""
    return (
        f"{size / 1e6:,.1f} MB, over the limit of {max_bytes / 1e6:g} MB a file "
        "(samba db import --max-file-mb raises it)"
    )
