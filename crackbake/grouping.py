"""Group equal keys in one linear pass (a hash table in numba) instead of a sort.

``np.unique`` sorts: at a few million keys that is most of a second on 2 cores.  The tangent
frames weld every output vertex this way (:mod:`crackbake.bake.tangents`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_MIX = np.uint64(0x9E3779B97F4A7C15)


def first_ids(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ids of equal keys numbered by first occurrence, and where each id first occurs.

    Parameters
    ----------
    keys : (N,) integer or (N, K) float64 / integer
        Rows compare bit for bit (floats: fold -0.0 into 0.0 first by adding 0.0).

    Returns
    -------
    ids : (N,) int64
        ``keys[first[ids]] == keys``.
    first : (M,) int64
        Increasing.
    """
    k = np.ascontiguousarray(keys)
    if k.ndim == 1:
        k = k.reshape(-1, 1)
    if k.dtype.itemsize != 8 or k.dtype.kind not in "iuf":
        k = k.astype(np.float64 if k.dtype.kind == "f" else np.int64)
    return exact_ids(np.ascontiguousarray(k).view(np.uint64))


@njit(cache=True, nogil=True)
def exact_ids(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ids of bit-identical rows, numbered by first occurrence, and each id's first row.

    Parameters
    ----------
    rows : (N, K) uint64
        The rows' bits (float64 rows viewed as uint64, with -0.0 already folded into 0.0).

    Returns
    -------
    ids : (N,) int64
    first : (M,) int64
        Row index where id ``m`` first occurs (increasing).
    """
    n, k = rows.shape
    size = 16
    while size < 2 * n:
        size *= 2
    mask = np.uint64(size - 1)
    table = np.full(size, -1, np.int64)  # slot -> id
    ids = np.empty(n, np.int64)
    first = np.empty(n, np.int64)
    count = 0
    for i in range(n):
        h = np.uint64(0)
        for j in range(k):
            h = (h ^ rows[i, j]) * _MIX
            h ^= h >> np.uint64(29)
        s = h & mask
        while True:
            m = table[s]
            if m < 0:
                table[s] = count
                first[count] = i
                ids[i] = count
                count += 1
                break
            r = first[m]
            same = True
            for j in range(k):
                if rows[r, j] != rows[i, j]:
                    same = False
                    break
            if same:
                ids[i] = m
                break
            s = (s + np.uint64(1)) & mask
    return ids, first[:count]




@njit(cache=True, nogil=True)
def find_root(parent: np.ndarray, i: int) -> int:
    """Union-find root of ``i`` in ``parent``, halving the path on the way."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True, nogil=True)
def number_roots(parent: np.ndarray, n: int, label: np.ndarray) -> int:
    """Label the first ``n`` union-find nodes by component (into ``label``); the count.

    Components are numbered in order of their roots, which must be their own smallest member
    (join by ``parent[max(ra, rb)] = min(ra, rb)``), so a root is labelled before its members
    and the numbering follows each component's lowest node.
    """
    count = 0
    for i in range(n):
        r = find_root(parent, i)
        if r == i:
            label[i] = count
            count += 1
        else:
            label[i] = label[r]
    return count
