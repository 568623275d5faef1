"""The crack bake's render targets and readback images by channel: names, types, band sizes.

In a module of their own, free of numba and GL, so that a ``--cracks`` re-bake (no solver to
hide the allocation behind) starts allocating them (:class:`crackbake.bake.prefetch.TargetPrefetch`)
before the bake's modules import numba: 0.3-0.4 s the allocation used to wait.
"""

from __future__ import annotations

import numpy as np

from crackbake.bake.prefetch import ArraySpec, Spec

#: The channel targets, in the order the crack pass writes them.
NAMES = ("mask", "width", "time", "depth", "distance", "id", "inside")
# width is float32 like depth: mesh units are unbounded (half stops at 65504 and loses digits
# below 6e-5), while mask and time are 0..1.
DTYPES = ("f2", "f4", "f2", "f4", "f4", "f4", "f1")
#: A target's texture dtype -> the numpy type it is read back into.
NUMPY_TYPES = {"f1": np.uint8, "f2": np.float16, "f4": np.float32}


def band_rows(res: int, tile: int) -> int:
    """Rows of each full-width band of a ``res``-texel bake: at most ``tile**2`` texels."""
    return max(1, min(res, (tile * tile) // res))


def channel_dtypes(with_normals: bool) -> tuple[str, ...]:
    """Each channel's texture dtype (:data:`NAMES`' order)."""
    # With the normal map the inside target also says which segment's depth wins (R32F).
    return (*DTYPES[:-1], "f4") if with_normals else DTYPES


def target_specs(res: int, tile: int, with_normals: bool) -> list[Spec]:
    """The textures a UV-placed bake of ``res`` texels draws into (``tile`` as given to
    :func:`crackbake.bake.raster.bake_cracks`, ``with_normals``: tangents given), for a
    :class:`~crackbake.bake.prefetch.TargetPrefetch`: one target per channel, a band each (a
    camera's placement adds the surface targets)."""
    size = (res, band_rows(res, tile))
    return [(size, 1, d) for d in channel_dtypes(with_normals)]


def image_specs(res: int, with_normals: bool) -> list[ArraySpec]:
    """The numpy images a UV-placed bake of ``res`` texels reads its targets back into, for a
    :class:`~crackbake.bake.prefetch.TargetPrefetch` (``arrays``): one per channel, and the
    normal's three planes."""
    images = [((res, res), np.dtype(NUMPY_TYPES[d]).str) for d in channel_dtypes(with_normals)]
    if with_normals:
        images += [((3, res, res), "<f4"), ((res, res), "<f2")]  # normal, occlusion
    return images
