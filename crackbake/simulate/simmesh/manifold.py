"""Making a welded triangle soup a 2-manifold for the simulation.

The crack solver, the fast-marching geodesic distance and the node -> asset map all assume that
every edge has one or two faces and that the faces around each vertex form one fan.  Users' meshes
break both: duplicated faces (the same triangle twice), fins (three faces on one edge), and
vertices where two sheets touch at a point (bow ties, also what a patch cut out of a clean mesh
has at its rim).  The functions here fix the *topology copy* only; the asset mesh is untouched
and the bake still renders every face.

* :func:`duplicate_faces` flags faces whose three vertices repeat an earlier face's (in any order
  or orientation): two coincident sim triangles would be two overlapping surfaces.
* :func:`split_nonmanifold` joins no faces through an edge with more than two faces and gives
  each fan of faces around a vertex (faces joined through manifold edges) its own copy of the
  vertex, so each manifold patch is its own surface.  A sheet that runs on through such an edge
  (a plate carrying a fin) keeps one copy of the edge's vertices, so it stays joined there and
  only the fin comes off; where more than two faces still share an edge after that, the extra
  faces are detached at that edge.
"""

from __future__ import annotations

import numpy as np

__all__ = ["duplicate_faces", "split_nonmanifold"]


def duplicate_faces(faces: np.ndarray) -> np.ndarray:
    """Flag faces that repeat an earlier face's vertex set, (F,) bool.

    Parameters
    ----------
    faces : (F, 3) int64
        Triangles of a welded mesh (equal positions share one index).

    Returns
    -------
    (F,) bool
        True for every copy after the first (lowest index) of a vertex triple.
    """
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    dup = np.zeros(len(f), dtype=bool)
    if not len(f):
        return dup
    # The sorted triple by min / max (np.sort(axis=1) is slow on rows of three).
    lo = np.minimum(np.minimum(f[:, 0], f[:, 1]), f[:, 2])
    hi = np.maximum(np.maximum(f[:, 0], f[:, 1]), f[:, 2])
    mid = f[:, 0] + f[:, 1] + f[:, 2] - lo - hi
    # A stable sort by the three columns keeps equal triples in face order, so every row equal
    # to the one before it is a later copy.  One int64 key and one sort where the vertex count
    # allows (n**3 < 2**63), else a lexsort of the columns (3x faster than np.unique(axis=0)).
    n = int(hi.max()) + 1
    if n < 2_000_000:
        key = (lo * n + mid) * n + hi
        order = np.argsort(key, kind="stable")
        k = key[order]
        dup[order[1:][k[1:] == k[:-1]]] = True
    else:
        order = np.lexsort((hi, mid, lo))
        k = np.stack([lo[order], mid[order], hi[order]], axis=1)
        dup[order[1:][(k[1:] == k[:-1]).all(axis=1)]] = True
    return dup


def split_nonmanifold(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Split non-manifold edges and vertices so that every edge has at most two faces and every
    vertex one fan of faces.

    Parameters
    ----------
    faces : (F, 3) int64
        Triangles indexing ``n_vertices`` vertices, without duplicates (:func:`duplicate_faces`).
    n_vertices : int
        Number of vertices.

    Returns
    -------
    faces : (F, 3) int64
        The same triangles on the split vertices.  A vertex's first fan (in face order) keeps
        its index, so a mesh that is already manifold comes back unchanged (same array values).
    origin : (V',) int64
        Original vertex of each split vertex (``V' >= n_vertices``; the first ``n_vertices``
        map to themselves).
    n_cut : int
        Number of edges with more than two faces in the input.
    """
    faces = np.asarray(faces, dtype=np.int64)
    out, origin, n_cut = _split_fans(faces, n_vertices)
    # Splitting vertices never adds faces to an edge: without crowded edges in the input there
    # are none to detach.
    for _ in range(3 if n_cut else 0):
        crowded = _crowded_faces(out, len(origin))
        if not crowded.any():
            break
        # Detach the extra faces at the edge: their corners get vertices of their own, and
        # the next pass splits any fan this leaves pinched.
        corners = np.flatnonzero(crowded)
        out = out.copy()
        more = out.ravel()[corners]
        out.ravel()[corners] = len(origin) + np.arange(len(corners))
        origin = np.concatenate([origin, origin[more]])
        out, sub, _ = _split_fans(out, len(origin))
        origin = origin[sub]
    return out, origin, n_cut


def _sides(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face sides (side k of face f runs from corner k to k+1, index 3 f + k): their start
    vertex (3F,), their undirected edge (3F,) and how many sides share each edge (E,)."""
    a = faces.ravel()
    b = faces[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * np.int64(n_vertices) + np.maximum(a, b)
    _, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    return a, inv, count


def _crowded_faces(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Corners (F * 3,) bool on an edge with more than two faces, except those of the first two
    faces of each such edge."""
    a, inv, count = _sides(faces, n_vertices)
    flag = np.zeros(len(a), dtype=bool)
    side = np.flatnonzero(count[inv] > 2)
    if len(side) == 0:
        return flag
    side = side[np.argsort(inv[side], kind="stable")]
    rank = np.arange(len(side)) - np.searchsorted(inv[side], inv[side])
    extra = side[rank >= 2]
    flag[extra] = True
    flag[3 * (extra // 3) + (extra % 3 + 1) % 3] = True
    return flag


def _split_fans(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, int]:
    """One copy of each vertex per fan (faces joined through edges with exactly two faces)."""
    from crackbake.simulate.simmesh.manifold_kernels import fan_split

    n_f = len(faces)
    a, inv, count, by_edge = _sorted_sides(faces, n_vertices)
    n_cut = int(np.count_nonzero(count > 2))
    # Corners c = 3 f + k.  The two sides of a manifold edge join the corners holding the
    # same vertex: corner k of one face with whichever corner of the other holds it.
    order = by_edge[count[inv[by_edge]] == 2]  # manifold sides, by edge, in side order
    s0, s1 = order[0::2], order[1::2]
    f0, k0 = s0 // 3, s0 % 3
    f1, k1 = s1 // 3, s1 % 3
    c_a0, c_b0 = 3 * f0 + k0, 3 * f0 + (k0 + 1) % 3
    same = a[s0] == a[s1]  # both sides run the same way (inconsistent orientation)
    c_a1 = np.where(same, 3 * f1 + k1, 3 * f1 + (k1 + 1) % 3)
    c_b1 = np.where(same, 3 * f1 + (k1 + 1) % 3, 3 * f1 + k1)
    # Fans per vertex: the vertex's first fan (by its first corner) keeps the vertex's index,
    # the others get new indices in the order of their first corners (a union-find kernel).
    vertex, extra = fan_split(a, np.concatenate([c_a0, c_b0]), np.concatenate([c_a1, c_b1]),
                              n_vertices)
    if len(extra) == 0:
        return faces, np.arange(n_vertices, dtype=np.int64), n_cut
    origin = np.concatenate([np.arange(n_vertices, dtype=np.int64), extra])
    return vertex.reshape(n_f, 3), origin, n_cut


def _sorted_sides(faces: np.ndarray, n_vertices: int):
    """:func:`_sides` and the sides in a stable order by edge, (3F,): the order of
    ``np.argsort(lo * n + hi, kind="stable")``, by a bucket kernel (half the time of that sort
    at 1.5M faces)."""
    from crackbake.simulate.simmesh.manifold_kernels import sorted_sides

    a = np.ascontiguousarray(faces.ravel(), np.int64)
    b = np.ascontiguousarray(faces[:, [1, 2, 0]].ravel(), np.int64)
    inv, count, by_edge = sorted_sides(a, b, int(n_vertices))
    return a, inv, count, by_edge
