"""Surface values of the written material: base colour with the cracks composited, roughness.

The base colour is the asset's own texture (or a neutral light grey) with the cracks painted
over it as the run's :class:`crackbake.looks.Look` says.  On the grey :data:`SURFACE_RGB` the
crack mask ``m`` blends towards the look's colour ``c`` (per channel, sRGB):

* ``darken``: ``S + m (min(S, c) - S)``, times the occlusion (converted to sRGB), so crack
  interiors also read dark under direct light (the default look, ``c`` = :data:`CRACK_RGB`);
* ``lighten``: ``S + m (max(S, c) - S)``, no occlusion: bright fracture lines (glass);
* ``multiply``: ``S (1 + m (c / 255 - 1))``, times the occlusion: a stain.

On a texture each channel is scaled by the same ratio as the grey surface (result / ``S``),
clipped to 255, so the texture's detail shows through.
"""

from __future__ import annotations

import numpy as np

#: Base colour of the default material: intact surface and crack interior (sRGB, 0..255).
SURFACE_RGB = np.array([200, 196, 188], np.float32)
CRACK_RGB = np.array([24, 20, 18], np.float32)

#: Roughness of the intact surface and of a crack's interior (linear, 0..1); metallic is 0.
ROUGHNESS_SURFACE = 0.8
ROUGHNESS_CRACK = 1.0

#: Largest edge of the GLB's embedded textures: 8K textures make GLBs slow to write and too
#: big for many viewers (WebGL/mobile limits); the EXR/PNG maps keep the full resolution.
GLB_TEXTURE_MAX = 4096


def half_lut(fn) -> np.ndarray:
    """A 65536-entry table of ``fn`` over every float16 bit pattern (NaN -> 0).

    Indexing it with ``plane.view(np.uint16)`` maps a float16 plane in one gather, several
    times faster than converting to float32 and computing.
    """
    x = np.arange(65536, dtype=np.uint16).view(np.float16).astype(np.float32)
    with np.errstate(all="ignore"):
        y = np.asarray(fn(np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0)), np.float32)
    return y


def downsample(image: np.ndarray, max_size: int | None) -> np.ndarray:
    """Box-filter by powers of two until the edge is at most ``max_size``.

    Returns ``image`` itself when it is small enough, else float32.  Four strided slices per
    level (a reshape-mean over two axes was 10x slower at 4096²).
    """
    m = image
    while max_size is not None and m.shape[0] > max_size and m.shape[0] % 2 == 0:
        acc = m[0::2, 0::2].astype(np.float32)
        acc += m[1::2, 0::2]
        acc += m[0::2, 1::2]
        acc += m[1::2, 1::2]
        acc *= np.float32(0.25)
        m = acc
    return m


def unit_u8(plane: np.ndarray) -> np.ndarray:
    """A [0, 1] plane rounded to uint8 (clipped; NaN -> 0); float16 through one table gather."""
    if plane.dtype == np.float16:
        return np.take(_unit_lut(), plane.view(np.uint16))
    q = np.asarray(plane, np.float32) * np.float32(255)
    q += np.float32(0.5)
    np.clip(q, 0, 255, out=q)
    return q.astype(np.uint8)


def _factors(look=None) -> np.ndarray:
    """(65536, 3) float64: the colour factor (result / :data:`SURFACE_RGB`) for mask
    m = i // 256 and occlusion o = i % 256 under ``look`` (None: the default look)."""
    m = np.repeat(np.arange(256) / 255.0, 256)[:, None]
    o = np.tile(np.arange(256) / 255.0, 256)[:, None]
    if look is None:
        return (1.0 + m * (CRACK_RGB / SURFACE_RGB - 1.0)) * o ** (1 / 2.2)
    c = np.asarray(look.color, np.float64)
    s = SURFACE_RGB.astype(np.float64)
    if look.mode == "lighten":
        return 1.0 + m * (np.maximum(s, c) / s - 1.0)
    if look.mode == "multiply":
        return (1.0 + m * (c / 255.0 - 1.0)) * o ** (1 / 2.2)
    return (1.0 + m * (np.minimum(s, c) / s - 1.0)) * o ** (1 / 2.2)


def base_color_table(textured: bool, look=None) -> np.ndarray:
    """(65536, 3) table indexed by ``mask level << 8 | occlusion level`` (8-bit levels).

    Without a texture: the uint8 sRGB colour over :data:`SURFACE_RGB`; with one: uint16
    factors (256 = 1, above 256 where a ``lighten`` look brightens) that scale the texture's
    sRGB values, rounded as ``min((t f + 128) >> 8, 255)``.  ``look``: a
    :class:`crackbake.looks.Look` (None: the default look).
    """
    if textured:
        return np.clip(_factors(look) * 256 + 0.5, 0, 4096).astype(np.uint16)
    return np.clip(_factors(look) * SURFACE_RGB + 0.5, 0, 255).astype(np.uint8)


def roughness_at(mask: np.ndarray, look=None) -> np.ndarray:
    """Roughness 0..1 for crack coverage ``mask``: the surface's towards the look's crack
    roughness (:data:`ROUGHNESS_CRACK` without a look)."""
    b = ROUGHNESS_CRACK if look is None else float(look.roughness)
    return ROUGHNESS_SURFACE + (b - ROUGHNESS_SURFACE) * np.clip(mask, 0, 1)


def base_color(
    mask: np.ndarray,
    max_size: int | None = None,
    occlusion: np.ndarray | None = None,
    texture: np.ndarray | None = None,
    look=None,
) -> np.ndarray:
    """sRGB uint8 (H, W, 3) base colour: the texture (or light grey) with the cracks composited
    as ``look`` (a :class:`crackbake.looks.Look`; None: the default dark look) says.

    Mask and occlusion are rounded to 8 bits and the colour looked up in a 65536-entry table
    (one gather for the whole page): the result is within one level of the exact formula.

    Parameters
    ----------
    mask : (H, W) ndarray
        Crack coverage 0..1.
    max_size : int, optional
        Box-filter the inputs down by a power of two until the edge is at most this.
    occlusion : (H, W) ndarray, optional
        0..1, 1 = open; multiplies the colour (in linear light).
    texture : (H, W, 3) uint8, optional
        The asset's sRGB base colour at the mask's resolution; :data:`SURFACE_RGB` when absent.
    """
    fused = _base_color_fused(mask, max_size, occlusion, texture, look)
    if fused is not None:
        return fused
    idx = unit_u8(downsample(mask, max_size)).astype(np.uint16) << 8
    if occlusion is None:
        idx |= 255
    else:
        idx |= unit_u8(downsample(occlusion, max_size))
    table = base_color_table(texture is not None, look)
    if texture is None:
        return np.take(table, idx, axis=0)  # 4x faster than table[idx] here
    tex = downsample(texture, max_size)
    out = np.asarray(tex, np.uint32) if tex.dtype == np.uint8 else (tex + 0.5).astype(np.uint32)
    out *= np.take(table, idx, axis=0)
    out += 128
    out >>= 8
    np.minimum(out, 255, out=out)
    return out.astype(np.uint8)


def _unit_lut() -> np.ndarray:
    """(65536,) uint8: :func:`unit_u8` of every float16 bit pattern."""
    return np.clip(half_lut(lambda x: x * 255 + 0.5), 0, 255).astype(np.uint8)


def _base_color_fused(mask, max_size, occlusion, texture, look=None) -> np.ndarray | None:
    """:func:`base_color` in one pass (:func:`crackbake.exchange.packing.base_color8`) for the
    usual full-size float16 maps and uint8 texture; None otherwise (the numpy path)."""
    from crackbake.exchange.packing import base_color8

    if max_size is not None and mask.shape[0] > max_size:
        return None
    if mask.dtype != np.float16 or (occlusion is not None and occlusion.dtype != np.float16):
        return None
    if texture is not None and (texture.dtype != np.uint8 or texture.shape[:2] != mask.shape):
        return None
    table = base_color_table(texture is not None, look)
    return base_color8(mask, occlusion, _unit_lut(), table, texture)
