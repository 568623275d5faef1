"""Inlined 3-vector algebra on scalars for the compiled kernels.

Each helper spells out the exact operation order the kernels used before they were shared
(``a0 * b0 + a1 * b1 + a2 * b2``, left to right), so the results are bit for bit the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(inline="always")
def dot3(a0, a1, a2, b0, b1, b2):
    """``a . b``."""
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(inline="always")
def norm3(a0, a1, a2):
    """``|a|``."""
    return np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)


@njit(inline="always")
def cross3(a0, a1, a2, b0, b1, b2):
    """``a x b`` as a tuple."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def angle(u0, u1, u2, v0, v1, v2):
    """Angle between ``u`` and ``v`` in radians (0 when either is zero)."""
    nu = norm3(u0, u1, u2)
    nv = norm3(v0, v1, v2)
    if nu == 0.0 or nv == 0.0:
        return 0.0
    return np.arccos(min(1.0, max(-1.0, dot3(u0, u1, u2, v0, v1, v2) / (nu * nv))))


@njit(inline="always")
def wrap(d, per):
    """Minimum image of the coordinate difference ``d`` on a period ``per`` (a tiling plate,
    docs/solver.md "Periodic plates"); ``per == 0`` (not periodic) returns ``d`` itself, so
    the non-periodic path is bit for bit the old one."""
    if per == 0.0:
        return d
    return d - per * np.floor(d / per + 0.5)
