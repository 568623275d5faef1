"""numba kernels for loading large OBJ files: the line scan, the line kinds and the number
parse in one pass each.

:mod:`crackbake.io.obj_checks` and :mod:`crackbake.io.obj_reader` do the same work with numpy;
from :data:`crackbake.io.obj_checks.JIT_BYTES` of text, numba's import and cache loads (about
0.5 CPU-s) cost less than numpy's passes over every byte: at 1.5M faces (107 MB)
``numpy.fromstring`` alone took 2 s of the 4.5 s load, the chunked scan 0.7 s.  Each kernel
gives the numpy path's arrays bit for bit, or says it cannot (``ok`` False) and the caller runs
the numpy path on the same input: a kernel takes only the numbers it parses exactly as
``numpy.fromstring`` does (see :func:`parse_floats`).

A module of its own so that small loads never import numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.jit import light_cache_loads

# the first kernel of a load: numba's cache loads without its compiler's set-up (0.3 CPU-s)
light_cache_loads()

_LF, _CR, _SPACE, _TAB, _HASH, _SLASH, _MINUS, _DOT = 10, 13, 32, 9, 35, 47, 45, 46
_ZERO, _NINE = 48, 57
# Line kinds, as obj_reader numbers them.
_BLANK, _V, _VT, _VN, _F, _O, _G, _S, _USEMTL, _MTLLIB, _COMMENT, _OTHER = range(12)
# 10**k for k <= 22 is exact in float64 (Clinger's fast path).
_POW10 = np.array([10.0**k for k in range(23)])
# Below 2**53 every integer mantissa is exact in float64.
_EXACT = 1 << 53


@njit(cache=True, nogil=True)
def scan_lines(a: np.ndarray, n_lines: int):
    """One pass of :func:`crackbake.io.obj_checks.scan` over ``a`` (uint8, ending in a newline
    and holding ``n_lines`` of them).

    Returns
    -------
    ends : (L,) int64
        Offset of each line's newline.
    tokens : (L,) int32
        Tokens per line, keyword included (whitespace: space, tab, CR, LF).
    first_short_v : int
        0-based line of the first ``v`` line with fewer than three numbers, -1: none.
    short_faces : int
        ``f`` lines with fewer than three corners.
    first_zero : int
        0-based line of the first ``f`` line with a token ``0`` or ``0/...``, -1: none.
    """
    n = len(a)
    ends = np.empty(n_lines, np.int64)
    tokens = np.empty(n_lines, np.int32)
    first_short_v = -1
    first_zero = -1
    short_faces = 0
    line = 0
    start = 0
    count = 0
    zero_here = False
    prev_ws = True
    for i in range(n):
        c = a[i]
        ws = c == _SPACE or c == _LF or c == _TAB or c == _CR
        if not ws and prev_ws:
            count += 1
            if c == _ZERO and i + 1 < n:
                d = a[i + 1]
                if d == _SPACE or d == _LF or d == _TAB or d == _CR or d == _SLASH:
                    zero_here = True
        prev_ws = ws
        if c == _LF:
            ends[line] = i
            tokens[line] = count
            b0 = a[start]
            b1 = a[min(start + 1, n - 1)]
            if b1 == _SPACE or b1 == _TAB:
                if b0 == 118:  # "v"
                    if count < 4 and first_short_v < 0:
                        first_short_v = line
                elif b0 == 102:  # "f"
                    if count < 4:
                        short_faces += 1
                    if zero_here and first_zero < 0:
                        first_zero = line
            line += 1
            start = i + 1
            count = 0
            zero_here = False
    return ends, tokens, first_short_v, short_faces, first_zero


@njit(cache=True, nogil=True)
def line_kinds(a: np.ndarray, ends: np.ndarray, tokens: np.ndarray) -> np.ndarray:
    """Each line's kind as :func:`crackbake.io.obj_reader._kinds` numbers it before it looks
    at the ``_OTHER`` lines (int8)."""
    n = len(a)
    kinds = np.empty(len(ends), np.int8)
    start = 0
    for line in range(len(ends)):
        b0 = a[start]
        b1 = a[min(start + 1, n - 1)]
        b2 = a[min(start + 2, n - 1)]
        k = _OTHER
        if b0 == _LF or tokens[line] == 0:
            k = _BLANK
        if b0 == _HASH:
            k = _COMMENT
        elif b1 == _SPACE:
            if b0 == 118:  # v
                k = _V
            elif b0 == 102:  # f
                k = _F
            elif b0 == 111:  # o
                k = _O
            elif b0 == 103:  # g
                k = _G
            elif b0 == 115:  # s
                k = _S
        elif b0 == 118 and b2 == _SPACE:
            if b1 == 116:  # vt
                k = _VT
            elif b1 == 110:  # vn
                k = _VN
        kinds[line] = k
        start = ends[line] + 1
    return kinds


@njit(cache=True, nogil=True)
def _is_space(c) -> bool:
    # C's isspace, which numpy.fromstring's separator " " matches
    return c == _SPACE or (c >= 9 and c <= 13)


@njit(cache=True, nogil=True)
def parse_floats(a: np.ndarray, starts: np.ndarray, ends: np.ndarray, lines: np.ndarray,
                 skip: int, expected: int):
    """The numbers of ``lines`` (after their first ``skip`` bytes, the keyword), in order.

    Takes only numbers ``[-]digits[.digits]`` (or ``[-].digits``) with a mantissa below 2**53
    and at most 22 decimals, separated by whitespace: their value ``m / 10**k`` is one
    correctly rounded division of exact doubles (Clinger's fast path), which is what
    ``numpy.fromstring``'s ``strtod`` gives.  Anything else (exponents, ``nan``, long
    mantissas, another count than ``expected``...) returns ``ok`` False.

    Returns
    -------
    values : (expected,) float64
    ok : bool
    """
    out = np.empty(expected, np.float64)
    k = 0
    for j in range(len(lines)):
        line = lines[j]
        i = starts[line] + skip
        end = ends[line]
        if i < end and not _is_space(a[i]):
            return out, False  # the keyword runs into a number
        while i < end:
            c = a[i]
            if _is_space(c):
                i += 1
                continue
            neg = False
            if c == _MINUS:
                neg = True
                i += 1
            m = 0
            digits = 0
            decimals = 0
            dot = False
            while i < end:
                c = a[i]
                if c >= _ZERO and c <= _NINE:
                    m = m * 10 + (c - _ZERO)
                    digits += 1
                    if dot:
                        decimals += 1
                    if m >= _EXACT:
                        return out, False
                elif c == _DOT and not dot:
                    dot = True
                else:
                    break
                i += 1
            if digits == 0 or decimals > 22 or k >= expected:
                return out, False
            if i < end and not _is_space(a[i]):
                return out, False
            value = np.float64(m) / _POW10[decimals]
            out[k] = -value if neg else value
            k += 1
    return out, k == expected


@njit(cache=True, nogil=True)
def parse_faces(a: np.ndarray, starts: np.ndarray, ends: np.ndarray, lines: np.ndarray,
                expected: int):
    """The integers of the face ``lines`` (keyword ``f`` and slashes read as spaces, as
    :func:`crackbake.io.obj_reader._read` reads them) in order, and the slashes counted.

    Takes only integers ``[-]digits`` (at most 18 digits); anything else, or another count
    than ``expected``, returns ``ok`` False.

    Returns
    -------
    values : (expected,) int64
    slashes : int
    ok : bool
    """
    out = np.empty(expected, np.int64)
    k = 0
    slashes = 0
    for j in range(len(lines)):
        line = lines[j]
        i = starts[line] + 1
        end = ends[line]
        while i < end:
            c = a[i]
            if c == _SLASH:
                slashes += 1
                i += 1
                continue
            if _is_space(c):
                i += 1
                continue
            neg = False
            if c == _MINUS:
                neg = True
                i += 1
            m = 0
            digits = 0
            while i < end:
                c = a[i]
                if c < _ZERO or c > _NINE:
                    break
                m = m * 10 + (c - _ZERO)
                digits += 1
                i += 1
            if digits == 0 or digits > 18 or k >= expected:
                return out, slashes, False
            if i < end and not (_is_space(a[i]) or a[i] == _SLASH):
                return out, slashes, False
            out[k] = -m if neg else m
            k += 1
    return out, slashes, k == expected


@njit(cache=True, nogil=True)
def corner_indices(ints: np.ndarray, column: int, count: int, zero_ok: bool):
    """Column ``column`` of the face integers ``ints`` (C, per corner) as
    :func:`crackbake.io.obj_reader._indices` gives it (0-based, negative ones kept), in one
    pass; ``ok`` False where it would decline (an index beyond ``count``, or 0 unless
    ``zero_ok``)."""
    out = np.empty(len(ints), np.int64)
    for i in range(len(ints)):
        raw = ints[i, column]
        if raw > count or raw < -count or (raw == 0 and not zero_ok):
            return out, False
        out[i] = raw - 1 if raw > 0 else raw
    return out, True


def warm() -> None:
    """Compile (or load from numba's cache) the kernels, which only files above
    :data:`crackbake.io.obj_checks.JIT_BYTES` reach, with the argument types the readers pass."""
    from crackbake.geometry_kernels import area_counts, face_cross_kernel, summed_normals
    from crackbake.grouping import exact_ids

    text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
    a = np.frombuffer(text, np.uint8)
    ends, tokens, *_ = scan_lines(a, text.count(b"\n"))
    kinds = line_kinds(a, ends, tokens)
    starts = np.concatenate(([0], ends[:-1] + 1))
    v = parse_floats(a, starts, ends, np.flatnonzero(kinds == _V), 1, 9)[0].reshape(3, 3)
    ints = parse_faces(a, starts, ends, np.flatnonzero(kinds == _F), 6)[0]
    corner_indices(ints.reshape(-1, 2), 1, 3, False)
    f = (ints[::2] - 1).reshape(1, 3)
    cross = face_cross_kernel(v, f)
    area_counts(cross)
    summed_normals(3, np.arange(3, dtype=np.int64), f, cross)
    exact_ids(np.ascontiguousarray(v).view(np.uint64))
