"""A vectorised parser of decimal CSV text, with numpy alone (issue 16).

gyrocal's recordings, and the CSV files most logging tools write, hold plain decimal numbers:
an optional minus sign, digits, at most one decimal point (``-0.0123456789``,
``3599.999000000``, ``17``), now and then with an exponent (``%g`` writes ``1.23456789e-05``).
:func:`parse_plain_decimal` reads a block of such lines without a Python object per row or per
field, in a few passes over the bytes:

1. the separators (commas and newlines) bound the fields; each line must have ``ncols``;
2. each field's last :data:`MAX_DIGITS` bytes, right-aligned in a row of a small matrix (a
   gather of a sliding window), give its digits: the row's digit bytes, eight to a 64-bit word,
   are combined into one integer (:func:`_digits_value`) in which the field's own digits are
   the value modulo ``10**length`` (the previous field's bytes only add multiples of it);
3. the last decimal point in the row, if it lies in the field, gives the decimal places, and
   the digits left of it are divided by ten (the point itself added nothing);
4. a minus sign may only be a field's first byte (counted against the buffer's minus signs),
   at most one point per field (likewise), and a field must have a digit.

Exactness. A field whose digits form an integer ``m < 2**53`` with ``k <= 22`` decimal places
is ``m / 10**k`` where both operands are exact doubles, so the one IEEE division rounds the
exact quotient to the nearest double: the result equals Python's ``float(text)`` bit for bit
(the fast path of W. D. Clinger, "How to read floating point numbers accurately", PLDI 1990).
The rare field this does not cover (an exponent or plus sign, more than :data:`MAX_DIGITS`
bytes, or ``m >= 2**53``) is converted by ``float`` itself, so every value this parser returns
is the correctly rounded double of its text, the value the line-by-line checker of
``kit.recording`` gives.

Anything else (spaces, ``inf``/``nan``, letters other than an exponent's, an empty field
outside the column that may be empty, a row with the wrong number of fields) makes it return
None, and the caller parses the block another way.
"""

from __future__ import annotations

import sys

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["POW10", "parse_plain_decimal"]

#: 10**k as int64, k = 0..18 (the largest power an int64 holds).
POW10 = np.array([10**k for k in range(19)], dtype=np.int64)
#: Largest exponent whose power of ten is an exact double (5**22 < 2**53).
_MAX_EXACT_POW = 22
#: 10**k as doubles, k = 0..22: every one exact.
_POW10_FLOAT = np.array([float(10**k) for k in range(_MAX_EXACT_POW + 1)])
#: Largest integer below which every int64 converts to a double exactly.
_EXACT_INT = 1 << 53
#: Longest field (bytes) read by the vectorised path (two 64-bit words); a longer one goes to
#: ``float``.
MAX_DIGITS = 16
_ROW_SHIFT = 4  # log2(MAX_DIGITS)
#: Most fields of a piece, as a fraction, worth converting one by one with ``float``; with more
#: (a file written with exponents throughout) the caller's parser is faster.
MAX_SPECIAL = 0.125
_BIG_ENDIAN = sys.byteorder == "big"
#: Word masks that clear a word's first k bytes (k = 0..8; its first byte is its lowest).
_KEEP = np.array([((1 << 64) - 1) >> (8 * k) << (8 * k) for k in range(9)], dtype=np.uint64)
#: Bytes parsed per pass; the temporaries are some 12 bytes per byte of text, so a piece of
#: this size keeps them near 6 MiB whatever the block size.
PIECE_BYTES = 1 << 19
_COMMA, _NEWLINE, _DOT, _MINUS = b",\n.-"


def parse_plain_decimal(block: bytes, ncols: int, empty_col: int | None = None
                        ) -> np.ndarray | None:
    """Parse lines of ``ncols`` comma-separated decimal numbers into an array.

    Parameters
    ----------
    block : bytes
        Whole lines, each ending with ``\\n`` (no carriage returns).
    ncols : int
        Fields per line.
    empty_col : int, optional
        The one column whose field may be empty (read as NaN).

    Returns
    -------
    ndarray (n, ncols) of float64, or None
        The values, each the correctly rounded double of its text (equal to ``float(text)``);
        None if a field is not a decimal number of the kind the module docstring describes,
        a field other than ``empty_col`` is empty, or a line does not have ``ncols`` fields.
    """
    buf = np.frombuffer(block, dtype=np.uint8)
    if buf.size == 0:
        return np.empty((0, ncols))
    if buf[-1] != _NEWLINE:
        return None
    pieces = []
    lo = 0
    while lo < buf.size:
        hi = min(lo + PIECE_BYTES, buf.size)
        if hi < buf.size:  # cut after a newline
            hi = block.find(b"\n", hi - 1) + 1
        part = _parse_piece(buf[lo:hi], block, lo, ncols, empty_col)
        if part is None:
            return None
        pieces.append(part)
        lo = hi
    return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)


def _digits_value(win: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Each row of ``win`` (``(n, 16)`` bytes, a field right-aligned) as the integer its
    field's last ``length`` bytes spell, any byte other than a digit counting as a 0 digit,
    exact in int64.

    The digits are combined eight bytes at a time in a 64-bit word, pairs into two-digit
    lanes, those into four- and eight-digit lanes (the usual SWAR reduction), so the work per
    field is a few word operations rather than one per byte; the bytes before the field (the
    previous field's) are masked off a word at a time.
    """
    d = win - np.uint8(ord("0"))
    d *= d < 10
    v = d.view(np.uint64)  # (n, 2): the first byte of each word is its most significant digit
    if _BIG_ENDIAN:
        v = v.byteswap()
    drop = MAX_DIGITS - length  # bytes before the field: from the first word, then the second
    v[:, 0] &= _KEEP[np.clip(drop, 0, 8)]
    v[:, 1] &= _KEEP[np.clip(drop - 8, 0, 8)]
    v = (v * np.uint64(10) + (v >> np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
    v = (v * np.uint64(100) + (v >> np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
    v = (v * np.uint64(10000) + (v >> np.uint64(32))) & np.uint64(0x00000000FFFFFFFF)
    return (v[:, 0] * np.uint64(10**8) + v[:, 1]).astype(np.int64)


def _parse_piece(buf: np.ndarray, block: bytes, offset: int, ncols: int,
                 empty_col: int | None) -> np.ndarray | None:
    """:func:`parse_plain_decimal` on one piece of whole lines, ``buf`` (uint8), which is
    ``block[offset:offset + buf.size]``."""
    newline = buf == _NEWLINE
    sepmask = newline | (buf == _COMMA)
    n_dot = int(np.count_nonzero(buf == _DOT))
    n_minus = int(np.count_nonzero(buf == _MINUS))
    n_known = n_dot + n_minus + int(np.count_nonzero(sepmask))
    n_known += int(np.count_nonzero((buf - np.uint8(ord("0"))) < 10))
    sep = np.flatnonzero(sepmask)
    nfields = sep.size
    if nfields % ncols:
        return None
    # every line has exactly ncols fields: its separators are ncols - 1 commas then a newline
    kinds = newline[sep].reshape(-1, ncols)
    if not (kinds[:, -1].all() and not kinds[:, :-1].any()):
        return None
    start = np.empty(nfields, dtype=np.int64)
    start[0] = 0
    start[1:] = sep[:-1] + 1
    length = sep - start
    empty = length == 0
    if empty.any():
        col = np.arange(nfields) % ncols
        if empty_col is None or (empty & (col != empty_col)).any():
            return None
    # fields for float(): an exponent or plus sign, or too long for the int64 path
    special = length > MAX_DIGITS
    if n_known != buf.size:
        other = (buf == ord("e")) | (buf == ord("E")) | (buf == ord("+"))
        if n_known + int(np.count_nonzero(other)) != buf.size:
            return None
        special[np.searchsorted(sep, np.flatnonzero(other))] = True
    if np.count_nonzero(special) > MAX_SPECIAL * nfields:
        return None
    ap = np.empty(buf.size + MAX_DIGITS, dtype=np.uint8)
    ap[:MAX_DIGITS] = _COMMA
    ap[MAX_DIGITS:] = buf
    win = sliding_window_view(ap, MAX_DIGITS)[sep]  # row i: the bytes before separator i
    mant = _digits_value(win, np.minimum(length, MAX_DIGITS))
    # the last point in the row, if inside the field: its distance from the end = places
    flat = np.flatnonzero(win == _DOT)  # row-major, so each row's points in order
    rows = flat >> _ROW_SHIFT
    lastof = np.ones(rows.size, dtype=bool)
    lastof[:-1] = rows[1:] != rows[:-1]
    last = np.full(nfields, -1, dtype=np.int64)
    last[rows[lastof]] = flat[lastof] & (MAX_DIGITS - 1)
    places = MAX_DIGITS - 1 - last
    hasdot = (last >= 0) & (places < length) & ~special
    places[~hasdot] = 0
    neg = (buf[start] == _MINUS) & ~empty & ~special
    spec = np.flatnonzero(special)
    texts = [block[offset + start[i]:offset + sep[i]] for i in spec.tolist()]
    # every other minus sign or point of the buffer is a second one in some field
    joined = b",".join(texts)
    if (int(np.count_nonzero(hasdot)) + joined.count(b".") != n_dot
            or int(np.count_nonzero(neg)) + joined.count(b"-") != n_minus):
        return None
    if ((length - neg - hasdot == 0) & ~empty & ~special).any():  # "-", ".", "-."
        return None
    # the point added nothing: the digits left of it are ten times too large
    low = mant[hasdot] % POW10[places[hasdot]]
    mant[hasdot] = (mant[hasdot] - low) // 10 + low
    value = mant.astype(np.float64)
    value /= _POW10_FLOAT[places]  # exact operands: one correctly rounded division
    np.negative(value, out=value, where=neg)
    value[empty] = np.nan
    for i in np.flatnonzero((mant >= _EXACT_INT) & ~special).tolist():
        spec_text = block[offset + start[i]:offset + sep[i]]
        value[i] = float(spec_text)  # more than 15 significant digits: exact conversion
    for i, text in zip(spec.tolist(), texts, strict=True):
        try:
            value[i] = float(text)
        except ValueError:
            return None
    return value.reshape(-1, ncols)
