"""Fused packing kernels: several maps quantised and interleaved into one texture in one pass.

The write stage encodes many files at once on a 2-core machine, where it is bound by memory
traffic: numpy's quantise-then-stack makes five passes over 100+ MB per packed 16-bit texture
and holds the GIL between them.  These kernels read each source texel once, write the packed
texel once, and release the GIL (``nogil``), so they run beside the encoders.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def _scaled16(x, gain):
    """``x * gain`` rounded to uint16, clipped; NaN compares false both ways and lands on 0,
    like the numpy path."""
    d = x * gain + np.float32(0.5)
    q = np.uint16(0)
    if d >= np.float32(65535.0):
        q = np.uint16(65535)
    elif d > np.float32(0.0):
        q = np.uint16(d)
    return q


@njit(cache=True, nogil=True, inline="always")
def _texel16(i, j, mask, width, time, depth, lut_mask, width_gain, lut_time, depth_gain):
    """The data texture's four 16-bit samples at texel (i, j): mask, width, depth, time."""
    return (lut_mask[mask[i, j]], _scaled16(width[i, j], width_gain),
            _scaled16(depth[i, j], depth_gain), lut_time[time[i, j]])


@njit(cache=True, nogil=True)
def _data16(mask, width, time, depth, lut_mask, width_gain, lut_time, depth_gain, out):
    h, w = mask.shape
    for i in range(h):
        for j in range(w):
            a, b, q, c = _texel16(i, j, mask, width, time, depth, lut_mask, width_gain,
                                  lut_time, depth_gain)
            # Big-endian samples, the byte order PNG stores.
            out[i, j, 0] = (a >> 8) | (a << 8)
            out[i, j, 1] = (b >> 8) | (b << 8)
            out[i, j, 2] = (q >> 8) | (q << 8)
            out[i, j, 3] = (c >> 8) | (c << 8)


@njit(cache=True, nogil=True)
def _data16_band(mask, width, time, depth, lut_mask, width_gain, lut_time, depth_gain, y0,
                 prev, rows):  # pragma: no cover - compiled
    # The data texture's rows y0 .. y0 + len(rows) already PNG-filtered ("Up": each byte minus
    # the byte above), written straight into the scanline buffer: no (H, W, 4) pixel array, no
    # second pass.  ``prev`` holds the unfiltered bytes of row y0 - 1 (zeros above row 0) and
    # is left holding the band's last row, for the next band.
    w = mask.shape[1]
    cur = np.empty(8 * w, np.uint8)
    for r in range(rows.shape[0]):
        i = y0 + r
        for j in range(w):
            a, b, q, c = _texel16(i, j, mask, width, time, depth, lut_mask, width_gain,
                                  lut_time, depth_gain)
            o = 8 * j  # big-endian samples: high byte first
            cur[o], cur[o + 1] = a >> 8, a & 0xFF
            cur[o + 2], cur[o + 3] = b >> 8, b & 0xFF
            cur[o + 4], cur[o + 5] = q >> 8, q & 0xFF
            cur[o + 6], cur[o + 7] = c >> 8, c & 0xFF
        row = rows[r]
        row[0] = 2
        for k in range(8 * w):
            row[k + 1] = cur[k] - prev[k]  # uint8 arithmetic wraps mod 256
            prev[k] = cur[k]


def data16_rows(mask, width, time, depth, luts, width_scale: float,
                depth_scale: float) -> np.ndarray:
    """:func:`data16`'s texture as PNG scanlines with the "Up" filter applied, in one pass.

    Returns
    -------
    (H, 1 + 8 W) uint8
        Each row: the filter type byte (2), then the row's big-endian samples minus the row
        above's (mod 256; the first row minus zeros), as :func:`~crackbake.exchange.pngenc.png_rows`
        takes them.
    """
    h, w = mask.shape
    rows = np.empty((h, 1 + 8 * w), np.uint8)
    inputs = _data16_inputs(mask, width, time, depth, luts, width_scale, depth_scale)
    _data16_band(*inputs, 0, np.zeros(8 * w, np.uint8), rows)
    return rows


def data16_bands(mask, width, time, depth, luts, width_scale: float, depth_scale: float,
                 band_bytes: int = 1 << 20, start: int = 0, stop: int | None = None):
    """:func:`data16_rows`' scanlines in bands of rows, each (k, 1 + 8 W) uint8 of about
    ``band_bytes``, from one buffer that the next band overwrites: consume each before asking
    for the next (:func:`~crackbake.exchange.pngenc.png_bands` deflates it at once).  The same
    bytes as :func:`data16_rows`, without its image-sized array (128 MB of fresh pages at 4096²,
    written once and read once).  ``start``, ``stop``: only those rows (the first filtered
    against row ``start - 1``, as in the whole image), for segments encoded apart."""
    h, w = mask.shape
    stop = h if stop is None else min(int(stop), h)
    inputs = _data16_inputs(mask, width, time, depth, luts, width_scale, depth_scale)
    k = max(1, min(h, band_bytes // (1 + 8 * w)))
    band = np.empty((k, 1 + 8 * w), np.uint8)
    prev = np.zeros(8 * w, np.uint8)
    if start > 0:  # prev <- row start - 1, unfiltered (the scanline written here is dropped)
        _data16_band(*inputs, start - 1, prev, band[:1])
    for y0 in range(start, stop, k):
        rows = band[: min(k, stop - y0)]
        _data16_band(*inputs, y0, prev, rows)
        yield rows


def data16(
    mask: np.ndarray,
    width: np.ndarray,
    time: np.ndarray,
    depth: np.ndarray,
    luts: tuple[np.ndarray, np.ndarray],
    width_scale: float,
    depth_scale: float,
) -> np.ndarray:
    """The 16-bit RGBA data texture: R mask, G width / ``width_scale``, B depth /
    ``depth_scale``, A time.

    Parameters
    ----------
    mask, time : (H, W) float16
        Quantised through ``luts``: two (65536,) uint16 tables indexed by the float16 bit
        pattern (native byte order), built by the caller with its rounding rule.
    width, depth : (H, W) float32
        Mesh units; rounded to ``x / scale * 65535`` (clipped, NaN -> 0).
    width_scale, depth_scale : float
        Width and depth that map to 65535, > 0.

    Returns
    -------
    (H, W, 4) big-endian uint16 (``>u2``)
    """
    out = np.empty((*mask.shape, 4), np.uint16)
    _data16(*_data16_inputs(mask, width, time, depth, luts, width_scale, depth_scale), out)
    return out.view(">u2")


def _data16_inputs(mask, width, time, depth, luts, width_scale: float,
                   depth_scale: float) -> tuple:
    """The data-texture kernels' inputs: mask and time as their float16 bit patterns, width and
    depth as float32, the two tables and the two gains (in the kernels' argument order)."""
    lut_mask, lut_time = (np.ascontiguousarray(t, dtype=np.uint16) for t in luts)
    return (
        np.ascontiguousarray(mask).view(np.uint16),
        np.ascontiguousarray(width, dtype=np.float32),
        np.ascontiguousarray(time).view(np.uint16),
        np.ascontiguousarray(depth, dtype=np.float32),
        lut_mask,
        np.float32(65535.0 / width_scale),
        lut_time,
        np.float32(65535.0 / depth_scale),
    )


# Channel sources of :func:`lut_planes`: a texel of ``a``, of ``b``, or the table's first entry.
SRC_A, SRC_B, SRC_CONST = 0, 1, 2


@njit(cache=True, nogil=True)
def _lut_planes(a, b, src, luts, out):
    # Row by row, one channel at a time: the source choice leaves the texel loop (a branch per
    # sample made the README run's 4096² ORM 2.5x slower); the rows stay in cache.
    h, w = a.shape
    c = out.shape[2]
    for i in range(h):
        row_a, row_b, row_out = a[i], b[i], out[i]
        for k in range(c):
            lut = luts[k]
            if src[k] == SRC_A:
                for j in range(w):
                    row_out[j, k] = lut[row_a[j]]
            elif src[k] == SRC_B:
                for j in range(w):
                    row_out[j, k] = lut[row_b[j]]
            else:
                value = lut[0]
                for j in range(w):
                    row_out[j, k] = value


def lut_planes(a: np.ndarray, b: np.ndarray, channels: list) -> np.ndarray:
    """Interleave channels looked up from two float16 planes, one pass, GIL released.

    Parameters
    ----------
    a, b : (H, W) float16
        The source planes (e.g. mask and occlusion); ``b`` may be ``a``.
    channels : list of (source, table)
        Per output channel: :data:`SRC_A`, :data:`SRC_B` or :data:`SRC_CONST`, and a (65536,)
        table indexed by the float16 bit pattern (a constant channel takes entry 0).  All
        tables share one dtype: uint8, or ``>u2`` for 16-bit PNG samples.

    Returns
    -------
    (H, W, C) array of the tables' dtype
    """
    dtype = np.asarray(channels[0][1]).dtype  # np.stack would give '>u2' in native order
    luts = np.stack([np.broadcast_to(t, (65536,)) for _, t in channels]).astype(dtype)
    store = np.uint8 if dtype.itemsize == 1 else np.uint16  # '>u2' bytes, stored as they are
    out = np.empty((*a.shape, len(channels)), store)
    _lut_planes(
        np.ascontiguousarray(a).view(np.uint16),
        np.ascontiguousarray(b).view(np.uint16),
        np.array([s for s, _ in channels], np.int64),
        np.ascontiguousarray(luts).view(store),
        out,
    )
    return out.view(dtype)


def planar(normal: np.ndarray) -> np.ndarray:
    """(3, H, W) float32 view of (H, W, 3) normals: free for the bake's planar storage
    (``CrackMaps.normal`` is a view of it); interleaved arrays are copied once."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(normal, np.float32), -1, 0))


@njit(cache=True, nogil=True)
def _normal_q(n, half, offset, flip_y, top1, swap, out):
    # Row by row, one component at a time (a plane's row in, every third sample out): the
    # flip and swap tests leave the texel loop, which ran 2x slower with them inside.
    c, h, w = n.shape
    for i in range(h):
        row = out[i]
        for k in range(c):
            src = n[k, i]
            flip = flip_y and k == 1
            for j in range(w):
                q = src[j] * half
                q = q + offset
                if flip:
                    q = top1 - q
                # Unit vectors give [0.5, top + 0.5]: truncation is the rounding (NaN -> 0).
                v = np.int64(q) if q >= 0 else np.int64(0)
                if swap:  # big-endian samples, the byte order PNG stores
                    v = ((v >> 8) | (v << 8)) & 0xFFFF
                row[j, k] = v


def normal_q(normal: np.ndarray, bits: int, flip_y: bool) -> np.ndarray:
    """Unit tangent-space normals to ``n * 0.5 + 0.5`` in 8 or 16 bits, one pass, GIL released.

    Parameters
    ----------
    normal : (H, W, 3) float32
        Unit vectors.
    bits : {8, 16}
    flip_y : bool
        DirectX convention: ``y -> -y``.

    Returns
    -------
    (H, W, 3) uint8, or big-endian uint16 (``>u2``)
    """
    top = 255 if bits == 8 else 65535
    half = np.float32(top / 2)
    store = np.uint8 if bits == 8 else np.uint16
    out = np.empty(normal.shape, store)
    offset, top1 = half + np.float32(0.5), np.float32(top + 1)
    _normal_q(planar(normal), half, offset, flip_y, top1, bits == 16, out)
    return out.view(">u2") if bits == 16 else out


@njit(cache=True, nogil=True)
def _base_color(mask, occ, lut_m, lut_o, table, out):
    h, w = mask.shape
    for i in range(h):
        for j in range(w):
            idx = (np.int64(lut_m[mask[i, j]]) << 8) | lut_o[occ[i, j]]
            for k in range(3):
                out[i, j, k] = table[idx, k]


@njit(cache=True, nogil=True)
def _base_color_tex(mask, occ, lut_m, lut_o, table, tex, out):
    h, w = mask.shape
    for i in range(h):
        for j in range(w):
            idx = (np.int64(lut_m[mask[i, j]]) << 8) | lut_o[occ[i, j]]
            for k in range(3):
                out[i, j, k] = min((np.uint32(tex[i, j, k]) * table[idx, k] + 128) >> 8, 255)


def base_color8(
    mask: np.ndarray,
    occlusion: np.ndarray | None,
    lut: np.ndarray,
    table: np.ndarray,
    texture: np.ndarray | None = None,
) -> np.ndarray:
    """The composited base colour in one pass (GIL released).

    Parameters
    ----------
    mask, occlusion : (H, W) float16
        ``occlusion`` None = open (index 255).
    lut : (65536,) uint8
        Float16 bit pattern -> 8-bit level.
    table : (65536, 3)
        Indexed by ``mask level << 8 | occlusion level``: uint8 colours without ``texture``,
        else uint16 factors (256 = 1) that scale the texture, rounded and clipped to 255.
    texture : (H, W, 3) uint8 or uint16, optional

    Returns
    -------
    (H, W, 3) uint8
    """
    m = np.ascontiguousarray(mask).view(np.uint16)
    lut_m = np.ascontiguousarray(lut, np.uint16)
    if occlusion is None:
        o, lut_o = m, np.full(65536, 255, np.uint16)
    else:
        o, lut_o = np.ascontiguousarray(occlusion).view(np.uint16), lut_m
    out = np.empty((*mask.shape, 3), np.uint8)
    if texture is None:
        _base_color(m, o, lut_m, lut_o, np.ascontiguousarray(table), out)
    else:
        _base_color_tex(m, o, lut_m, lut_o, np.ascontiguousarray(table, np.uint32),
                        np.ascontiguousarray(texture), out)  # fmt: skip
    return out


@njit(cache=True, nogil=True)
def _half_max(bits, table):
    best = table[bits[0]]
    for i in range(bits.size):
        v = table[bits[i]]
        if v != v:  # NaN wins, as in np.max
            return v
        if v > best:
            best = v
    return best


def half_max(plane: np.ndarray) -> float:
    """``float(np.max(plane))`` of a non-empty float16 plane (NaN if any), GIL released: numpy's
    float16 reduction is scalar code, 20x slower on a 4096² map."""
    table = np.arange(65536, dtype=np.uint16).view(np.float16).astype(np.float32)
    return float(_half_max(np.ascontiguousarray(plane).view(np.uint16).reshape(-1), table))


@njit(cache=True, nogil=True)
def _take(lut, idx, out):
    for i in range(idx.shape[0]):
        out[i] = lut[idx[i]]


def take_half(lut: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """``np.take(lut, plane.view(np.uint16))`` for a float16 plane, the GIL released.

    numpy's gather holds the GIL (0.05 s per 4096² plane here), so the texture jobs of the
    write stage queued behind each other on it.

    Parameters
    ----------
    lut : (65536,) ndarray
        Indexed by the float16 bit pattern (native byte order); any dtype of 1, 2 or 4 bytes,
        ``>u2`` included (its bytes are copied as they are).
    plane : (H, W) float16

    Returns
    -------
    (H, W) array of ``lut``'s dtype
    """
    lut = np.asarray(lut)
    store = {1: np.uint8, 2: np.uint16, 4: np.uint32}[lut.dtype.itemsize]
    idx = np.ascontiguousarray(plane, np.float16).view(np.uint16)
    out = np.empty(idx.shape, store)
    _take(np.ascontiguousarray(lut).view(store), idx.reshape(-1), out.reshape(-1))
    return out.view(lut.dtype)


@njit(cache=True, nogil=True)
def _quantise(src, gain, top, swap, out):
    for i in range(src.shape[0]):
        d = src[i] * gain
        d = d + np.float32(0.5)  # two roundings, as numpy's multiply then add
        v = np.uint32(0)
        if d >= top:
            v = np.uint32(top)
        elif d > np.float32(0.0):  # NaN compares false: 0
            v = np.uint32(d)
        if swap:  # big-endian samples, the byte order PNG stores
            v = ((v >> 8) | (v << 8)) & 0xFFFF
        out[i] = v


def quantise_float(plane: np.ndarray, bits: int, scale: float = 1.0) -> np.ndarray:
    """``plane / scale`` in [0, 1] rounded to uint8 or big-endian uint16, one pass, GIL released
    (the depth PNG; :func:`~crackbake.exchange.targets.quantise` keeps numpy for the rest).

    The numpy expression it replaces (``q = x * (top / scale); q += 0.5``, NaN to 0, clipped,
    truncated) made five passes over the plane and held the GIL between them: 0.13 s for a
    4096² 16-bit depth map here against 0.02 s.  Same values for every float32 input, NaN and
    infinities included (``tests/test_packing.py``).

    Parameters
    ----------
    plane : (H, W) float
        Converted to float32 first, as numpy's expression does.
    bits : {8, 16}
    scale : float
        The value that maps to the top code, > 0.

    Returns
    -------
    (H, W) uint8, or ``>u2``
    """
    top = 255 if bits == 8 else 65535
    src = np.ascontiguousarray(plane, np.float32)
    store = np.uint8 if bits == 8 else np.uint16
    out = np.empty(src.shape, store)
    _quantise(src.reshape(-1), np.float32(top / scale), np.float32(top), bits == 16,
              out.reshape(-1))  # fmt: skip
    return out if bits == 8 else out.view(">u2")
