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
    for _pass in range(nrelax):
        _displace(s, w, nrn, stamp, rate)
        if _strain(s, w, nrf) < RELAX_TOL:
            break
    disp, regn = w.disp, w.regn
    for i in range(nrn):
        disp[regn[i], 0] = disp[regn[i], 1] = disp[regn[i], 2] = 0.0


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _displace(s, w, nrn, stamp, rate):
    """Displacement ``d = rate K^-1 F_net`` of each region node whose fan lies in the region."""
    F, S, NF, NFc, area, grad, fst = s.F, s.S, s.NF, s.NFc, s.area, s.grad, s.fst
    regn, disp = w.regn, w.disp
    for i in range(nrn):
        n = regn[i]
        free = True
        f0 = f1 = f2 = 0.0
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
            g = grad[f, k]
            sf = S[f]
            A = area[f]
            f0 -= A * (sf[0, 0] * g[0] + sf[0, 1] * g[1] + sf[0, 2] * g[2])
            f1 -= A * (sf[1, 0] * g[0] + sf[1, 1] * g[1] + sf[1, 2] * g[2])
            f2 -= A * (sf[2, 0] * g[0] + sf[2, 1] * g[1] + sf[2, 2] * g[2])
            gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2]
            k00 += A * (gg + g[0] * g[0])
            k01 += A * g[0] * g[1]
            k02 += A * g[0] * g[2]
            k11 += A * (gg + g[1] * g[1])
            k12 += A * g[1] * g[2]
            k22 += A * (gg + g[2] * g[2])
        # Inverse by cofactors (the block is symmetric positive definite).
        c00 = k11 * k22 - k12 * k12
        c01 = k02 * k12 - k01 * k22
        c02 = k01 * k12 - k02 * k11
        det = k00 * c00 + k01 * c01 + k02 * c02
        if free and det > 0:
            c11 = k00 * k22 - k02 * k02
            c12 = k01 * k02 - k00 * k12
            c22 = k00 * k11 - k01 * k01
            r = 1.5 * rate / det
            disp[n, 0] = r * (c00 * f0 + c01 * f1 + c02 * f2)
            disp[n, 1] = r * (c01 * f0 + c11 * f1 + c12 * f2)
            disp[n, 2] = r * (c02 * f0 + c12 * f1 + c22 * f2)
        else:
            disp[n, 0] = disp[n, 1] = disp[n, 2] = 0.0


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _strain(s, w, nrf):
    """Add each region face's strain ``sym(sum_i d_i g_i^T)`` (in-plane displacements), capped
    at ``RELAX_CAP`` of its stress norm; returns the largest relative change."""
    F, S, nrm, grad, regf, disp = s.F, s.S, s.nrm, s.grad, w.regf, w.disp
    worst = 0.0
    for i in range(nrf):
        f = regf[i]
        nf_ = nrm[f]
        m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
        for q in range(3):
            d = disp[F[f, q]]
            dn = d[0] * nf_[0] + d[1] * nf_[1] + d[2] * nf_[2]
            d0 = d[0] - dn * nf_[0]
            d1 = d[1] - dn * nf_[1]
            d2 = d[2] - dn * nf_[2]
            g = grad[f, q]
            m00 += d0 * g[0]
            m01 += d0 * g[1]
            m02 += d0 * g[2]
            m10 += d1 * g[0]
            m11 += d1 * g[1]
            m12 += d1 * g[2]
            m20 += d2 * g[0]
            m21 += d2 * g[1]
            m22 += d2 * g[2]
        a01 = 0.5 * (m01 + m10)
        a02 = 0.5 * (m02 + m20)
        a12 = 0.5 * (m12 + m21)
        nds = np.sqrt(m00 * m00 + m11 * m11 + m22 * m22
                      + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12))
        sf = S[f]
        ns = 0.0
        for a in range(3):
            for b in range(3):
                ns += sf[a, b] * sf[a, b]
        ns = np.sqrt(ns)
        scale = 1.0
        if nds > RELAX_CAP * ns:
            scale = RELAX_CAP * ns / nds
        if ns > 0.0:
            worst = max(worst, scale * nds / ns)
        sf[0, 0] += scale * m00
        sf[1, 1] += scale * m11
        sf[2, 2] += scale * m22
        sf[0, 1] += scale * a01
        sf[1, 0] += scale * a01
        sf[0, 2] += scale * a02
        sf[2, 0] += scale * a02
        sf[1, 2] += scale * a12
        sf[2, 1] += scale * a12
    return worst
