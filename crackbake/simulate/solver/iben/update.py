"""Whole-mesh updates, the node -> face table and the failure heap of the iben loop."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from crackbake.simulate.solver.iben.constants import TIP_PRIORITY, UPDATE_CHUNK
from crackbake.simulate.solver.iben.element import face_update
from crackbake.simulate.solver.iben.heap import heap_push
from crackbake.simulate.solver.iben.separation import node_update
from crackbake.simulate.solver.iben.state import HEAP, NODES


@njit(cache=True)
def scratch():
    """Scratch rows of :func:`node_update` (14,), (2, 3, 3), (3, 3) and :func:`face_update`
    (2, 3), (6,)."""
    return np.empty(14), np.empty((2, 3, 3)), np.empty((3, 3)), np.empty((2, 3)), np.empty(6)


@njit(cache=True, parallel=True)
def update_all(nn, nf, X, F, S, area, nrm, grad, pr, NF, NFc, rho, val, vec, crack_of, G, gp,
               grain, seed, tipn):
    """Recompute the first ``nf`` faces (stress ``S``) and ``nn`` nodes (setup, drying, end).

    Each face and each node writes only its own entries, so the chunks run in parallel and
    the result does not depend on the thread count.  A growth step on a 1M-face sim mesh
    costs about a second on one core, and drying runs take tens of them.  (Arrays rather
    than the state: a parallel kernel taking the whole named state compiled 40 % slower.)
    """
    for ch in prange((nf + UPDATE_CHUNK - 1) // UPDATE_CHUNK):
        _sc, _acc, _ev, fr, r6 = scratch()
        for f in range(ch * UPDATE_CHUNK, min(nf, (ch + 1) * UPDATE_CHUNK)):
            face_update(f, X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
    for ch in prange((nn + UPDATE_CHUNK - 1) // UPDATE_CHUNK):
        sc, acc, ev, _fr, _r6 = scratch()
        for n in range(ch * UPDATE_CHUNK, min(nn, (ch + 1) * UPDATE_CHUNK)):
            node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec,
                        crack_of[n] >= 0, grain, seed, sc, acc, ev, G, gp, tipn)


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


@njit(cache=True)
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


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def update_state(s, S, nn, nf, grain, seed):
    """:func:`update_all` on state ``s`` with stress ``S``."""
    update_all(nn, nf, s.X, s.F, S, s.area, s.nrm, s.grad, s.pr, s.NF, s.NFc, s.rho, s.val, s.vec,
               s.crack_of, s.G, s.gp, grain, seed, s.tipn)
