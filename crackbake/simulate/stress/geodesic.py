"""Impact points on the surface and geodesic distance from them.

Impacts use the *geodesic* distance over the surface, not the straight-line one, so an impact on
one wall of a thin shell or a bottle does not leak through to the opposite wall.  The distance
comes from geometry-central's fast marching (``potpourri3d``), run only on the part of the mesh
that can lie within the impact's reach.  That patch is made manifold first (its rim can pinch to
single vertices, and a user's non-manifold edges are already cut in the sim mesh), so fast
marching runs on clean meshes and on broken ones; only where that library is missing or fails
do shortest edge paths (Dijkstra, a few percent longer than the true geodesic) stand in.
"""

from __future__ import annotations

import warnings

import numpy as np

from crackbake.errors import CrackbakeWarning
from crackbake.geometry import (
    closest_on_triangles,
    content_key,
    edges,
    memo,
    recall,
    remember,
    shared_centroids,
    shared_shells,
)
from crackbake.simulate.simmesh.manifold import split_nonmanifold
from crackbake.simulate.stress.sources import _finite_vector


def _snap(sim, point: np.ndarray) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, float]:
    """Nearest surface point.

    Returns the point (3,), its sim face, its barycentrics (3,), the face centroids (M, 3) and
    the largest centroid-to-corner distance.
    """
    vertices, faces = np.asarray(sim.vertices), np.asarray(sim.faces)
    centroid, reach = shared_centroids(vertices, faces)
    dc = np.linalg.norm(centroid - point, axis=1)
    # The face holding the true closest point q has |centroid - p| <= |q - p| + |centroid - q|
    # <= min centroid distance + the largest centroid-to-corner distance; only those can win.
    cand = np.flatnonzero(dc <= dc.min() + reach * (1 + 1e-9) + 1e-300)
    tri = vertices[faces[cand]]
    q, bary = closest_on_triangles(point, *(tri[:, k] for k in range(3)))
    dist = np.linalg.norm(q - point, axis=1)
    k = int(np.argmin(dist))
    return q[k], int(cand[k]), bary[k], centroid, reach


def _fast_marching(vertices: np.ndarray, faces: np.ndarray):
    """potpourri3d's fast-marching solver of a triangle mesh (``compute_distance(curves)``).

    Its compiled solver directly where potpourri3d 1.x has it: the package's Python layer
    imports scipy.sparse for its other tools, 0.35 s of a run's main thread that the solver
    does not use.  The arrays are what potpourri3d's own check asks for (float64 (V, 3),
    int64 (F, 3) indices into them).  Through the package otherwise (another version)."""
    try:
        from potpourri3d_bindings import MeshFastMarchingDistance
    except ImportError:
        MeshFastMarchingDistance = None
    v = np.ascontiguousarray(vertices, np.float64)
    f = np.ascontiguousarray(faces, np.int64)
    if MeshFastMarchingDistance is None:
        return _packaged(v, f)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError("fast marching: face indices outside the patch's vertices")
    try:
        return _Bound(MeshFastMarchingDistance(v, f), v, f)
    except TypeError:  # another binding's signature: the package knows its own
        return _packaged(v, f)


def _packaged(v: np.ndarray, f: np.ndarray):
    import potpourri3d as pp3d

    return pp3d.MeshFastMarchingDistanceSolver(v, f)


class _Bound:
    """The compiled solver with potpourri3d's ``compute_distance(curves)`` call (no initial
    distances, unsigned, as its wrapper passes them); through the package when the binding
    takes its arguments otherwise."""

    def __init__(self, solver, v: np.ndarray, f: np.ndarray) -> None:
        self.solver, self.v, self.f = solver, v, f

    def compute_distance(self, curves):
        try:
            return self.solver.compute_distance(curves, [], False)
        except TypeError:
            self.solver = _packaged(self.v, self.f)
            return self.solver.compute_distance(curves)


def _patch_solver(vertices: np.ndarray, faces: np.ndarray):
    """The fast-marching solver of a patch (``vertices`` (P, 3), ``faces`` (Q, 3) into them) and
    the patch node of each of its vertices, (P',): once per patch (the stress field and the
    star check measure the same impact on the same sim mesh; :func:`~crackbake.geometry.memo`,
    by content, so a patch that differs by one face is built anew).  Raises ImportError
    without potpourri3d, RuntimeError or ValueError where it refuses the patch."""

    def compute():
        # A patch cut out of a clean surface can have vertices where two sheets of it meet at
        # one point (its rim zig-zags); fast marching refuses those, so each fan gets its own
        # copy and a node takes the nearest of its copies.  The sim mesh itself is manifold.
        split_faces, origin, _ = split_nonmanifold(faces, len(vertices))
        return origin, _fast_marching(vertices[origin], split_faces)

    return memo("fast marching", compute, vertices, faces)


def _edge_dijkstra(vertices, faces, face: int, point: np.ndarray, limit: float) -> np.ndarray:
    import scipy.sparse as sp  # here, not at the top: scipy is 0.35 s of imports
    from scipy.sparse.csgraph import dijkstra

    n = len(vertices)
    e = edges(faces, n)[0]  # sorted (low, high) pairs, lexicographic order
    length = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    # A virtual node n stands for the point inside its face; csgraph drops zero weights, so a
    # point sitting on a node gets a vanishing positive one instead.
    corner = faces[face]
    to_corner = np.maximum(np.linalg.norm(vertices[corner] - point, axis=1), 1e-300)
    rows = np.concatenate([e[:, 0], np.full(3, n)])
    cols = np.concatenate([e[:, 1], corner])
    w = np.concatenate([np.maximum(length, 1e-300), to_corner])
    graph = sp.coo_matrix((w, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    d = dijkstra(graph, directed=False, indices=n, limit=limit)
    return d[:n]


def impact_distance(
    sim, point, max_distance: float | None = None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Geodesic distance over the sim surface from the surface point nearest ``point``.

    Parameters
    ----------
    sim : SimMesh
        Uses ``vertices`` (N, 3) and ``faces`` (M, 3).
    point : (3,) array_like
        Mesh units; snapped to the nearest point of the surface.
    max_distance : float, optional
        Only distances up to this need be right: the computation is restricted to the faces that
        lie within this straight-line reach of the point (a geodesic that short cannot leave
        them), and nodes outside get ``inf``.

    Returns
    -------
    distance : (N,) float64
        Per node, mesh units; ``inf`` where unreachable (other connected pieces, or beyond
        ``max_distance``).
    snapped : (3,) float64
        The surface point the distance is measured from.
    face : int
        Sim face holding ``snapped``.

    Notes
    -----
    The result is kept per mesh, ``snapped`` point and ``max_distance``
    (:func:`~crackbake.geometry.memo`, read-only arrays): the star check measures from the
    point the stress field reports (``snapped``), and gets the field's distance, not a second
    fast marching from a point one rounding away.  Not kept when fast marching failed (the
    edge-path fallback warns on each call).
    """
    vertices = np.asarray(sim.vertices, dtype=np.float64)
    faces = np.asarray(sim.faces, dtype=np.int64)
    p = _finite_vector(point, "impact point")
    link = float(getattr(sim, "edge_length", 0.0) or 0.0)
    limit_key = None if max_distance is None else float(max_distance)
    mesh = content_key(vertices, faces)
    kept = recall(("impact distance", mesh, p.tobytes(), limit_key, link))
    if kept is None:
        distance, snapped, face, marched = _impact_distance(sim, vertices, faces, p,
                                                            max_distance, link)
        kept = (distance, snapped, face)
        if marched:
            remember(("impact distance", mesh, snapped.tobytes(), limit_key, link), kept)
    distance, snapped, face = kept
    return distance, snapped, int(face)


def _impact_distance(sim, vertices: np.ndarray, faces: np.ndarray, p: np.ndarray,
                     max_distance: float | None, link: float):
    """:func:`impact_distance` computed: the distance, the snapped point, its face and whether
    fast marching measured it (False: the edge-path fallback)."""
    snapped, face, bary, centroid, reach = _snap(sim, p)

    if max_distance is not None and np.isfinite(max_distance):
        # A geodesic of length <= max_distance stays inside that ball around the point, and a
        # face meeting the ball has its centroid within max_distance + reach of the point.
        keep = np.linalg.norm(centroid - snapped, axis=1) <= (max_distance + reach) * (1 + 1e-9)
        keep[face] = True
        sub_faces_global = faces[keep]
        nodes, sub_faces = np.unique(sub_faces_global, return_inverse=True)
        sub_faces = sub_faces.reshape(-1, 3)
        sub_face = int(np.count_nonzero(keep[:face]))
        limit = float(max_distance)
    else:
        nodes = np.arange(len(vertices))
        sub_faces, sub_face, limit = faces, face, np.inf
    marched = True
    try:
        origin, solver = _patch_solver(vertices[nodes], sub_faces)
        d_split = np.asarray(solver.compute_distance([[(sub_face, [float(x) for x in bary])]]),
                             np.float64)
        d_sub = np.full(len(nodes), np.inf)
        np.minimum.at(d_sub, origin, d_split)
    except (ImportError, RuntimeError, ValueError) as exc:
        fix = ("install potpourri3d to avoid it" if isinstance(exc, ImportError)
               else f"fast marching failed: {str(exc).splitlines()[0] if str(exc) else exc!r}")
        warnings.warn(
            "geodesic distance for the impact falls back to edge paths, which run a few "
            f"percent long; {fix}",
            CrackbakeWarning,
            stacklevel=3,
        )
        marched = False
        d_sub = _edge_dijkstra(vertices[nodes], sub_faces, sub_face, snapped, limit)

    if link > 0.0:
        shell = shared_shells(faces, len(vertices))
        if shell.max() > 0:
            d_sub = _hop_shells(vertices[nodes], sub_faces, d_sub, link, limit, shell[nodes])
    distance = np.full(len(vertices), np.inf)
    distance[nodes] = d_sub
    distance[~np.isfinite(distance)] = np.inf
    return distance, snapped, face, marched


def _hop_shells(vertices: np.ndarray, faces: np.ndarray, d: np.ndarray, link: float,
                limit: float, shell: np.ndarray) -> np.ndarray:
    """Carry the distance ``d`` (N,) across to separate shells that touch the reached ones.

    Shells closer than ``link`` (a sim edge) to a reached node are one surface for the impact
    (a nail on a finger, a plate lying on another): each node of an unreached shell within
    ``link`` of a reached node starts at that node's distance plus the gap, and the distance
    runs on over its shell along edge paths (Dijkstra, a few percent long); shells reached so
    may reach further ones.  Nodes past ``limit`` stay ``inf``.  ``shell`` (N,) is each node's
    shell over the whole sim mesh: parts of one shell that the patch cut apart (the two walls of
    a fold) are not joined, their distance runs round through the shell itself.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components, dijkstra
    from scipy.spatial import cKDTree

    n = len(vertices)
    e = edges(faces, n)[0]
    graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    n_comp, comp = connected_components(graph, directed=False)
    if n_comp < 2:
        return d
    d = d.copy()
    length = np.maximum(np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1), 1e-300)
    for _ in range(n_comp):
        reached = np.isfinite(d)
        done = np.zeros(n_comp, dtype=bool)
        done[comp[reached]] = True
        todo = ~done[comp]
        if not reached.any() or not todo.any():
            break
        # Seeds: unreached nodes within `link` of a reached node of another shell.
        todo &= ~np.isin(shell, np.unique(shell[reached]))
        if not todo.any():
            break
        tree = cKDTree(vertices[reached])
        gap, near = tree.query(vertices[todo], distance_upper_bound=link)
        hit = np.isfinite(gap)
        if not hit.any():
            break
        seeds = np.flatnonzero(todo)[hit]
        start = d[np.flatnonzero(reached)[near[hit]]] + gap[hit]
        # One virtual source at n, joined to every seed by its start distance.
        inside = todo[e[:, 0]]
        rows = np.concatenate([e[inside, 0], np.full(len(seeds), n)])
        cols = np.concatenate([e[inside, 1], seeds])
        w = np.concatenate([length[inside], np.maximum(start, 1e-300)])
        g = sp.coo_matrix((w, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
        hop = dijkstra(g, directed=False, indices=n, limit=limit)[:n]
        d[todo] = hop[todo]
        d[~np.isfinite(d)] = np.inf
    return d


def iso_length(
    vertices: np.ndarray, faces: np.ndarray, distance: np.ndarray, level: float
) -> float:
    """Length of the contour ``distance == level`` over the mesh (linear inside each face).

    Parameters
    ----------
    vertices : (N, 3) float64
    faces : (M, 3) int
    distance : (N,) float64
        Per-node field; faces with an ``inf`` corner are left out (a node the distance did not
        reach lies far past any level the callers ask about).
    level : float
        Same units as ``distance``.

    Returns
    -------
    float
        Summed length of the contour's segments, mesh units (``2 pi level`` for a geodesic
        circle on a flat, fine mesh; less round a thin feature).
    """
    d = distance[faces]  # (M, 3)
    below = d < level
    cut = below.sum(axis=1)
    cut = ((cut == 1) | (cut == 2)) & np.isfinite(d).all(axis=1)
    d, tri = d[cut], faces[cut]
    # The two points where the contour crosses a face's edges: the lone corner (the one on
    # its own side of the level) to each of the other two.
    b = below[cut]
    lone = np.where(b.sum(axis=1) == 1, np.argmax(b, axis=1), np.argmin(b, axis=1))
    rows = np.arange(len(tri))
    ends = []
    for step in (1, 2):
        other = (lone + step) % 3
        d0, d1 = d[rows, lone], d[rows, other]
        t = ((level - d0) / (d1 - d0))[:, None]  # d0, d1 on either side: never equal
        p0, p1 = vertices[tri[rows, lone]], vertices[tri[rows, other]]
        ends.append(p0 + t * (p1 - p0))
    return float(np.linalg.norm(ends[1] - ends[0], axis=1).sum())
