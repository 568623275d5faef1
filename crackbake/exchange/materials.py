"""Surface values of the written material: base colour with the cracks composited, roughness.

The base colour is the asset's own texture (or a neutral light grey) with the cracks painted
over it: each channel is scaled towards :data:`CRACK_RGB` / :data:`SURFACE_RGB` by the crack
mask (so on the grey default the crack colour is exactly :data:`CRACK_RGB`), then multiplied by
the occlusion (converted to sRGB), so crack interiors also read dark under direct light.
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
    """Box-filter by powers of two until the edge is at most ``max_size`` (float32 out)."""
    m = np.asarray(image, np.float32)
    while max_size is not None and m.shape[0] > max_size and m.shape[0] % 2 == 0:
        m = m.reshape(m.shape[0] // 2, 2, m.shape[1] // 2, 2, *m.shape[2:]).mean(axis=(1, 3))
    return m


def base_color(
    mask: np.ndarray,
    max_size: int | None = None,
    occlusion: np.ndarray | None = None,
    texture: np.ndarray | None = None,
) -> np.ndarray:
    """sRGB uint8 (H, W, 3) base colour: the texture (or light grey) with dark cracks.

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
    m = downsample(mask, max_size)
    tint = CRACK_RGB / SURFACE_RGB - 1.0
    # factor = 1 + tint * m per channel: exactly CRACK_RGB on the grey default at m = 1.
    factor = m[..., None] * tint
    factor += 1.0
    if occlusion is not None:
        occ = downsample(occlusion, max_size)
        np.clip(occ, 0.0, 1.0, out=occ)
        factor *= (occ ** (1 / 2.2))[..., None]  # linear multiply, applied to sRGB values
    if texture is None:
        factor *= SURFACE_RGB
    else:
        factor *= downsample(texture, max_size)
    factor += 0.5
    np.clip(factor, 0, 255, out=factor)
    return factor.astype(np.uint8)
