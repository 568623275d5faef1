"""Mesh topology kernels of the iben solver: the node -> face table, edge and node splits.

:func:`split_edge` and :func:`separate` work on the solver's preallocated state (the struct
reference of :class:`crackbake.simulate.solver.iben.state.State`) without allocating, so the
compiled crack loop can call them; the helpers take the node -> face table alone.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.grouping import find_root, number_roots
from crackbake.simulate.solver.iben.state import FACES, NODES, SEGS


@njit(cache=True)
def nf_remove(NF, NFc, n, f):
    k = NFc[n]
    for j in range(k):
        if NF[n, j] == f:
            NF[n, j] = NF[n, k - 1]
            NFc[n] = k - 1
            return


@njit(cache=True)
def nf_add(NF, NFc, n, f):
    NF[n, NFc[n]] = f
    NFc[n] += 1


@njit(cache=True)
def spoke_count(F, NF, NFc, c, x):
    """Number of faces holding the edge (c, x): 1 on a boundary or crack, 2 inside."""
    cnt = 0
    for j in range(NFc[c]):
        f = NF[c, j]
        if F[f, 0] == x or F[f, 1] == x or F[f, 2] == x:
            cnt += 1
    return cnt


@njit(cache=True)
def on_boundary(F, NF, NFc, c):
    """True if any edge at ``c`` has a single face (mesh boundary or crack side)."""
    for j in range(NFc[c]):
        f = NF[c, j]
        for k in range(3):
            x = F[f, k]
            if x != c and spoke_count(F, NF, NFc, c, x) == 1:
                return True
    return False




@njit(cache=True)
def split_edge(s, a, b, tt):
    """Split edge (a, b) of state ``s`` at ``a + tt (b - a)``: one new node, each face on the
    edge in two.

    Children keep the parent's world stress (so its in-frame rotation is implicit), asset face and
    growth.  If the edge is a crack side, the recorded crack segment is split too so the network
    keeps its junction there; ``segof`` maps a node to the last live segment starting or ending
    at it, which finds that segment without a search.  Returns the new node.
    """
    X, F, NF, NFc, pid, onb, hn, taun = s.X, s.F, s.NF, s.NFc, s.pid, s.onb, s.hn, s.taun
    segp, seg_alive, seg_info, segof, cnt = s.segp, s.seg_alive, s.seg_info, s.segof, s.cnt
    per = s.period
    f_0 = -1
    f_1 = -1
    nfl = 0
    for j in range(NFc[a]):
        f = NF[a, j]
        if F[f, 0] == b or F[f, 1] == b or F[f, 2] == b:
            if nfl == 0:
                f_0 = f
            elif nfl == 1:
                f_1 = f
            nfl += 1
    p = cnt[NODES]
    cnt[NODES] += 1
    for q in range(3):
        X[p, q] = X[a, q] + tt * (X[b, q] - X[a, q])
    if per != 0.0:
        # Periodic plate: along the shorter way round, back into [0, per).
        for q in range(2):
            d = X[b, q] - X[a, q]
            d -= per * np.floor(d / per + 0.5)
            X[p, q] = (X[a, q] + tt * d) % per
    pid[p] = p
    hn[p] = 0.5 * (hn[a] + hn[b])
    taun[p] = 0.5 * (taun[a] + taun[b])
    s.rho[p] = 0.0
    s.crack_of[p] = -1
    s.nver[p] = 0
    NFc[p] = 0
    onb[p] = False
    segof[p] = -1
    S, AF, GR = s.S, s.AF, s.GR
    for i in range(min(nfl, 2)):
        f = f_0 if i == 0 else f_1
        g = cnt[FACES]
        cnt[FACES] += 1
        for k in range(3):
            F[g, k] = F[f, k]
        o = -1
        for k in range(3):
            if F[g, k] == a:
                F[g, k] = p
            if F[f, k] == b:
                F[f, k] = p
            if F[f, k] != a and F[f, k] != p:
                o = F[f, k]
        # Element by element: a slice copy compiles numba's shape checks and their messages.
        for i in range(3):
            for j in range(3):
                S[g, i, j] = S[f, i, j]
        AF[g] = AF[f]
        if GR.shape[0] > 1:
            for i in range(3):
                for j in range(3):
                    GR[g, i, j] = GR[f, i, j]
        nf_remove(NF, NFc, b, f)
        nf_add(NF, NFc, b, g)
        nf_add(NF, NFc, o, g)
        nf_add(NF, NFc, p, f)
        nf_add(NF, NFc, p, g)
    if nfl == 1:
        pa = pid[a]
        pb = pid[b]
        found = -1
        for cand in (segof[pa], segof[pb]):
            if cand >= 0 and seg_alive[cand] and (
                    (segp[cand, 0] == pa and segp[cand, 1] == pb)
                    or (segp[cand, 0] == pb and segp[cand, 1] == pa)):
                found = cand
                break
        if found < 0:
            # Not the last segment at either end: fall back to a search from the newest.
            for k in range(cnt[SEGS] - 1, -1, -1):
                if seg_alive[k] and ((segp[k, 0] == pa and segp[k, 1] == pb)
                                     or (segp[k, 0] == pb and segp[k, 1] == pa)):
                    found = k
                    break
        if found >= 0:
            k = found
            seg_alive[k] = False
            for q in range(2):
                t = cnt[SEGS]
                cnt[SEGS] += 1
                segp[t, 0] = segp[k, 0] if q == 0 else p
                segp[t, 1] = p if q == 0 else segp[k, 1]
                seg_alive[t] = True
                for q2 in range(3):
                    seg_info[t, q2] = seg_info[k, q2]
                segof[segp[t, 0]] = t
                segof[segp[t, 1]] = t
        else:
            onb[p] = onb[a] and onb[b]
    return p


@njit(cache=True)
def separate(s, w, c, cut1, cut2):
    """Split node ``c`` of state ``s`` into one node per edge-connected group of its faces
    (``s``, ``w``: the struct references of the state and the scratch).

    Faces around ``c`` are connected through shared edges (c, x), except through the cut edges
    (c, cut1) and (c, cut2): cutting them opens the crack; with no cuts this only mends pinched
    (bow-tie) nodes left where a crack reached a boundary.  New nodes are written to ``w.buf``;
    returns their number.
    """
    F, NF, NFc, cnt = s.F, s.NF, s.NFc, s.cnt
    out, par, comp, faces = w.buf, w.par, w.comp, w.fbuf
    k = NFc[c]
    for i in range(k):
        par[i] = i
    for i in range(k):
        fi = NF[c, i]
        for j in range(i + 1, k):
            fj = NF[c, j]
            for q in range(3):
                x = F[fi, q]
                if x == c or x == cut1 or x == cut2:
                    continue
                if F[fj, 0] == x or F[fj, 1] == x or F[fj, 2] == x:
                    ri = find_root(par, i)
                    rj = find_root(par, j)
                    if ri != rj:
                        par[max(ri, rj)] = min(ri, rj)
    ncomp = number_roots(par, k, comp)
    if ncomp <= 1:
        return 0
    for i in range(k):
        faces[i] = NF[c, i]
    NFc[c] = 0
    for i in range(k):
        if comp[i] == 0:
            nf_add(NF, NFc, c, faces[i])
    X, pid, onb, hn, taun = s.X, s.pid, s.onb, s.hn, s.taun
    for q in range(1, ncomp):
        c2 = cnt[NODES]
        cnt[NODES] += 1
        for m in range(3):
            X[c2, m] = X[c, m]
        pid[c2] = pid[c]
        onb[c2] = onb[c]
        hn[c2] = hn[c]
        taun[c2] = taun[c]
        s.rho[c2] = 0.0
        s.crack_of[c2] = -1
        s.nver[c2] = 0
        NFc[c2] = 0
        for i in range(k):
            if comp[i] == q:
                f = faces[i]
                for m in range(3):
                    if F[f, m] == c:
                        F[f, m] = c2
                nf_add(NF, NFc, c2, f)
        if q - 1 < out.shape[0]:
            out[q - 1] = c2
    return min(ncomp - 1, out.shape[0])
