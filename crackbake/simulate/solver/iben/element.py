"""Per-face FEM of the iben loop: geometry and the principal split of the effective stress.

The formulas are those of :mod:`crackbake.simulate.solver.fem` (tested against it in
tests/test_iben.py), written per element for use inside the loop: corner forces
``f_i = -A S± g_i`` are rebuilt from the stored principal split ``pr`` whenever a node needs
them, which is cheaper in memory than storing them and costs only a few flops.

With several impacts the shadow is a stack of grid blocks (:mod:`.shadow`); faces read it
through :func:`.shadow.face_shadow` only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.shadow import face_shadow
from crackbake.simulate.solver.iben.vec import wrap


@njit(cache=True)
def _principal(a, b, c):
    """Eigenvalues (l1 >= l2) and the angle of l1's eigenvector of the 2x2 [[a, b], [b, c]]."""
    mean = 0.5 * (a + c)
    rad = np.sqrt((0.5 * (a - c)) ** 2 + b * b)
    return mean + rad, mean - rad, 0.5 * np.arctan2(2.0 * b, a - c)


@njit(cache=True)
def face_frame(f, X, F, nrm, per, fr):
    """In-plane frame of face f: u along edge 0->1 -> fr[0], w = n x u -> fr[1] (``per``:
    the tile period, 0: not periodic)."""
    i0, i1 = F[f, 0], F[f, 1]
    e0 = wrap(X[i1, 0] - X[i0, 0], per)
    e1 = wrap(X[i1, 1] - X[i0, 1], per)
    e2 = X[i1, 2] - X[i0, 2]
    le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    fr[0, 0] = e0 / le
    fr[0, 1] = e1 / le
    fr[0, 2] = e2 / le
    n0, n1, n2 = nrm[f, 0], nrm[f, 1], nrm[f, 2]
    fr[1, 0] = n1 * fr[0, 2] - n2 * fr[0, 1]
    fr[1, 1] = n2 * fr[0, 0] - n0 * fr[0, 2]
    fr[1, 2] = n0 * fr[0, 1] - n1 * fr[0, 0]


@njit(cache=True)
def _quad(S, f, fr, i, j):
    """x^T S[f] y for the frame rows x = fr[i], y = fr[j]."""
    acc = 0.0
    for k in range(3):
        acc += fr[i, k] * (S[f, k, 0] * fr[j, 0] + S[f, k, 1] * fr[j, 1]
                           + S[f, k, 2] * fr[j, 2])
    return acc


@njit(cache=True)
def _quad6(r, o, fr, i, j):
    """x^T R y for the frame rows x = fr[i], y = fr[j], with R given as the six components
    xx xy xz yy yz zz at ``r[o:o + 6]``."""
    return (fr[i, 0] * (r[o] * fr[j, 0] + r[o + 1] * fr[j, 1] + r[o + 2] * fr[j, 2])
            + fr[i, 1] * (r[o + 1] * fr[j, 0] + r[o + 3] * fr[j, 1] + r[o + 4] * fr[j, 2])
            + fr[i, 2] * (r[o + 2] * fr[j, 0] + r[o + 4] * fr[j, 1] + r[o + 5] * fr[j, 2]))


@njit(cache=True)
def face_update(s, f, fr, r6):
    """Geometry and the principal split of the effective stress of face ``f`` of state ``s``
    (its struct reference): ``area``, ``nrm``, ``grad`` and ``pr`` from ``X``, ``F``, ``S``.

    Effective stress = stress minus the shadow-grid release at the centroid, projected on the
    face plane.  The release may not create compression the raw stress did not have (a crack
    cannot push its neighbourhood into compression), so the effective principal stresses are
    clamped at ``min(0, smallest raw principal stress)``.  ``fr`` (2, 3) and ``r6`` (6,) are
    scratch rows.
    """
    X, F, area, nrm, grad, pr, per = s.X, s.F, s.area, s.nrm, s.grad, s.pr, s.period
    S, G, gp = s.S, s.G, s.gp
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    e10 = wrap(X[i1, 0] - X[i0, 0], per)
    e11 = wrap(X[i1, 1] - X[i0, 1], per)
    e12 = X[i1, 2] - X[i0, 2]
    e20 = wrap(X[i2, 0] - X[i0, 0], per)
    e21 = wrap(X[i2, 1] - X[i0, 1], per)
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
        d0 = wrap(X[k, 0] - X[j, 0], per)
        d1 = wrap(X[k, 1] - X[j, 1], per)
        d2 = X[k, 2] - X[j, 2]
        # grad N_i = n x (x_k - x_j) / (2A).
        grad[f, i, 0] = (n1 * d2 - n2 * d1) / ta
        grad[f, i, 1] = (n2 * d0 - n0 * d2) / ta
        grad[f, i, 2] = (n0 * d1 - n1 * d0) / ta
    face_frame(f, X, F, nrm, per, fr)  # u = fr[0], w = fr[1]
    a = _quad(S, f, fr, 0, 0)
    b = 0.5 * (_quad(S, f, fr, 0, 1) + _quad(S, f, fr, 1, 0))
    c = _quad(S, f, fr, 1, 1)
    l1r, l2r, th = _principal(a, b, c)
    if G.shape[0] >= 2:
        face_shadow(f, X, F, G, gp, per, r6)
        ra = _quad6(r6, 0, fr, 0, 0)
        rc = _quad6(r6, 0, fr, 1, 1)
        if ra != 0.0 or rc != 0.0:
            l1, l2, th = _principal(a - ra, b - _quad6(r6, 0, fr, 0, 1), c - rc)
            floor = min(0.0, l2r)
            l1r = max(l1, floor)
            l2r = max(l2, floor)
    ct = np.cos(th)
    st = np.sin(th)
    pr[f, 0] = l1r
    pr[f, 1] = l2r
    for q in range(3):
        pr[f, 2 + q] = ct * fr[0, q] + st * fr[1, q]
        pr[f, 5 + q] = -st * fr[0, q] + ct * fr[1, q]


@njit(cache=True)
def tip_principal(s, f, n0, n1, n2, fr, out):
    """Principal split of the stress a crack tip with normal ``n`` sees in face f of state
    ``s`` (its struct reference) -> out[:8].

    The stress minus the shadow-grid release with the component along the tip's own crack
    normal projected out (``P R P``, ``P = I - n̂n̂ᵀ`` in the face plane): the tip's own crack
    (and cracks parallel to it) must not stall it, so its opening stress ``n̂·S·n̂`` stays raw,
    but the release of other cracks across its path is seen.  A concentric link between two
    radial impact cracks then keeps running along the wedge, whose hoop stress they released,
    instead of turning back into the raw hoop direction.  Clamped like :func:`face_update`.
    ``out`` needs 14 entries (8 to 13 are scratch).
    """
    X, F, G, S = s.X, s.F, s.G, s.S
    face_frame(f, X, F, s.nrm, s.period, fr)  # u = fr[0], w = fr[1]
    a = _quad(S, f, fr, 0, 0)
    b = 0.5 * (_quad(S, f, fr, 0, 1) + _quad(S, f, fr, 1, 0))
    c = _quad(S, f, fr, 1, 1)
    l1, l2, th = _principal(a, b, c)
    p0 = n0 * fr[0, 0] + n1 * fr[0, 1] + n2 * fr[0, 2]
    p1 = n0 * fr[1, 0] + n1 * fr[1, 1] + n2 * fr[1, 2]
    lp = np.sqrt(p0 * p0 + p1 * p1)
    if G.shape[0] >= 2 and lp > 0.0:
        r6 = out[8:14]
        face_shadow(f, X, F, G, s.gp, s.period, r6)
        ra = _quad6(r6, 0, fr, 0, 0)
        rb = _quad6(r6, 0, fr, 0, 1)
        rc = _quad6(r6, 0, fr, 1, 1)
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
        out[2 + q] = ct * fr[0, q] + st * fr[1, q]
        out[5 + q] = -st * fr[0, q] + ct * fr[1, q]
