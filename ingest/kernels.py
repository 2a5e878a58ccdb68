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
_MAX_DIGITS = 18
"""Significant digits an int64 mantissa holds without overflow."""
_MAX_EXPONENT_DIGITS = 6
"""Exponent digits kept; a longer exponent makes the number one for Python's `float`."""

_TAB, _LF, _CR, _SPACE = 9, 10, 13, 32
_PLUS, _MINUS, _DOT, _ZERO = 43, 45, 46, 48
_LOWER_E, _UPPER_E = 101, 69


@compiled
def motion_table_kernel(
    text: np.ndarray, n_columns: int, max_rows: int, max_inexact: int
) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Read `text` (bytes as a uint8 array): whitespace-separated plain decimal numbers,
    `n_columns` per non-blank line, at most `max_rows` lines. Spaces, tabs and CRs
    separate numbers (a CR ends no line: CRLF files read as LF); the text ends as if with
    a line end.

    Returns (status, rows, values (max_rows * n_columns,) float64 of which the first
    rows * n_columns are the table row by row, inexact (k, 3) int64: value slot, first
    and past-last byte of each number left for Python's `float`). The status is `READ`,
    `NOT_A_TABLE` or `NOT_PLAIN` (at most `max_inexact` inexact numbers are listed).

    A number `[+-]digits[.digits][(e|E)[+-]digits]` is exact when its digits, less
    leading zeros, fit below 2^53 (at most `_MAX_DIGITS` of them read) and their power of
    ten lies within 10^-22..10^22: then one correctly rounded product or quotient of exact
    float64s gives it, as `float` would; any other is listed as inexact.
    """
    values = np.empty(max_rows * n_columns)
    inexact = np.empty((max_inexact, 3), dtype=np.int64)
    n_inexact = 0
    slot = 0
    rows = 0
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
            rows += 1 if in_row else 0
            in_row = 0
            i += 1
            continue
        if in_row == n_columns or (in_row == 0 and rows == max_rows):
            return NOT_A_TABLE, rows, values, inexact[:n_inexact]
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


def _example_table() -> tuple[int, int, np.ndarray, np.ndarray]:
    """Compile `motion_table_kernel` for the reader's argument types."""
    return motion_table_kernel(np.frombuffer(b"1.5 -2e3\n", dtype=np.uint8), 2, 1, 4)


KERNELS = KernelSet("BVH reader", (motion_table_kernel,), (_example_table,), estimate_s=2.0)
"""The reader's kernel, warmed by the first BVH file read."""
