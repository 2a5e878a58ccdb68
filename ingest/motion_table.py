"""The motion section of a BVH file: its frame lines read as a (frames, channels) float64
table, by the compiled reader (`samba.ingest.kernels.motion_table_kernel`) or else by
`np.loadtxt`, its reference; a table that does not read is diagnosed by its first bad line
(`samba.ingest.errors.BvhError` naming the file and line).

A reader may ask for only some frames (`held`): the others are then checked for their
count of values and their characters but not converted, which is most of the cost of a
frame (an import at 30 fps uses one frame in four of a 120 fps file). A number made of
number characters that is no number (`1.2.3`) in a frame not converted is not found.
"""

from __future__ import annotations

import io
import math
import re
from types import ModuleType
from typing import NoReturn

import numpy as np

from samba.base import KernelSet, kernels_enabled
from samba.ingest.errors import BvhError
from samba.ingest.input_files import quoted

PLAIN_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
"""A plain decimal number: `[+-]digits[.digits][(e|E)[+-]digits]`."""
_GATHERED_TOKEN_BYTES = 40
"""Longest number `_convert_inexact` converts among the others (a (k, width) byte table)."""
_INEXACT_SHARE = 8
"""The reader's kernel leaves at most one number in this many to Python's `float` (more
than 15 significant digits, or beyond 10^22 either way: a Daz export writes two such in
every frame, 3.88251e-19) before it hands the file to `np.loadtxt`."""
_LINE_BYTES_A_VALUE = 64
"""Bytes a motion line may hold per value before `np.loadtxt` is not asked to read it (a
line far longer than its values need is diagnosed without being read as numbers)."""


def read_frames(
    body: str,
    first_line: int,
    frames: int,
    n_channels: int,
    source: str,
    held: np.ndarray | None = None,
) -> np.ndarray:
    """The motion table of the frame lines `body` (starting at line `first_line` of
    `source`), declared as `frames` rows of `n_channels` values: its rows `held`
    (ascending frame indices; all when None) as a (len(held), n_channels) float64 array.
    Read by the compiled reader, or else by `np.loadtxt`; a table that reads as neither,
    or holds NaN or infinity, raises a `BvhError` naming its first bad line."""
    motion = None
    if n_channels:
        buffer = np.frombuffer(body.encode("utf-8"), dtype=np.uint8)
        table = read_table(buffer, frames, n_channels, held)
        if table is not None:
            return table
        if _longest_line(buffer) <= _LINE_BYTES_A_VALUE * (n_channels + 1):
            motion = _read_numbers(body)
    if motion is None or motion.shape != (frames, n_channels) or not np.isfinite(motion).all():
        _diagnose_frames(body.split("\n"), first_line, frames, n_channels, source)
    return motion if held is None else motion[held]


def read_table(
    buffer: np.ndarray, frames: int, n_columns: int, held: np.ndarray | None = None
) -> np.ndarray | None:
    """The rows `held` (ascending indices below `frames`; all when None) of the table of
    plain decimal numbers in `buffer` (uint8 bytes, one row per non-blank line), as a
    (len(held), n_columns) float64 array read by the compiled kernel
    (`samba.ingest.kernels`): the same floats as `np.loadtxt`. None when the kernel is off
    or the text is anything else: other than `frames` rows of `n_columns`, NaN, infinity,
    a word (the caller then reads it with `np.loadtxt` and diagnoses it)."""
    if not kernels_enabled():
        return None
    kernels = compiled_reader()
    # A row takes at least two bytes a number: a header may claim more frames than the
    # text can hold, and the table is sized by the text.
    most_rows = min(frames, len(buffer) // (2 * n_columns) + 1)
    if held is None:
        held = np.arange(most_rows)
    elif most_rows < frames:
        return None  # too short for its frames
    most_inexact = 64 + len(held) * n_columns // _INEXACT_SHARE
    status, rows, values, inexact = kernels.motion_table_kernel(
        buffer, n_columns, most_rows, most_inexact, held
    )
    if status != kernels.READ or rows != frames:
        return None
    if len(inexact):
        _convert_inexact(buffer, values, inexact)
    if not np.isfinite(values).all():
        return None
    return values.reshape(len(held), n_columns)


def _longest_line(buffer: np.ndarray) -> int:
    """Bytes of the longest line of `buffer` (uint8 text, LF line ends)."""
    ends = np.flatnonzero(buffer == ord("\n"))
    bounds = np.concatenate([[-1], ends, [len(buffer)]])
    return int(np.diff(bounds).max()) - 1


def _convert_inexact(buffer: np.ndarray, values: np.ndarray, inexact: np.ndarray) -> None:
    """Set the numbers the kernel left, `inexact` (k, 3) rows of (slot in `values`, first
    and past-last byte in `buffer`), correctly rounded as Python's `float` and `np.loadtxt`
    read them: in one numpy conversion of their bytes (a number longer than
    `_GATHERED_TOKEN_BYTES` by `float` alone)."""
    long = inexact[:, 2] - inexact[:, 1] > _GATHERED_TOKEN_BYTES
    for slot, start, end in inexact[long].tolist():
        values[slot] = float(buffer[start:end].tobytes())
    slots, starts, ends = inexact[~long].T
    if len(slots):
        width = int((ends - starts).max())
        at = starts[:, None] + np.arange(width)
        tokens = buffer[np.minimum(at, len(buffer) - 1)]
        tokens[at >= ends[:, None]] = 0  # NUL ends a numpy bytes string
        values[slots] = tokens.view(f"S{width}").ravel().astype(np.float64)


def compiled_reader() -> ModuleType:
    """`samba.ingest.kernels`, imported and warmed (`KernelSet.warm_up`) on first use:
    numba's import (0.2 s) stays off commands that read no BVH."""
    import samba.ingest.kernels as kernels

    kernels.KERNELS.warm_up()
    return kernels


def reader_kernels() -> KernelSet:
    """The BVH reader's compiled kernels (`samba.ingest.kernels.KERNELS`), for `samba
    warmup`; importing them imports numba."""
    import samba.ingest.kernels as kernels

    return kernels.KERNELS


def _read_numbers(body: str) -> np.ndarray | None:
    """Whitespace-separated numbers, one row per non-blank line, as a (rows, columns)
    float64 array; None when the text does not read as such a table (a short row, a
    word). Reads with `np.loadtxt`'s C parser: the reference of `read_table`, which
    reads what it cannot (NaN, infinity, other number forms) and when kernels are off."""
    if not body.strip():  # loadtxt warns on empty input
        return None
    try:
        with np.errstate(all="ignore"):
            return np.loadtxt(io.StringIO(body), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        return None


def _diagnose_frames(
    lines: list[str], first_line: int, frames: int, n_channels: int, source: str
) -> NoReturn:
    """Find the first offending data line and raise a `BvhError` naming it."""
    row = 0
    last = max((i for i, line in enumerate(lines) if line.strip()), default=-1)
    for i, line in enumerate(lines):
        values = line.split(maxsplit=n_channels)  # a longer line: its first values, the rest
        if not values:
            continue
        where = first_line + i
        if i == last and len(values) < n_channels and row < frames:
            raise BvhError(
                source,
                f"file ends inside frame {row} ({len(values)} of {n_channels} values; truncated?)",
                where,
            )
        if row >= frames:
            raise BvhError(source, f"more frame lines than 'Frames: {frames}' declares", where)
        for v in values[:n_channels]:
            if not PLAIN_NUMBER.match(v) and v.lower().lstrip("+-") not in (
                "nan",
                "inf",
                "infinity",
            ):
                raise BvhError(source, f"frame {row}: {quoted(v)} is not a number", where)
        if len(values) != n_channels:
            short = len(line) <= _LINE_BYTES_A_VALUE * (n_channels + 1)  # counted at once
            count = len(line.split()) if short else f"more than {n_channels}"
            raise BvhError(
                source,
                f"frame {row} has {count} values, the hierarchy declares {n_channels} channels",
                where,
            )
        if not all(math.isfinite(float(v)) for v in values):
            raise BvhError(source, f"frame {row} holds NaN or infinity", where)
        row += 1
    if row < frames:
        raise BvhError(
            source,
            f"file ends after {row} of the {frames} frames 'Frames:' declares (truncated?)",
            first_line + last if last >= 0 else first_line - 1,
        )
    raise BvhError(source, "motion data could not be read", first_line)
