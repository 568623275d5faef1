"""Fused kernels for the preview's textures: the maps halved, composited and quantised in one pass.

The preview samples at most 2048² textures; from a 4096² bake the numpy path box-filters each
map to float32 (fresh 16-64 MB arrays), composites, renormalises and quantises in several
passes on the main thread, holding the GIL.  These kernels do it in one pass per texture with
the GIL released and give the same bytes (the same float32 operations in the same order).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.exchange.packing import planar


@njit(cache=True, nogil=True)
def _val(a, lut, i, j):
    # numba has no float16: half planes come as bit patterns with a float32 table (len 65536).
    if lut.size:
        return lut[np.int64(a[i, j])]
    return np.float32(a[i, j])


@njit(cache=True, nogil=True)
def _box(a, lut, i, j):
    # The order of materials.downsample's four strided adds, in float32.
    s = _val(a, lut, 2 * i, 2 * j) + _val(a, lut, 2 * i + 1, 2 * j)
    s = s + _val(a, lut, 2 * i, 2 * j + 1)
    s = s + _val(a, lut, 2 * i + 1, 2 * j + 1)
    return s * np.float32(0.25)


def _half_or_float(plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(array, table) for :func:`_val`: float16 as bit patterns + table, else float32 as is."""
    if plane.dtype == np.float16:
        table = np.arange(65536, dtype=np.uint16).view(np.float16).astype(np.float32)
        return np.ascontiguousarray(plane).view(np.uint16), table
    return np.ascontiguousarray(plane, dtype=np.float32), np.empty(0, np.float32)


@njit(cache=True, nogil=True)
def _level(x):
    # materials.unit_u8's float path: x * 255 + 0.5, clipped, truncated (NaN -> 0).
    q = x * np.float32(255.0)
    q = q + np.float32(0.5)
    if q >= np.float32(255.0):
        return np.int64(255)
    if q > np.float32(0.0):
        return np.int64(q)
    return np.int64(0)


@njit(cache=True, nogil=True)
def _base_color_half(mask, lut_m, occ, lut_o, has_occ, table, tex, has_tex, out):
    h, w = out.shape[0], out.shape[1]
    for i in range(h):
        for j in range(w):
            o = _level(_box(occ, lut_o, i, j)) if has_occ else np.int64(255)
            idx = (_level(_box(mask, lut_m, i, j)) << 8) | o
            for k in range(3):
                if has_tex:
                    t = np.float32(tex[2 * i, 2 * j, k]) + np.float32(tex[2 * i + 1, 2 * j, k])
                    t = t + np.float32(tex[2 * i, 2 * j + 1, k])
                    t = t + np.float32(tex[2 * i + 1, 2 * j + 1, k])
                    t = t * np.float32(0.25) + np.float32(0.5)
                    out[i, j, k] = min((np.int64(t) * np.int64(table[idx, k]) + 128) >> 8, 255)
                else:
                    out[i, j, k] = table[idx, k]


def base_color_half(
    mask: np.ndarray,
    occlusion: np.ndarray | None,
    table: np.ndarray,
    texture: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`crackbake.exchange.materials.base_color` of the maps box-filtered by 2, in one
    pass (GIL released): equal to ``base_color(mask, size // 2, occlusion, texture)``.

    Parameters
    ----------
    mask, occlusion : (H, W) float16 or float32, H and W even
    table : (65536, 3)
        uint8 colours without ``texture``, else uint16 factors (256 = 1); indexed by
        ``mask level << 8 | occlusion level``.
    texture : (H, W, 3) uint8 or float32, optional

    Returns
    -------
    (H / 2, W / 2, 3) uint8
    """
    h, w = mask.shape[0] // 2, mask.shape[1] // 2
    out = np.empty((h, w, 3), np.uint8)
    m = _half_or_float(mask)
    o = m if occlusion is None else _half_or_float(occlusion)
    tex = np.zeros((1, 1, 3), np.uint8) if texture is None else np.ascontiguousarray(texture)
    _base_color_half(*m, *o, occlusion is not None, np.ascontiguousarray(table), tex,
                     texture is not None, out)  # fmt: skip
    return out


@njit(cache=True, nogil=True)
def _normal_half(n, out):
    h, w = out.shape[0], out.shape[1]
    half = np.float32(127.5)
    v = np.empty(3, np.float32)
    for i in range(h):
        for j in range(w):
            for k in range(3):
                s = n[k, 2 * i, 2 * j] + n[k, 2 * i + 1, 2 * j]
                s = s + n[k, 2 * i, 2 * j + 1]
                s = s + n[k, 2 * i + 1, 2 * j + 1]
                v[k] = s * np.float32(0.25)
            # np.linalg.norm's float32 sum over the last axis: x0² + (x1² + x2²).
            r = np.sqrt(v[0] * v[0] + (v[1] * v[1] + v[2] * v[2]))
            r = max(r, np.float32(1e-12))
            for k in range(3):
                q = (v[k] / r) * half
                q = q + np.float32(128.0)
                out[i, j, k] = np.int64(q) if q >= 0 else np.int64(0)


def normal_half(normal: np.ndarray) -> np.ndarray:
    """Normals box-filtered by 2, renormalised and stored as 8-bit ``n * 0.5 + 0.5`` (OpenGL),
    one pass, GIL released.

    Parameters
    ----------
    normal : (H, W, 3) float32, H and W even

    Returns
    -------
    (H / 2, W / 2, 3) uint8
    """
    out = np.empty((normal.shape[0] // 2, normal.shape[1] // 2, 3), np.uint8)
    _normal_half(planar(normal), out)
    return out


@njit(cache=True, nogil=True)
def _mip_half(a, out):  # pragma: no cover - compiled
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            for k in range(a.shape[2]):
                top = (np.uint16(a[2 * i, 2 * j, k]) + np.uint16(a[2 * i, 2 * j + 1, k]) + 1) >> 1
                low = (np.uint16(a[2 * i + 1, 2 * j, k]) + np.uint16(a[2 * i + 1, 2 * j + 1, k])
                       + 1) >> 1  # fmt: skip
                out[i, j, k] = np.uint8((top + low + 1) >> 1)


def mip_half(image: np.ndarray) -> np.ndarray:
    """The next mip level of an (H, W, C) uint8 image, H and W even: each 2 x 2 block's rows
    averaged by pairs, halves rounded up, then the two rows' (what llvmpipe's
    ``glGenerateMipmap`` writes; :func:`crackbake.bake.preview.mip_levels`), GIL released."""
    out = np.empty((image.shape[0] // 2, image.shape[1] // 2, image.shape[2]), np.uint8)
    _mip_half(np.ascontiguousarray(image), out)
    return out


def warm() -> None:
    """Compile (or load from numba's cache) the kernels a run at more than 2048² uses that
    :mod:`crackbake.precompile`'s small runs never reach: these halving kernels and the
    textured base colour, with the argument types real runs pass."""
    from crackbake.exchange.materials import base_color_table
    from crackbake.exchange.packing import base_color8

    mask = np.zeros((4, 4), np.float16)
    tex = np.zeros((4, 4, 3), np.uint8)
    for textured in (False, True):
        table = base_color_table(textured)
        base_color_half(mask, mask, table, tex if textured else None)
        base_color_half(mask, None, table, tex if textured else None)
    base_color8(mask, mask, np.zeros(65536, np.uint8), base_color_table(True), tex)
    normal_half(np.moveaxis(np.zeros((3, 4, 4), np.float32), 0, -1))
    mip_half(np.zeros((4, 4, 3), np.uint8))
