"""numba kernels for :mod:`crackbake.bake.tangents`: the passes numpy could only do by sorting.

Welding, edge pairing, grouping and vertex splitting are lookups by key.  numpy does them with
``argsort``/``unique`` (O(n log n), several passes over 4.5M corners at 1.5M faces: about 3 s on
2 cores); here each is one linear pass with a hash table or a bucket per vertex.  Every kernel
returns what the sorting version did (same numbering, same pairing, same summation order); the
tangents differ from it by rounding only (3e-16).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.grouping import find_root, number_roots


@njit(cache=True, nogil=True)
def match_edges(weld: np.ndarray, nondeg: np.ndarray) -> np.ndarray:
    """(3F,) the edge (``3 * face + corner``) paired with each edge, or -1.

    Edge ``c`` of face ``f`` runs from welded vertex ``weld[f, c]`` to ``weld[f, c + 1]``.  A
    backward edge (start > end) pairs with a forward edge between the same two vertices; with
    more than two, the k-th backward (in edge order) takes the k-th forward.  Edges are
    bucketed by their lower vertex, so each lookup scans a vertex's few edges.
    """
    n_faces = weld.shape[0]
    n = 3 * n_faces
    n_weld = 0
    for f in range(n_faces):
        for c in range(3):
            n_weld = max(n_weld, weld[f, c] + 1)
    lo = np.empty(n, np.int64)
    hi = np.empty(n, np.int64)
    start = np.zeros(n_weld + 1, np.int64)
    for f in range(n_faces):
        for c in range(3):
            e = 3 * f + c
            a, b = weld[f, c], weld[f, (c + 1) % 3]
            lo[e], hi[e] = min(a, b), max(a, b)
            if nondeg[f]:
                start[lo[e] + 1] += 1
    for v in range(n_weld):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    bucket = np.empty(start[n_weld], np.int64)
    for e in range(n):  # edge order within each bucket
        if nondeg[e // 3]:
            bucket[fill[lo[e]]] = e
            fill[lo[e]] += 1
    partner = np.full(n, -1, np.int64)
    for v in range(n_weld):
        for i in range(start[v], start[v + 1]):
            e = bucket[i]
            f, c = e // 3, e % 3
            if weld[f, c] <= weld[f, (c + 1) % 3]:
                continue  # forward edges are taken by backward ones
            for j in range(start[v], start[v + 1]):
                g = bucket[j]
                if partner[g] < 0 and hi[g] == hi[e] and weld[g // 3, g % 3] < hi[g]:
                    partner[g] = e
                    partner[e] = g
                    break
    return partner


@njit(cache=True, nogil=True)
def components(
    n: int, src: np.ndarray, dst: np.ndarray, good: np.ndarray
) -> tuple[np.ndarray, int, np.ndarray]:
    """Connected components of ``n`` nodes linked by ``src[i] - dst[i]`` (union-find).

    Returns
    -------
    label : (n,) int64
        Components numbered by their lowest node (as scipy's ``connected_components``).
    n_comp : int
    start : (n_comp,) int64
        Each component's lowest node with ``good`` set, or ``n`` when it has none.
    """
    parent = np.arange(n)
    for i in range(len(src)):
        a, b = find_root(parent, src[i]), find_root(parent, dst[i])
        if a != b:
            if a < b:
                parent[b] = a
            else:
                parent[a] = b
    label = np.empty(n, np.int64)
    count = number_roots(parent, n, label)
    start = np.full(count, n, np.int64)
    for x in range(n):
        if good[x] and x < start[label[x]]:
            start[label[x]] = x
    return label, count, start


@njit(cache=True, nogil=True)
def _unit_in_plane(n0, n1, n2, x, y, z):
    d = n0 * x + n1 * y + n2 * z
    x, y, z = x - n0 * d, y - n1 * d, z - n2 * d
    length = np.sqrt(x * x + y * y + z * z)
    if length > 0:
        return x / length, y / length, z / length
    return x, y, z


@njit(cache=True, nogil=True)
def face_frames(
    p: np.ndarray, t: np.ndarray, faces: np.ndarray, tiny: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per face: unit ``dP/du`` (F, 3), orientation preserving (F,), good (F,), non-degenerate
    (F,): MikkTSpace's triangle classification (see :mod:`crackbake.bake.tangents`)."""
    n_faces = faces.shape[0]
    tangent = np.zeros((n_faces, 3))
    orient = np.empty(n_faces, np.bool_)
    good = np.empty(n_faces, np.bool_)
    nondeg = np.empty(n_faces, np.bool_)
    for f in range(n_faces):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        same_ij = p[i, 0] == p[j, 0] and p[i, 1] == p[j, 1] and p[i, 2] == p[j, 2]
        same_ik = p[i, 0] == p[k, 0] and p[i, 1] == p[k, 1] and p[i, 2] == p[k, 2]
        same_jk = p[j, 0] == p[k, 0] and p[j, 1] == p[k, 1] and p[j, 2] == p[k, 2]
        nondeg[f] = not (same_ij or same_ik or same_jk)
        d1x, d1y, d1z = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
        d2x, d2y, d2z = p[k, 0] - p[i, 0], p[k, 1] - p[i, 1], p[k, 2] - p[i, 2]
        s1, t1 = t[j, 0] - t[i, 0], t[j, 1] - t[i, 1]
        s2, t2 = t[k, 0] - t[i, 0], t[k, 1] - t[i, 1]
        area = s1 * t2 - t1 * s2
        ox, oy, oz = t2 * d1x - t1 * d2x, t2 * d1y - t1 * d2y, t2 * d1z - t1 * d2z
        ux, uy, uz = -s2 * d1x + s1 * d2x, -s2 * d1y + s1 * d2y, -s2 * d1z + s1 * d2z
        len_os2 = ox * ox + oy * oy + oz * oz
        len_ot2 = ux * ux + uy * uy + uz * uz
        orient[f] = area > 0
        good[f] = abs(area) > tiny and len_os2 > tiny and len_ot2 > tiny
        if good[f]:
            scale = (1.0 if area > 0 else -1.0) / np.sqrt(len_os2)
            tangent[f, 0], tangent[f, 1], tangent[f, 2] = ox * scale, oy * scale, oz * scale
        good[f] = good[f] and nondeg[f]
    return tangent, orient, good, nondeg


@njit(cache=True, nogil=True)
def group_sums(
    p: np.ndarray, nrm: np.ndarray, faces: np.ndarray, tangent: np.ndarray, good: np.ndarray,
    label: np.ndarray, n_groups: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Per group: the sum of its corners' tangents, each projected into the corner's tangent
    plane and weighted by the corner angle measured in that plane; and whether any corner comes
    from a good face.

    Parameters
    ----------
    p, nrm : (V, 3) float64
        Positions and unit normals.
    faces : (F, 3) int64
    tangent : (F, 3) float64
        Face tangents.
    good : (F,) bool
    label : (3F,) int64
        Group of each corner.

    Returns
    -------
    sums : (n_groups, 3) float64
        Summed in corner order.
    has_good : (n_groups,) bool
    """
    sums = np.zeros((n_groups, 3))
    has_good = np.zeros(n_groups, np.bool_)
    for f in range(faces.shape[0]):
        if not good[f]:
            continue
        for c in range(3):
            g = label[3 * f + c]
            has_good[g] = True
            v, a, b = faces[f, c], faces[f, (c + 1) % 3], faces[f, (c + 2) % 3]
            nx, ny, nz = nrm[v, 0], nrm[v, 1], nrm[v, 2]
            ax, ay, az = _unit_in_plane(nx, ny, nz, p[a, 0] - p[v, 0], p[a, 1] - p[v, 1],
                                        p[a, 2] - p[v, 2])
            bx, by, bz = _unit_in_plane(nx, ny, nz, p[b, 0] - p[v, 0], p[b, 1] - p[v, 1],
                                        p[b, 2] - p[v, 2])
            angle = np.arccos(min(max(ax * bx + ay * by + az * bz, -1.0), 1.0))
            tx, ty, tz = _unit_in_plane(nx, ny, nz, tangent[f, 0], tangent[f, 1], tangent[f, 2])
            sums[g, 0] += tx * angle
            sums[g, 1] += ty * angle
            sums[g, 2] += tz * angle
    return sums, has_good


@njit(cache=True, nogil=True)
def fallback(nx: float, ny: float, nz: float) -> tuple[float, float, float]:
    """MikkTSpace's default tangent +X made orthogonal to ``n`` (+Y where n is +-X)."""
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    length = max(length, 1e-30)
    nx, ny, nz = nx / length, ny / length, nz / length
    tx, ty, tz = 1.0 - nx * nx, 0.0 - ny * nx, 0.0 - nz * nx
    length = np.sqrt(tx * tx + ty * ty + tz * tz)
    if length < 1e-6:
        tx, ty, tz = 0.0 - nx * ny, 1.0 - ny * ny, 0.0 - nz * ny
        length = np.sqrt(tx * tx + ty * ty + tz * tz)
    if length < 1e-6:  # a zero or broken normal
        return 1.0, 0.0, 0.0
    return tx / length, ty / length, tz / length


@njit(cache=True, nogil=True)
def fallback_rows(nrm: np.ndarray) -> np.ndarray:
    """(N, 3) :func:`fallback` of each row of ``nrm`` (N, 3)."""
    out = np.empty((nrm.shape[0], 3))
    for i in range(nrm.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = fallback(nrm[i, 0], nrm[i, 1], nrm[i, 2])
    return out


@njit(cache=True, nogil=True)
def assemble(
    nrm: np.ndarray, faces: np.ndarray, label: np.ndarray, sums: np.ndarray,
    has_good: np.ndarray, group_orient: np.ndarray, nondeg: np.ndarray,
) -> np.ndarray:
    """(3F, 4) each corner's frame: its group's normalised tangent sum and sign; the fallback
    frame (w = -1) where the group has no good face, its sum is zero, or the face is
    degenerate."""
    n_groups = sums.shape[0]
    unit = np.zeros((n_groups, 3))
    ok = np.zeros(n_groups, np.bool_)
    for g in range(n_groups):
        length = np.sqrt(sums[g, 0] * sums[g, 0] + sums[g, 1] * sums[g, 1]
                         + sums[g, 2] * sums[g, 2])
        if length > 0:
            ok[g] = True
            unit[g, 0], unit[g, 1], unit[g, 2] = (sums[g, 0] / length, sums[g, 1] / length,
                                                 sums[g, 2] / length)
    out = np.empty((3 * faces.shape[0], 4))
    for f in range(faces.shape[0]):
        for c in range(3):
            e, g = 3 * f + c, label[3 * f + c]
            take = nondeg[f] and has_good[g]
            if take and ok[g]:
                out[e, 0], out[e, 1], out[e, 2] = unit[g, 0], unit[g, 1], unit[g, 2]
            else:
                v = faces[f, c]
                out[e, 0], out[e, 1], out[e, 2] = fallback(nrm[v, 0], nrm[v, 1], nrm[v, 2])
            out[e, 3] = (1.0 if group_orient[g] else -1.0) if take else -1.0
    return out


@njit(cache=True, nogil=True)
def split_vertices(
    corner_vertex: np.ndarray, frame: np.ndarray, n_vert: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give each distinct (vertex, frame) pair a vertex: the first keeps the index.

    Parameters
    ----------
    corner_vertex : (C,) int64
        Vertex of each face corner.
    frame : (C, 4) float64
        Tangent frame of each corner.
    n_vert : int

    Returns
    -------
    new_vertex : (C,) int64
        Output vertex of each corner.  A vertex's first frame (in corner order) keeps the
        vertex's index; every further frame gets ``n_vert + k``, numbered by first corner.
    source : (V',) int64
        Input vertex each output vertex copies.
    first : (V',) int64
        A corner of each output vertex (its first), or -1 for unused input vertices.
    """
    n = len(corner_vertex)
    start = np.zeros(n_vert + 1, np.int64)
    for c in range(n):
        start[corner_vertex[c] + 1] += 1
    for v in range(n_vert):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for c in range(n):
        order[fill[corner_vertex[c]]] = c
        fill[corner_vertex[c]] += 1
    rep = np.empty(n, np.int64)  # the first corner with the same vertex and frame
    for v in range(n_vert):
        for i in range(start[v], start[v + 1]):
            c = order[i]
            rep[c] = c
            for j in range(start[v], i):
                d = order[j]
                if rep[d] == d and frame[d, 0] == frame[c, 0] and frame[d, 1] == frame[c, 1] \
                        and frame[d, 2] == frame[c, 2] and frame[d, 3] == frame[c, 3]:
                    rep[c] = d
                    break
    new_vertex = np.empty(n, np.int64)
    n_new = 0
    for c in range(n):
        if rep[c] == c and order[start[corner_vertex[c]]] != c:
            n_new += 1
    source = np.empty(n_vert + n_new, np.int64)
    first = np.full(n_vert + n_new, -1, np.int64)
    source[:n_vert] = np.arange(n_vert)
    k = n_vert
    for c in range(n):
        if rep[c] != c:
            new_vertex[c] = new_vertex[rep[c]]
        elif order[start[corner_vertex[c]]] == c:
            new_vertex[c] = corner_vertex[c]
            first[corner_vertex[c]] = c
        else:
            new_vertex[c] = k
            source[k] = corner_vertex[c]
            first[k] = c
            k += 1
    return new_vertex, source, first
