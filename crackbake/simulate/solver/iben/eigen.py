"""Small symmetric 3x3 algebra of the iben kernels: largest eigenpair, outer-product updates."""

from __future__ import annotations

import numpy as np
from numba import njit


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
def eig_max_value(m):
    """Largest eigenvalue of the symmetric 3x3 ``m`` (destroyed): :func:`eig_max_into`'s, bit
    for bit (the same rotations of ``m``), without accumulating the eigenvectors."""
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
    best = 0
    for k in range(1, 3):
        if m[k, k] > m[best, best]:
            best = k
    return m[best, best]


@njit(cache=True)
def add_m(acc, f0, f1, f2, sign):
    """acc += sign * f f^T / |f| (the paper's m(f); m(0) = 0), upper triangle only."""
    n = np.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    if n > 0.0:
        add_dd(acc, sign / n, f0, f1, f2)


@njit(cache=True)
def add_dd(acc, w, d0, d1, d2):
    """acc += w d d^T (upper triangle only)."""
    acc[0, 0] += w * d0 * d0
    acc[0, 1] += w * d0 * d1
    acc[0, 2] += w * d0 * d2
    acc[1, 1] += w * d1 * d1
    acc[1, 2] += w * d1 * d2
    acc[2, 2] += w * d2 * d2
