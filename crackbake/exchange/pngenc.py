"""PNG encoding in memory: numpy scanline filter + :func:`zlib.compress`, 8 or 16 bit.

Why our own encoder: the output stage encodes many large maps at once on a thread pool, and
CPython's zlib releases the GIL while it deflates, so encodes overlap on every core (Pillow's PNG
encoder holds the GIL, so its encodes run one after another).  The "Up" filter (each byte minus
the byte above) is one vectorised subtraction and compresses smooth maps about as well as
Pillow's adaptive filtering; at zlib level 1 it encoded a 4096² RGB test image in 0.40 s
against Pillow's 0.76 s at level 1 (measured here, one thread).

The maps are deflated by zlib-ng (its Python bindings, the ``zlib`` API) when it is installed:
with the Z_RLE strategy (run lengths only: the level changes nothing in either library) it writes
the very bytes stdlib zlib 1.2/1.3 writes (checked on every file of a 4096² run: same SHA-256)
4-5x faster (the 4096² 16-bit data map: 0.09 s against 0.35 s of CPU), and it releases the GIL
the same way.  Level 0 (stored blocks, sized differently) stays with stdlib zlib.

Colour textures carry an ``sRGB`` chunk; data maps carry no colour chunk at all (no sRGB, gAMA
or cHRM), so readers take the values as they are.
"""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np

from crackbake.errors import CrackbakeError

try:  # an optional speed-up: the same bytes either way (module docstring)
    from zlib_ng import zlib_ng as _rle_zlib
except ImportError:  # pragma: no cover - zlib-ng is a dependency; a bare install still works
    _rle_zlib = zlib

PathLike = str | os.PathLike

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOUR_TYPE = {1: 0, 2: 4, 3: 2, 4: 6}  # channels -> grey, grey+alpha, RGB, RGBA
_FILTER_UP = 2

#: zlib level of the maps: level 1 is 3-5x faster than level 6 for files about 10 % larger
#: (a noisy 4096² RGB test image: 0.4 s / 11.4 MB at 1 against 1.9 s / 9.0 MB at 6).
PNG_LEVEL = 1


#: Bytes of scanlines filtered and deflated at a time (:func:`png_bytes`): the band's buffer
#: stays in the CPU's cache, and no image-sized copy of the scanlines is made (the README run's
#: PNGs: about 0.3 GB of fresh pages less, each written once and read once); the deflated
#: stream is the same, band after band, as of all the rows at once.
BAND_BYTES = 1 << 20


def data_deflate(data) -> bytes:
    """zlib stream of the 16-bit data texture's filtered rows (a buffer): zlib-ng level 3.

    Its rows hold short varied runs (width, depth and time inside the cracks), where a
    matcher finds what run lengths miss: on the README run's 4096² map zlib-ng's default
    strategy at level 3 wrote 1.26 MB in 0.085 CPU-s, Z_RLE (the other maps' deflate) 1.60 MB
    in 0.069 (``benchmarks/bench_write.py --levels``).  ISA-L's level 1 (1.37 MB, 0.039 CPU-s)
    is not used: its streams are not always the same for the same data (:data:`crackbake.
    exchange.exrzip.ZIP_LEVEL`).
    """
    return _rle_zlib.compress(data, 3)


def data_compressor():
    """:func:`data_deflate`'s deflate as a compressor object (``compress`` then ``flush``), for
    :func:`png_bands`: the same stream, fed band by band."""
    return _rle_zlib.compressobj(3)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(pixels: np.ndarray, level: int = PNG_LEVEL, srgb: bool = False) -> bytes:
    """Encode an image as PNG bytes.

    Parameters
    ----------
    pixels : (H, W) or (H, W, C) uint8 or uint16, C in 1..4
        Row 0 = top of the image; the dtype sets the bit depth (8 or 16).  Big-endian uint16
        (``>u2``) is used as it is, any other byte order converted.
    level : int
        zlib level 0..9.
    srgb : bool
        Tag the image as sRGB colour (base colour); untagged otherwise (linear data).

    Returns
    -------
    bytes
        A complete PNG file.
    """
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if (
        pixels.ndim != 3
        or pixels.shape[2] not in _COLOUR_TYPE
        or pixels.dtype.kind != "u"
    or pixels.dtype.itemsize not in (1, 2)
        or 0 in pixels.shape
    ):
        raise CrackbakeError(
            f"PNG encoder got {pixels.shape} {pixels.dtype}; pass (H, W[, 1..4]) uint8 or uint16"
        )
    h, w, c = pixels.shape
    bits = 8 * pixels.dtype.itemsize
    return png_bands(_up_filtered(pixels), w, h, bits, c, level=level, srgb=srgb)


def _up_filtered(pixels: np.ndarray, band_bytes: int | None = None):
    """The PNG scanlines of (H, W, C) ``pixels`` with the "Up" filter (each byte minus the byte
    above, mod 256), in bands of rows from one reused (k, 1 + W C B) uint8 buffer: consume each
    before asking for the next."""
    h = pixels.shape[0]
    flat = pixels.reshape(h, -1)
    swap = pixels.dtype.itemsize == 2 and pixels.dtype != np.dtype(">u2")
    line = flat.shape[1] * pixels.dtype.itemsize
    k = max(1, min(h, (band_bytes or BAND_BYTES) // (line + 1)))
    band = np.empty((k, line + 1), np.uint8)
    band[:, 0] = _FILTER_UP
    for y0 in range(0, h, k):
        y1 = min(y0 + k, h)
        above = max(y0 - 1, 0)
        part = flat[above:y1]
        if swap:  # PNG stores 16-bit samples big-endian
            part = part.astype(">u2")
        raw = np.ascontiguousarray(part).view(np.uint8).reshape(y1 - above, line)
        rows = band[: y1 - y0]
        if y0 == 0:  # the first row minus zeros
            rows[0, 1:] = raw[0]
            np.subtract(raw[1:], raw[:-1], out=rows[1:, 1:])  # uint8 arithmetic wraps
        else:
            np.subtract(raw[1:], raw[:-1], out=rows[:, 1:])
        yield rows


def png_rows(
    rows: np.ndarray, width: int, bits: int, channels: int, level: int = PNG_LEVEL,
    srgb: bool = False, deflate=None,
) -> bytes:
    """PNG bytes from scanlines already filtered: (H, 1 + W C bits / 8) uint8, each row's
    filter type byte first (what :func:`png_bytes` builds; fused packers write it directly).
    ``deflate``: a function from the rows' buffer to a zlib stream (e.g. :func:`data_deflate`)
    instead of Z_RLE at ``level``."""
    if deflate is not None:
        view = memoryview(np.ascontiguousarray(rows)).cast("B")
        return _png(deflate(view), width, rows.shape[0], bits, channels, srgb)
    return png_bands([rows], width, rows.shape[0], bits, channels, level=level, srgb=srgb)


def png_bands(
    bands, width: int, height: int, bits: int, channels: int, level: int = PNG_LEVEL,
    srgb: bool = False, compressor=None,
) -> bytes:
    """PNG bytes from filtered scanlines given band by band: an iterable of (k, 1 + W C bits /
    8) uint8 arrays, ``height`` rows in all, each deflated as it comes (a band's buffer may be
    reused for the next).  ``compressor``: a zlib compressor object (e.g.
    :func:`data_compressor`) instead of Z_RLE at ``level``."""
    if compressor is None:
        # Z_RLE: after the Up filter the maps are long runs of zeros; on crackbake's maps it
        # was as fast as the default strategy or faster and 4-25 % smaller (base colour: 4x
        # smaller).
        lib = _rle_zlib if int(level) >= 1 else zlib
        compressor = lib.compressobj(int(level), lib.DEFLATED, 15, 9, lib.Z_RLE)
    parts = [compressor.compress(memoryview(np.ascontiguousarray(b)).cast("B")) for b in bands]
    parts.append(compressor.flush())
    return _png(b"".join(parts), width, height, bits, channels, srgb)


def png_segments(segments, width: int, height: int, bits: int, channels: int,
                 threads: int = 0, srgb: bool = False) -> bytes:
    """PNG bytes of the data texture from row segments deflated apart, on ``threads`` worker
    threads besides the calling one.

    Parameters
    ----------
    segments : sequence of callables
        Each returns an iterable of filtered scanline bands (as :func:`png_bands` takes them)
        for its rows, top to bottom; ``height`` rows in all.
    threads : int
        Workers besides the calling thread (0: the calling thread alone).  The file is the
        same for any count: each segment is one raw deflate (:func:`data_deflate`'s, zlib-ng
        level 3) from an empty window, ended byte-aligned, and the zlib stream is their
        concatenation with the header and the Adler-32 of all the rows.

    The one 16-bit data map was the write's longest job on a 16-core machine (0.32 s, the
    EXR master 0.26 s): one zlib stream deflates on one core.  A segment starts without the
    previous one's window, which costs a few hundred bytes per segment here.
    """
    from concurrent.futures import ThreadPoolExecutor

    def deflate(i: int) -> tuple[bytes, int, int]:
        compressor = _rle_zlib.compressobj(3, _rle_zlib.DEFLATED, -15)
        adler, length, parts = 1, 0, []
        for band in segments[i]():
            data = memoryview(np.ascontiguousarray(band)).cast("B")
            adler, length = zlib.adler32(data, adler), length + len(data)
            parts.append(compressor.compress(data))
        last = i == len(segments) - 1
        parts.append(compressor.flush(zlib.Z_FINISH if last else zlib.Z_SYNC_FLUSH))
        return b"".join(parts), adler, length

    n = len(segments)
    if threads <= 0 or n == 1:
        done = [deflate(i) for i in range(n)]
    else:
        workers = min(int(threads), n - 1)
        with ThreadPoolExecutor(workers, thread_name_prefix="crackbake-png") as pool:
            later = [pool.submit(deflate, i) for i in range(1, n)]
            done = [deflate(0)] + [job.result() for job in later]
    adler = done[0][1]
    for _, a, length in done[1:]:
        adler = adler32_combine(adler, a, length)
    stream = _ZLIB_HEADER_L3 + b"".join(d for d, _, _ in done) + struct.pack(">I", adler)
    return _png(stream, width, height, bits, channels, srgb)


#: The zlib header zlib writes at level 3 (32 KiB window, the "fast" level flag).
_ZLIB_HEADER_L3 = bytes([0x78, 0x5E])


def adler32_combine(adler1: int, adler2: int, length2: int) -> int:
    """The Adler-32 of two buffers one after the other from the first's ``adler1``, the
    second's ``adler2`` and its length (zlib's ``adler32_combine``, which Python does not
    expose)."""
    base = 65521
    rem = length2 % base
    sum1 = adler1 & 0xFFFF
    sum2 = (rem * sum1) % base
    sum1 = (sum1 + (adler2 & 0xFFFF) + base - 1) % base
    sum2 = (sum2 + (adler1 >> 16) + (adler2 >> 16) + base - rem) % base
    return sum1 | (sum2 << 16)


def _png(stream: bytes, width: int, height: int, bits: int, channels: int,
         srgb: bool) -> bytes:
    """A PNG file around one zlib ``stream`` of filtered scanlines."""
    ihdr = struct.pack(">IIBBBBB", width, height, bits, _COLOUR_TYPE[channels], 0, 0, 0)
    parts = [_SIGNATURE, _chunk(b"IHDR", ihdr)]
    if srgb:
        parts.append(_chunk(b"sRGB", b"\x00"))  # perceptual intent
    parts += [_chunk(b"IDAT", stream), _chunk(b"IEND", b"")]
    return b"".join(parts)


def write_bytes(path: PathLike, data: bytes) -> None:
    """Write encoded bytes to ``path`` with the output stage's error message."""
    try:
        with open(path, "wb") as fh:
            fh.write(data)
    except OSError as exc:
        raise CrackbakeError(
            f"cannot write '{path}': {exc.strerror or exc}; "
            "check that the folder exists, is writable and has space"
        ) from exc
