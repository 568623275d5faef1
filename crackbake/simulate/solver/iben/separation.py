"""Per-node separation tensors of the iben loop (the crack criterion and direction).

The shadow (several impacts: a stack of grid blocks) is read through :mod:`.shadow` only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.eigen import add_dd, add_m, eig_max_into, eig_max_value
from crackbake.simulate.solver.iben.element import tip_principal

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
def _splitmix(z):
    z = z + np.uint64(0x632BE59BD9B4E019)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True)
def grain_angle(seed, n, n0, x, y, z, q):
    """Seeded angle in [0, 2 pi) of node ``n``'s material grain (splitmix64).

    A node of the initial sim mesh (``n < n0``, ``State.gn0``) hashes its rest point
    ``(x, y, z)`` counted in whole units of ``q`` (``State.gq``): its index depends on how many
    points other impacts' refined balls added before it, its point does not, so a star grown
    alone and beside other impacts starts from the same grain, at any mesh scale.  A node made
    by a split hashes its rank among the split nodes (``n - n0``): a copy of a split node must
    not share the grain of the node it was split from (copies sharing one grain widened mud's
    gaps past its look), and that rank depends only on the splits before it.  A pure function,
    so nothing is stored or carried over when nodes are created.
    """
    h = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15)
    if n < n0:
        h = _splitmix(h + np.uint64(np.int64(np.floor(x / q))))
        h = _splitmix(h + np.uint64(np.int64(np.floor(y / q))))
        h = _splitmix(h + np.uint64(np.int64(np.floor(z / q))))
    else:
        h = _splitmix(h + np.uint64(0xD1B54A32D192ED03) + np.uint64(n - n0))
    return 2.0 * np.pi * float(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def node_update(s, n, raw, grain, seed, sc, acc, ev):
    """Separation tensor (plus residual) of node ``n`` of state ``s`` (its struct reference);
    stores its largest eigenpair in ``val[n]``, ``vec[n]``.

    The paper's ``ς = ½(−m(Σf⁺) + Σm(f⁺) + m(Σf⁻) − Σm(f⁻))`` sees how the mesh is laid out
    (the paper is silent on this): under isotropic stress ``Σm(f)`` equals
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
    casts over them does not stall them).  ``grain`` and ``seed`` are the grain's weight and
    seed; ``sc`` (14,), ``acc`` (2, 3, 3), ``ev`` (3, 3) are scratch.
    """
    # Scalars rather than row views (pr[f], grad[f, k], rho[n]): a view in the loop costs an
    # atomic incref and decref of its array (docs/solver.md, "Implementation notes").
    F, NF, NFc, area, nrm, grad, pr, tipn = s.F, s.NF, s.NFc, s.area, s.nrm, s.grad, s.pr, s.tipn
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
            tip_principal(s, f, tipn[n, 0], tipn[n, 1], tipn[n, 2], ev, sc)
            l1, l2, p2, p3, p4, p5, p6, p7 = sc[0], sc[1], sc[2], sc[3], sc[4], sc[5], sc[6], sc[7]
        else:
            l1, l2, p2, p3, p4 = pr[f, 0], pr[f, 1], pr[f, 2], pr[f, 3], pr[f, 4]
            p5, p6, p7 = pr[f, 5], pr[f, 6], pr[f, 7]
        g0, g1_, g2_ = grad[f, k, 0], grad[f, k, 1], grad[f, k, 2]
        A = area[f]
        vn0 += A * nrm[f, 0]
        vn1 += A * nrm[f, 1]
        vn2 += A * nrm[f, 2]
        g1 = -A * l1 * (p2 * g0 + p3 * g1_ + p4 * g2_)
        g2 = -A * l2 * (p5 * g0 + p6 * g1_ + p7 * g2_)
        a0 = g1 * p2
        a1 = g1 * p3
        a2 = g1 * p4
        b0 = g2 * p5
        b1 = g2 * p6
        b2 = g2 * p7
        wc = A * np.sqrt(g0 * g0 + g1_ * g1_ + g2_ * g2_)
        if l1 > 0 and l2 > 0:
            sp0 += a0 + b0
            sp1 += a1 + b1
            sp2 += a2 + b2
            add_m(t, a0 + b0, a1 + b1, a2 + b2, 1.0)
            e1, e2 = _iso_m(l1, l2)
            add_dd(u, wc * e1, p2, p3, p4)
            add_dd(u, wc * e2, p5, p6, p7)
        elif l1 > 0:
            sp0 += a0
            sp1 += a1
            sp2 += a2
            sm0 += b0
            sm1 += b1
            sm2 += b2
            add_m(t, a0, a1, a2, 1.0)
            add_m(t, b0, b1, b2, -1.0)
            e1, _ = _iso_m(l1, 0.0)
            e2, _ = _iso_m(-l2, 0.0)
            add_dd(u, wc * e1, p2, p3, p4)
            add_dd(u, -wc * e2, p5, p6, p7)
        else:
            sm0 += a0 + b0
            sm1 += a1 + b1
            sm2 += a2 + b2
            add_m(t, a0 + b0, a1 + b1, a2 + b2, -1.0)
            e1, e2 = _iso_m(-l1, -l2)
            add_dd(u, -wc * e1, p2, p3, p4)
            add_dd(u, -wc * e2, p5, p6, p7)
    add_m(t, sp0, sp1, sp2, -1.0)
    add_m(t, sm0, sm1, sm2, 1.0)
    add_m(u, sp0, sp1, sp2, -1.0)
    add_m(u, sm0, sm1, sm2, 1.0)
    rho = s.rho
    for i in range(3):
        for j in range(i, 3):
            t[i, j] = 0.5 * t[i, j] + rho[n, i, j]
            u[i, j] = 0.5 * u[i, j] + rho[n, i, j]
    for i in range(3):
        for j in range(i, 3):
            t[i, j] = ISO_FAILURE * u[i, j] + (1.0 - ISO_FAILURE) * t[i, j]
    for i in range(3):
        for j in range(i):
            t[i, j] = t[j, i]
            u[i, j] = u[j, i]
    v = eig_max_value(t)  # the failure value only: its vector is u's
    s.val[n] = v
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
        X = s.X
        th = grain_angle(seed, n, s.gn0, X[n, 0], X[n, 1], X[n, 2], s.gq)
        ct = np.cos(th)
        st = np.sin(th)
        d0 = ct * x0 + st * y0
        d1 = ct * x1 + st * y1
        d2 = ct * x2 + st * y2
        add_dd(u, grain * v, d0, d1, d2)
        u[1, 0] = u[0, 1]
        u[2, 0] = u[0, 2]
        u[2, 1] = u[1, 2]
    eig_max_into(u, ev)
    vec = s.vec
    for q in range(3):
        vec[n, q] = ev[q, 0]
