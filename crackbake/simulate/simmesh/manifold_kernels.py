"""The numba kernels of :mod:`.manifold`: the fans of faces around each vertex by union-find,
in place of a sparse graph's connected components (1.2 s of a 1.5M-face asset's 3.6 s)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _root(parent: np.ndarray, c: int) -> int:  # pragma: no cover - numba
    while parent[c] != c:
        parent[c] = parent[parent[c]]  # path halving
        c = parent[c]
    return c


@njit(cache=True, nogil=True)
def fan_split(a: np.ndarray, rows: np.ndarray, cols: np.ndarray,
              n_vertices: int):  # pragma: no cover - numba
    """Each corner's vertex when every fan gets its own copy of its vertex.

    Parameters
    ----------
    a : (C,) int64
        Vertex of each corner (corner ``3 f + k`` is corner ``k`` of face ``f``).
    rows, cols : (J,) int64
        Pairs of corners joined (the same vertex seen across a manifold edge).
    n_vertices : int

    Returns
    -------
    vertex : (C,) int64
        The corner's vertex after the split: a vertex's first fan (the fan of its lowest
        corner) keeps its index, every other fan gets ``n_vertices + j``, ``j`` counting such
        fans in the order of their lowest corners.
    extra : (X,) int64
        The original vertex of each new one, ``n_vertices + j`` -> ``extra[j]``.
    """
    n = len(a)
    parent = np.arange(n)
    for j in range(len(rows)):
        r, s = _root(parent, rows[j]), _root(parent, cols[j])
        if r < s:  # the root of a fan is its lowest corner
            parent[s] = r
        elif s < r:
            parent[r] = s
    seen = np.zeros(n_vertices, np.bool_)
    vertex = np.empty(n, np.int64)
    extra = np.empty(n, np.int64)
    n_extra = 0
    for c in range(n):  # a root comes before every other corner of its fan
        r = _root(parent, c)
        if r == c:
            v = a[c]
            if seen[v]:
                vertex[c] = n_vertices + n_extra
                extra[n_extra] = v
                n_extra += 1
            else:
                seen[v] = True
                vertex[c] = v
        else:
            vertex[c] = vertex[r]
    return vertex, extra[:n_extra].copy()
