"""Numba kernels of the iben solver: per-face FEM, per-node separation, mutable mesh topology.

Everything here works on a preallocated *state* (plain arrays) so the sequential crack loop can
run compiled without touching Python objects.  The arrays are described in
:func:`crackbake.solver.iben.solve_iben`; briefly

* ``X (Ncap, 3)`` node positions (nodes never move during the simulation);
* ``F (Mcap, 3)`` faces, ``S (Mcap, 3, 3)`` world in-plane stress per face (tension positive),
  ``AF (Mcap,)`` asset face, ``area``, ``nrm``, ``grad (Mcap, 3, 3)``, ``fp``/``fm (Mcap, 3, 3)``
  per-corner forces of the tensile / compressive stress;
* ``NF (Ncap, W)`` incident faces per node (``NFc`` counts), ``rho (Ncap, 3, 3)`` persistent
  residual, ``val (Ncap,)`` largest separation eigenvalue, ``vec (Ncap, 3)`` its eigenvector,
  ``taun (Ncap,)`` per-node toughness in separation units, ``nver`` heap versions.

The FEM formulas are those of :mod:`crackbake.solver.fem` (tested against it in
tests/test_iben.py), written per element for use inside the loop.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# --------------------------------------------------------------------------- small linear algebra


@njit(cache=True)
def eig_max_sym3(a):
    """Largest eigenvalue and unit eigenvector of a symmetric 3x3 matrix (cyclic Jacobi).

    Jacobi is used rather than the closed form because separation tensors are often nearly
    isotropic in the plane (uniform tension), where closed-form eigenvectors lose all accuracy.
    """
    m = a.copy()
    v = np.eye(3)
    scale = abs(m[0, 0]) + abs(m[1, 1]) + abs(m[2, 2]) + abs(m[0, 1]) + abs(m[0, 2]) + abs(m[1, 2])
    for _sweep in range(16):
        off = abs(m[0, 1]) + abs(m[0, 2]) + abs(m[1, 2])
        if off <= 1e-15 * scale or off == 0.0:
            break
        for r in range(3):
            p = 0 if r < 2 else 1
            q = 1 if r == 0 else 2
            apq = m[p, q]
            if apq == 0.0:
                continue
            theta = (m[q, q] - m[p, p]) / (2.0 * apq)
            t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            # m <- J^T m J with J the rotation in the (p, q) plane; v <- v J.
            for k in range(3):
                mkp = m[k, p]
                mkq = m[k, q]
                m[k, p] = c * mkp - s * mkq
                m[k, q] = s * mkp + c * mkq
            for k in range(3):
                mpk = m[p, k]
                mqk = m[q, k]
                m[p, k] = c * mpk - s * mqk
                m[q, k] = s * mpk + c * mqk
            for k in range(3):
                vkp = v[k, p]
                vkq = v[k, q]
                v[k, p] = c * vkp - s * vkq
                v[k, q] = s * vkp + c * vkq
    best = 0
    for k in range(1, 3):
        if m[k, k] > m[best, best]:
            best = k
    out = np.empty(3)
    for k in range(3):
        out[k] = v[k, best]
    return m[best, best], out


@njit(cache=True)
def _add_m(acc, f, sign):
    """acc += sign * f f^T / |f| (the paper's m(f); m(0) = 0)."""
    n = np.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
    if n > 0.0:
        for i in range(3):
            for j in range(3):
                acc[i, j] += sign * f[i] * f[j] / n


# --------------------------------------------------------------------------- per-face FEM


@njit(cache=True)
def face_update(f, X, F, S, area, nrm, grad, fp, fm):
    """Geometry and tensile/compressive corner forces of face ``f`` (fem.py formulas)."""
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    e1 = X[i1] - X[i0]
    e2 = X[i2] - X[i0]
    cr = np.cross(e1, e2)
    ta = np.sqrt(cr[0] ** 2 + cr[1] ** 2 + cr[2] ** 2)
    if ta <= 0.0:
        area[f] = 0.0
        nrm[f] = 0.0
        grad[f] = 0.0
        fp[f] = 0.0
        fm[f] = 0.0
        return
    n = cr / ta
    area[f] = 0.5 * ta
    nrm[f] = n
    for i in range(3):
        j = F[f, (i + 1) % 3]
        k = F[f, (i + 2) % 3]
        grad[f, i] = np.cross(n, X[k] - X[j]) / ta
    # In-plane frame, 2x2 principal split (fem.split_tension).
    u = e1 / np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    w = np.cross(n, u)
    s = S[f]
    su = s @ u
    sw = s @ w
    a = u @ su
    b = 0.5 * (u @ sw + w @ su)
    c = w @ sw
    mean = 0.5 * (a + c)
    rad = np.sqrt((0.5 * (a - c)) ** 2 + b * b)
    l1 = mean + rad
    l2 = mean - rad
    th = 0.5 * np.arctan2(2.0 * b, a - c)
    d1 = np.cos(th) * u + np.sin(th) * w
    d2 = -np.sin(th) * u + np.cos(th) * w
    for i in range(3):
        g = grad[f, i]
        g1 = d1 @ g
        g2 = d2 @ g
        # f_i = -A * S_part @ g_i with S_part = sum_k l_k d_k d_k^T over the positive / negative k.
        vp = np.zeros(3)
        vm = np.zeros(3)
        if l1 > 0:
            vp += l1 * g1 * d1
        else:
            vm += l1 * g1 * d1
        if l2 > 0:
            vp += l2 * g2 * d2
        else:
            vm += l2 * g2 * d2
        fp[f, i] = -area[f] * vp
        fm[f, i] = -area[f] * vm


@njit(cache=True)
def node_update(n, F, NF, NFc, fp, fm, rho, val, vec):
    """Separation tensor (plus residual) of node ``n``; stores its largest eigenpair."""
    sp = np.zeros(3)
    sm = np.zeros(3)
    acc = np.zeros((3, 3))
    for j in range(NFc[n]):
        f = NF[n, j]
        k = 0
        while F[f, k] != n:
            k += 1
        sp += fp[f, k]
        sm += fm[f, k]
        _add_m(acc, fp[f, k], 1.0)
        _add_m(acc, fm[f, k], -1.0)
    _add_m(acc, sp, -1.0)
    _add_m(acc, sm, 1.0)
    acc *= 0.5
    acc += rho[n]
    v, e = eig_max_sym3(acc)
    val[n] = v
    vec[n] = e


# --------------------------------------------------------------------------- max-heap


@njit(cache=True)
def heap_push(hk, hn, hv, cnt, key, node, ver):
    """Push (key, node, version); returns False when the heap is full."""
    i = cnt[0]
    if i >= hk.shape[0]:
        return False
    cnt[0] = i + 1
    while i > 0:
        p = (i - 1) // 2
        # Ties broken by the smaller node id so the order never depends on push history.
        if hk[p] > key or (hk[p] == key and hn[p] < node):
            break
        hk[i] = hk[p]
        hn[i] = hn[p]
        hv[i] = hv[p]
        i = p
    hk[i] = key
    hn[i] = node
    hv[i] = ver
    return True


@njit(cache=True)
def heap_pop(hk, hn, hv, cnt):
    """Pop the largest entry; returns (key, node, version)."""
    key, node, ver = hk[0], hn[0], hv[0]
    last = cnt[0] - 1
    cnt[0] = last
    if last > 0:
        lk, ln, lv = hk[last], hn[last], hv[last]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= last:
                break
            if c + 1 < last and (hk[c + 1] > hk[c] or (hk[c + 1] == hk[c] and hn[c + 1] < hn[c])):
                c += 1
            if lk > hk[c] or (lk == hk[c] and ln < hn[c]):
                break
            hk[i] = hk[c]
            hn[i] = hn[c]
            hv[i] = hv[c]
            i = c
        hk[i] = lk
        hn[i] = ln
        hv[i] = lv
    return key, node, ver


# --------------------------------------------------------------------------- topology helpers


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
def _find(par, i):
    while par[i] != i:
        par[i] = par[par[i]]
        i = par[i]
    return i


@njit(cache=True)
def split_edge(a, b, tt, X, F, S, AF, GR, NF, NFc, pid, onb, hn, taun, rho, crack_of, nver,
               segp, seg_alive, seg_info, cnt):
    """Split edge (a, b) at ``a + tt (b - a)``: one new node, each face on the edge in two.

    Children keep the parent's world stress (so its in-frame rotation is implicit), asset face and
    growth.  If the edge is a crack side, the recorded crack segment is split too so the network
    keeps its junction there.  Returns the new node.
    """
    fl = np.full(2, -1, np.int64)
    nfl = 0
    for j in range(NFc[a]):
        f = NF[a, j]
        if F[f, 0] == b or F[f, 1] == b or F[f, 2] == b:
            if nfl < 2:
                fl[nfl] = f
            nfl += 1
    p = cnt[1]
    cnt[1] += 1
    X[p] = X[a] + tt * (X[b] - X[a])
    pid[p] = p
    hn[p] = 0.5 * (hn[a] + hn[b])
    taun[p] = 0.5 * (taun[a] + taun[b])
    rho[p] = 0.0
    crack_of[p] = -1
    nver[p] = 0
    NFc[p] = 0
    onb[p] = False
    for i in range(min(nfl, 2)):
        f = fl[i]
        g = cnt[2]
        cnt[2] += 1
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
        S[g] = S[f]
        AF[g] = AF[f]
        if GR.shape[0] > 1:
            GR[g] = GR[f]
        nf_remove(NF, NFc, b, f)
        nf_add(NF, NFc, b, g)
        nf_add(NF, NFc, o, g)
        nf_add(NF, NFc, p, f)
        nf_add(NF, NFc, p, g)
    if nfl == 1:
        pa = pid[a]
        pb = pid[b]
        found = False
        for s in range(cnt[3] - 1, -1, -1):
            if seg_alive[s] and ((segp[s, 0] == pa and segp[s, 1] == pb)
                                 or (segp[s, 0] == pb and segp[s, 1] == pa)):
                seg_alive[s] = False
                for q in range(2):
                    t = cnt[3]
                    cnt[3] += 1
                    segp[t, 0] = segp[s, 0] if q == 0 else p
                    segp[t, 1] = p if q == 0 else segp[s, 1]
                    seg_alive[t] = True
                    seg_info[t] = seg_info[s]
                found = True
                break
        if not found:
            onb[p] = onb[a] and onb[b]
    return p


@njit(cache=True)
def separate(c, cut1, cut2, X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of, nver, cnt, out):
    """Split node ``c`` into one node per edge-connected group of its faces.

    Faces around ``c`` are connected through shared edges (c, x), except through the cut edges
    (c, cut1) and (c, cut2): cutting them opens the crack; with no cuts this only mends pinched
    (bow-tie) nodes left where a crack reached a boundary.  New nodes are written to ``out``;
    returns their number.
    """
    k = NFc[c]
    par = np.arange(k)
    for i in range(k):
        fi = NF[c, i]
        for j in range(i + 1, k):
            fj = NF[c, j]
            for q in range(3):
                x = F[fi, q]
                if x == c or x == cut1 or x == cut2:
                    continue
                if F[fj, 0] == x or F[fj, 1] == x or F[fj, 2] == x:
                    ri = _find(par, i)
                    rj = _find(par, j)
                    if ri != rj:
                        par[max(ri, rj)] = min(ri, rj)
    lab = np.full(k, -1, np.int64)
    comp = np.empty(k, np.int64)
    ncomp = 0
    for i in range(k):
        r = _find(par, i)
        if lab[r] < 0:
            lab[r] = ncomp
            ncomp += 1
        comp[i] = lab[r]
    if ncomp <= 1:
        return 0
    faces = NF[c, :k].copy()
    NFc[c] = 0
    for i in range(k):
        if comp[i] == 0:
            nf_add(NF, NFc, c, faces[i])
    for q in range(1, ncomp):
        c2 = cnt[1]
        cnt[1] += 1
        X[c2] = X[c]
        pid[c2] = pid[c]
        onb[c2] = onb[c]
        hn[c2] = hn[c]
        taun[c2] = taun[c]
        rho[c2] = 0.0
        crack_of[c2] = -1
        nver[c2] = 0
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
