"""A decimated stand-in for an asset far denser than the simulation needs.

The solver's cost grows with crack length over sim edge length, and a simulation mesh built by
refinement can never be coarser than the asset: a 1.5M-face scan would be simulated on 1.5M
faces whatever ``--sim-faces`` says.  Above :func:`proxy_limit` faces the asset's welded surface
is decimated (shortest edges first, :mod:`.collapse`; open borders put back on the asset's
border) to about the wanted face count and the simulation mesh is refined inside the *proxy's*
faces.  Its nodes then lie near the asset surface, not on it, so everything that must be on the
asset is projected to the closest asset point (libigl's AABB tree, :class:`SurfaceIndex`): each sim
node's asset face and barycentrics, each sim face's asset face (of its centroid) and, after the
solve, every crack point (:func:`onto_asset`).
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from crackbake.geometry import SurfaceIndex, edges
from crackbake.simulate.simmesh.collapse import decimate_shortest

# Assets up to twice the wanted sim face count (and never below 200k faces) are simulated on a
# refinement of their own faces: there the solve costs seconds and the proxy's decimation and
# projections would cost as much as they save.
PROXY_RATIO = 2.0
PROXY_MIN_FACES = 200_000


@dataclass(frozen=True, eq=False)
class Proxy:
    """The decimated surface and the way back to the asset.

    Attributes
    ----------
    vertices : (P, 3) float64
        Decimated surface, mesh units.
    faces : (Q, 3) int64
        Its triangles.
    surface : SurfaceIndex
        Closest points on the asset's welded, non-degenerate faces.
    rows : (R,) int64
        Asset face (row of ``Mesh.faces``) of each face of ``surface``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    surface: SurfaceIndex
    rows: np.ndarray

    def onto_asset(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest asset point to each of ``points`` (K, 3): asset face (K,), barycentrics in
        that face's corner order (K, 3) and position (K, 3), mesh units."""
        face, bary, position = self.surface.closest(points)
        return self.rows[face], bary, position


def proxy_limit(n_wanted: float) -> int:
    """Asset face count above which a sim mesh of about ``n_wanted`` faces uses a proxy."""
    return int(max(PROXY_RATIO * n_wanted, PROXY_MIN_FACES))


def decimate(vertices: np.ndarray, faces: np.ndarray, rows: np.ndarray, n_faces: int) -> Proxy:
    """The asset's welded surface decimated to about ``n_faces`` faces.

    Shortest edges collapse first, to their midpoints (:func:`.collapse.decimate_shortest`,
    libigl's rule in rounds, about 4x faster than its ``decimate``): the result is
    nearly isotropic, which the solver needs (quadric decimation keeps the shape better but
    leaves ~7% needle triangles, and one needle's stress spike set every crack's width).
    Collapses next to an open border pull it inward by up to half an edge, so the proxy's
    border vertices are put back on the asset's border.

    Parameters
    ----------
    vertices : (W, 3) float64
        Welded asset vertices.
    faces : (R, 3) int64
        Welded, non-degenerate, manifold asset faces, corner order as in the asset.
    rows : (R,) int64
        Asset face of each row of ``faces``.
    n_faces : int
        Wanted proxy face count (fewer than ``len(faces)``).

    Returns
    -------
    Proxy
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    # The asset's AABB tree (2 s at 1.5M faces) is built beside the decimation: two
    # independent results, so the same ones as one after the other.  libigl's AABB.init holds
    # the GIL and the decimation kernel releases it, so the kernel must start first (the other
    # way round the decimation waited for the whole tree): it runs on the worker and the tree
    # is built here once the worker is about to enter it.
    started = threading.Event()
    with ThreadPoolExecutor(1) as pool:
        job = pool.submit(decimate_shortest, v, f, int(min(n_faces, len(f) - 1)), started)
        while not started.wait(0.01) and not job.done():  # done: it failed before the kernel
            pass
        surface = SurfaceIndex(v, f)
        border = _asset_border(v, f)  # also while the kernel runs
        pv, pf = job.result()
    _onto_border(pv, pf, v, border)
    return Proxy(vertices=pv, faces=pf, surface=surface, rows=np.asarray(rows, np.int64))


def _asset_border(v: np.ndarray, f: np.ndarray):
    """The asset's open-border edges (B, 2) and their AABB tree (None without a border)."""
    import igl

    from crackbake.simulate.simmesh.collapse_kernels import border_edges

    asset_border = border_edges(f, len(v))
    if not len(asset_border):
        return asset_border, None
    tree = igl.AABB()
    tree.init(v, asset_border)
    return asset_border, tree


def _onto_border(pv: np.ndarray, pf: np.ndarray, v: np.ndarray, border) -> None:
    """Move the proxy's border vertices (in place) to the closest point of the asset's border
    (:func:`_asset_border`)."""
    asset_border, tree = border
    pe, p_count = edges(pf, len(pv))
    ends = np.unique(pe[p_count == 1])
    if not len(ends) or tree is None:
        return
    _, _, closest = tree.squared_distance(v, asset_border, np.ascontiguousarray(pv[ends]))
    pv[ends] = closest


def onto_asset(paths: list, proxy: Proxy | None) -> list:
    """Crack paths grown on a proxy, moved to the closest asset points and faces.

    ``paths`` are :class:`~crackbake.simulate.solver.CrackPath`; returned unchanged when
    ``proxy`` is None (a sim mesh inside the asset's own faces).
    """
    if proxy is None:
        return paths
    if not paths:
        proxy.surface.stop_worker()  # built ahead for a query that will not come
        return paths
    counts = [len(p.points) for p in paths]
    face, _, position = proxy.onto_asset(np.concatenate([p.points for p in paths]))
    cut = np.cumsum(counts)[:-1]
    return [replace(p, points=x, asset_faces=f)
            for p, x, f in zip(paths, np.split(position, cut), np.split(face, cut), strict=True)]
