"""The numba kernel behind :func:`crackbake.geometry.face_cross`, in a module of its own so
that importing :mod:`crackbake.geometry` (every mesh reader does) does not import numba."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def face_cross_kernel(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``(b - a) x (c - a)`` per face of ``f`` (F, 3) int64 over ``v`` (V, 3) float64: (F, 3)."""
    # One pass, no (F, 3, 3) gather: at 1.5M faces numpy's version took 0.3-0.6 s a call.
    out = np.empty((len(f), 3))
    for k in range(len(f)):
        a, b, c = f[k, 0], f[k, 1], f[k, 2]
        ux, uy, uz = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        wx, wy, wz = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        out[k, 0] = uy * wz - uz * wy
        out[k, 1] = uz * wx - ux * wz
        out[k, 2] = ux * wy - uy * wx
    return out
