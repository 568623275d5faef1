"""The cut of one crack event: its plane, the crossed edges, snapping, and the mesh splits.

Each step reads and writes the event's scratch (:class:`crackbake.simulate.solver.iben.state.Work`):
``geo`` (centre, crack normal, direction along the crack) and per side (+t, -t) the crossed
edge ``sa, sb`` at ``st``, the tip node ``tip`` and whether it is a new node (``split``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.vec import angle, cross3, dot3, norm3, wrap
from crackbake.simulate.solver.topology import on_boundary, separate, split_edge, spoke_count


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def crack_plane(s, w, c):
    """The cut through node ``c``: its crack normal ``vec[c]`` projected on the tangent plane
    (area-weighted fan normal) -> ``w.geo``; False when the fan or the projection vanishes."""
    X, NF, NFc, area, nrm, vec = s.X, s.NF, s.NFc, s.area, s.nrm, s.vec
    vn0 = vn1 = vn2 = 0.0
    for j in range(NFc[c]):
        f = NF[c, j]
        vn0 += area[f] * nrm[f, 0]
        vn1 += area[f] * nrm[f, 1]
        vn2 += area[f] * nrm[f, 2]
    lvn = norm3(vn0, vn1, vn2)
    if lvn == 0.0:
        return False
    vn0 /= lvn
    vn1 /= lvn
    vn2 /= lvn
    e0, e1, e2 = vec[c, 0], vec[c, 1], vec[c, 2]
    en = dot3(e0, e1, e2, vn0, vn1, vn2)
    nc0 = e0 - en * vn0
    nc1 = e1 - en * vn1
    nc2 = e2 - en * vn2
    lnc = norm3(nc0, nc1, nc2)
    if lnc < 1e-6:
        return False
    nc0 /= lnc
    nc1 /= lnc
    nc2 /= lnc
    g = w.geo
    g[0, 0], g[0, 1], g[0, 2] = X[c, 0], X[c, 1], X[c, 2]
    g[1, 0], g[1, 1], g[1, 2] = nc0, nc1, nc2
    g[2, 0], g[2, 1], g[2, 2] = cross3(vn0, vn1, vn2, nc0, nc1, nc2)
    return True


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def normal_stress(s, w, c):
    """Area-weighted effective stress across the cut at ``c`` (so overlapping shadows do not
    double count), at least 0."""
    NF, NFc, area, pr = s.NF, s.NFc, s.area, s.pr
    nc0, nc1, nc2 = w.geo[1, 0], w.geo[1, 1], w.geo[1, 2]
    asum = 0.0
    for j in range(NFc[c]):
        asum += area[NF[c, j]]
    sig_n = 0.0
    for j in range(NFc[c]):
        f = NF[c, j]
        p = pr[f]
        a1 = dot3(p[2], p[3], p[4], nc0, nc1, nc2)
        a2 = dot3(p[5], p[6], p[7], nc0, nc1, nc2)
        sig_n += area[f] * (p[0] * a1 * a1 + p[1] * a2 * a2)
    return max(sig_n / asum, 0.0) if asum > 0 else 0.0


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def crossings(s, w, c):
    """The nearest opposite edge of ``c``'s fan that the cut crosses on each side."""
    X, F, NF, NFc = s.X, s.F, s.NF, s.NFc
    sa, sb, st, sd = w.sa, w.sb, w.st, w.sd
    xc0, xc1, xc2 = w.geo[0, 0], w.geo[0, 1], w.geo[0, 2]
    nc0, nc1, nc2 = w.geo[1, 0], w.geo[1, 1], w.geo[1, 2]
    tc0, tc1, tc2 = w.geo[2, 0], w.geo[2, 1], w.geo[2, 2]
    for side in range(2):
        sa[side] = -1
        sb[side] = -1
        st[side] = 0.0
        sd[side] = np.inf
    for j in range(NFc[c]):
        f = NF[c, j]
        k = 0
        while F[f, k] != c:
            k += 1
        a = F[f, (k + 1) % 3]
        b = F[f, (k + 2) % 3]
        da = dot3(wrap(X[a, 0] - xc0, s.period), wrap(X[a, 1] - xc1, s.period),
                  X[a, 2] - xc2, nc0, nc1, nc2)
        db = dot3(wrap(X[b, 0] - xc0, s.period), wrap(X[b, 1] - xc1, s.period),
                  X[b, 2] - xc2, nc0, nc1, nc2)
        if da == db or da * db > 0:
            continue
        tt = da / (da - db)
        p0 = wrap(X[a, 0] + tt * wrap(X[b, 0] - X[a, 0], s.period) - xc0, s.period)
        p1 = wrap(X[a, 1] + tt * wrap(X[b, 1] - X[a, 1], s.period) - xc1, s.period)
        p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
        along = dot3(p0, p1, p2, tc0, tc1, tc2)
        side = 0 if along > 0 else 1
        dist = norm3(p0, p1, p2)
        if dist < sd[side]:
            sd[side] = dist
            sa[side] = a
            sb[side] = b
            st[side] = tt


@njit(cache=True, inline="always")
def _crossing(s, w, side):
    """Crossing point on ``side``, relative to the centre."""
    X = s.X
    a, b, tt = w.sa[side], w.sb[side], w.st[side]
    p0 = wrap(X[a, 0] + tt * wrap(X[b, 0] - X[a, 0], s.period) - w.geo[0, 0], s.period)
    p1 = wrap(X[a, 1] + tt * wrap(X[b, 1] - X[a, 1], s.period) - w.geo[0, 1], s.period)
    p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - w.geo[0, 2]
    return p0, p1, p2


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def choose_tips(s, p, w, c):
    """Per side: snap the cut to an end of the crossed edge (within ``snap`` of it, or
    ``snap_b`` at a crack or the boundary, or ``snap_t`` of the edge) or split the edge there.
    A snap along an edge that already is a crack side or boundary adds nothing (no tip)."""
    X, F, NF, NFc = s.X, s.F, s.NF, s.NFc
    tip, split = w.tip, w.split
    xc0, xc1, xc2 = w.geo[0, 0], w.geo[0, 1], w.geo[0, 2]
    for side in range(2):
        tip[side] = -1
        split[side] = False
        if w.sa[side] < 0:
            continue
        a, b, tt = w.sa[side], w.sb[side], w.st[side]
        p0, p1, p2 = _crossing(s, w, side)
        ang_a = angle(p0, p1, p2, wrap(X[a, 0] - xc0, s.period),
                        wrap(X[a, 1] - xc1, s.period), X[a, 2] - xc2)
        ang_b = angle(p0, p1, p2, wrap(X[b, 0] - xc0, s.period),
                        wrap(X[b, 1] - xc1, s.period), X[b, 2] - xc2)
        thr_a = p.snap_b if on_boundary(F, NF, NFc, a) else p.snap
        thr_b = p.snap_b if on_boundary(F, NF, NFc, b) else p.snap
        snap_a = ang_a < thr_a or tt < p.snap_t
        snap_bb = ang_b < thr_b or tt > 1.0 - p.snap_t
        if snap_a and (not snap_bb or ang_a <= ang_b):
            x = a
        elif snap_bb:
            x = b
        else:
            x = -1
        if x >= 0:
            if spoke_count(F, NF, NFc, c, x) == 2:
                tip[side] = x
        else:
            tip[side] = a
            split[side] = True
    if tip[0] >= 0 and tip[1] >= 0 and not split[0] and not split[1] and tip[0] == tip[1]:
        tip[1] = -1


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def drop_back_cuts(s, p, w, c):
    """A cut that runs back along a crack or boundary edge at ``c`` (within ``back``) would
    fork the crack behind its tip (a stub): cracks only grow forward from there."""
    X, F, NF, NFc = s.X, s.F, s.NF, s.NFc
    tip, split = w.tip, w.split
    xc0, xc1, xc2 = w.geo[0, 0], w.geo[0, 1], w.geo[0, 2]
    for side in range(2):
        if tip[side] < 0 or w.sa[side] < 0:
            continue
        p0, p1, p2 = _crossing(s, w, side)
        for j in range(NFc[c]):
            f = NF[c, j]
            for q in range(3):
                y = F[f, q]
                if y != c and y != tip[side] and spoke_count(F, NF, NFc, c, y) == 1:
                    if angle(p0, p1, p2, wrap(X[y, 0] - xc0, s.period),
                             wrap(X[y, 1] - xc1, s.period), X[y, 2] - xc2) < p.back:
                        tip[side] = -1
                        split[side] = False


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def has_room(s, w, c):
    """Whether the node -> face table has room for the faces the event's splits add."""
    F, NF, NFc = s.F, s.NF, s.NFc
    width = NF.shape[1]
    if NFc[c] + 2 > width:
        return False
    for side in range(2):
        if w.split[side]:
            a, b = w.sa[side], w.sb[side]
            for j in range(NFc[a]):
                f = NF[a, j]
                if F[f, 0] == b or F[f, 1] == b or F[f, 2] == b:
                    for q in range(3):
                        if NFc[F[f, q]] + 2 > width:
                            return False
    return True


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def split_tips(s, w):
    """Split the crossed edges where the tips are new nodes, and give each new node its own
    edge length: the separation of a node scales with it, and a new node's fan is smaller than
    its parents' (inheriting theirs would make it artificially tough)."""
    X, F, NF, NFc, hn, taun = s.X, s.F, s.NF, s.NFc, s.hn, s.taun
    tip = w.tip
    for side in range(2):
        if w.split[side]:
            tip[side] = split_edge(s, w.sa[side], w.sb[side], w.st[side])
            s.nevl[tip[side]] = -1
    for side in range(2):
        if w.split[side]:
            p = tip[side]
            hsum = 0.0
            hcnt = 0
            for j in range(NFc[p]):
                f = NF[p, j]
                for q in range(3):
                    y = F[f, q]
                    if y != p:
                        hsum += np.sqrt(wrap(X[y, 0] - X[p, 0], s.period) ** 2
                                        + wrap(X[y, 1] - X[p, 1], s.period) ** 2
                                        + (X[y, 2] - X[p, 2]) ** 2)
                        hcnt += 1
            if hcnt > 0:
                scale = (hsum / hcnt) / hn[p]
                hn[p] *= scale
                taun[p] *= scale


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def open_node(s, w, c):
    """Split ``c`` along the cut edges and mend tips that the cut pinched against a boundary.

    Lists the nodes whose 1-ring changed in ``w.centers`` (``c``, the nodes split off it, each
    tip and the nodes split off it) and sets ``w.free_tip``; returns ``(nsplit, ncen)``, the
    nodes split off ``c`` and the centre count (``nsplit == 0``: the cut opened nothing).
    """
    tip, centers = w.tip, w.centers
    nsplit = separate(s, w, c, tip[0], tip[1])
    if nsplit == 0:
        return 0, 0
    ncen = 0
    centers[ncen] = c
    ncen += 1
    for q in range(nsplit):
        centers[ncen] = w.buf[q]
        ncen += 1
    for side in range(2):
        w.free_tip[side] = False
        if tip[side] < 0:
            continue
        centers[ncen] = tip[side]
        ncen += 1
        # A tip that lay on a boundary is pinched by the cut: mend it; its crack is finished.
        m = separate(s, w, tip[side], np.int64(-1), np.int64(-1))
        w.free_tip[side] = m == 0
        for q in range(m):
            centers[ncen] = w.buf[q]
            ncen += 1
    return nsplit, ncen
