"""World-scale rules of the iben loop: ball search, ligament bridges, near-crack, footprint."""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.vec import cross3, dot3, norm3, wrap


@njit(cache=True, inline="always")
def next_stamp(w):
    """A fresh visit stamp for a breadth-first search (``w.vst``)."""
    w.vstamp[0] += 1
    return w.vstamp[0]


@njit(cache=True, inline="always")
def _enqueue_near(s, w, n, x0, x1, x2, r2, vstamp, tail):
    """Breadth-first step: queue the unvisited neighbours of ``n`` within ``sqrt(r2)`` of
    ``(x0, x1, x2)``; returns the new queue tail."""
    X, F, NF, NFc, vst, queue = s.X, s.F, s.NF, s.NFc, w.vst, w.queue
    for j in range(NFc[n]):
        f = NF[n, j]
        for q in range(3):
            y = F[f, q]
            if vst[y] == vstamp:
                continue
            vst[y] = vstamp
            e0 = wrap(X[y, 0] - x0, s.period)
            e1 = wrap(X[y, 1] - x1, s.period)
            e2 = X[y, 2] - x2
            if dot3(e0, e1, e2, e0, e1, e2) <= r2:
                queue[tail] = y
                tail += 1
    return tail


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def ball(s, w, c, rad):
    """The nodes connected to ``c`` over the mesh within ``rad`` of it (breadth-first; cracks
    separate): ``w.queue[:count]``, ``c`` first; returns ``count``."""
    X, vst, queue = s.X, w.vst, w.queue
    vstamp = next_stamp(w)
    r2 = rad * rad
    x0, x1, x2 = X[c, 0], X[c, 1], X[c, 2]
    vst[c] = vstamp
    queue[0] = c
    head = 0
    tail = 1
    while head < tail:
        tail = _enqueue_near(s, w, queue[head], x0, x1, x2, r2, vstamp, tail)
        head += 1
    return tail


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def bridge(s, w, t, cid, rad, coscone, own_len):
    """Ligament failure: when the free tip ``t`` is arrested (its separation is below the
    toughness) and another crack or the mesh boundary lies ahead of it within ``rad`` (inside
    the cone ``acos(coscone)`` around its smoothed direction), the thin ligament between them
    breaks: the tip is made to fail (``val`` just above ``taun``) with its cut aimed at the
    nearest such point.  Returns whether it did.  Without this a crack stopped a few edges
    short of the crack it was running into, a gap that shows in the textures.  The boundary
    counts only once the tip's crack (``own_len`` long) is at least ``rad`` long: short cracks
    starting beside an open boundary otherwise curled back onto it at both ends (hooks).
    """
    X, NF, NFc, nrm, area, pid, pcid, pdir, onb = (s.X, s.NF, s.NFc, s.nrm, s.area, s.pid,
                                                    s.pcid, s.pdir, s.onb)
    queue = w.queue
    to_boundary = own_len >= rad
    p = pid[t]
    d0, d1, d2 = pdir[p, 0], pdir[p, 1], pdir[p, 2]
    ld = norm3(d0, d1, d2)
    if ld == 0.0 or rad <= 0.0:
        return False
    x0, x1, x2 = X[t, 0], X[t, 1], X[t, 2]
    best = -1
    bd = np.inf
    for i in range(1, ball(s, w, t, rad)):
        n = queue[i]
        if (pcid[pid[n]] >= 0 and pcid[pid[n]] != cid) or (onb[n] and to_boundary):
            e0 = wrap(X[n, 0] - x0, s.period)
            e1 = wrap(X[n, 1] - x1, s.period)
            e2 = X[n, 2] - x2
            le = norm3(e0, e1, e2)
            if 0.0 < le < bd and dot3(e0, e1, e2, d0, d1, d2) >= coscone * le * ld:
                best = n
                bd = le
    if best < 0:
        return False
    vn0 = vn1 = vn2 = 0.0
    for j in range(NFc[t]):
        f = NF[t, j]
        vn0 += area[f] * nrm[f, 0]
        vn1 += area[f] * nrm[f, 1]
        vn2 += area[f] * nrm[f, 2]
    e0 = wrap(X[best, 0] - x0, s.period)
    e1 = wrap(X[best, 1] - x1, s.period)
    e2 = X[best, 2] - x2
    # Cut normal: in the tangent plane, perpendicular to the way to the target.
    c0, c1, c2 = cross3(vn0, vn1, vn2, e0, e1, e2)
    lc = norm3(c0, c1, c2)
    if lc == 0.0:
        return False
    s.vec[t, 0], s.vec[t, 1], s.vec[t, 2] = c0 / lc, c1 / lc, c2 / lc
    s.val[t] = s.taun[t] * (1.0 + 1e-9)
    return True


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def near_other(s, w, t, cid, d0, d1, d2, rad, cospar, rad_any):
    """Whether another crack comes near node ``t`` (breadth-first over the mesh).

    Returns 1 when a point of another crack lies within ``rad_any`` of ``t``, 2 when one lies
    within ``rad`` and that crack's smoothed direction there (``pdir``) runs within
    ``acos(cospar)`` of ``d``, else 0.
    """
    X, pid, pcid, pdir, vst, queue = s.X, s.pid, s.pcid, s.pdir, w.vst, w.queue
    vstamp = next_stamp(w)
    ld = norm3(d0, d1, d2)
    r2 = max(rad, rad_any) ** 2
    ra2 = rad_any * rad_any
    x0, x1, x2 = X[t, 0], X[t, 1], X[t, 2]
    vst[t] = vstamp
    queue[0] = t
    head = 0
    tail = 1
    found = 0
    while head < tail:
        n = queue[head]
        head += 1
        p = pid[n]
        o = pcid[p]
        if o >= 0 and o != cid:
            e0 = wrap(X[n, 0] - x0, s.period)
            e1 = wrap(X[n, 1] - x1, s.period)
            e2 = X[n, 2] - x2
            if dot3(e0, e1, e2, e0, e1, e2) <= ra2:
                return 1
            u0, u1, u2 = pdir[p, 0], pdir[p, 1], pdir[p, 2]
            lu = norm3(u0, u1, u2)
            if lu > 0.0 and ld > 0.0 and abs(dot3(u0, u1, u2, d0, d1, d2)) >= cospar * lu * ld:
                if rad_any == 0.0:
                    return 2
                found = 2
        tail = _enqueue_near(s, w, n, x0, x1, x2, r2, vstamp, tail)
    return found


@njit(cache=True)
def smooth_dir(pc, pt, d0, d1, d2, length, pdir):
    """Direction of a crack at its new point ``pt``: an exponential moving average over the
    last ``length`` (mesh units) of its path, from the one at ``pc`` and the new segment ``d``.

    A world-scale memory: a single segment's direction zig-zags across the sim triangles, and
    the finer the mesh the more it does, so tests on it would depend on the resolution.
    """
    ld = norm3(d0, d1, d2)
    if ld == 0.0:
        return
    u0, u1, u2 = pdir[pc, 0], pdir[pc, 1], pdir[pc, 2]
    w = np.exp(-ld / length) if length > 0.0 else 0.0
    if dot3(u0, u1, u2, d0, d1, d2) < 0.0:
        w = -w
    e0 = w * u0 + (1.0 - abs(w)) * d0 / ld
    e1 = w * u1 + (1.0 - abs(w)) * d1 / ld
    e2 = w * u2 + (1.0 - abs(w)) * d2 / ld
    le = norm3(e0, e1, e2)
    if le > 0.0:
        pdir[pt, 0], pdir[pt, 1], pdir[pt, 2] = e0 / le, e1 / le, e2 / le


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def footprint_fails(s, w, c, rad):
    """Whether the mean normalised separation ``v+ / h`` over the nodes within ``rad`` of node
    ``c`` (breadth-first over the mesh) exceeds their mean normalised toughness."""
    val, taun, hn, dead, queue = s.val, s.taun, s.hn, s.dead, w.queue
    sv = 0.0
    st = 0.0
    for i in range(ball(s, w, c, rad)):
        n = queue[i]
        if not dead[n] and taun[n] > 0.0 and hn[n] > 0.0:
            sv += val[n] / hn[n]
            st += taun[n] / hn[n]
    return sv > st
