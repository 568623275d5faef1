"""Whole-mesh updates, the node -> face table and the failure heap of the iben loop.

The shadow (several impacts: a stack of grid blocks) is read through :mod:`.shadow` only.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import get_num_threads, njit

from crackbake.simulate.solver.iben.constants import TIP_PRIORITY, UPDATE_CHUNK
from crackbake.simulate.solver.iben.element import face_update
from crackbake.simulate.solver.iben.heap import heap_push
from crackbake.simulate.solver.iben.separation import node_update
from crackbake.simulate.solver.iben.state import DEPOSITS, HEAP, NODES, State
from crackbake.simulate.solver.iben.structs import state_ref


@njit(cache=True, nogil=True)
def update_faces(lo, hi, s):
    """Recompute faces ``lo:hi`` of ``s`` (a State; each face writes only its own entries)."""
    r = state_ref(s)
    fr, r6 = np.empty((2, 3)), np.empty(6)
    for f in range(lo, hi):
        face_update(r, f, fr, r6)


@njit(cache=True, nogil=True)
def update_nodes(lo, hi, s, grain, seed):
    """Recompute nodes ``lo:hi`` of ``s`` (a State; each node writes only its own entries)."""
    r = state_ref(s)
    crack_of = r.crack_of
    sc, acc, ev = np.empty(14), np.empty((2, 3, 3)), np.empty((3, 3))
    for n in range(lo, hi):
        node_update(r, n, crack_of[n] >= 0, grain, seed, sc, acc, ev)


def _chunks(count: int) -> list[tuple[int, int]]:
    return [(lo, min(count, lo + UPDATE_CHUNK)) for lo in range(0, count, UPDATE_CHUNK)]


def update_all(s: State, nn: int, nf: int, grain: float, seed: int) -> None:
    """Recompute the first ``nf`` faces and ``nn`` nodes of ``s`` (setup, drying, end; for
    another stress, pass ``s._replace(S=stress)``: the same arrays but that stress).

    Each face and each node writes only its own entries, so chunks run on ``get_num_threads()``
    threads (the kernels release the GIL) and the result does not depend on the thread count.
    A growth step on a 1M-face sim mesh costs about a second on one core, and drying runs take
    tens of them.  Threads rather than ``parallel=True``: a parallel kernel compiled for about
    10 s on first use, these serial ones in about 2 s.
    """
    threads = min(get_num_threads(), max(1, nf // UPDATE_CHUNK))
    if threads <= 1:
        update_faces(0, nf, s)
        update_nodes(0, nn, s, grain, seed)
        return
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(lambda r: update_faces(r[0], r[1], s), _chunks(nf)))
        list(pool.map(lambda r: update_nodes(r[0], r[1], s, grain, seed), _chunks(nn)))


@njit(cache=True)
def incidence(nf, F, NF, NFc):
    """Fill the node -> face table from the first ``nf`` faces."""
    for f in range(nf):
        for k in range(3):
            n = F[f, k]
            NF[n, NFc[n]] = f
            NFc[n] += 1


@njit(cache=True)
def key(val, taun, crack_of, n, tip_first):
    """Heap key of node ``n``: v+/tau, plus TIP_PRIORITY for free crack tips when
    ``tip_first``."""
    k = val[n] / taun[n]
    if tip_first and crack_of[n] >= 0:
        k += TIP_PRIORITY
    return k


@njit(cache=True, nogil=True)
def rebuild(s, tip_first):
    """:func:`rebuild_heap` on named tuple ``s`` (a State)."""
    rebuild_heap(state_ref(s), tip_first)


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def rebuild_heap(s, tip_first):
    """Heap of every live node that fails now."""
    val, taun, crack_of, dead, nver, cnt = s.val, s.taun, s.crack_of, s.dead, s.nver, s.cnt
    cnt[HEAP] = 0
    for n in range(cnt[NODES]):
        if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
            heap_push(s.hk, s.hnode, s.hv, cnt, key(val, taun, crack_of, n, tip_first), n,
                      nver[n])


@njit(cache=True, inline="always")
def push(s, n, tip_first):
    """Invalidate node ``n``'s heap entries and push it again if it fails."""
    nver, val, taun = s.nver, s.val, s.taun
    nver[n] += 1
    if not s.dead[n] and taun[n] > 0 and val[n] > taun[n]:
        k = key(val, taun, s.crack_of, n, tip_first)
        if not heap_push(s.hk, s.hnode, s.hv, s.cnt, k, n, nver[n]):
            rebuild_heap(s, tip_first)


@njit(cache=True, nogil=True)
def requeue_all(s, tip_first):
    """After a drying step (every node recomputed): invalidate every node's heap entry, mark it
    evaluated with the current shadow and rebuild the heap (``s``: a State)."""
    nver, nevl, cnt = s.nver, s.nevl, s.cnt
    for n in range(cnt[NODES]):
        nver[n] += 1
        nevl[n] = cnt[DEPOSITS]
    rebuild_heap(state_ref(s), tip_first)
