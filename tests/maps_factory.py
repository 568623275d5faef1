"""Synthetic baked maps with every field (normal, occlusion) and a plate UV mesh with tangents,
for the output-file tests; values analytic so expected pixels can be derived by hand."""

from __future__ import annotations

import numpy as np
from conftest import plate_mesh

from crackbake.bake.raster import CrackMaps
from crackbake.bake.uv import UVMesh


def synthetic_maps(res: int = 32, surface: bool = True) -> CrackMaps:
    """A vertical crack band with ramps; a tilted normal field; occlusion = 1 - 0.6 mask.

    ``mask`` rises along x (columns), ``time`` along rows, ``width``/``depth`` are the mask
    scaled; the normal is unit with x, y varying over the page (both signs).
    """
    j = (np.arange(res) + 0.5) / res
    x, y = np.meshgrid(j, j, indexing="xy")  # x = column (u), y = row (down the image)
    mask = np.clip(1.0 - np.abs(x - 0.5) * 4, 0, 1)
    normal = occlusion = None
    if surface:
        n = np.stack([0.6 * np.sin(6 * x), 0.5 * np.cos(5 * y) - 0.2, np.ones_like(x)], -1)
        normal = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
        occlusion = (1.0 - 0.6 * mask).astype(np.float16)
    return CrackMaps(
        res=res,
        mask=mask.astype(np.float16),
        width=(0.02 * mask).astype(np.float16),
        time=y.astype(np.float16),
        depth=(0.05 * mask).astype(np.float32),
        distance=np.abs(x - 0.5).astype(np.float32),
        crack_id=np.where(mask > 0, 0.0, -1.0).astype(np.float32),
        inside=np.ones((res, res), bool),
        max_distance=0.5,
        profile_shape=1.0,
        normal=normal,
        occlusion=occlusion,
    )


def plate_uvmesh(tangents: bool = True):
    """The unit plate (:func:`conftest.plate_mesh` with 2 cells) as a UV mesh; tangents +x."""
    m = plate_mesh(2)
    n = len(m.vertices)
    return m, UVMesh(
        vertices=m.vertices,
        faces=m.faces,
        uv=m.uv,
        normals=m.normals,
        vertex_map=np.arange(n),
        method="kept",
        overlap_fraction=0.0,
        padding_px=0,
        tangents=np.tile([1.0, 0.0, 0.0, 1.0], (n, 1)) if tangents else None,
    )
