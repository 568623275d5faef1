"""The GLB's and the preview's base colour: a light surface with dark cracks (sRGB)."""

from __future__ import annotations

import numpy as np

#: Base colour of the GLB preview material: intact surface and crack interior (sRGB, 0..255).
SURFACE_RGB = np.array([200, 196, 188], np.float32)
CRACK_RGB = np.array([24, 20, 18], np.float32)

#: Largest edge of the GLB's embedded base colour: 8K textures make GLBs slow to write and too
#: big for many viewers (WebGL/mobile limits); the EXR/PNG maps keep the full resolution.
GLB_TEXTURE_MAX = 4096


def base_color(mask: np.ndarray, max_size: int | None = None) -> np.ndarray:
    """sRGB uint8 (H, W, 3) preview colour: light surface, dark cracks.

    Parameters
    ----------
    mask : (H, W) ndarray
        Crack coverage 0..1.
    max_size : int, optional
        Box-filter the mask down by a power of two until its edge is at most this.
    """
    m = mask.astype(np.float32)
    while max_size is not None and m.shape[0] > max_size and m.shape[0] % 2 == 0:
        m = m.reshape(m.shape[0] // 2, 2, m.shape[1] // 2, 2).mean(axis=(1, 3))
    m = m[..., None]
    rgb = SURFACE_RGB + (CRACK_RGB - SURFACE_RGB) * m
    return np.clip(rgb + 0.5, 0, 255).astype(np.uint8)
