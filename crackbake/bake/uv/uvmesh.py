"""The output mesh the textures are baked for (:class:`UVMesh`) and the unwrap's gutter size.

Conventions: UVs are in [0, 1] with ``v`` pointing up (OBJ/Blender); texel ``(i, j)`` of a
``res`` x ``res`` page covers ``u`` in ``[i, i+1] / res`` and ``v`` in ``[j, j+1] / res`` (GL's
framebuffer rows, row 0 at the bottom).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crackbake.io.mesh import Mesh


@dataclass(frozen=True, eq=False)
class UVMesh:
    """The output mesh: the asset's faces (same count and order as ``Mesh.faces``), UVs used.

    Attributes
    ----------
    vertices : (V', 3) float64
        Positions, mesh units; ``vertices == mesh.vertices[vertex_map]`` exactly.
    faces : (F, 3) int64
        Same faces, same order and same corner order as the input ``Mesh.faces``.
    uv : (V', 2) float64
        In [0, 1], ``v`` up (OBJ/Blender convention), one square page.
    normals : (V', 3) float64
        Unit normals, ``mesh.normals[vertex_map]``.
    vertex_map : (V',) int64
        Index into the input ``Mesh.vertices`` for each output vertex.
    method : str
        ``"kept"`` (the asset's UVs) or ``"unwrapped"`` (xatlas).
    overlap_fraction : float
        Overlapping UV area / covered UV area, 0..1 (NaN when an unwrap could not measure it
        because no OpenGL context was available).
    padding_px : int
        Chart gutter in texels at the resolution unwrapped for (0 when kept).
    tangents : (V', 4) float64 or None
        MikkTSpace tangent frames (:func:`crackbake.bake.tangents.with_tangents` sets them and
        splits vertices whose corners disagree): ``xyz`` unit, along +u and orthogonal to the
        normal; ``w`` = +1 or -1, the bitangent sign, so ``B = w * cross(N, T)`` points
        towards +v (up in the image).  None until computed.
    wraps : (K, 3) int64 or None
        Kept UVs only: copies (face, du, dv) of faces straying past the page, baked at
        ``uv - (du, dv)`` where an engine sampling with REPEAT shows them
        (:func:`crackbake.bake.uv.check.check_uvs` chose those that overlap no other face).
        The GLB keeps the artist's UVs; only the bake draws the copies (:func:`bake_arrays`).
    udim : (T, 2) int64 or None
        Kept UVs on UDIM tiles only: the used tiles' integer (u, v) corners in UDIM order
        (:mod:`crackbake.bake.udim` bakes one page per tile); ``uv`` then spans the tiles.
        None for a single 0-1 page.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    normals: np.ndarray
    vertex_map: np.ndarray
    method: str
    overlap_fraction: float
    padding_px: int
    tangents: np.ndarray | None = None
    wraps: np.ndarray | None = None
    udim: np.ndarray | None = None


def bake_arrays(uvmesh: UVMesh) -> dict[str, np.ndarray | None]:
    """The triangles the textures are baked from: the faces plus their wrapped copies.

    Parameters
    ----------
    uvmesh : UVMesh

    Returns
    -------
    dict
        ``vertices`` (V'', 3), ``faces`` (F + K, 3), ``uv`` (V'', 2), ``normals`` (V'', 3) and
        ``tangents`` (V'', 4) or None: the keyword arguments of
        :func:`crackbake.bake.raster.bake_cracks`.  The first V' vertices and F faces are
        ``uvmesh``'s own; each copy in ``uvmesh.wraps`` adds three vertices (its face's
        corners, same position, normal and tangent, UVs shifted by whole tiles) and a face.
    """
    out = {
        "vertices": uvmesh.vertices,
        "faces": uvmesh.faces,
        "uv": uvmesh.uv,
        "normals": uvmesh.normals,
        "tangents": uvmesh.tangents,
    }
    wraps = uvmesh.wraps
    if wraps is None or len(wraps) == 0:
        return out
    wraps = np.asarray(wraps, np.int64)
    corners = np.asarray(uvmesh.faces, np.int64)[wraps[:, 0]].reshape(-1)  # (3K,)
    shift = np.repeat(wraps[:, 1:3].astype(np.float64), 3, axis=0)
    n = len(uvmesh.vertices)
    out["vertices"] = np.concatenate([uvmesh.vertices, uvmesh.vertices[corners]])
    out["uv"] = np.concatenate([uvmesh.uv, uvmesh.uv[corners] - shift])
    out["normals"] = np.concatenate([uvmesh.normals, uvmesh.normals[corners]])
    if uvmesh.tangents is not None:
        out["tangents"] = np.concatenate([uvmesh.tangents, uvmesh.tangents[corners]])
    out["faces"] = np.concatenate(
        [uvmesh.faces, n + np.arange(3 * len(wraps), dtype=np.int64).reshape(-1, 3)]
    )
    return out


def uv_area_coverage(uv: np.ndarray, faces: np.ndarray) -> float:
    """Share of the [0, 1] page inside UV triangles, from their areas: (F, 3) faces into (V, 2).

    Exact for an unwrap (xatlas charts never overlap and lie in the page); for kept UVs it
    counts overlapping area twice, so reports use the bake's footprint
    (:attr:`crackbake.bake.raster.CrackMaps.inside`) instead.
    """
    c = np.asarray(uv, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    return float(min(1.0, 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()))


def mesh_label(mesh: Mesh) -> str:
    """The mesh's file name (or object name) for messages."""
    return Path(mesh.source).name if mesh.source else mesh.name


def unwrapped_uvmesh(
    mesh: Mesh,
    vertex_map: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    overlap: float,
    padding: int,
) -> UVMesh:
    """The :class:`UVMesh` of an unwrap: ``mesh``'s positions and normals gathered by
    ``vertex_map``."""
    return UVMesh(
        vertices=np.asarray(mesh.vertices, dtype=np.float64)[vertex_map],
        faces=faces,
        uv=uv,
        normals=np.asarray(mesh.normals, dtype=np.float64)[vertex_map],
        vertex_map=vertex_map,
        method="unwrapped",
        overlap_fraction=overlap,
        padding_px=int(padding),
    )
