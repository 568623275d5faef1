"""Numba kernels of the iben solver: per-face FEM, per-node separation, shadow grid, topology.

Everything here works on a preallocated *state* (plain arrays) so the sequential crack loop can
run compiled without touching Python objects, and without allocating inside the hot loops (small
temporaries are scalars or scratch rows passed in).  The arrays are described in
:func:`crackbake.simulate.solver.iben.solve_iben`; briefly

* ``X (Ncap, 3)`` node positions (nodes never move during the simulation);
* ``F (Mcap, 3)`` faces, ``S (Mcap, 3, 3)`` world in-plane stress per face (tension positive),
  ``AF (Mcap,)`` asset face, ``area``, ``nrm``, ``grad (Mcap, 3, 3)``, and ``pr (Mcap, 8)`` the
  principal split of the *effective* stress (stress minus the shadow-grid release, see below):
  ``l1, l2, d1 (3), d2 (3)``;
* ``NF (Ncap, W)`` incident faces per node (``NFc`` counts), ``rho (Ncap, 3, 3)`` persistent
  residual, ``val (Ncap,)`` largest separation eigenvalue, ``vec (Ncap, 3)`` its eigenvector,
  ``taun (Ncap,)`` per-node toughness in separation units, ``nver`` heap versions.
* ``G (nx, ny, nz, 6)`` the shadow grid: released stress (symmetric, xx xy xz yy yz zz) sampled
  at cell centres; ``gp`` = ``origin (3), cell size, kernel radius``.

The FEM formulas are those of :mod:`crackbake.simulate.solver.fem` (tested against it in
tests/test_iben.py), written per element for use inside the loop: corner forces
``f_i = -A S± g_i`` are rebuilt from the stored principal split whenever a node needs them,
which is cheaper in memory than storing them and costs only a few flops.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# --------------------------------------------------------------------------- small linear algebra


@njit(cache=True)
def eig_max_into(m, v):
    """Largest eigenvalue of the symmetric 3x3 ``m`` (destroyed); its unit eigenvector -> v[:, 0].

    Cyclic Jacobi rather than a closed form: separation tensors are often nearly isotropic in the
    plane (uniform tension), where closed-form eigenvectors lose all accuracy.  ``v`` is a 3x3
    scratch; on return column 0 holds the eigenvector.
    """
    for i in range(3):
        for j in range(3):
            v[i, j] = 1.0 if i == j else 0.0
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
    if best != 0:
        for k in range(3):
            v[k, 0] = v[k, best]
    return m[best, best]


@njit(cache=True)
def eig_max_sym3(a):
    """Largest eigenvalue and unit eigenvector of a symmetric 3x3 matrix (allocating wrapper)."""
    m = a.copy()
    v = np.empty((3, 3))
    val = eig_max_into(m, v)
    return val, v[:, 0].copy()


@njit(cache=True)
def _add_m(acc, f0, f1, f2, sign):
    """acc += sign * f f^T / |f| (the paper's m(f); m(0) = 0), upper triangle only."""
    n = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    if n > 0.0:
        _add_dd(acc, sign / n, f0, f1, f2)


# --------------------------------------------------------------------------- shadow grid


@njit(cache=True)
def shadow_at(x0, x1, x2, G, gp, out):
    """Released stress at a point: trilinear interpolation of the cell-centred grid -> out[6]."""
    for q in range(6):
        out[q] = 0.0
    if G.shape[0] < 2:
        return
    cs = gp[3]
    u0 = (x0 - gp[0]) / cs - 0.5
    u1 = (x1 - gp[1]) / cs - 0.5
    u2 = (x2 - gp[2]) / cs - 0.5
    i0 = min(max(int(np.floor(u0)), 0), G.shape[0] - 2)
    i1 = min(max(int(np.floor(u1)), 0), G.shape[1] - 2)
    i2 = min(max(int(np.floor(u2)), 0), G.shape[2] - 2)
    w0 = min(max(u0 - i0, 0.0), 1.0)
    w1 = min(max(u1 - i1, 0.0), 1.0)
    w2 = min(max(u2 - i2, 0.0), 1.0)
    for a in range(2):
        wa = w0 if a else 1.0 - w0
        for b in range(2):
            wb = w1 if b else 1.0 - w1
            for c in range(2):
                w = wa * wb * (w2 if c else 1.0 - w2)
                if w == 0.0:
                    continue
                for q in range(6):
                    out[q] += w * G[i0 + a, i1 + b, i2 + c, q]


@njit(cache=True)
def face_shadow(f, X, F, G, gp, out):
    """Released stress at the centroid of face f -> out[6] (see :func:`shadow_at`)."""
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    shadow_at((X[i0, 0] + X[i1, 0] + X[i2, 0]) / 3.0, (X[i0, 1] + X[i1, 1] + X[i2, 1]) / 3.0,
              (X[i0, 2] + X[i1, 2] + X[i2, 2]) / 3.0, G, gp, out)


@njit(cache=True)
def shadow_add(p0, p1, p2, amount, n0, n1, n2, G, gp):
    """Deposit ``amount * n n^T * k(r)`` with a compact kernel around p into the grid.

    ``k(r) = (1 - r²/R²)² / (16 R / 15)`` for ``r < R`` (R = ``gp[4]``): its integral across a
    straight line is 1, so a long crack whose segments each deposit ``length x normal stress``
    releases exactly its normal stress on the crack line, fading to nothing at distance R.
    """
    if G.shape[0] < 2:
        return
    cs = gp[3]
    rk = gp[4]
    norm = amount / (16.0 * rk / 15.0)
    lo0 = max(int(np.floor((p0 - rk - gp[0]) / cs)), 0)
    hi0 = min(int(np.floor((p0 + rk - gp[0]) / cs)), G.shape[0] - 1)
    lo1 = max(int(np.floor((p1 - rk - gp[1]) / cs)), 0)
    hi1 = min(int(np.floor((p1 + rk - gp[1]) / cs)), G.shape[1] - 1)
    lo2 = max(int(np.floor((p2 - rk - gp[2]) / cs)), 0)
    hi2 = min(int(np.floor((p2 + rk - gp[2]) / cs)), G.shape[2] - 1)
    t00 = n0 * n0
    t01 = n0 * n1
    t02 = n0 * n2
    t11 = n1 * n1
    t12 = n1 * n2
    t22 = n2 * n2
    for i in range(lo0, hi0 + 1):
        d0 = gp[0] + (i + 0.5) * cs - p0
        for j in range(lo1, hi1 + 1):
            d1 = gp[1] + (j + 0.5) * cs - p1
            for k in range(lo2, hi2 + 1):
                d2 = gp[2] + (k + 0.5) * cs - p2
                r2 = (d0 * d0 + d1 * d1 + d2 * d2) / (rk * rk)
                if r2 >= 1.0:
                    continue
                w = norm * (1.0 - r2) * (1.0 - r2)
                G[i, j, k, 0] += w * t00
                G[i, j, k, 1] += w * t01
                G[i, j, k, 2] += w * t02
                G[i, j, k, 3] += w * t11
                G[i, j, k, 4] += w * t12
                G[i, j, k, 5] += w * t22


# --------------------------------------------------------------------------- per-face FEM


@njit(cache=True)
def _principal(a, b, c):
    """Eigenvalues (l1 >= l2) and the angle of l1's eigenvector of the 2x2 [[a, b], [b, c]]."""
    mean = 0.5 * (a + c)
    rad = np.sqrt((0.5 * (a - c)) ** 2 + b * b)
    return mean + rad, mean - rad, 0.5 * np.arctan2(2.0 * b, a - c)


@njit(cache=True)
def face_frame(f, X, F, nrm, fr):
    """In-plane frame of face f: u along edge 0->1 -> fr[0], w = n x u -> fr[1]."""
    i0, i1 = F[f, 0], F[f, 1]
    e0 = X[i1, 0] - X[i0, 0]
    e1 = X[i1, 1] - X[i0, 1]
    e2 = X[i1, 2] - X[i0, 2]
    le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    fr[0, 0] = e0 / le
    fr[0, 1] = e1 / le
    fr[0, 2] = e2 / le
    n = nrm[f]
    fr[1, 0] = n[1] * fr[0, 2] - n[2] * fr[0, 1]
    fr[1, 1] = n[2] * fr[0, 0] - n[0] * fr[0, 2]
    fr[1, 2] = n[0] * fr[0, 1] - n[1] * fr[0, 0]


@njit(cache=True)
def _quad(s, x, y):
    """x^T s y for 3-vectors."""
    acc = 0.0
    for i in range(3):
        acc += x[i] * (s[i, 0] * y[0] + s[i, 1] * y[1] + s[i, 2] * y[2])
    return acc


@njit(cache=True)
def _quad6(r, x, y):
    """x^T R y with R given as the six components xx xy xz yy yz zz."""
    return (x[0] * (r[0] * y[0] + r[1] * y[1] + r[2] * y[2])
            + x[1] * (r[1] * y[0] + r[3] * y[1] + r[4] * y[2])
            + x[2] * (r[2] * y[0] + r[4] * y[1] + r[5] * y[2]))


@njit(cache=True)
def face_update(f, X, F, S, area, nrm, grad, pr, G, gp, fr, r6):
    """Geometry and the principal split of the effective stress of face ``f``.

    Effective stress = stress minus the shadow-grid release at the centroid, projected on the
    face plane.  The release may not create compression the raw stress did not have (a crack
    cannot push its neighbourhood into compression), so the effective principal stresses are
    clamped at ``min(0, smallest raw principal stress)``.  ``fr`` (2, 3) and ``r6`` (6,) are
    scratch rows.
    """
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    e10 = X[i1, 0] - X[i0, 0]
    e11 = X[i1, 1] - X[i0, 1]
    e12 = X[i1, 2] - X[i0, 2]
    e20 = X[i2, 0] - X[i0, 0]
    e21 = X[i2, 1] - X[i0, 1]
    e22 = X[i2, 2] - X[i0, 2]
    c0 = e11 * e22 - e12 * e21
    c1 = e12 * e20 - e10 * e22
    c2 = e10 * e21 - e11 * e20
    ta = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    if ta <= 0.0:
        area[f] = 0.0
        for q in range(3):
            nrm[f, q] = 0.0
            for r in range(3):
                grad[f, q, r] = 0.0
        for q in range(8):
            pr[f, q] = 0.0
        return
    n0, n1, n2 = c0 / ta, c1 / ta, c2 / ta
    area[f] = 0.5 * ta
    nrm[f, 0], nrm[f, 1], nrm[f, 2] = n0, n1, n2
    for i in range(3):
        j = F[f, (i + 1) % 3]
        k = F[f, (i + 2) % 3]
        d0 = X[k, 0] - X[j, 0]
        d1 = X[k, 1] - X[j, 1]
        d2 = X[k, 2] - X[j, 2]
        # grad N_i = n x (x_k - x_j) / (2A).
        grad[f, i, 0] = (n1 * d2 - n2 * d1) / ta
        grad[f, i, 1] = (n2 * d0 - n0 * d2) / ta
        grad[f, i, 2] = (n0 * d1 - n1 * d0) / ta
    face_frame(f, X, F, nrm, fr)
    u = fr[0]
    w = fr[1]
    s = S[f]
    a = _quad(s, u, u)
    b = 0.5 * (_quad(s, u, w) + _quad(s, w, u))
    c = _quad(s, w, w)
    l1r, l2r, th = _principal(a, b, c)
    if G.shape[0] >= 2:
        face_shadow(f, X, F, G, gp, r6)
        ra = _quad6(r6, u, u)
        rc = _quad6(r6, w, w)
        if ra != 0.0 or rc != 0.0:
            l1, l2, th = _principal(a - ra, b - _quad6(r6, u, w), c - rc)
            floor = min(0.0, l2r)
            l1r = max(l1, floor)
            l2r = max(l2, floor)
    ct = np.cos(th)
    st = np.sin(th)
    pr[f, 0] = l1r
    pr[f, 1] = l2r
    for q in range(3):
        pr[f, 2 + q] = ct * u[q] + st * w[q]
        pr[f, 5 + q] = -st * u[q] + ct * w[q]


@njit(cache=True)
def tip_principal(f, X, F, S, nrm, G, gp, n0, n1, n2, fr, out):
    """Principal split of the stress a crack tip with normal ``n`` sees in face f -> out[:8].

    The stress minus the shadow-grid release with the component along the tip's own crack
    normal projected out (``P R P``, ``P = I - n̂n̂ᵀ`` in the face plane): the tip's own crack
    (and cracks parallel to it) must not stall it, so its opening stress ``n̂·S·n̂`` stays raw,
    but the release of other cracks across its path is seen.  A concentric link between two
    radial impact cracks then keeps running along the wedge, whose hoop stress they released,
    instead of turning back into the raw hoop direction.  Clamped like :func:`face_update`.
    ``out`` needs 14 entries (8 to 13 are scratch).
    """
    face_frame(f, X, F, nrm, fr)
    u = fr[0]
    w = fr[1]
    s = S[f]
    a = _quad(s, u, u)
    b = 0.5 * (_quad(s, u, w) + _quad(s, w, u))
    c = _quad(s, w, w)
    l1, l2, th = _principal(a, b, c)
    p0 = n0 * u[0] + n1 * u[1] + n2 * u[2]
    p1 = n0 * w[0] + n1 * w[1] + n2 * w[2]
    lp = np.sqrt(p0 * p0 + p1 * p1)
    if G.shape[0] >= 2 and lp > 0.0:
        r6 = out[8:14]
        face_shadow(f, X, F, G, gp, r6)
        ra = _quad6(r6, u, u)
        rb = _quad6(r6, u, w)
        rc = _quad6(r6, w, w)
        if ra != 0.0 or rc != 0.0:
            # In the face frame, P = I - p p^T with p the tip normal; P R P keeps only the
            # release along the tip's direction of travel q = (-p1, p0).
            p0 /= lp
            p1 /= lp
            q0, q1 = -p1, p0
            rq = q0 * q0 * ra + 2.0 * q0 * q1 * rb + q1 * q1 * rc
            l1e, l2e, the = _principal(a - rq * q0 * q0, b - rq * q0 * q1, c - rq * q1 * q1)
            floor = min(0.0, l2)
            l1 = max(l1e, floor)
            l2 = max(l2e, floor)
            th = the
    ct = np.cos(th)
    st = np.sin(th)
    out[0] = l1
    out[1] = l2
    for q in range(3):
        out[2 + q] = ct * u[q] + st * w[q]
        out[5 + q] = -st * u[q] + ct * w[q]


# Mid-point angles on a quarter circle for the mean over in-plane directions in
# :func:`_iso_m`: eight points give the isotropic case exactly and the uniaxial one to 0.4 %.
_QN = 8
ISO_FAILURE = 0.75
"""Share of the direction-averaged separation in the tensor whose largest eigenvalue decides
failure (the rest is the paper's); the direction always comes from the averaged one.  Measured
(4 seeds each): 1 makes the 2- and 20,000-triangle plates crack alike (length -2 %, count -3 %)
but raises the shrinkage crack count by +27 % when the edge length halves (paper: +20 %); 0
keeps +24 % but gives the fine-asset plate 26 % fewer cracks; 0.75 gives -3..-8 % length,
-12..-17 % count and +24 % (shrinkage) / +10 % (glass) under halving."""
_QC = np.cos((np.arange(_QN) + 0.5) * (0.5 * np.pi / _QN))
_QS = np.sin((np.arange(_QN) + 0.5) * (0.5 * np.pi / _QN))


@njit(cache=True)
def _iso_m(p, q):
    """Mean of ``m(S ĝ)`` over unit in-plane ``ĝ`` for ``S = diag(p, q)``, ``p, q >= 0``.

    The mean is diagonal in the same frame; returns its two entries.  By symmetry a quarter
    circle is enough.
    """
    a = 0.0
    b = 0.0
    for k in range(_QN):
        x = p * _QC[k]
        y = q * _QS[k]
        r = np.sqrt(x * x + y * y)
        if r > 0.0:
            a += x * x / r
            b += y * y / r
    return a / _QN, b / _QN


@njit(cache=True)
def _add_dd(acc, w, d0, d1, d2):
    """acc += w d d^T (upper triangle only)."""
    acc[0, 0] += w * d0 * d0
    acc[0, 1] += w * d0 * d1
    acc[0, 2] += w * d0 * d2
    acc[1, 1] += w * d1 * d1
    acc[1, 2] += w * d1 * d2
    acc[2, 2] += w * d2 * d2


@njit(cache=True)
def grain_angle(seed, n):
    """Seeded angle in [0, 2 pi) of node ``n``'s material grain (splitmix64 of seed and id).

    A pure function of the pair, so runs are reproducible and nothing has to be stored or
    carried over when nodes are created.
    """
    z = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(n)
    z = z + np.uint64(0x632BE59BD9B4E019)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return 2.0 * np.pi * float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec, raw, grain, seed, sc,
                acc, ev, G, gp, tipn):
    """Separation tensor (plus residual) of node ``n``; stores its largest eigenpair.

    The paper's ``ς = ½(−m(Σf⁺) + Σm(f⁺) + m(Σf⁻) − Σm(f⁻))`` sees how the mesh is laid out
    (method.md §A5 is silent on this): under isotropic stress ``Σm(f)`` equals
    ``½ Σ L n̂n̂ᵀ`` over the fan's outer edges, whose anisotropy is pure mesh layout.  A sim mesh
    refining a regular asset grid has whole straight lines of edges along the asset's edges and
    diagonals, and cracks followed them.  So a second tensor ``ς̄`` replaces each corner's
    ``m(f) = A|g| m(S ĝ)`` by its mean over the direction ``ĝ`` of the opposite edge's normal,
    ``A|g| E[m(S ĝ)]``: it keeps each corner's weight (its opposite edge length) and the
    stress's own anisotropy, so directional and impact fields still decide, and ``−m(Σf)``
    (unbalanced forces at boundaries, crack sides and stress gradients) is kept exactly.

    * The crack normal ``vec`` is the largest eigenvector of ``ς̄ + ρ`` plus a seeded grain
      term: where that tensor is (nearly) isotropic the direction is physically undecided,
      and a per-node grain direction (:func:`grain_angle`) of weight ``grain x v⁺`` breaks
      the tie instead of round-off.
    * ``val`` (failure) is the largest eigenvalue of
      ``ISO_FAILURE ς̄ + (1 − ISO_FAILURE) ς + ρ``, without the grain: the grain steers but
      never makes a node fail.

    Corner forces ``f = -A (l1 (d1.g) d1 [+ or -] l2 (d2.g) d2)`` are rebuilt from the principal
    split, the effective one from ``pr`` unless ``raw`` (crack tips: :func:`tip_principal`
    with the tip's crack normal ``tipn[n]``, so the world-scale shadow that their own crack
    casts over them does not stall them).  ``sc`` (14,), ``acc`` (2, 3, 3), ``ev`` (3, 3) are
    scratch; ``G``, ``gp`` the shadow grid.
    """
    t = acc[0]
    u = acc[1]
    for i in range(3):
        for j in range(3):
            t[i, j] = 0.0
            u[i, j] = 0.0
    sp0 = sp1 = sp2 = 0.0
    sm0 = sm1 = sm2 = 0.0
    vn0 = vn1 = vn2 = 0.0
    for j in range(NFc[n]):
        f = NF[n, j]
        k = 0
        while F[f, k] != n:
            k += 1
        if raw:
            tip_principal(f, X, F, S, nrm, G, gp, tipn[n, 0], tipn[n, 1], tipn[n, 2], ev, sc)
            p = sc
        else:
            p = pr[f]
        g = grad[f, k]
        A = area[f]
        vn0 += A * nrm[f, 0]
        vn1 += A * nrm[f, 1]
        vn2 += A * nrm[f, 2]
        l1 = p[0]
        l2 = p[1]
        g1 = -A * l1 * (p[2] * g[0] + p[3] * g[1] + p[4] * g[2])
        g2 = -A * l2 * (p[5] * g[0] + p[6] * g[1] + p[7] * g[2])
        a0 = g1 * p[2]
        a1 = g1 * p[3]
        a2 = g1 * p[4]
        b0 = g2 * p[5]
        b1 = g2 * p[6]
        b2 = g2 * p[7]
        wc = A * np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
        if l1 > 0 and l2 > 0:
            sp0 += a0 + b0
            sp1 += a1 + b1
            sp2 += a2 + b2
            _add_m(t, a0 + b0, a1 + b1, a2 + b2, 1.0)
            e1, e2 = _iso_m(l1, l2)
            _add_dd(u, wc * e1, p[2], p[3], p[4])
            _add_dd(u, wc * e2, p[5], p[6], p[7])
        elif l1 > 0:
            sp0 += a0
            sp1 += a1
            sp2 += a2
            sm0 += b0
            sm1 += b1
            sm2 += b2
            _add_m(t, a0, a1, a2, 1.0)
            _add_m(t, b0, b1, b2, -1.0)
            e1, _ = _iso_m(l1, 0.0)
            e2, _ = _iso_m(-l2, 0.0)
            _add_dd(u, wc * e1, p[2], p[3], p[4])
            _add_dd(u, -wc * e2, p[5], p[6], p[7])
        else:
            sm0 += a0 + b0
            sm1 += a1 + b1
            sm2 += a2 + b2
            _add_m(t, a0 + b0, a1 + b1, a2 + b2, -1.0)
            e1, e2 = _iso_m(-l1, -l2)
            _add_dd(u, -wc * e1, p[2], p[3], p[4])
            _add_dd(u, -wc * e2, p[5], p[6], p[7])
    _add_m(t, sp0, sp1, sp2, -1.0)
    _add_m(t, sm0, sm1, sm2, 1.0)
    _add_m(u, sp0, sp1, sp2, -1.0)
    _add_m(u, sm0, sm1, sm2, 1.0)
    r = rho[n]
    for i in range(3):
        for j in range(i, 3):
            t[i, j] = 0.5 * t[i, j] + r[i, j]
            u[i, j] = 0.5 * u[i, j] + r[i, j]
    for i in range(3):
        for j in range(i, 3):
            t[i, j] = ISO_FAILURE * u[i, j] + (1.0 - ISO_FAILURE) * t[i, j]
    for i in range(3):
        for j in range(i):
            t[i, j] = t[j, i]
            u[i, j] = u[j, i]
    v = eig_max_into(t, ev)
    val[n] = v
    lvn = np.sqrt(vn0 * vn0 + vn1 * vn1 + vn2 * vn2)
    if grain > 0.0 and v > 0.0 and lvn > 0.0:
        vn0 /= lvn
        vn1 /= lvn
        vn2 /= lvn
        # Tangent basis from the axis least aligned with the normal; the grain angle is
        # uniform, so which basis does not matter.
        if abs(vn0) <= abs(vn1) and abs(vn0) <= abs(vn2):
            x0, x1, x2 = 0.0, -vn2, vn1
        elif abs(vn1) <= abs(vn2):
            x0, x1, x2 = vn2, 0.0, -vn0
        else:
            x0, x1, x2 = -vn1, vn0, 0.0
        lx = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        x0 /= lx
        x1 /= lx
        x2 /= lx
        y0 = vn1 * x2 - vn2 * x1
        y1 = vn2 * x0 - vn0 * x2
        y2 = vn0 * x1 - vn1 * x0
        th = grain_angle(seed, n)
        c = np.cos(th)
        s = np.sin(th)
        d0 = c * x0 + s * y0
        d1 = c * x1 + s * y1
        d2 = c * x2 + s * y2
        _add_dd(u, grain * v, d0, d1, d2)
        u[1, 0] = u[0, 1]
        u[2, 0] = u[0, 2]
        u[2, 1] = u[1, 2]
    eig_max_into(u, ev)
    for q in range(3):
        vec[n, q] = ev[q, 0]


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
               segp, seg_alive, seg_info, segof, cnt):
    """Split edge (a, b) at ``a + tt (b - a)``: one new node, each face on the edge in two.

    Children keep the parent's world stress (so its in-frame rotation is implicit), asset face and
    growth.  If the edge is a crack side, the recorded crack segment is split too so the network
    keeps its junction there; ``segof`` maps a node to the last live segment starting or ending
    at it, which finds that segment without a search.  Returns the new node.
    """
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
    p = cnt[1]
    cnt[1] += 1
    for q in range(3):
        X[p, q] = X[a, q] + tt * (X[b, q] - X[a, q])
    pid[p] = p
    hn[p] = 0.5 * (hn[a] + hn[b])
    taun[p] = 0.5 * (taun[a] + taun[b])
    rho[p] = 0.0
    crack_of[p] = -1
    nver[p] = 0
    NFc[p] = 0
    onb[p] = False
    segof[p] = -1
    for i in range(min(nfl, 2)):
        f = f_0 if i == 0 else f_1
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
        found = -1
        for cand in (segof[pa], segof[pb]):
            if cand >= 0 and seg_alive[cand] and (
                    (segp[cand, 0] == pa and segp[cand, 1] == pb)
                    or (segp[cand, 0] == pb and segp[cand, 1] == pa)):
                found = cand
                break
        if found < 0:
            # Not the last segment at either end: fall back to a search from the newest.
            for s in range(cnt[3] - 1, -1, -1):
                if seg_alive[s] and ((segp[s, 0] == pa and segp[s, 1] == pb)
                                     or (segp[s, 0] == pb and segp[s, 1] == pa)):
                    found = s
                    break
        if found >= 0:
            s = found
            seg_alive[s] = False
            for q in range(2):
                t = cnt[3]
                cnt[3] += 1
                segp[t, 0] = segp[s, 0] if q == 0 else p
                segp[t, 1] = p if q == 0 else segp[s, 1]
                seg_alive[t] = True
                seg_info[t] = seg_info[s]
                segof[segp[t, 0]] = t
                segof[segp[t, 1]] = t
        else:
            onb[p] = onb[a] and onb[b]
    return p


@njit(cache=True)
def separate(c, cut1, cut2, X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of, nver, cnt, out,
             par, comp, faces):
    """Split node ``c`` into one node per edge-connected group of its faces.

    Faces around ``c`` are connected through shared edges (c, x), except through the cut edges
    (c, cut1) and (c, cut2): cutting them opens the crack; with no cuts this only mends pinched
    (bow-tie) nodes left where a crack reached a boundary.  New nodes are written to ``out``;
    returns their number.  ``par``, ``comp``, ``faces`` are scratch rows at least the table width.
    """
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
                    ri = _find(par, i)
                    rj = _find(par, j)
                    if ri != rj:
                        par[max(ri, rj)] = min(ri, rj)
    ncomp = 0
    # Roots are their own smallest member, so a root's label is assigned before its members'.
    for i in range(k):
        r = _find(par, i)
        if r == i:
            comp[i] = ncomp
            ncomp += 1
        else:
            comp[i] = comp[r]
    if ncomp <= 1:
        return 0
    for i in range(k):
        faces[i] = NF[c, i]
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
