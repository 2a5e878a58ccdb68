"""Compiled kernel of the BVH reader (numba, `@njit(cache=True)`).

| kernel | numpy reference |
|---|---|
| `motion_table_kernel` | `np.loadtxt` (`samba.ingest.bvh._read_numbers`) |

`np.loadtxt` reads the motion section of the 49 shared CMU files (85 MB of text) in 0.4 to
1.6 s on one core, depending on the machine; this kernel tokenizes and converts the same
bytes in one pass, in 0.24 to 0.3 s, to the same float64 bits (`tests/test_bvh_reader.py`).
It accepts only plain decimal numbers (`[+-]digits[.digits][e[+-]digits]`) separated by
spaces, tabs and line ends; anything else (NaN, infinity, a word, a comment, a byte that
is not ASCII) makes it give up, and the reader falls back to `np.loadtxt` and its
diagnosis. Numbers whose value one float operation cannot give exactly (more than 15
significant digits, or a power of ten beyond 10^22) are listed, and converted after it,
correctly rounded, as Python's `float` converts them.
`KERNELS` warms it (`samba.base.KernelSet`).
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
_MAX_DIGITS = 19
"""Significant digits a uint64 mantissa holds without overflow."""
_MAX_EXPONENT_DIGITS = 6
"""Exponent digits kept; a longer exponent makes the number one for Python's `float`."""

_LF = 10
_BLANK = np.zeros(256, dtype=np.bool_)
_BLANK[[ord(" "), ord("\t"), ord("\r")]] = True
"""Bytes that separate numbers within a line (a CR ends no line: CRLF files read as LF)."""
_SEPARATOR = _BLANK.copy()
_SEPARATOR[_LF] = True
"""Bytes that may follow a number."""
_PLUS, _MINUS, _DOT, _ZERO, _NINE = 43, 45, 46, 48, 57
_LOWER_E, _UPPER_E = 101, 69


@compiled
def motion_table_kernel(
    text: np.ndarray, n_columns: int, max_rows: int, max_inexact: int
) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Read `text` (bytes as a uint8 array): whitespace-separated plain decimal numbers,
    `n_columns` per non-blank line, at most `max_rows` lines.

    Returns (status, rows, values (max_rows * n_columns,) float64 of which the first
    rows * n_columns are the table row by row, inexact (k, 3) int64: value slot, first
    and past-last byte of each number left for Python's `float`). The status is `READ`,
    `NOT_A_TABLE` or `NOT_PLAIN` (at most `max_inexact` inexact numbers are listed).
    """
    values = np.empty(max_rows * n_columns)
    inexact = np.empty((max_inexact, 3), dtype=np.int64)
    n_inexact = 0
    slot = 0
    rows = 0
    in_row = 0  # numbers read on the current line
    i = 0
    while i <= len(text):
        c = text[i] if i < len(text) else _LF  # the text ends as if with a line end
        if _BLANK[c]:
            i += 1
        elif c == _LF:
            if in_row and in_row != n_columns:
                return NOT_A_TABLE, rows, values, inexact[:n_inexact]
            if in_row:
                rows += 1
            in_row = 0
            i += 1
        elif in_row == n_columns or (in_row == 0 and rows == max_rows):
            return NOT_A_TABLE, rows, values, inexact[:n_inexact]
        else:
            end, value, exact = _number_at(text, i)
            if end < 0:
                return NOT_PLAIN, rows, values, inexact[:n_inexact]
            if not exact:
                if n_inexact == max_inexact:
                    return NOT_PLAIN, rows, values, inexact[:n_inexact]
                inexact[n_inexact, 0] = slot
                inexact[n_inexact, 1] = i
                inexact[n_inexact, 2] = end
                n_inexact += 1
            values[slot] = value
            slot += 1
            in_row += 1
            i = end
    return READ, rows, values, inexact[:n_inexact]


@compiled
def _number_at(text: np.ndarray, start: int) -> tuple[int, float, bool]:
    """The plain decimal number `[+-]digits[.digits][(e|E)[+-]digits]` at byte `start` of
    `text` (uint8), followed by a separator or the end: (past-last byte, value, whether
    the value is exact). Exact when the digits, less leading zeros, fit below 2^53 and
    their power of ten lies within 10^-22..10^22: then one correctly rounded product or
    quotient of exact float64s gives it, as `float` would. Past-last byte -1 when the
    bytes are no such number."""
    n = len(text)
    i = start
    negative = text[i] == _MINUS
    if text[i] in (_PLUS, _MINUS):
        i += 1
    mantissa = np.uint64(0)
    digits = 0  # significant digits read into the mantissa
    scale = 0  # power of ten of the mantissa's last digit
    seen_digit = False
    seen_dot = False
    exact = True
    while i < n:
        c = text[i]
        if _ZERO <= c <= _NINE:
            seen_digit = True
            if digits == _MAX_DIGITS:
                exact = False
            else:
                if digits or c != _ZERO:
                    mantissa = mantissa * np.uint64(10) + np.uint64(c - _ZERO)
                    digits += 1
                if seen_dot:
                    scale -= 1
        elif c == _DOT and not seen_dot:
            seen_dot = True
        else:
            break
        i += 1
    if not seen_digit:
        return -1, 0.0, False
    if i < n and text[i] in (_LOWER_E, _UPPER_E):
        i, exponent, exponent_exact = _exponent_at(text, i + 1)
        if i < 0:
            return -1, 0.0, False
        scale += exponent
        exact = exact and exponent_exact
    if i < n and not _SEPARATOR[text[i]]:
        return -1, 0.0, False
    if mantissa == 0 and exact:
        return i, -0.0 if negative else 0.0, True
    if not exact or mantissa >= _EXACT_MANTISSA or not -22 <= scale <= 22:
        return i, 0.0, False
    if scale >= 0:
        value = np.float64(mantissa) * _EXACT_POWERS[scale]
    else:
        value = np.float64(mantissa) / _EXACT_POWERS[-scale]
    return i, -value if negative else value, True


@compiled
def _exponent_at(text: np.ndarray, start: int) -> tuple[int, int, bool]:
    """The exponent `[+-]digits` at byte `start` of `text` (uint8, after the 'e'):
    (past-last byte, its value, whether it has at most `_MAX_EXPONENT_DIGITS` digits);
    past-last byte -1 when there are no digits."""
    n = len(text)
    i = start
    negative = i < n and text[i] == _MINUS
    if i < n and text[i] in (_PLUS, _MINUS):
        i += 1
    exponent = 0
    n_digits = 0
    while i < n and _ZERO <= text[i] <= _NINE:
        if n_digits < _MAX_EXPONENT_DIGITS:
            exponent = exponent * 10 + (text[i] - _ZERO)
        n_digits += 1
        i += 1
    if n_digits == 0:
        return -1, 0, False
    return i, -exponent if negative else exponent, n_digits <= _MAX_EXPONENT_DIGITS


def _example_table() -> tuple[int, int, np.ndarray, np.ndarray]:
    """Compile `motion_table_kernel` for the reader's argument types."""
    return motion_table_kernel(np.frombuffer(b"1.5 -2e3\n", dtype=np.uint8), 2, 1, 4)


KERNELS = KernelSet("BVH reader", (motion_table_kernel,), (_example_table,), estimate_s=2.0)
"""The reader's kernel, warmed by the first BVH file read."""
