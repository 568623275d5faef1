"""Scanline EXR files with ZIP or ZIPS compression, encoded here: numba + zlib-ng.

Why not the OpenEXR bindings for these: the 4096² crack master is 0.47 GB of planes, and
OpenEXR's ZIP path spent about 1.3 CPU-s on it (quiet 2-core machine; 2.9 s loaded), 40 % in
its byte reordering and predictor and 53 % in deflate, at every zip level: the write stage's
critical path.  The same transform as numba passes (GIL released) and zlib-ng's deflate take
about a quarter of that (the transform 0.25, deflate 0.27 CPU-s on a loaded machine where the
bindings took 2.9), split over threads (``benchmarks/bench_write.py``).  The transform reads
each channel's rows where they lie (:func:`_predict_channel`): no gathered copy of the
scanlines (it was 0.09 CPU-s and a pass over the 0.47 GB).  The files are standard
OpenEXR 2.0 single-part scanline images: the same header attributes, channel list and
pixels as the bindings write (``tests/test_exrzip.py`` reads them back with OpenEXR and
OpenImageIO, Blender in the reference checks); only the deflate streams differ, and one
attribute is added, ``crackbake:stats``: each plane's statistics for ``crackbake inspect``,
tied to the chunks by their SHA-256 (:mod:`crackbake.exchange.exrstats`).  No
compression, PIZ, RLE and ZSTD are left to the bindings
(:func:`crackbake.exchange.exr.write_exr`).

The layout, from the OpenEXR file-layout specification: magic ``76 2f 31 01``, version 2 (bit
10 set when a name is longer than 31 bytes), the header's attributes (name, type name, size,
value) and a null byte, one 64-bit file offset per chunk, then the chunks: the first
scanline's y (int32), the data's size (int32), the data.  A chunk holds ``lines`` scanlines
(ZIP 16, ZIPS 1), each the channels' rows in channel-name order, little-endian.  ZIP
data is zlib's format of those bytes reordered (the even bytes, then the odd ones) and
delta-coded (each byte minus the one before, plus 128, mod 256); a chunk that would not shrink
is stored as it is (readers take a chunk whose size is the raw size as uncompressed).
"""

from __future__ import annotations

import os
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from llvmlite import ir
from numba import njit
from numba.core import types
from numba.extending import intrinsic

from crackbake.exchange.exrstats import STATS_ATTRIBUTE, fingerprint, plane_stats, stats_text

try:  # the same module pngenc uses; stdlib zlib writes valid (slower) files too
    from zlib_ng import zlib_ng as _zlib
except ImportError:  # pragma: no cover - zlib-ng is a dependency
    _zlib = zlib

#: Compressions written here, with the scanlines per chunk and the file's compression code.
SCANLINE_COMPRESSIONS = {"zips": (1, 2), "zip": (16, 3)}
#: zlib-ng's deflate level of the chunks.  On the README run's 4096² crack master (loaded
#: machine, one thread) zlib-ng's deflate took 0.19 / 0.23 / 0.27 / 0.29 / 0.49 CPU-s at levels
#: 1 / 2 / 3 / 4 / 6 for 10.6 / 7.05 / 6.99 / 6.98 / 6.91 MB, and on its 1024² stress file
#: 0.08 / 0.13 / 0.14 / 0.16 / 0.19 CPU-s for 7.25 / 6.49 / 6.38 / 6.28 / 6.22 MB
#: (``benchmarks/bench_write.py --levels``): level 2 costs 1-2 % in size for 10-15 % of the
#: deflate; level 1 (static codes) grows the master by half.  The bindings wrote 6.84 MB
#: (their level 4).  ISA-L's level 1 (the ``isal`` package) took 0.11 CPU-s for 7.50 MB, but its
#: streams are not always the same for the same chunk (valid, the pixels equal): 4 of 30 writes
#: of the crack master on two threads at once differed, and one chunk compressed alone differed
#: between two processes, so a run's EXR bytes (and the manifest's hashes) varied.  Output
#: bytes that follow from the inputs come first (docs/benchmarks.md, "ISA-L dropped").
ZIP_LEVEL = 2


def deflate(data, level: int | None = None) -> bytes:
    """zlib stream of ``data`` (a buffer): zlib-ng (stdlib zlib without it) at ``level``
    (None: :data:`ZIP_LEVEL`)."""
    return _zlib.compress(data, ZIP_LEVEL if level is None else int(level))


_MAGIC = b"\x76\x2f\x31\x01"
_PIXEL_TYPE = {np.dtype(np.uint32): 0, np.dtype(np.float16): 1, np.dtype(np.float32): 2}
_LONG_NAMES = 0x400


@njit(cache=True, nogil=True)
def _predict_channel(cur, pred, shift, y0, y1, e0, half_line, h1, first_odd,
                     out):  # pragma: no cover - compiled
    """ZIP's transform of one channel's rows ``y0:y1`` written into the chunk ``out``, without
    gathering the scanlines first.

    The chunk's bytes ``t`` (each scanline's channel rows one after the other) become its even
    bytes then its odd bytes, each minus the one before it plus 128 (mod 256), ``t[0]`` kept.
    A row holds whole 16-bit words (``cur``, (H, B/2) uint16, little-endian: the low byte is
    the even one), so its even bytes go to ``out[e:e + B/2]`` and its odd ones to
    ``out[h1 + e:...]``, ``e`` = ``e0`` + (y - y0) ``half_line``.  The word before a row's
    first one in ``t`` is the last word of ``pred``'s row ``y - shift`` (the previous channel,
    shift 0; the previous line's last channel, shift 1); before the chunk's first odd byte
    comes its last even byte, ``first_odd``.  Word-wise, both predictions of word ``i`` are
    the low and high bytes of ``w[i] - w[i - 1]`` (+ 128): one pass of contiguous loads.
    """
    m = cur.shape[1]
    pb = pred.shape[1]
    for y in range(y0, y1):
        e = e0 + (y - y0) * half_line
        o = h1 + e
        row = cur[y]
        w = np.int32(row[0])
        if y - shift < y0:  # the chunk's first row: t[0] is kept
            out[e] = np.uint8(w & 255)
            out[o] = np.uint8(((w >> 8) - np.int32(first_odd) + 128) & 255)
        else:
            p = np.int32(pred[y - shift, pb - 1])
            out[e] = np.uint8((w - p + 128) & 255)
            out[o] = np.uint8(((w >> 8) - (p >> 8) + 128) & 255)
        # Views from the row's second word on, indexed by the loop counter alone: with
        # ``out[e + i]`` numba's negative-index wrap-around of the sum stayed in the loop and
        # kept LLVM from vectorising it (3x slower).  One store stream per loop; unsigned
        # arithmetic, the same bytes mod 256.
        cur1, prev1 = row[1:], row[:m - 1]
        even, odd = out[e + 1:e + m], out[o + 1:o + m]
        for i in range(m - 1):
            even[i] = np.uint8((np.uint32(cur1[i]) - np.uint32(prev1[i]) + np.uint32(128))
                               & np.uint32(255))  # fmt: skip
        for i in range(m - 1):
            odd[i] = np.uint8(((np.uint32(cur1[i]) >> 8) - (np.uint32(prev1[i]) >> 8)
                               + np.uint32(128)) & np.uint32(255))  # fmt: skip


@intrinsic
def _half_bits(typingctx, x):  # pragma: no cover - compiled
    """IEEE float32 -> binary16 bits, rounded to nearest even: LLVM's ``fptrunc`` (one F16C
    instruction where the CPU has it)."""
    if x != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(builder.fptrunc(args[0], ir.HalfType()), ir.IntType(16))

    return types.uint16(types.float32), codegen


@njit(cache=True, nogil=True)
def _to_half(src, out):  # pragma: no cover - compiled
    for i in range(src.shape[0]):
        out[i] = _half_bits(src[i])


def to_half(plane: np.ndarray) -> np.ndarray:
    """``plane.astype(np.float16)`` for float32 planes, 5-10x faster, the GIL released.

    numpy converts float32 to half one element at a time (0.12 CPU-s per 4096² plane here);
    this is the hardware conversion (0.01 s).  It gives numpy's half bits for every float32
    but signalling NaNs, which come out quiet (``tests/test_exrzip.py`` checks every upper
    16 bits with the low bits rounding turns on, and 16M random patterns).
    """
    plane = np.asarray(plane)
    if plane.dtype != np.float32:
        return plane.astype(np.float16)
    src = np.ascontiguousarray(plane)
    out = np.empty(src.shape, np.uint16)
    _to_half(src.reshape(-1), out.reshape(-1))
    return out.view(np.float16)


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _value(name: str, value) -> tuple[str, bytes]:
    """An extra attribute's EXR type and bytes, as the OpenEXR bindings store a Python value."""
    if isinstance(value, str):
        return "string", value.encode("utf-8")
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return "int", struct.pack("<i", int(value))
    if isinstance(value, float | np.floating):
        return "float", struct.pack("<f", float(value))
    raise TypeError(f"attribute {name!r}: {type(value).__name__}")


def header_bytes(names: list[str], dtypes: list[np.dtype], width: int, height: int,
                 code: int, attributes: dict) -> tuple[bytes, bool]:  # fmt: skip
    """The header (magic, version, attributes, terminating null) and whether it needs the
    long-names flag."""
    chlist = b"".join(
        n.encode() + b"\0" + struct.pack("<iB3xii", _PIXEL_TYPE[d], 0, 1, 1)
        for n, d in zip(names, dtypes, strict=True)
    ) + b"\0"
    window = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    attrs = {
        "channels": ("chlist", chlist),
        "compression": ("compression", bytes([code])),
        "dataWindow": ("box2i", window),
        "displayWindow": ("box2i", window),
        "lineOrder": ("lineOrder", b"\0"),  # increasing y
        "pixelAspectRatio": ("float", struct.pack("<f", 1.0)),
        "screenWindowCenter": ("v2f", struct.pack("<ff", 0.0, 0.0)),
        "screenWindowWidth": ("float", struct.pack("<f", 1.0)),
    }
    for key, value in attributes.items():
        attrs[key] = _value(key, value)
    longest = max(len(s.encode()) for s in [*attrs, *names])
    if longest > 255:  # what readers accept even with the long-names flag
        raise ValueError(f"an EXR attribute or channel name is {longest} bytes; at most 255")
    body = b"".join(_attribute(k, *attrs[k]) for k in sorted(attrs)) + b"\0"
    version = 2 | (_LONG_NAMES if longest > 31 else 0)
    return _MAGIC + struct.pack("<I", version) + body, longest > 31


@njit(cache=True, nogil=True)
def _uniform(texels, y0, y1):  # pragma: no cover - compiled
    """Whether rows ``y0:y1`` of ``texels`` (a channel's pixels as unsigned integers of their
    width) all hold the bits of ``texels[y0, 0]``; stops at the first other one."""
    first = texels[y0, 0]
    for y in range(y0, y1):
        row = texels[y]
        for x in range(row.shape[0]):
            if row[x] != first:
                return False
    return True


def _chunks(rows: list[np.ndarray], starts: range, lines: int, height: int,
            line_bytes: int, level: int, sizes: list[int] | None = None,
            ) -> list[tuple[bytes, bytes]]:  # fmt: skip
    """Each chunk's (y and size, data) for the chunks starting at the rows ``starts``;
    ``sizes``: each channel's bytes a texel (None: the chunks are encoded one by one).

    A chunk's data follows from its own bytes alone, so a chunk in which every channel holds
    one value throughout (the background away from the cracks: 57 % of the README bake's
    crack master) takes the data of the first such chunk of the same values and height
    instead of a transform and a deflate of its own: the same bytes, about 40 % of the
    master's encoding CPU saved.
    """
    out = np.empty(lines * line_bytes, np.uint8)
    offsets = np.cumsum([0] + [r.shape[1] for r in rows])
    words = [r.view(np.uint16) for r in rows]  # every pixel type is whole 16-bit words
    kinds = {2: np.uint16, 4: np.uint32}
    texels = None
    if sizes is not None and all(size in kinds for size in sizes):
        texels = [r.view(kinds[size]) for r, size in zip(rows, sizes, strict=True)]
    same: dict[tuple, bytes] = {}
    done = []
    for y0 in starts:
        y1 = min(y0 + lines, height)
        n = (y1 - y0) * line_bytes
        key = None
        if texels is not None and all(_uniform(t, y0, y1) for t in texels):
            key = (y1 - y0, tuple(int(t[y0, 0]) for t in texels))
        data = same.get(key) if key is not None else None
        if data is None:
            first_odd = int(rows[-1][y1 - 1, -2])
            for c, r in enumerate(words):  # nogil kernels: no gathered copy of the scanlines
                pred, shift = (words[c - 1], 0) if c else (words[-1], 1)
                _predict_channel(r, pred, shift, y0, y1, int(offsets[c]) // 2,
                                 line_bytes // 2, n // 2, first_odd, out)  # fmt: skip
            data = deflate(memoryview(out[:n]), level)
            if len(data) >= n:  # stored as it is: the scanlines' bytes, channel after channel
                data = np.concatenate([r[y0:y1] for r in rows], axis=1).tobytes()
            if key is not None:
                same[key] = data
        done.append((struct.pack("<ii", y0, len(data)), data))
    return done


def write_scanline(path: str | os.PathLike, planes: dict[str, np.ndarray], attributes: dict,
                   compression: str = "zip", threads: int = 0,
                   level: int | None = None, stats: bool = True) -> None:  # fmt: skip
    """Write one part of (H, W) planes as a scanline EXR with ZIP or ZIPS compression.

    Parameters
    ----------
    path : str or os.PathLike
    planes : dict of str to (H, W) ndarray
        Channel name to pixels (float16, float32 or uint32), all one shape, row 0 the top;
        checked by the caller (:func:`crackbake.exchange.exr.write_exr`).
    attributes : dict of str to str, int or float
        Extra header attributes (string, int, float), checked by the caller.
    compression : {"zip", "zips"}
    threads : int
        Worker threads besides the calling one (0: the calling thread alone); the chunks are
        split among them in contiguous runs, so the file is the same for any count.
    level : int, optional
        zlib-ng's deflate level 1..9; None: :data:`ZIP_LEVEL`.
    stats : bool
        Record each plane's statistics and the pixel data's fingerprint in the
        ``crackbake:stats`` attribute (:mod:`crackbake.exchange.exrstats`: what ``crackbake
        inspect`` then shows without reading the pixels); taken on the encoder's threads.

    Raises
    ------
    OSError
        When the file cannot be written.
    """
    lines, code = SCANLINE_COMPRESSIONS[compression]
    names = sorted(planes)  # the file's channel order: by name, bytes compared
    arrays = [np.ascontiguousarray(planes[n]) for n in names]
    arrays = [a if a.dtype.byteorder != ">" else a.astype(a.dtype.newbyteorder("<"))
              for a in arrays]  # fmt: skip
    height, width = arrays[0].shape
    rows = [a.view(np.uint8).reshape(height, -1) for a in arrays]
    line_bytes = sum(r.shape[1] for r in rows)
    starts = range(0, height, lines)
    groups = max(1, min(int(threads) + 1, len(starts)))
    cut = np.linspace(0, len(starts), groups + 1).round().astype(int)
    parts = [starts[a:b] for a, b in zip(cut[:-1], cut[1:], strict=True)]
    args = (lines, height, line_bytes, None if level is None else int(level),
            [a.dtype.itemsize for a in arrays])
    figures: list[dict] = []
    if groups == 1:
        chunks = _chunks(rows, parts[0], *args)
        figures = [plane_stats(a) for a in arrays] if stats else []
    else:
        with ThreadPoolExecutor(groups - 1, thread_name_prefix="crackbake-exr") as pool:
            later = [pool.submit(_chunks, rows, p, *args) for p in parts[1:]]
            # Each plane's statistics (a numba kernel without the GIL) queue behind the
            # chunks; the calling thread, done with its own chunks, takes those no worker
            # has started yet, from the last.
            jobs = [pool.submit(plane_stats, a) for a in arrays] if stats else []
            chunks = _chunks(rows, parts[0], *args)
            figures = [None] * len(jobs)  # type: ignore[list-item]
            for i in reversed(range(len(jobs))):
                if jobs[i].cancel():
                    figures[i] = plane_stats(arrays[i])
            for job in later:
                chunks += job.result()
            for i, job in enumerate(jobs):
                if figures[i] is None:
                    figures[i] = job.result()
    sizes = [8 + len(data) for _, data in chunks]

    def header(digest: str) -> bytes:
        extra = dict(attributes)
        if stats:
            extra[STATS_ATTRIBUTE] = stats_text(dict(zip(names, figures, strict=True)), digest)
        return header_bytes(names, [a.dtype for a in arrays], width, height, code, extra)[0]

    head = header("0" * 64)  # the digest's length: the offsets do not depend on its value
    offsets = len(head) + 8 * len(chunks) + np.cumsum([0] + sizes[:-1], dtype=np.uint64)
    table = offsets.astype("<u8").tobytes()
    if stats:
        final = header(fingerprint(head, [table, *(b for pair in chunks for b in pair)]))
        assert len(final) == len(head), "the offsets assumed the digest's length"
        head = final
    with open(path, "wb") as fh:
        fh.write(head)
        fh.write(table)
        for pair in chunks:
            fh.writelines(pair)
