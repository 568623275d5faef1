"""Whole-mesh updates, the node -> face table and the failure heap of the iben loop."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from crackbake.simulate.solver.iben.constants import _HEAP, _NN, TIP_PRIORITY, UPDATE_CHUNK
from crackbake.simulate.solver.topology import face_update, heap_push, node_update


@njit(cache=True)
def _scratch():
    return np.empty(14), np.empty((2, 3, 3)), np.empty((3, 3)), np.empty((2, 3)), np.empty(6)



@njit(cache=True, parallel=True)
def _update_all(nn, nf, X, F, S, area, nrm, grad, pr, NF, NFc, rho, val, vec, crack_of, G, gp,
                grain, seed, tipn):
    """Recompute every face and every node (setup, growth steps, the final state).

    Each face and each node writes only its own entries, so the chunks run in parallel and
    the result does not depend on the thread count.  A growth step on a 1M-face sim mesh
    costs about a second on one core, and drying runs take tens of them.
    """
    for ch in prange((nf + UPDATE_CHUNK - 1) // UPDATE_CHUNK):
        _sc, _acc, _ev, fr, r6 = _scratch()
        for f in range(ch * UPDATE_CHUNK, min(nf, (ch + 1) * UPDATE_CHUNK)):
            face_update(f, X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
    for ch in prange((nn + UPDATE_CHUNK - 1) // UPDATE_CHUNK):
        sc, acc, ev, _fr, _r6 = _scratch()
        for n in range(ch * UPDATE_CHUNK, min(nn, (ch + 1) * UPDATE_CHUNK)):
            node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec,
                        crack_of[n] >= 0, grain, seed, sc, acc, ev, G, gp, tipn)


@njit(cache=True)
def _incidence(nf, F, NF, NFc):
    for f in range(nf):
        for k in range(3):
            n = F[f, k]
            NF[n, NFc[n]] = f
            NFc[n] += 1


@njit(cache=True)
def _key(n, val, taun, crack_of, tip_first):
    """Heap key: v+/tau, plus TIP_PRIORITY for free crack tips when ``tip_first``."""
    k = val[n] / taun[n]
    if tip_first and crack_of[n] >= 0:
        k += TIP_PRIORITY
    return k


@njit(cache=True)
def _rebuild_heap(hk, hn, hv, cnt, val, taun, nver, dead, crack_of, tip_first):
    cnt[_HEAP] = 0
    for n in range(cnt[_NN]):
        if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
            heap_push(hk, hn, hv, cnt, _key(n, val, taun, crack_of, tip_first), n, nver[n])


@njit(cache=True)
def _push(n, hk, hn, hv, cnt, val, taun, nver, dead, crack_of, tip_first):
    nver[n] += 1
    if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
        if not heap_push(hk, hn, hv, cnt, _key(n, val, taun, crack_of, tip_first), n, nver[n]):
            _rebuild_heap(hk, hn, hv, cnt, val, taun, nver, dead, crack_of, tip_first)


@njit(cache=True)
def _angle(u0, u1, u2, v0, v1, v2):
    nu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    nv = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if nu == 0.0 or nv == 0.0:
        return 0.0
    return np.arccos(min(1.0, max(-1.0, (u0 * v0 + u1 * v1 + u2 * v2) / (nu * nv))))
