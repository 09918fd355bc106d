"""Numbers as text, whole columns at a time: rows of a data file written in bulk.

A million particles' positions are three million floats; Python's ``repr``
of each takes seconds.  Here every column is turned into text by array
arithmetic: :func:`float_text` writes each float with 17 significant digits
(``-1.2345678901234567e+01``; trailing zeros dropped, ``0.0`` and ``-0.0`` as
such), which reads back bit for bit (17 digits tell every double from its
neighbours), :func:`int_text` writes integers.  Each gives a block of bytes,
one row per value, padded with NUL bytes; :func:`write_rows` puts the blocks
of a row side by side, drops the padding and writes the rows to a binary file
in chunks, so that no text of the whole file is held at once.

The digits of a float ``x`` are the integer ``D = round(x * 10**-k)`` with ``k``
chosen so that ``D`` has 17 digits; ``x * 10**-k`` is computed in double-double
arithmetic (the product split exactly into two doubles, Dekker's method, and
``10**-k`` as two doubles), far more precisely than the half unit of the 17th
digit that the round trip needs.  Floats beyond :data:`FAST_RANGE`
(subnormals, the largest magnitudes), infinities and NaN are written by
Python's ``repr``, one by one.
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache

import numpy as np

DIGITS = 17  # significant digits that tell every double from its neighbours
#: magnitudes written by array arithmetic (the double-double steps neither
#: overflow nor lose bits to underflow inside it); the others by ``repr``
FAST_RANGE = (1e-280, 1e280)
#: the bytes of one float's text: sign, 17 digits and a point, "e", the
#: exponent's sign and up to three digits (``repr`` of any double fits too)
FLOAT_WIDTH = 1 + DIGITS + 1 + 1 + 1 + 3
ROWS_PER_CHUNK = 1 << 16  # rows formatted and written at a time
_DEKKER = 134217729.0  # 2**27 + 1: splits a double into two of 26 bits each
_NUL, _SPACE, _NEWLINE = 0, ord(" "), ord("\n")
_ZERO = ord("0")


@lru_cache(maxsize=1)
def _powers_of_ten():
    """``10**p`` for the ``p`` the fast range needs, each as two doubles
    ``hi + lo`` (``hi`` the nearest double, ``lo`` the nearest to the rest);
    index ``p - first``."""
    first, last = -DIGITS - 300, 300
    hi, lo = [], []
    for p in range(first, last + 1):
        exact = Fraction(10) ** p
        hi.append(float(exact))
        lo.append(float(exact - Fraction(hi[-1])))
    return first, np.array(hi), np.array(lo)


def _split(a):
    """``a`` as ``hi + lo``, each with at most 26 significant bits (Dekker)."""
    c = _DEKKER * a
    hi = c - (c - a)
    return hi, a - hi


def _scaled(x, k):
    """``round(x * 10**-k)`` as int64, for ``x * 10**-k`` near ``10**16``."""
    first, hi_p, lo_p = _powers_of_ten()
    p_hi, p_lo = hi_p[-k - first], lo_p[-k - first]
    product = x * p_hi
    x_hi, x_lo = _split(x)
    p_hi_hi, p_hi_lo = _split(p_hi)
    # the rounding error of x * p_hi, exactly (Dekker's product), plus x * p_lo
    rest = (((x_hi * p_hi_hi - product) + x_hi * p_hi_lo + x_lo * p_hi_hi)
            + x_lo * p_hi_lo) + x * p_lo
    # (product is above 2**53: a whole number, exactly an int64)
    return product.astype(np.int64) + np.rint(rest).astype(np.int64)


def _digits(x):
    """``D`` (17 digits) and ``k`` with ``D * 10**k`` the nearest such number
    to ``|x|`` (``|x|`` in :data:`FAST_RANGE`)."""
    k = np.floor(np.log10(x)).astype(np.int64) - (DIGITS - 1)
    d = _scaled(x, k)
    for _ in range(2):  # (log10 may be one off next to a power of ten)
        high, low = d >= 10 ** DIGITS, d < 10 ** (DIGITS - 1)
        if not (high.any() or low.any()):
            break
        k = k + high - low
        off = high | low
        d[off] = _scaled(x[off], k[off])
    return d, k


@lru_cache(maxsize=1)
def _three_digits() -> np.ndarray:
    """The ASCII digits of 0..999, three each (``"007"``): ``(1000, 3)`` uint8."""
    return np.frombuffer("".join(f"{n:03d}" for n in range(1000)).encode(),
                         np.uint8).reshape(1000, 3)


def _decimal(n: np.ndarray, width: int) -> np.ndarray:
    """The last ``width`` decimal digits of each of ``n`` (int64, at least
    0), leading zeros included: ``(N, width)`` ASCII bytes.  Three digits at a
    time (one division each, then a table): NumPy's integer division is slow."""
    groups = []
    for _ in range(-(-width // 3)):
        n, rest = np.divmod(n, 1000)
        groups.append(_three_digits()[rest])
    return np.hstack(groups[::-1])[:, -width:] if groups else np.zeros((len(n), 0), np.uint8)


def float_text(x) -> np.ndarray:
    """Floats as text that reads back bit for bit: ``(N, FLOAT_WIDTH)`` bytes
    (uint8), one row per float, NUL where a row's text is shorter."""
    x = np.ascontiguousarray(x, dtype=np.float64).ravel()
    out = np.zeros((len(x), FLOAT_WIDTH), np.uint8)
    magnitude = np.abs(x)
    fast = (magnitude >= FAST_RANGE[0]) & (magnitude <= FAST_RANGE[1])
    d, k = _digits(magnitude[fast])
    digit = _decimal(d, DIGITS)
    fraction = digit[:, 1:]
    # the fraction's digits up to its last nonzero one (none: no point either)
    nonzero = fraction != _ZERO
    kept = np.where(nonzero.any(axis=1), DIGITS - 1 - np.argmax(nonzero[:, ::-1], axis=1), 0)
    text = np.zeros((len(d), FLOAT_WIDTH), np.uint8)
    text[:, 0] = np.where(x[fast] < 0, ord("-"), _NUL)
    text[:, 1] = digit[:, 0]
    text[:, 2] = np.where(kept > 0, ord("."), _NUL)
    at = 3 + DIGITS - 1  # where the exponent starts
    text[:, 3:at] = np.where(np.arange(DIGITS - 1) < kept[:, None], fraction, _NUL)
    exponent = k + DIGITS - 1
    shown = exponent != 0  # (no "e+00")
    e = np.abs(exponent)
    text[:, at] = np.where(shown, ord("e"), _NUL)
    text[:, at + 1] = np.where(shown, np.where(exponent < 0, ord("-"), ord("+")), _NUL)
    text[:, at + 2:] = np.where(shown[:, None], _decimal(e, 3), _NUL)
    text[:, at + 2] = np.where(e >= 100, text[:, at + 2], _NUL)  # at least two digits
    out[fast] = text
    zero = x == 0
    out[zero, :4] = np.frombuffer(b"-0.0", np.uint8)
    out[zero & ~np.signbit(x), 0] = _NUL
    for n in np.flatnonzero(~fast & ~zero):  # subnormal, huge, inf, nan: rare
        word = repr(float(x[n])).encode()
        out[n, :len(word)] = np.frombuffer(word, np.uint8)
    return out


def int_text(n) -> np.ndarray:
    """Integers (at least 0) as text: ``(N, width)`` bytes, NUL-padded."""
    n = np.asarray(n, dtype=np.int64).ravel()
    if len(n) and n.min() < 0:
        raise ValueError(f"int_text writes integers from 0 up, got {n.min()}")
    width = len(str(int(n.max(initial=0))))
    powers = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
    leading = (n[:, None] < powers) & (powers > 1)
    return np.where(leading, _NUL, _decimal(n, width)).astype(np.uint8)


def word_text(words) -> np.ndarray:
    """Strings (such as chemical symbols) as ``(N, width)`` bytes, NUL-padded."""
    words = np.asarray(words, dtype=np.bytes_)
    return words.view(np.uint8).reshape(len(words), words.dtype.itemsize)


def _block(column, rows: slice) -> np.ndarray:
    """The text of rows ``rows`` of one column: a string (the same in every
    row), a ``range`` of integers, or an array of floats, integers or strings."""
    if isinstance(column, str):
        return np.tile(np.frombuffer(column.encode(), np.uint8), (rows.stop - rows.start, 1))
    part = column[rows]
    if isinstance(part, range):
        return int_text(np.arange(part.start, part.stop, part.step))
    if part.dtype.kind == "f":
        return float_text(part)
    if part.dtype.kind in "iu":
        return int_text(part)
    return word_text(part)


def write_rows(fh, columns, count: int) -> None:
    """Write ``count`` rows to the binary file ``fh``, the columns of each
    separated by a space: each column a string (every row the same), a
    ``range`` of integers, or an array of ``count`` floats (:func:`float_text`),
    integers or strings."""
    for start in range(0, count, ROWS_PER_CHUNK):
        rows = slice(start, min(start + ROWS_PER_CHUNK, count))
        size = rows.stop - rows.start
        blocks = []
        for column in columns:
            blocks += [_block(column, rows), np.full((size, 1), _SPACE, np.uint8)]
        blocks[-1] = np.full((size, 1), _NEWLINE, np.uint8)
        text = np.hstack(blocks)
        fh.write(text[text != _NUL].tobytes())
