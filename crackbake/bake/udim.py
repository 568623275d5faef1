"""UDIM tiles: one baked page per used tile, and the tiles packed into one page for the GLB.

A UDIM layout (:func:`crackbake.bake.uv.check.is_udim`: every face inside one integer UV tile,
``u`` in 0..9, ``v`` >= 0) is baked tile by tile, each tile a ``res`` x ``res`` page of its own:
its faces moved by whole tiles onto the 0-1 page, the whole crack network measured against
them.  The crack pass measures world-space distances per texel, so a crack leaving one tile's
island continues on the next tile's exactly as it continues across a UV seam inside one page:
the tiles are pages of one atlas.  The distance clamp is the whole mesh's, the data scales
(width, depth divisors of the 16-bit data map) the largest over all tiles, so every tile's
files read the same way.

glTF has no UDIM: :func:`packed_uv` and :func:`packed_maps` lay the tiles side by side on a
grid of ``ceil(sqrt(T))`` columns and as many rows as they fill (tiles in UDIM order, row by
row from the bottom), one page of square texels the GLB and the preview use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from crackbake.bake.uv.check import udim_number, udim_tiles

#: UDIM number of the 0-1 tile.
UDIM_FIRST = 1001


@dataclass(eq=False)
class UdimMaps:
    """The crack bake of a UDIM layout: one :class:`~crackbake.bake.raster.CrackMaps` per tile.

    Attributes
    ----------
    tiles : (T, 2) int64
        Integer (u, v) corner of each tile, UDIM order.
    pages : list of CrackMaps
        The tiles' maps, each (res, res), same order.
    timings : dict
        Seconds per bake phase, summed over the tiles.
    scales : dict
        The data map's width and depth divisors shared by every tile (set by :func:`bake_udim`).

    The scalar attributes the writers read from a bake (``res``, ``max_distance``,
    ``profile_shape``, ``min_px``, ``look``, ``normal`` and ``occlusion`` being baked) are the
    tiles' common values.
    """

    tiles: np.ndarray
    pages: list
    timings: dict[str, float] = field(default_factory=dict)
    scales: dict | None = None

    @property
    def numbers(self) -> list[int]:
        """UDIM numbers of the tiles, ascending."""
        return [int(n) for n in udim_number(self.tiles)]

    @property
    def res(self) -> int:
        return int(self.pages[0].res)

    @property
    def max_distance(self) -> float:
        return float(self.pages[0].max_distance)

    @property
    def profile_shape(self) -> float:
        return float(self.pages[0].profile_shape)

    @property
    def min_px(self) -> float:
        return float(self.pages[0].min_px)

    @property
    def look(self):
        return self.pages[0].look

    @property
    def normal(self):
        return self.pages[0].normal

    @property
    def occlusion(self):
        return self.pages[0].occlusion

    def channels(self) -> dict[str, np.ndarray]:
        """Role -> the first tile's image (the roles baked, the same on every tile)."""
        return self.pages[0].channels()

    def coverage(self) -> float:
        """Share of the tiles' texels inside UV islands (mean over the tiles)."""
        return float(np.mean([p.inside.mean() for p in self.pages]))

    def shared_scales(self) -> dict[str, float]:
        """The data map's width and depth divisors over every tile (mesh units, 1 when 0)."""
        w = max(data_scales_raw(p)["width"] for p in self.pages)
        d = max(data_scales_raw(p)["depth"] for p in self.pages)
        return {"width": w if w > 0 else 1.0, "depth": d if d > 0 else 1.0}


def data_scales_raw(maps) -> dict[str, float]:
    """Largest width and depth of one page, mesh units (0 when none)."""
    w = float(np.max(maps.width)) if maps.width.size else 0.0
    d = float(np.max(maps.depth)) if maps.depth.size else 0.0
    return {"width": w, "depth": d}


def tile_faces(uv: np.ndarray, faces: np.ndarray, tiles: np.ndarray) -> list[np.ndarray]:
    """The face indices on each tile, in ``tiles``' order.

    Parameters
    ----------
    uv : (V, 2) float
    faces : (F, 3) int
    tiles : (T, 2) int
        Integer tile corners (``UVMesh.udim``).

    Returns
    -------
    list of (F_t,) int64
    """
    face_number = udim_number(udim_tiles(np.asarray(uv, np.float64)[faces]))
    return [np.flatnonzero(face_number == n) for n in udim_number(tiles)]


def bake_udim(arrays: dict, tiles: np.ndarray, segments, res: int, *, max_distance=None,
              **bake_kwargs) -> UdimMaps:
    """Bake every tile of a UDIM layout into a page of its own.

    Parameters
    ----------
    arrays : dict
        ``vertices``, ``faces``, ``uv``, ``normals``, ``tangents``
        (:func:`crackbake.bake.uv.uvmesh.bake_arrays`), UVs spanning the tiles.
    tiles : (T, 2) int
        The used tiles (``UVMesh.udim``).
    segments : Segments
        The whole network: each tile measures every crack, so cracks run on across tile edges.
    res : int
        Texels per tile edge (``--res`` is per tile).
    max_distance : float, optional
        Distance clamp, mesh units; default the whole mesh's (not a tile's) diagonal fraction.
    **bake_kwargs
        The other keywords of :func:`crackbake.bake.raster.bake_cracks`.

    Returns
    -------
    UdimMaps
    """
    from crackbake.bake.raster import _max_distance, bake_cracks

    vertices = np.asarray(arrays["vertices"], np.float64)
    faces = np.asarray(arrays["faces"], np.int64)
    uv = np.asarray(arrays["uv"], np.float64)
    # Once for the whole mesh (and one warning), so every tile clamps alike.
    max_distance = _max_distance(vertices, segments, max_distance)
    pages = []
    timings: dict[str, float] = {}
    for tile, own in zip(tiles, tile_faces(uv, faces, tiles), strict=True):
        # Every vertex of a tile's face lies in that tile (is_udim), so one shift moves them
        # all onto the 0-1 page; vertices of other tiles are not drawn.
        maps = bake_cracks(vertices, faces[own], uv - np.asarray(tile, np.float64), segments,
                           res, max_distance=max_distance, normals=arrays["normals"],
                           tangents=arrays["tangents"], **bake_kwargs)  # fmt: skip
        for k, v in maps.timings.items():
            timings[k] = timings.get(k, 0.0) + v
        pages.append(maps)
    out = UdimMaps(tiles=np.asarray(tiles, np.int64), pages=pages, timings=timings)
    scales = out.shared_scales()
    out.scales = scales
    for p in pages:
        p.scales = scales  # every tile's data map divides by the same width and depth
    return out


def tile_uvmesh(uvmesh, tile: np.ndarray):
    """``uvmesh`` with its UVs moved by whole tiles so that ``tile`` lies on the 0-1 page (the
    other tiles' faces fall outside it and draw nothing)."""
    return replace(uvmesh, uv=np.asarray(uvmesh.uv, np.float64) - np.asarray(tile, np.float64),
                   udim=None)  # fmt: skip


def grid_size(n_tiles: int) -> tuple[int, int]:
    """(columns, rows) of the grid the GLB packs ``n_tiles`` tiles on: ``ceil(sqrt(T))``
    columns and as many rows as they fill, so no row is left empty (2 tiles: 2 x 1)."""
    cols = max(1, math.ceil(math.sqrt(n_tiles)))
    return cols, max(1, math.ceil(n_tiles / cols))


def packed_uv(uv: np.ndarray, faces: np.ndarray, tiles: np.ndarray) -> np.ndarray:
    """The UVs remapped onto the packed page: tile ``i`` to cell ``(i % cols, i // cols)``.

    Returns
    -------
    (V, 2) float64
        In [0, 1]; vertices no face uses keep their UVs divided by the grid size.
    """
    uv = np.asarray(uv, np.float64)
    cols, rows = grid_size(len(tiles))
    shift = np.zeros_like(uv)
    for i, own in enumerate(tile_faces(uv, faces, tiles)):
        cell = np.array([i % cols, i // cols], np.float64)
        verts = np.unique(np.asarray(faces)[own])
        shift[verts] = cell - np.asarray(tiles[i], np.float64)
    return (uv + shift) / np.array([cols, rows], np.float64)


@dataclass(eq=False)
class PackedPage:
    """The tiles' mask, normal and occlusion side by side on one page, (rows x cell,
    cols x cell) texels: what the GLB's base colour, normal and ORM textures and the preview
    are made from.  ``res`` is its larger edge."""

    res: int
    mask: np.ndarray
    normal: np.ndarray | None
    occlusion: np.ndarray | None
    look: object = None
    texture: np.ndarray | None = None


def packed_maps(maps: UdimMaps, max_size: int, textures: list | None = None) -> PackedPage:
    """The tiles box-filtered (by halvings) into square cells of a page at most ``max_size``
    texels wide (the GLB's texture limit), laid out as :func:`packed_uv` lays out the UVs.

    ``textures``: the asset's base colour per tile ((res, res, 3) uint8, or None for a tile
    without one), packed the same way into ``PackedPage.texture``; tiles without one and
    empty cells get the grey the untextured base colour uses, so they composite as before.
    """
    from crackbake.exchange.materials import SURFACE_RGB, downsample

    cols, rows = grid_size(len(maps.pages))
    cell = maps.res
    while cols * cell > max_size and cell % 2 == 0:
        cell //= 2
    shape = (rows * cell, cols * cell)
    first = maps.pages[0]
    mask_dtype = first.mask.dtype if cell == maps.res else np.float32
    mask = np.zeros(shape, mask_dtype)
    normal = None
    if first.normal is not None:
        normal = np.zeros((*shape, 3), np.float32)
        normal[..., 2] = 1.0
    occ = None
    if first.occlusion is not None:
        occ = np.ones(shape, first.occlusion.dtype if cell == maps.res else np.float32)
    texture = None
    if textures is not None and any(t is not None for t in textures):
        texture = np.empty((*shape, 3), np.uint8)
        texture[:] = SURFACE_RGB.astype(np.uint8)
    for i, p in enumerate(maps.pages):
        col, row = i % cols, i // cols
        # Image rows run from the top (v = 1): cell row 0 (v 0..1/rows) is the last band.
        r0, c0 = (rows - 1 - row) * cell, col * cell
        mask[r0:r0 + cell, c0:c0 + cell] = downsample(p.mask, cell)
        if normal is not None:
            n = downsample(p.normal, cell)
            if cell != maps.res:
                n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
            normal[r0:r0 + cell, c0:c0 + cell] = n
        if occ is not None:
            occ[r0:r0 + cell, c0:c0 + cell] = downsample(p.occlusion, cell)
        if texture is not None and textures[i] is not None:
            t = downsample(textures[i], cell)
            texture[r0:r0 + cell, c0:c0 + cell] = t if t.dtype == np.uint8 else t + 0.5
    return PackedPage(res=max(shape), mask=mask, normal=normal, occlusion=occ, look=first.look,
                      texture=texture)  # fmt: skip


def udim_name(name: str, number: int | str) -> str:
    """``name`` with ``.<number>`` before its extension: ``a_mask.png`` -> ``a_mask.1001.png``."""
    stem, dot, ext = name.rpartition(".")
    if not dot:
        return f"{name}.{number}"
    return f"{stem}.{number}.{ext}"
