"""Fine relaxation: damped block-Jacobi passes over the region around a crack event."""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.constants import RELAX_CAP, RELAX_TOL


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def region(s, w, nrf, stamp, rings):
    """Grow the event's region ``w.regf[:nrf]`` (stamped faces) by ``rings`` rings of faces and
    list its nodes in ``w.regn``; returns the new face and node counts."""
    F, NF, NFc, fst, nst, regf, regn = s.F, s.NF, s.NFc, s.fst, s.nst, w.regf, w.regn
    lo = 0
    hi = nrf
    for _ring in range(rings):
        for i in range(lo, hi):
            f = regf[i]
            for q in range(3):
                n = F[f, q]
                for j in range(NFc[n]):
                    g = NF[n, j]
                    if fst[g] != stamp:
                        fst[g] = stamp
                        regf[nrf] = g
                        nrf += 1
        lo = hi
        hi = nrf
    nrn = 0
    for i in range(nrf):
        f = regf[i]
        for q in range(3):
            n = F[f, q]
            if nst[n] != stamp:
                nst[n] = stamp
                regn[nrn] = n
                nrn += 1
    return nrf, nrn


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def relax(s, w, nrf, nrn, stamp, nrelax, rate):
    """Fine relaxation of the region's stress (raw ``S``): at most ``nrelax`` damped
    block-Jacobi passes (docs/solver.md, "Stress relief")."""
    if nrelax > 0:
        _stiffness(s, w, nrn, stamp, rate)
    for _pass in range(nrelax):
        _displace(s, w, nrn)
        if _strain(s, w, nrf) < RELAX_TOL:
            break
    disp, regn = w.disp, w.regn
    for i in range(nrn):
        disp[regn[i], 0] = disp[regn[i], 1] = disp[regn[i], 2] = 0.0


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _stiffness(s, w, nrn, stamp, rate):
    """Inverse block stiffness of each region node whose fan lies in the region, scaled by
    ``1.5 rate`` -> ``w.kinv[i]`` (six cofactors over the determinant's scale, row ``i`` of
    ``w.regn``); ``kinv[i, 6]`` is 0 where the node does not move.  The geometry does not change
    during the passes, so this is worked out once per event rather than once per pass."""
    F, NF, NFc, area, grad, fst = s.F, s.NF, s.NFc, s.area, s.grad, s.fst
    regn, kinv = w.regn, w.kinv
    for i in range(nrn):
        n = regn[i]
        free = True
        # Block stiffness of the node, (2/3) sum A (|g|^2 I + g g^T) (upper triangle): the
        # exact diagonal block of the strain operator, scaled so that a fan with edges in
        # all directions gets the scalar sum A |g|^2.  A scalar alone over-relaxes across
        # the dominant edge direction of an anisotropic fan (rows of sim edges along the
        # asset's edges), which steered crack tips along them.
        k00 = k01 = k02 = k11 = k12 = k22 = 0.0
        for j in range(NFc[n]):
            f = NF[n, j]
            if fst[f] != stamp:
                free = False
                break
            k = 0
            while F[f, k] != n:
                k += 1
            g0, g1, g2 = grad[f, k, 0], grad[f, k, 1], grad[f, k, 2]
            A = area[f]
            gg = g0 * g0 + g1 * g1 + g2 * g2
            k00 += A * (gg + g0 * g0)
            k01 += A * g0 * g1
            k02 += A * g0 * g2
            k11 += A * (gg + g1 * g1)
            k12 += A * g1 * g2
            k22 += A * (gg + g2 * g2)
        # Inverse by cofactors (the block is symmetric positive definite).
        c00 = k11 * k22 - k12 * k12
        c01 = k02 * k12 - k01 * k22
        c02 = k01 * k12 - k02 * k11
        det = k00 * c00 + k01 * c01 + k02 * c02
        kinv[i, 6] = 0.0
        if free and det > 0:
            kinv[i, 0] = c00
            kinv[i, 1] = c01
            kinv[i, 2] = c02
            kinv[i, 3] = k00 * k22 - k02 * k02
            kinv[i, 4] = k01 * k02 - k00 * k12
            kinv[i, 5] = k00 * k11 - k01 * k01
            kinv[i, 6] = 1.5 * rate / det


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _displace(s, w, nrn):
    """Displacement ``d = rate K^-1 F_net`` of each region node that moves
    (:func:`_stiffness`); 0 for the others."""
    F, S, NF, NFc, area, grad = s.F, s.S, s.NF, s.NFc, s.area, s.grad
    regn, disp, kinv = w.regn, w.disp, w.kinv
    for i in range(nrn):
        n = regn[i]
        r = kinv[i, 6]
        if not r > 0.0:
            disp[n, 0] = disp[n, 1] = disp[n, 2] = 0.0
            continue
        f0 = f1 = f2 = 0.0
        for j in range(NFc[n]):
            f = NF[n, j]
            k = 0
            while F[f, k] != n:
                k += 1
            # Scalars, not row views: a view costs an atomic incref and decref.
            g0, g1, g2 = grad[f, k, 0], grad[f, k, 1], grad[f, k, 2]
            A = area[f]
            f0 -= A * (S[f, 0, 0] * g0 + S[f, 0, 1] * g1 + S[f, 0, 2] * g2)
            f1 -= A * (S[f, 1, 0] * g0 + S[f, 1, 1] * g1 + S[f, 1, 2] * g2)
            f2 -= A * (S[f, 2, 0] * g0 + S[f, 2, 1] * g1 + S[f, 2, 2] * g2)
        c00, c01, c02 = kinv[i, 0], kinv[i, 1], kinv[i, 2]
        c11, c12, c22 = kinv[i, 3], kinv[i, 4], kinv[i, 5]
        disp[n, 0] = r * (c00 * f0 + c01 * f1 + c02 * f2)
        disp[n, 1] = r * (c01 * f0 + c11 * f1 + c12 * f2)
        disp[n, 2] = r * (c02 * f0 + c12 * f1 + c22 * f2)


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _strain(s, w, nrf):
    """Add each region face's strain ``sym(sum_i d_i g_i^T)`` (in-plane displacements), capped
    at ``RELAX_CAP`` of its stress norm; returns the largest relative change."""
    F, S, nrm, grad, regf, disp = s.F, s.S, s.nrm, s.grad, w.regf, w.disp
    worst = 0.0
    for i in range(nrf):
        f = regf[i]
        nf0, nf1, nf2 = nrm[f, 0], nrm[f, 1], nrm[f, 2]
        m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
        for q in range(3):
            c = F[f, q]
            e0, e1, e2 = disp[c, 0], disp[c, 1], disp[c, 2]
            dn = e0 * nf0 + e1 * nf1 + e2 * nf2
            d0 = e0 - dn * nf0
            d1 = e1 - dn * nf1
            d2 = e2 - dn * nf2
            g0, g1, g2 = grad[f, q, 0], grad[f, q, 1], grad[f, q, 2]
            m00 += d0 * g0
            m01 += d0 * g1
            m02 += d0 * g2
            m10 += d1 * g0
            m11 += d1 * g1
            m12 += d1 * g2
            m20 += d2 * g0
            m21 += d2 * g1
            m22 += d2 * g2
        a01 = 0.5 * (m01 + m10)
        a02 = 0.5 * (m02 + m20)
        a12 = 0.5 * (m12 + m21)
        nds = np.sqrt(m00 * m00 + m11 * m11 + m22 * m22
                      + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12))
        ns = 0.0
        for a in range(3):
            for b in range(3):
                ns += S[f, a, b] * S[f, a, b]
        ns = np.sqrt(ns)
        scale = 1.0
        if nds > RELAX_CAP * ns:
            scale = RELAX_CAP * ns / nds
        if ns > 0.0:
            worst = max(worst, scale * nds / ns)
        S[f, 0, 0] += scale * m00
        S[f, 1, 1] += scale * m11
        S[f, 2, 2] += scale * m22
        S[f, 0, 1] += scale * a01
        S[f, 1, 0] += scale * a01
        S[f, 0, 2] += scale * a02
        S[f, 2, 0] += scale * a02
        S[f, 1, 2] += scale * a12
        S[f, 2, 1] += scale * a12
    return worst
