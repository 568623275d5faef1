"""A numba reader of ZIP/ZIPS scanline EXRs that takes ``crackbake inspect``'s statistics in
one pass: kept here, out of the package, to re-measure why ``crackbake inspect`` does not use
it (``benchmarks/bench_inspect.py``).

The idea (issue 25, ``inspect`` of a 4096² crack master in ≤ 0.5 s): instead of the OpenEXR
bindings' read (0.47 GB of half and float planes allocated, inflated, un-predicted and
scattered) and numpy's statistics of the planes, inflate each chunk (libdeflate through the
``deflate`` package where installed, else zlib-ng), undo the ZIP predictor and byte reorder
and take every channel's statistics in one numba pass while the chunk is in cache (GIL
released, the chunks split among threads), keeping no plane unless asked for.  It gives the
bindings' planes and numpy's statistics to the bit (``bench_inspect.py`` checks); but a
fresh process pays numba's start-up first (``import numba`` and the first call of a cached
kernel: 1.0 CPU-s on the loaded 2-core machine, where the bindings' read and numpy's
statistics together took 1.4), and its own pass (the predictor is a running sum over every
byte, two chains side by side) then costs about as much again: the command would be slower.
It could pay only where numba is already loaded (an in-process caller, a UDIM set of many
tiles).

The statistics are the ones :func:`crackbake.exchange.inspect._stats` takes with numpy, to
the bit: min and max are exact whatever the order; the mean is numpy's float64 sum, which
casts 8192 elements at a time into a buffer, adds each buffer pairwise (blocks of 128
elements summed in 8 lanes, halves added recursively) and the buffers one after another.
The pass keeps each aligned 128-element block's sum (the blocks never straddle two chunks
when a chunk's texel count is a multiple of 128) and the caller adds them up in numpy's
order.  Whatever this pass cannot match exactly gives None (a caller would take the
bindings and numpy): other compressions, tiled, deep or multi-part files, subsampled
channels, chunks not aligned to 128 texels, a NaN or an infinity in a plane, a float plane
whose minimum or maximum is zero while it holds both +0 and -0 (numpy's SIMD reduction picks
either), and any damage (the bindings then name it).

The layout (OpenEXR's file-layout specification; :mod:`crackbake.exchange.exrzip` writes it):
magic, version, the header's attributes, a null byte, one 64-bit offset per chunk, then the
chunks: the first scanline's y, the data's size, the data; ZIP data is zlib's format of the
scanlines' bytes reordered (the even bytes, then the odd ones) and delta-coded; a chunk whose
size is the raw size is stored as it is.
"""

from __future__ import annotations

import os
import struct
import threading

import numpy as np
from llvmlite import ir
from numba import njit
from numba.core import types
from numba.extending import intrinsic

try:  # libdeflate: a fifth of zlib-ng's CPU on these long-match streams
    import deflate as _deflate
except ImportError:  # pragma: no cover - optional
    _deflate = None
from zlib_ng import zlib_ng as _zlib

#: numpy's reduction buffer (elements cast and summed at a time) and its pairwise block.
SUM_BUFFER = 8192
SUM_BLOCK = 128
#: Chunk lines of each compression this module reads, by the file's compression code.
_LINES = {2: 1, 3: 16}
_NAMES = {2: "zips", 3: "zip"}
_SIZES = {0: 4, 1: 2, 2: 4}  # pixel type -> bytes
_DTYPES = {0: np.dtype(np.uint32), 1: np.dtype(np.float16), 2: np.dtype(np.float32)}
#: Version flags this reader refuses: tiled, deep, multi-part.
_OTHER_LAYOUTS = 0x200 | 0x800 | 0x1000
#: Worker threads besides the calling one (the chunks are independent).
THREADS = max(1, min(4, (os.cpu_count() or 1))) - 1


class Layout:
    """What the header says of the pixels: channels, size, chunks."""

    def __init__(self, names, types_, width, height, ymin, code, first_chunk):
        self.names = names
        self.ymin = ymin
        self.types = types_  # EXR pixel type per channel (0 uint, 1 half, 2 float)
        self.width = width
        self.height = height
        self.code = code
        self.lines = _LINES[code]
        self.first_chunk = first_chunk  # file offset of the chunk offset table


def parse_layout(buf: bytes) -> Layout | None:
    """The layout of a single-part ZIP or ZIPS scanline file, or None for anything else
    (or anything this parse does not understand: the bindings then read it)."""
    if len(buf) < 8 or buf[:4] != b"\x76\x2f\x31\x01":
        return None
    (version,) = struct.unpack_from("<I", buf, 4)
    if version & 0xFF != 2 or version & _OTHER_LAYOUTS:
        return None
    p, end = 8, len(buf)
    attrs = {}
    while p < end and buf[p] != 0:
        n = buf.find(b"\0", p, p + 256)
        t = buf.find(b"\0", n + 1, n + 257) if n >= 0 else -1
        if t < 0 or t + 5 > end:
            return None
        (size,) = struct.unpack_from("<i", buf, t + 1)
        if size < 0 or t + 5 + size > end:
            return None
        attrs[buf[p:n]] = (buf[n + 1 : t], t + 5, size)
        p = t + 5 + size
    if p >= end:
        return None
    try:
        kind, at, size = attrs[b"compression"]
        code = buf[at] if kind == b"compression" and size == 1 else -1
        if code not in _LINES:
            return None
        kind, at, size = attrs[b"dataWindow"]
        if kind != b"box2i" or size != 16:
            return None
        x0, y0, x1, y1 = struct.unpack_from("<iiii", buf, at)
        kind, at, size = attrs[b"channels"]
        if kind != b"chlist":
            return None
    except KeyError:
        return None
    names, types_ = [], []
    q, stop = at, at + size
    while q < stop and buf[q] != 0:
        n = buf.find(b"\0", q, stop)
        if n < 0 or n + 17 > stop:
            return None
        ptype, _, xs, ys = struct.unpack_from("<iB3xii", buf, n + 1)
        if ptype not in _SIZES or xs != 1 or ys != 1:
            return None
        try:
            names.append(buf[q:n].decode("utf-8"))
        except UnicodeDecodeError:
            return None
        types_.append(ptype)
        q = n + 17
    width, height = x1 - x0 + 1, y1 - y0 + 1
    if not names or width <= 0 or height <= 0 or names != sorted(names, key=str.encode):
        return None
    return Layout(names, types_, width, height, y0, code, p + 1)


@intrinsic
def _half_to_double(typingctx, x):  # pragma: no cover - compiled
    """binary16 bits -> float64, exact: LLVM's ``fpext`` (F16C where the CPU has it)."""
    if x != types.uint16:
        return None

    def codegen(context, builder, signature, args):
        half = builder.bitcast(args[0], ir.HalfType())
        return builder.fpext(half, ir.DoubleType())

    return types.float64(types.uint16), codegen


@intrinsic
def _float_to_double(typingctx, x):  # pragma: no cover - compiled
    """float32 bits -> float64, exact."""
    if x != types.uint32:
        return None

    def codegen(context, builder, signature, args):
        single = builder.bitcast(args[0], ir.FloatType())
        return builder.fpext(single, ir.DoubleType())

    return types.float64(types.uint32), codegen


@njit(cache=True, nogil=True)
def _block_sums(vals, kind, first, blocks, count):  # pragma: no cover - compiled
    """numpy's pairwise sums of ``count`` aligned 128-texel blocks of a row: 8 lanes summed
    down each block, then combined.  ``vals``: the row's bits (uint16 half, uint32 float or
    uint); ``first``: the index in ``blocks`` of the row's first block.  The lanes start at
    +0 where numpy starts at the first value: the same sums but for a lane of -0 only, which
    comes out +0; the plane's total starts at +0 too, so the sum is the same."""
    for b in range(count):
        o = b * SUM_BLOCK
        l0 = l1 = l2 = l3 = l4 = l5 = l6 = l7 = 0.0
        for i in range(o, o + SUM_BLOCK, 8):
            l0 += _value(vals, kind, i)
            l1 += _value(vals, kind, i + 1)
            l2 += _value(vals, kind, i + 2)
            l3 += _value(vals, kind, i + 3)
            l4 += _value(vals, kind, i + 4)
            l5 += _value(vals, kind, i + 5)
            l6 += _value(vals, kind, i + 6)
            l7 += _value(vals, kind, i + 7)
        blocks[first + b] = ((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7))


@njit(cache=True, nogil=True)
def _value(vals, kind, x):  # pragma: no cover - compiled
    if kind == 1:
        return _half_to_double(np.uint16(vals[x]))
    if kind == 2:
        return _float_to_double(np.uint32(vals[x]))
    return np.float64(vals[x])


@njit(cache=True, nogil=True)
def _row_stats(bits, kind, c, t0, acc, flags, blocks, tail, tail_from):  # pragma: no cover
    """Fold one row of channel ``c`` (its bits, uint16 or uint32; texel ``t0`` of the plane
    first) into the statistics.

    acc[c]: (min key, max key, non-zero count): half and float keys are the bits with the
    negative values' magnitude bits flipped, so that integer order is float order (-0 below
    +0); uint keys the values.  flags[c]: bit 0 a NaN or inf, bit 1 a +0, bit 2 a -0.
    blocks[c, k]: the pairwise sum of aligned block k of 128 texels (numpy's order), for the
    texels before ``tail_from``; tail[c, i]: texel ``tail_from + i`` as float64.
    """
    width = bits.shape[0]
    knz = np.int64(0)
    if kind == 1:
        kmn = np.int64(0x7FFF)
        kmx = np.int64(-0x8000)
        bad = False
        for x in range(width):
            v = np.int32(bits[x])
            key = v if v < 0x8000 else np.int32(0x7FFF) - v
            kmn = min(kmn, np.int64(key))
            kmx = max(kmx, np.int64(key))
            knz += np.int64((v & 0x7FFF) != 0)
            bad |= (v & 0x7C00) == 0x7C00
        if bad:
            flags[c] |= 1
    elif kind == 2:
        kmn = np.int64(0x7FFFFFFF)
        kmx = np.int64(-0x80000000)
        bad = False
        pz = False
        ng = False
        for x in range(width):
            v = np.int32(bits[x])
            key = v ^ ((v >> 31) & np.int32(0x7FFFFFFF))
            kmn = min(kmn, np.int64(key))
            kmx = max(kmx, np.int64(key))
            knz += np.int64((v & 0x7FFFFFFF) != 0)
            bad |= (v & 0x7F800000) == 0x7F800000
            pz |= v == 0
            ng |= v == np.int32(-0x80000000)
        if bad:
            flags[c] |= 1
        if pz:
            flags[c] |= 2
        if ng:
            flags[c] |= 4
    else:
        kmn = np.int64(0xFFFFFFFF)
        kmx = np.int64(0)
        for x in range(width):
            v = np.int64(bits[x])
            kmn = min(kmn, v)
            kmx = max(kmx, v)
            knz += np.int64(v != 0)
    acc[c, 0] = min(acc[c, 0], kmn)
    acc[c, 1] = max(acc[c, 1], kmx)
    acc[c, 2] += knz
    whole = min(width, max(tail_from - t0, 0)) // SUM_BLOCK
    if whole:
        _block_sums(bits, kind, t0 // SUM_BLOCK, blocks[c], whole)
    for x in range(whole * SUM_BLOCK, width):
        tail[c, t0 + x - tail_from] = _value(bits, kind, x)


@njit(cache=True, nogil=True)
def _zip_chunk(data, nl, width, kinds, base, acc, flags, blocks, tail, tail_from, planes,
               starts, keep, row16, row32):  # pragma: no cover - compiled
    """Decode one inflated ZIP chunk's ``nl`` scanlines and fold them into the statistics.

    The ZIP predictor is one running sum over the reordered bytes (each byte minus 128, that
    is xor 128, mod 256), the even bytes of the scanlines first, then the odd ones; the
    scanlines' bytes come out in order from two running sums side by side, one down each
    half (the second starts where the first ends: found first with a vectorised sum).  Each
    channel's row is built in a small buffer (``row16``/``row32``, in L1) and its statistics
    taken from there; no chunk-sized buffer is written.  With ``keep`` the rows are copied
    into ``planes`` (every plane's bytes, plane c from byte ``starts[c]``).
    """
    n = data.shape[0]
    h1 = n // 2
    s = np.int64(0)
    for i in range(h1):
        s += np.int64(data[i])
    a = np.int64(128)  # the sum before byte 0: 128 + (data[0] ^ 128) == data[0]
    b = a + s + 128 * h1
    k = 0
    nc = kinds.shape[0]
    for y in range(nl):
        t0 = base + y * width
        for c in range(nc):
            if kinds[c] == 1:
                for x in range(width):
                    a += np.int64(data[k] ^ 128)
                    b += np.int64(data[h1 + k] ^ 128)
                    row16[x] = np.uint16((a & 255) | ((b & 255) << 8))
                    k += 1
                _row_stats(row16, 1, c, t0, acc, flags, blocks, tail, tail_from)
                if keep:
                    planes[starts[c] + 2 * t0 : starts[c] + 2 * (t0 + width)] = row16.view(np.uint8)
            else:
                for x in range(width):
                    a += np.int64(data[k] ^ 128)
                    b += np.int64(data[h1 + k] ^ 128)
                    lo = (a & 255) | ((b & 255) << 8)
                    a += np.int64(data[k + 1] ^ 128)
                    b += np.int64(data[h1 + k + 1] ^ 128)
                    row32[x] = np.uint32(lo | (((a & 255) | ((b & 255) << 8)) << 16))
                    k += 2
                _row_stats(row32, kinds[c], c, t0, acc, flags, blocks, tail, tail_from)
                if keep:
                    planes[starts[c] + 4 * t0 : starts[c] + 4 * (t0 + width)] = row32.view(np.uint8)


@njit(cache=True, nogil=True)
def _raw_chunk(raw, nl, width, kinds, base, acc, flags, blocks, tail, tail_from, planes,
               starts, keep, row16, row32):  # pragma: no cover - compiled
    """:func:`_zip_chunk` for a chunk stored as it is (it would not shrink)."""
    k = 0
    nc = kinds.shape[0]
    for y in range(nl):
        t0 = base + y * width
        for c in range(nc):
            if kinds[c] == 1:
                row16.view(np.uint8)[:] = raw[k : k + 2 * width]
                k += 2 * width
                _row_stats(row16, 1, c, t0, acc, flags, blocks, tail, tail_from)
                if keep:
                    planes[starts[c] + 2 * t0 : starts[c] + 2 * (t0 + width)] = row16.view(np.uint8)
            else:
                row32.view(np.uint8)[:] = raw[k : k + 4 * width]
                k += 4 * width
                _row_stats(row32, kinds[c], c, t0, acc, flags, blocks, tail, tail_from)
                if keep:
                    planes[starts[c] + 4 * t0 : starts[c] + 4 * (t0 + width)] = row32.view(np.uint8)


def _pairwise(a: np.ndarray) -> float:
    """numpy's pairwise sum of a float64 run (its ``pairwise_sum``), for the last, partial
    buffer of a plane."""
    n = len(a)
    if n < 8:
        res = 0.0
        for v in a:
            res += float(v)
        return res
    if n <= SUM_BLOCK:
        r = [float(v) for v in a[:8]]
        i = 8
        while i < n - n % 8:
            for j in range(8):
                r[j] += float(a[i + j])
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for v in a[i:]:
            res += float(v)
        return res
    half = n // 2
    half -= half % 8
    return _pairwise(a[:half]) + _pairwise(a[half:])


def _sum(blocks: np.ndarray, tail: np.ndarray) -> float:
    """numpy's float64 sum of a plane from its block sums (whole buffers) and its tail."""
    per = SUM_BUFFER // SUM_BLOCK
    s = blocks.reshape(-1, per)
    while s.shape[1] > 1:  # the pairwise halving of each buffer, left + right
        s = s[:, 0::2] + s[:, 1::2]
    total = 0.0
    for v in s[:, 0].tolist():
        total += v
    if len(tail):
        total += _pairwise(tail)
    return total


class Unreadable(Exception):
    """The fast path cannot read this file exactly: the caller takes the bindings."""


def _inflate(data, n: int) -> bytes:
    if _deflate is not None:
        return _deflate.zlib_decompress(data, n)
    return _zlib.decompress(data, 15, n)


def scan(path: str | os.PathLike, keep: bool = False) -> dict | None:
    """Every channel's statistics (and with ``keep`` its plane) of a ZIP/ZIPS scanline EXR.

    Returns
    -------
    dict or None
        None when this reader does not handle the file (see the module docstring); else
        ``{"width", "height", "compression", "channels": {name: dict(dtype, min, max, sum,
        nonzero, size)}, "planes": {name: (H, W) ndarray} or None}``; ``min``/``max`` as
        Python floats, ``sum`` numpy's float64 sum.
    """
    try:
        with open(path, "rb") as fh:
            buf = fh.read()
    except OSError:
        return None
    layout = parse_layout(buf)
    if layout is None:
        return None
    try:
        return _scan(buf, layout, keep)
    except Unreadable:
        return None


def _scan(buf: bytes, lay: Layout, keep: bool) -> dict:
    w, h, nl = lay.width, lay.height, lay.lines
    npx = w * h
    tail_from = npx - npx % SUM_BUFFER
    if tail_from and w % SUM_BLOCK:  # a 128-texel block would straddle two rows
        raise Unreadable
    nchunks = -(-h // nl)
    if lay.first_chunk + 8 * nchunks > len(buf):
        raise Unreadable
    offs = np.frombuffer(buf, "<u8", nchunks, lay.first_chunk).astype(np.int64)
    sizes = [_SIZES[t] for t in lay.types]
    line_bytes = w * sum(sizes)
    kinds = np.array(lay.types, np.int64)
    nc = len(lay.names)
    blocks = np.zeros((nc, tail_from // SUM_BLOCK), np.float64)
    tail = np.zeros((nc, npx - tail_from), np.float64)
    starts = np.cumsum([0] + [npx * s for s in sizes[:-1]]).astype(np.int64)
    planes = np.empty(npx * sum(sizes) if keep else 0, np.uint8)
    next_chunk = iter(range(nchunks))
    lock = threading.Lock()
    results = []
    failed = []

    def work():
        acc = np.zeros((nc, 3), np.int64)
        acc[:, 0] = 2**62
        acc[:, 1] = -(2**62)
        flags = np.zeros(nc, np.int64)
        row16 = np.empty(w, np.uint16)
        row32 = np.empty(w, np.uint32)
        try:
            while True:
                with lock:
                    i = next(next_chunk, None)
                if i is None or failed:
                    break
                o = int(offs[i])
                if o < 0 or o + 8 > len(buf):
                    raise Unreadable
                y, size = struct.unpack_from("<ii", buf, o)
                rows = min(nl, h - i * nl)
                n = rows * line_bytes
                if y - lay.ymin != i * nl or size <= 0 or o + 8 + size > len(buf):
                    raise Unreadable
                data = memoryview(buf)[o + 8 : o + 8 + size]
                args = (rows, w, kinds, i * nl * w, acc, flags, blocks, tail, tail_from,
                        planes, starts, keep, row16, row32)  # fmt: skip
                if size == n:  # stored as it is
                    _raw_chunk(np.frombuffer(data, np.uint8), *args)
                    continue
                try:
                    plain = _inflate(data, n)
                except Exception as exc:  # noqa: BLE001 - any damage: the bindings say it
                    raise Unreadable from exc
                if len(plain) != n:
                    raise Unreadable
                _zip_chunk(np.frombuffer(plain, np.uint8), *args)
        except Unreadable:
            failed.append(True)
            return
        results.append((acc, flags))

    extra = [threading.Thread(target=work) for _ in range(min(THREADS, nchunks - 1))]
    for t in extra:
        t.start()
    work()
    for t in extra:
        t.join()
    if failed:
        raise Unreadable
    lo = np.min([r[0][:, 0] for r in results], axis=0)
    hi = np.max([r[0][:, 1] for r in results], axis=0)
    nonzero = np.sum([r[0][:, 2] for r in results], axis=0)
    flags = np.bitwise_or.reduce([r[1] for r in results], axis=0)
    channels = {}
    for c, name in enumerate(lay.names):
        kind = lay.types[c]
        if flags[c] & 1:
            raise Unreadable  # NaN or inf: the caller's masked statistics
        if kind == 2 and flags[c] & 6 == 6 and {lo[c], hi[c]} & {-1, 0}:
            raise Unreadable  # numpy's min/max of mixed zeros depends on its SIMD order
        if kind == 1:
            back = np.array([lo[c], hi[c]], np.int64).astype(np.int16)
            back ^= (back >> 15) & np.int16(0x7FFF)
            mn, mx = (float(v) for v in back.view(np.float16))
        elif kind == 2:
            back = np.array([lo[c], hi[c]], np.int64).astype(np.int32)
            back ^= (back >> 31) & np.int32(0x7FFFFFFF)
            mn, mx = (float(v) for v in back.view(np.float32))
        else:
            mn, mx = float(lo[c]), float(hi[c])
        channels[name] = {
            "dtype": _DTYPES[kind],
            "min": mn,
            "max": mx,
            "sum": _sum(blocks[c], tail[c]),
            "nonzero": int(nonzero[c]),
            "size": npx,
        }
    out_planes = None
    if keep:
        out_planes = {
            name: planes[starts[c] : starts[c] + npx * sizes[c]].view(
                _DTYPES[lay.types[c]]).reshape(h, w)
            for c, name in enumerate(lay.names)
        }
    return {"width": w, "height": h, "compression": _NAMES[lay.code], "channels": channels,
            "planes": out_planes}  # fmt: skip
