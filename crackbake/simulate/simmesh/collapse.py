"""Shortest-edge decimation in rounds (a numba kernel, :mod:`.collapse_kernels`).

libigl's ``decimate`` collapses one edge at a time from a priority queue that it updates after
each collapse: 1.4M collapses of a 1.5M-face asset took 11.5 s on one core.  Here each round
sorts the live edges once and walks the shortest of them (``ROUND_SHARE``) in order, collapsing
each to its midpoint unless a collapse of the same round has already moved one of its ends
(its length is then stale: it waits for the next round's sort).  So edges still go shortest
first in every neighbourhood and the result is as isotropic as libigl's (minimum angles, edge
length spread: docs/benchmarks.md) at about a quarter of the time.  A collapse is refused when
it would break the manifold (the link condition; an interior edge joining two border vertices;
an edge of more than two faces) or turn a face over.
"""

from __future__ import annotations

import threading

import numpy as np

# Rounds after which the face count is taken as it is: the last rounds collapse only a few
# edges each (the wanted count is "about").
MAX_ROUNDS = 60
# A round that gets within this fraction of the wanted face count ends the decimation.
CLOSE_ENOUGH = 0.002
# Share of a round's edges offered for collapse (the shortest ones).
ROUND_SHARE = 0.3


def decimate_shortest(vertices: np.ndarray, faces: np.ndarray, n_faces: int,
                      started: threading.Event | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A surface decimated to about ``n_faces`` faces by collapsing its shortest edges to their
    midpoints.

    Parameters
    ----------
    vertices : (V, 3) float64
        Mesh units.
    faces : (F, 3) int64
        Manifold triangles (each edge used by one or two faces).
    n_faces : int
        Wanted face count; the result has from one face fewer to 0.2 % more (more where no
        further collapse is allowed).
    started : threading.Event, optional
        Set just before the kernel (which releases the GIL) is called, so that a caller on
        another thread can start GIL-holding work without stalling it.

    Returns
    -------
    vertices : (P, 3) float64
        Every one of them used by a face.
    faces : (Q, 3) int64
        Corner order kept from the input faces.
    """
    from crackbake.simulate.simmesh.collapse_kernels import collapse_rounds

    v = np.array(vertices, dtype=np.float64)
    f = np.array(faces, dtype=np.int64)
    if started is not None:
        # Loaded before the signal, so the call below goes straight into the GIL-free kernel:
        # a first call loads it under numba's compiler lock, which the solver's warm-up thread
        # may hold while it waits for the GIL, and the caller's GIL-holding work (libigl's AABB
        # tree, 3 s at 1.5M faces) then kept the kernel waiting until the tree was done.
        _load(collapse_rounds)
        started.set()
    alive = collapse_rounds(v, f, max(int(n_faces), 1), ROUND_SHARE, CLOSE_ENOUGH, MAX_ROUNDS)
    f = f[alive]
    used = np.unique(f)
    index = np.zeros(len(v), np.int64)
    index[used] = np.arange(len(used))
    return v[used], index[f]


def _load(kernel) -> None:
    """``kernel`` (:func:`.collapse_kernels.collapse_rounds`) loaded from numba's cache, or
    compiled on a fan of faces when the cache has none for this source."""
    from crackbake.jit import preload

    preload(kernel)
    if not kernel.overloads:
        v, f = _fan()
        kernel(v, f, 6, ROUND_SHARE, CLOSE_ENOUGH, MAX_ROUNDS)


def _fan() -> tuple[np.ndarray, np.ndarray]:
    """Eight faces around a raised centre: (9, 3) float64, (8, 3) int64."""
    ring = np.array([[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0, 2 * np.pi, 9)[:-1]])
    v = np.vstack([[0.0, 0.0, 0.1], ring])
    return v, np.array([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)], np.int64)


def warm() -> None:
    """Compile (or load from numba's cache) the decimation kernel, which only assets above
    200k faces reach (:mod:`crackbake.precompile`'s runs are smaller): a fan of eight faces
    taken to six, and its border
    (:func:`.proxy.decimate` lists the asset's border edges)."""
    v, f = _fan()
    decimate_shortest(v, f, 6)
    from crackbake.simulate.simmesh.collapse_kernels import border_edges

    border_edges(f, len(v))
