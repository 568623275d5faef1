"""Nearest points and connected pieces, as numba kernels: what the run path took from
scipy.spatial's ``cKDTree`` and scipy.sparse.csgraph's ``connected_components``.

A solving run used them in the simulation (the meshes' shells, the cracks' pieces for the
arrival times), the star check (each arm point's nearest face) and the stress bake (the faces
that hold the nodes the solver added).  Their imports alone cost about 0.35 s (scipy.sparse
brings scipy's array-API layer and, with it, numpy.f2py and numpy.testing), on the main thread
before the solver: on a GPU machine, where the run is its CPU stages, a sixth of the whole.

- :func:`components`: the same labels as ``connected_components(directed=False)`` (each piece
  numbered in the order of its lowest node), by union-find.
- :func:`nearest_k`: the ``k`` nearest reference points of each query, exact, through a uniform
  grid; equal distances are ordered by index (a KD-tree orders them by its own traversal, so a
  query exactly as far from two points may get them the other way round; measured on no mesh
  in the tests or the examples).
"""

from __future__ import annotations

import numpy as np
from numba import njit


def components(n: int, edges: np.ndarray) -> np.ndarray:
    """Connected piece of each of ``n`` nodes over ``edges`` (E, 2), (n,) int32.

    Pieces are numbered 0, 1, ... in the order of their lowest node, as scipy's
    ``connected_components(..., directed=False)`` numbers them.
    """
    e = np.ascontiguousarray(np.asarray(edges).reshape(-1, 2), np.int64)
    return _components_kernel(int(n), e)


@njit(cache=True, nogil=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True, nogil=True)
def _components_kernel(n: int, edges: np.ndarray) -> np.ndarray:
    parent = np.arange(n)
    for k in range(len(edges)):
        a = _find(parent, edges[k, 0])
        b = _find(parent, edges[k, 1])
        if a != b:
            if a < b:
                parent[b] = a
            else:
                parent[a] = b
    label = np.empty(n, np.int32)
    of_root = np.full(n, -1, np.int64)
    count = 0
    for i in range(n):
        r = _find(parent, i)
        if of_root[r] < 0:
            of_root[r] = count
            count += 1
        label[i] = of_root[r]
    return label


def nearest_k(points: np.ndarray, queries: np.ndarray, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest of ``points`` (M, 3) to each of ``queries`` (P, 3), nearest first.

    Parameters
    ----------
    points : (M, 3) float
        Reference points, M >= k >= 1.
    queries : (P, 3) float
    k : int

    Returns
    -------
    distance : (P, k) float64
        Euclidean distances, ascending per row.
    index : (P, k) int64
        Indices into ``points``; equal distances in ascending index.
    """
    pts = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    qs = np.ascontiguousarray(queries, np.float64).reshape(-1, 3)
    if not 1 <= k <= len(pts):
        raise ValueError(f"k={k} nearest of {len(pts)} points")
    if not (np.isfinite(pts).all() and np.isfinite(qs).all()):
        raise ValueError("nearest points of non-finite coordinates")
    lo = pts.min(axis=0)
    extent = float((pts.max(axis=0) - lo).max())
    # About two points a cell over the bounding box's longest side cubed; flat sets (a plate)
    # get the same cell size, so their cells hold more (the search stays exact either way).
    cells = max(1.0, (len(pts) / 2.0) ** (1.0 / 3.0))
    h = extent / cells if extent > 0 else 1.0
    dims = np.minimum(np.floor((pts.max(axis=0) - lo) / h).astype(np.int64) + 1, 1 << 20)
    start, order = _grid(pts, lo, h, dims)
    return _query(pts, qs, int(k), lo, h, dims, start, order)


@njit(cache=True, nogil=True)
def _cell(x: float, lo: float, h: float, n: int) -> int:
    c = int(np.floor((x - lo) / h)) if x > lo else 0
    return min(max(c, 0), n - 1)


@njit(cache=True, nogil=True)
def _grid(pts: np.ndarray, lo: np.ndarray, h: float, dims: np.ndarray):
    """Counting sort of the points by cell: ``order[start[c]:start[c + 1]]`` are cell c's,
    ascending."""
    n_cells = dims[0] * dims[1] * dims[2]
    cell = np.empty(len(pts), np.int64)
    start = np.zeros(n_cells + 1, np.int64)
    for i in range(len(pts)):
        c = ((_cell(pts[i, 0], lo[0], h, dims[0]) * dims[1]
              + _cell(pts[i, 1], lo[1], h, dims[1])) * dims[2]
             + _cell(pts[i, 2], lo[2], h, dims[2]))  # fmt: skip
        cell[i] = c
        start[c + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(len(pts), np.int64)
    for i in range(len(pts)):
        order[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return start, order


@njit(cache=True, nogil=True)
def _query(pts, qs, k, lo, h, dims, start, order):
    n_q = len(qs)
    best_d = np.empty((n_q, k))
    best_i = np.empty((n_q, k), np.int64)
    d2 = np.empty(k)
    idx = np.empty(k, np.int64)
    home = np.empty(3, np.int64)
    for q in range(n_q):
        x, y, z = qs[q, 0], qs[q, 1], qs[q, 2]
        home[0] = _cell(x, lo[0], h, dims[0])
        home[1] = _cell(y, lo[1], h, dims[1])
        home[2] = _cell(z, lo[2], h, dims[2])
        found = 0
        r = 0
        while True:
            # the cells of the ring at Chebyshev distance r from home
            for i in range(max(home[0] - r, 0), min(home[0] + r, dims[0] - 1) + 1):
                for j in range(max(home[1] - r, 0), min(home[1] + r, dims[1] - 1) + 1):
                    on_shell_ij = abs(i - home[0]) == r or abs(j - home[1]) == r
                    for m in range(max(home[2] - r, 0), min(home[2] + r, dims[2] - 1) + 1):
                        if not on_shell_ij and abs(m - home[2]) != r:
                            continue
                        c = (i * dims[1] + j) * dims[2] + m
                        for s in range(start[c], start[c + 1]):
                            p = order[s]
                            dx, dy, dz = pts[p, 0] - x, pts[p, 1] - y, pts[p, 2] - z
                            dd = dx * dx + dy * dy + dz * dz
                            if found == k and (dd > d2[k - 1]
                                               or (dd == d2[k - 1] and p > idx[k - 1])):
                                continue
                            # insert, ordered by (distance, index)
                            t = found if found < k else k - 1
                            while t > 0 and (d2[t - 1] > dd or (d2[t - 1] == dd
                                                                and idx[t - 1] > p)):
                                d2[t] = d2[t - 1]
                                idx[t] = idx[t - 1]
                                t -= 1
                            d2[t] = dd
                            idx[t] = p
                            if found < k:
                                found += 1
            # the nearest any cell outside the searched cube can be
            bound = np.inf
            for a in range(3):
                v = x if a == 0 else (y if a == 1 else z)
                if home[a] - r > 0:
                    bound = min(bound, v - (lo[a] + (home[a] - r) * h))
                if home[a] + r < dims[a] - 1:
                    bound = min(bound, lo[a] + (home[a] + r + 1) * h - v)
            if bound == np.inf:
                break  # the whole grid is searched
            bound -= 1e-9 * h  # a cell's edge as floor() placed its points, to the rounding
            if found == k and bound > 0.0 and d2[k - 1] < bound * bound:
                break
            r += 1
        for t in range(k):
            best_d[q, t] = np.sqrt(d2[t])
            best_i[q, t] = idx[t]
    return best_d, best_i
