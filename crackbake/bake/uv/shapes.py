"""Generated stand-ins for the meshes users unwrap: a scan-like blob and a flat relief.

Used by the unwrap tests and ``benchmarks/bench_unwrap.py`` (neither may depend on files users
do not have).  Both are deterministic for a given seed and carry no UVs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crackbake.geometry import welded_vertex_normals
from crackbake.io.mesh import Mesh

__all__ = ["relief_plane", "scan_blob", "write_obj"]


def _cube_sphere(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed cube of ``6 n^2`` quads (``12 n^2`` triangles) on integer lattice points."""
    t = np.arange(n + 1)
    a, b = np.meshgrid(t, t, indexing="ij")
    a, b = a.ravel(), b.ravel()
    k0 = np.zeros_like(a)
    kn = np.full_like(a, n)
    # Each cube face as (n+1)^2 lattice points; corners and edges repeat, merged below.
    sides = [
        np.stack([k0, b, a], 1), np.stack([kn, a, b], 1),
        np.stack([a, k0, b], 1), np.stack([b, kn, a], 1),
        np.stack([b, a, k0], 1), np.stack([a, b, kn], 1),
    ]  # fmt: skip
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    q0 = (i * (n + 1) + j).ravel()
    q1, q2, q3 = q0 + (n + 1), q0 + (n + 1) + 1, q0 + 1
    quad_tris = np.concatenate([np.stack([q0, q1, q2], 1), np.stack([q0, q2, q3], 1)])
    points = np.concatenate(sides)
    faces = np.concatenate([quad_tris + s * (n + 1) ** 2 for s in range(6)])
    unique, inverse = np.unique(points, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    return unique.astype(np.float64) / n - 0.5, faces.astype(np.int64)


def _outward(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``faces`` wound so the normals of a star-shaped closed surface point away from 0."""
    c = vertices[faces]
    n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    flip = np.einsum("ij,ij->i", n, c.mean(axis=1)) < 0
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    return faces


def scan_blob(n_faces: int = 5000, diagonal: float = 0.15, seed: int = 0) -> Mesh:
    """A bumpy closed surface like a scanned head or stone, about ``n_faces`` triangles.

    A cube subdivided into ``12 n^2`` triangles (``n`` from ``n_faces``), its lattice jittered
    (irregular triangles, as a scan's), projected onto a sphere and displaced by a few dozen
    random bumps; scaled so the bounding-box diagonal is ``diagonal`` (mesh units).
    """
    rng = np.random.default_rng(seed)
    n = max(2, int(round(np.sqrt(n_faces / 12.0))))
    v, f = _cube_sphere(n)
    # Wound on the plain cube, where every face's normal points away from the centre; the
    # jitter and the bumps below move vertices along rays and keep that winding (winding the
    # bumpy surface by the same test flipped faces on the flanks of bumps).
    f = _outward(v, f)
    v = v + rng.uniform(-0.3, 0.3, v.shape) / n
    d = v / np.linalg.norm(v, axis=1, keepdims=True)
    centres = rng.normal(size=(40, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    amp = rng.uniform(-0.12, 0.18, 40)
    width = rng.uniform(0.15, 0.5, 40)
    r = 1.0 + (amp * np.exp(-((1.0 - d @ centres.T) / width**2))).sum(axis=1)
    r += 0.01 * np.sin(25.0 * d[:, 0]) * np.sin(23.0 * d[:, 1])  # fine detail, as scans have
    v = d * r[:, None] * np.array([0.8, 1.0, 0.9])
    return _finish(v, f, diagonal, "scan_blob")


def relief_plane(
    n: int = 60, diagonal: float = 1.0, seed: int = 0, thickness: float = 0.0
) -> Mesh:
    """A flat heightfield (a relief, a planar character): ``2 n^2`` triangles, open border.

    Heights are at most 5 % of the width, from a few random bumps and ridges.  With
    ``thickness`` > 0 (fraction of the width) it is a closed slab: a flat back ``thickness``
    below and thin side walls one quad high (``4 n^2 + 8 n`` triangles), as a carved panel is.
    """
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    z = np.zeros_like(x)
    for _ in range(12):
        cx, cy, s = rng.uniform(0.1, 0.9), rng.uniform(0.1, 0.9), rng.uniform(0.04, 0.15)
        z += rng.uniform(-0.04, 0.05) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / s**2)
    v = np.stack([x.ravel(), 0.7 * y.ravel(), z.ravel()], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    q0 = (i * (n + 1) + j).ravel()
    q1, q2, q3 = q0 + (n + 1), q0 + (n + 1) + 1, q0 + 1
    f = np.concatenate([np.stack([q0, q1, q2], 1), np.stack([q0, q2, q3], 1)])
    if thickness > 0:
        m = (n + 1) ** 2
        back = v.copy()
        back[:, 2] = -thickness
        v = np.concatenate([v, back])
        f = np.concatenate([f, f[:, ::-1] + m])
        # The border loop (counter-clockwise seen from +z), stitched to its copy on the back.
        g = np.arange(m).reshape(n + 1, n + 1)
        loop = np.concatenate([g[:, 0], g[-1, 1:], g[-2::-1, -1], g[0, -2:0:-1]])
        a, b = loop, np.roll(loop, -1)
        f = np.concatenate([f, np.stack([a, a + m, b + m], 1), np.stack([a, b + m, b], 1)])
    return _finish(v, f.astype(np.int64), diagonal, "relief_plane")


def _finish(v: np.ndarray, f: np.ndarray, diagonal: float, name: str) -> Mesh:
    v = v - v.min(axis=0)
    v *= diagonal / np.linalg.norm(v.max(axis=0))
    return Mesh(vertices=v, faces=f, uv=None, normals=welded_vertex_normals(v, f),
                source=f"{name}.obj", name=name)  # fmt: skip


def write_obj(mesh: Mesh, path: str | Path) -> Path:
    """Write positions and faces (no UVs, no normals) as a Wavefront OBJ; return ``path``."""
    path = Path(path)
    with open(path, "w") as fh:
        np.savetxt(fh, mesh.vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(fh, mesh.faces + 1, fmt="f %d %d %d")
    return path
