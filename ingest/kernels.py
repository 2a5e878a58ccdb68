"""Compiled kernels of the BVH reader (numba, `@njit(cache=True)`).

| kernel | numpy reference |
|---|---|
| `motion_table_kernel` | `np.loadtxt` (`samba.ingest.motion_table._read_numbers`) |
| `sampled_positions_kernel` | `samba.ingest.bvh.BvhFile.sampled_positions` with kernels off |

`np.loadtxt` reads the motion section of the 49 shared CMU files (85 MB of text) in 0.46 to
1.6 s on one core, depending on the machine; this kernel tokenizes and converts the same
bytes in one pass, in 0.17 to 0.3 s, to the same float64 bits (`tests/test_bvh_reader.py`).
It accepts only plain decimal numbers (`[+-]digits[.digits][e[+-]digits]`) separated by
spaces, tabs and line ends; anything else (NaN, infinity, a word, a comment, a byte that
is not ASCII) makes it give up, and the reader falls back to `np.loadtxt` and its
diagnosis. Numbers whose value one float operation cannot give exactly (more than 15
significant digits, or a power of ten beyond 10^22) are listed, and converted after it,
correctly rounded, as Python's `float` converts them. Rows the caller does not need are
only checked (count of values, characters), not converted.

The second kernel turns the motion rows into joint positions, sampled at the output
frame rate: Euler angles to quaternions, interpolation and forward kinematics in one loop
(the numpy path builds (frames, joints, 4) and (frames, joints, 3, 3) arrays for each
step). Both release the GIL, so `samba db import`'s reading threads overlap them.
`KERNELS` warms them (`samba.base.KernelSet`).
"""

from __future__ import annotations

import numpy as np

from samba.base import KernelSet, compiled

READ = 0
"""Status: every line read, rows counted."""
NOT_A_TABLE = 1
"""Status: a line holds another number of values than the columns, or there are more
rows than room was given for."""
NOT_PLAIN = 2
"""Status: a token is not a plain decimal number, or too many need Python's `float`."""

_EXACT_POWERS = np.array([10.0**k for k in range(23)])
"""10^0 .. 10^22: the powers of ten a float64 holds exactly."""
_EXACT_MANTISSA = 2**53
"""Integers below it are exact in a float64."""
_MAX_DIGITS = 18
"""Significant digits an int64 mantissa holds without overflow."""
_MAX_EXPONENT_DIGITS = 6
"""Exponent digits kept; a longer exponent makes the number one for Python's `float`."""

_TAB, _LF, _CR, _SPACE = 9, 10, 13, 32
_PLUS, _MINUS, _DOT, _ZERO = 43, 45, 46, 48
_LOWER_E, _UPPER_E = 101, 69

_BYTE_KINDS = np.full(256, 2, dtype=np.int64)
"""Each byte's kind in a row that is only checked: 0 separates numbers (space, tab, CR),
1 may be part of one (digits, signs, '.', 'e', 'E'), 2 may not (any other byte)."""
_BYTE_KINDS[[_SPACE, _TAB, _CR]] = 0
_BYTE_KINDS[list(b"0123456789+-.eE")] = 1


@compiled
def _checked_row(text: np.ndarray, i: int) -> tuple[int, int, bool]:
    """The end (index of its LF, or the text's length) of the row from byte `i` of `text`,
    its count of values (runs of number characters) and whether it holds a byte that is
    not `_BYTE_KINDS` 0 or 1; without a branch a byte but the line end's."""
    n = len(text)
    tokens = 0
    previous = 0
    kinds = 0
    while i < n:
        c = text[i]
        if c == _LF:
            break
        kind = _BYTE_KINDS[c]
        tokens += kind & (1 - previous)
        previous = kind & 1
        kinds |= kind
        i += 1
    return i, tokens, kinds > 1


@compiled
def motion_table_kernel(
    text: np.ndarray, n_columns: int, max_rows: int, max_inexact: int, held: np.ndarray
) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Read `text` (bytes as a uint8 array): whitespace-separated plain decimal numbers,
    `n_columns` per non-blank line, at most `max_rows` lines. Spaces, tabs and CRs
    separate numbers (a CR ends no line: CRLF files read as LF); the text ends as if with
    a line end. Only the rows `held` (ascending int64 row indices) are converted; any
    other row is checked for its count of values and its characters (digits, signs, '.',
    'e', 'E') alone, in two fifths of the time.

    Returns (status, rows, values (len(held) * n_columns,) float64 whose first
    k * n_columns are the k held rows below `rows`, row by row, inexact (m, 3) int64: value
    slot, first and past-last byte of each number left for Python's `float`). The status
    is `READ`, `NOT_A_TABLE` or `NOT_PLAIN` (at most `max_inexact` inexact numbers are
    listed).

    A number `[+-]digits[.digits][(e|E)[+-]digits]` is exact when its digits, less
    leading zeros, fit below 2^53 (at most `_MAX_DIGITS` of them read) and their power of
    ten lies within 10^-22..10^22: then one correctly rounded product or quotient of exact
    float64s gives it, as `float` would; any other is listed as inexact.
    """
    values = np.empty(len(held) * n_columns)
    inexact = np.empty((max_inexact, 3), dtype=np.int64)
    n_inexact = 0
    slot = 0
    rows = 0
    next_held = 0  # index into `held` of the next row to convert
    in_row = 0  # numbers read on the current line
    n = len(text)
    i = 0
    while i <= n:
        c = text[i] if i < n else _LF
        if c in (_SPACE, _TAB, _CR):
            i += 1
            continue
        if c == _LF:
            if in_row and in_row != n_columns:
                return NOT_A_TABLE, rows, values, inexact[:n_inexact]
            if in_row:
                rows += 1
                next_held += 1
            in_row = 0
            i += 1
            continue
        if in_row == n_columns or (in_row == 0 and rows == max_rows):
            return NOT_A_TABLE, rows, values, inexact[:n_inexact]
        if in_row == 0 and (next_held == len(held) or held[next_held] != rows):
            i, tokens, other = _checked_row(text, i)  # a row not held: only checked
            if other:
                return NOT_PLAIN, rows, values, inexact[:n_inexact]
            if tokens != n_columns:
                return NOT_A_TABLE, rows, values, inexact[:n_inexact]
            rows += 1
            i += 1
            continue
        start = i
        negative = c == _MINUS
        if c in (_MINUS, _PLUS):
            i += 1
        mantissa = 0
        digits = 0  # significant digits read into the mantissa
        scale = 0  # power of ten of the mantissa's last digit
        seen_digit = False
        exact = True
        in_fraction = False
        while i < n:
            digit = np.int64(text[i]) - _ZERO
            if 0 <= digit <= 9:
                seen_digit = True
                if digits == _MAX_DIGITS:
                    exact = False
                else:
                    if digits or digit:
                        mantissa = mantissa * 10 + digit
                        digits += 1
                    scale -= 1 if in_fraction else 0
            elif text[i] == _DOT and not in_fraction:
                in_fraction = True
            else:
                break
            i += 1
        if not seen_digit:
            return NOT_PLAIN, rows, values, inexact[:n_inexact]
        if i < n and text[i] in (_LOWER_E, _UPPER_E):
            i += 1
            exponent_negative = i < n and text[i] == _MINUS
            if i < n and text[i] in (_MINUS, _PLUS):
                i += 1
            exponent = 0
            exponent_digits = 0
            while i < n:
                digit = np.int64(text[i]) - _ZERO
                if not 0 <= digit <= 9:
                    break
                if exponent_digits < _MAX_EXPONENT_DIGITS:
                    exponent = exponent * 10 + digit
                exponent_digits += 1
                i += 1
            if exponent_digits == 0:
                return NOT_PLAIN, rows, values, inexact[:n_inexact]
            exact = exact and exponent_digits <= _MAX_EXPONENT_DIGITS
            scale += -exponent if exponent_negative else exponent
        if i < n and text[i] not in (_SPACE, _TAB, _CR, _LF):
            return NOT_PLAIN, rows, values, inexact[:n_inexact]
        value = 0.0
        if not exact or mantissa >= _EXACT_MANTISSA or not -22 <= scale <= 22:
            if mantissa or not exact:  # a zero of a short exponent is exact whatever its scale
                if n_inexact == max_inexact:
                    return NOT_PLAIN, rows, values, inexact[:n_inexact]
                inexact[n_inexact, 0] = slot
                inexact[n_inexact, 1] = start
                inexact[n_inexact, 2] = i
                n_inexact += 1
        elif scale >= 0:
            value = mantissa * _EXACT_POWERS[scale]
        else:
            value = mantissa / _EXACT_POWERS[-scale]
        values[slot] = -value if negative else value
        slot += 1
        in_row += 1
    return READ, rows, values, inexact[:n_inexact]


@compiled
def sampled_positions_kernel(
    motion: np.ndarray,
    parents: np.ndarray,
    offsets: np.ndarray,
    rotation_columns: np.ndarray,
    rotation_axes: np.ndarray,
    position_columns: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    fractions: np.ndarray,
) -> np.ndarray:
    """World positions (m, J, 3) of a joint hierarchy driven by BVH channels, sampled
    between motion rows: sample f lies `fractions[f]` (0..1) of the way from row
    `before[f]` to row `after[f]` of `motion` (rows, channels; degrees and file units).

    Joint j has parent `parents[j]` (-1 for a root; parents first) and rest translation
    `offsets[j]` (3,) in file units, whose component a replaced by column
    `position_columns[j, a]` where that is not -1; it turns by the intrinsic rotations
    about axes `rotation_axes[j, k]` (0, 1, 2 for X, Y, Z) by the angles in columns
    `rotation_columns[j, k]`, k in order up to the first -1. Rotations are interpolated as
    unit quaternions on the shorter arc (normalised lerp), translations linearly: the
    kernel of `local_transforms`, `sample_rotations`, `sample_linear` and
    `forward_kinematics` in turn (`samba.ingest.bvh.BvhFile.sampled_positions`).
    """
    m, n_joints = len(before), len(parents)
    world = np.empty((m, n_joints, 3))
    turns = np.empty((n_joints, 3, 3))  # world rotation of each joint in the current sample
    local = np.empty((3, 3))
    ends = np.empty((2, 4))  # the joint's quaternion at the rows before and after
    offset = np.empty(3)
    for f in range(m):
        t = fractions[f]
        for j in range(n_joints):
            for e in range(2):
                if e == 1 and after[f] == before[f]:
                    ends[1] = ends[0]
                    break
                row = before[f] if e == 0 else after[f]
                x, y, z, w = 0.0, 0.0, 0.0, 1.0
                for k in range(3):
                    column = rotation_columns[j, k]
                    if column < 0:
                        break
                    half = np.radians(motion[row, column]) / 2
                    s, c = np.sin(half), np.cos(half)
                    axis = rotation_axes[j, k]
                    bx = s if axis == 0 else 0.0
                    by = s if axis == 1 else 0.0
                    bz = s if axis == 2 else 0.0
                    x, y, z, w = (
                        w * bx + x * c + y * bz - z * by,
                        w * by - x * bz + y * c + z * bx,
                        w * bz + x * by - y * bx + z * c,
                        w * c - x * bx - y * by - z * bz,
                    )
                ends[e, 0], ends[e, 1], ends[e, 2], ends[e, 3] = x, y, z, w
            dot = 0.0
            for k in range(4):
                dot += ends[0, k] * ends[1, k]
            sign = 1.0 if dot >= 0 else -1.0
            for k in range(4):
                ends[0, k] += t * (sign * ends[1, k] - ends[0, k])
            norm = np.sqrt(ends[0, 0] ** 2 + ends[0, 1] ** 2 + ends[0, 2] ** 2 + ends[0, 3] ** 2)
            x, y, z, w = ends[0, 0] / norm, ends[0, 1] / norm, ends[0, 2] / norm, ends[0, 3] / norm
            local[0, 0] = 1 - 2 * (y * y + z * z)
            local[0, 1] = 2 * (x * y - z * w)
            local[0, 2] = 2 * (x * z + y * w)
            local[1, 0] = 2 * (x * y + z * w)
            local[1, 1] = 1 - 2 * (x * x + z * z)
            local[1, 2] = 2 * (y * z - x * w)
            local[2, 0] = 2 * (x * z - y * w)
            local[2, 1] = 2 * (y * z + x * w)
            local[2, 2] = 1 - 2 * (x * x + y * y)
            for a in range(3):
                offset[a] = offsets[j, a]
                column = position_columns[j, a]
                if column >= 0:
                    start = motion[before[f], column]
                    offset[a] = start + t * (motion[after[f], column] - start)
            parent = parents[j]
            if parent < 0:
                turns[j] = local
                world[f, j] = offset
                continue
            for a in range(3):
                moved = 0.0
                for b in range(3):
                    moved += turns[parent, a, b] * offset[b]
                    turns[j, a, b] = (
                        turns[parent, a, 0] * local[0, b]
                        + turns[parent, a, 1] * local[1, b]
                        + turns[parent, a, 2] * local[2, b]
                    )
                world[f, j, a] = world[f, parent, a] + moved
    return world


def _example_table() -> tuple[int, int, np.ndarray, np.ndarray]:
    """Compile `motion_table_kernel` for the reader's argument types."""
    text = np.frombuffer(b"1.5 -2e3\n0 1\n", dtype=np.uint8)
    return motion_table_kernel(text, 2, 2, 4, np.array([1]))


def _example_positions() -> np.ndarray:
    """Compile `sampled_positions_kernel` for the reader's argument types."""
    joints = np.array([[0, 1, 2], [-1, -1, -1]])
    return sampled_positions_kernel(
        np.zeros((2, 3)),
        np.array([-1, 0]),
        np.zeros((2, 3)),
        joints,
        joints,
        joints[::-1].copy(),
        np.array([0]),
        np.array([1]),
        np.array([0.5]),
    )


KERNELS = KernelSet(
    "BVH reader",
    (motion_table_kernel, sampled_positions_kernel),
    (_example_table, _example_positions),
    estimate_s=4.0,
)
"""The reader's kernels, warmed by the first BVH file read."""
