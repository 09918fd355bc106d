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
GROUP_SIZE = 10 ** 4  # digits are written four at a time, from tables
FRACTION_GROUPS = (DIGITS - 1) // 4  # the groups after the point
EXPONENT_BOUND = 400  # the exponents tabled, -400..400 (doubles need -324..308)
_DEKKER = 134217729.0  # 2**27 + 1: splits a double into two of 26 bits each
_NUL, _SPACE, _NEWLINE, _ZERO = 0, ord(" "), ord("\n"), ord("0")


@lru_cache(maxsize=1)
def _powers_of_ten():
    """``10**p`` for the ``p`` the fast range needs, each as two doubles
    ``hi + lo`` (``hi`` the nearest double, ``lo`` the nearest to the rest),
    with ``hi`` split in halves (:func:`_split`); index ``p - first``."""
    first, last = -DIGITS - 300, 300
    hi, lo = [], []
    for p in range(first, last + 1):
        exact = Fraction(10) ** p
        hi.append(float(exact))
        lo.append(float(exact - Fraction(hi[-1])))
    hi = np.array(hi)
    return first, hi, np.array(lo), *_split(hi)


def _split(a):
    """``a`` as ``hi + lo``, each with at most 26 significant bits (Dekker)."""
    c = _DEKKER * a
    hi = c - (c - a)
    return hi, a - hi


def _scaled(x, k):
    """``round(x * 10**-k)`` as int64, for ``x * 10**-k`` near ``10**16``."""
    first, hi_p, lo_p, hi_hi_p, hi_lo_p = _powers_of_ten()
    at = -k - first
    p_hi, p_lo, p_hi_hi, p_hi_lo = hi_p[at], lo_p[at], hi_hi_p[at], hi_lo_p[at]
    product = x * p_hi
    x_hi, x_lo = _split(x)
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


def _words(texts) -> np.ndarray:
    """Texts of four bytes each (NUL-padded) as uint32 words, for gathering."""
    return np.frombuffer(b"".join(t.encode().rjust(4, b"\0") for t in texts), np.uint32)


@lru_cache(maxsize=1)
def _tables():
    """Four-digit groups as words: ``padded`` (``"0042"``), ``bare`` (leading
    zeros NUL, 0 all NUL: a leading group), ``units`` (``bare`` with 0 as
    ``"0"``: a number's only group) and ``stripped`` (trailing zeros NUL: the
    last group of a fraction); and the exponents ``e-324``..``e+308`` as rows
    of five bytes (exponent 0: none)."""
    group = range(GROUP_SIZE)
    padded = _words(f"{n:04d}" for n in group)
    bare = _words("" if n == 0 else str(n) for n in group)
    units = _words(str(n) for n in group)
    stripped = np.frombuffer(b"".join(f"{n:04d}".rstrip("0").encode().ljust(4, b"\0")
                                      for n in group), np.uint32)
    exponents = np.frombuffer(b"".join(
        (f"e{e:+03d}" if e else "").encode().ljust(5, b"\0")
        for e in range(-EXPONENT_BOUND, EXPONENT_BOUND + 1)), np.uint8).reshape(-1, 5)
    return padded, bare, units, stripped, exponents


def float_text(x) -> np.ndarray:
    """Floats as text that reads back bit for bit: ``(N, FLOAT_WIDTH)`` bytes
    (uint8), one row per float, NUL where a row's text is shorter."""
    padded, _, _, stripped, exponents = _tables()
    x = np.ascontiguousarray(x, dtype=np.float64).ravel()
    magnitude = np.abs(x)
    fast = (magnitude >= FAST_RANGE[0]) & (magnitude <= FAST_RANGE[1])
    every = fast.all()  # (as a rule: then no copies of a part)
    d, k = _digits(magnitude if every else magnitude[fast])
    lead, fraction = np.divmod(d, 10 ** (DIGITS - 1))
    # the fraction's 16 digits in four groups, up to its last nonzero group,
    # whose trailing zeros are dropped (a fraction of 0: no point either)
    high, low = np.divmod(fraction, GROUP_SIZE ** 2)
    groups = np.stack([*np.divmod(high, GROUP_SIZE), *np.divmod(low, GROUP_SIZE)], axis=1)
    nonzero = groups != 0
    last = FRACTION_GROUPS - 1 - np.argmax(nonzero[:, ::-1], axis=1)
    last[~nonzero.any(axis=1)] = -1
    words = np.zeros((len(d), FRACTION_GROUPS), np.uint32)
    for g in range(FRACTION_GROUPS):
        part = groups[:, g]
        words[:, g] = np.where(g < last, padded[part], np.where(g == last, stripped[part], 0))
    text = np.zeros((len(d), FLOAT_WIDTH), np.uint8)
    text[:, 0] = np.where((x if every else x[fast]) < 0, ord("-"), _NUL)
    text[:, 1] = lead + _ZERO
    text[:, 2] = np.where(last >= 0, ord("."), _NUL)
    at = 3 + DIGITS - 1  # where the exponent starts
    text[:, 3:at] = words.view(np.uint8)
    text[:, at:] = exponents[k + (DIGITS - 1) + EXPONENT_BOUND]
    if every:
        return text
    out = np.zeros((len(x), FLOAT_WIDTH), np.uint8)
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
    padded, bare, units, _, _ = _tables()
    n = np.asarray(n, dtype=np.int64).ravel()
    if len(n) and n.min() < 0:
        raise ValueError(f"int_text writes integers from 0 up, got {n.min()}")
    count = max(1, -(-len(str(int(n.max(initial=0)))) // 4))  # four-digit groups
    words = np.empty((len(n), count), np.uint32)
    rest = n
    for p in range(count):  # the p-th group from the right
        rest, part = np.divmod(rest, GROUP_SIZE)
        alone = units if p == 0 else bare  # (its text where no digits stand before it)
        words[:, count - 1 - p] = (alone[part] if p == count - 1 else
                                   np.where(n >= GROUP_SIZE ** (p + 1), padded[part],
                                            alone[part]))
    return words.view(np.uint8)


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
        blocks = [_block(column, rows) for column in columns]
        text = np.empty((rows.stop - rows.start,
                         sum(block.shape[1] + 1 for block in blocks)), np.uint8)
        at = 0
        for block in blocks:  # each followed by a space
            text[:, at:at + block.shape[1]] = block
            at += block.shape[1] + 1
            text[:, at - 1] = _SPACE
        text[:, -1] = _NEWLINE
        fh.write(text.tobytes().translate(None, b"\0"))  # (the padding dropped)
