"""The world-scale stress shadow: a uniform grid of released stress (docs/solver.md).

The grid ``G`` (nx, ny, nz, 6) holds the released stress per cell (xx xy xz yy yz zz); its
parameters ``gp`` are ``origin (3), cell, kernel radius`` (5,), followed with several impacts
by the table below.  The tile period (``State.period``, 0: not periodic) is its own field;
with it the grid spans one period in x and y and its cells wrap around.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.vec import wrap


@njit(cache=True)
def shadow_at(x0, x1, x2, G, gp, per, out):
    """Released stress at a point: trilinear interpolation of the cell-centred grid -> out[6]
    (``per``: the tile period, 0: not periodic)."""
    for q in range(6):
        out[q] = 0.0
    if G.shape[0] < 2:
        return
    if gp.shape[0] > IMPACTS:
        _blocks_at(x0, x1, x2, G, gp, out)
        return
    cs = gp[3]
    u0 = (x0 - gp[0]) / cs - 0.5
    u1 = (x1 - gp[1]) / cs - 0.5
    u2 = (x2 - gp[2]) / cs - 0.5
    if per != 0.0:
        _periodic_at(u0, u1, u2, G, out)
        return
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
def face_shadow(f, X, F, G, gp, per, out):
    """Released stress at the centroid of face f -> out[6] (see :func:`shadow_at`)."""
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    if per != 0.0:
        # Periodic plate: the centroid of the corners' nearest images of corner 0.
        shadow_at(X[i0, 0] + (wrap(X[i1, 0] - X[i0, 0], per) + wrap(X[i2, 0] - X[i0, 0], per))
                  / 3.0,
                  X[i0, 1] + (wrap(X[i1, 1] - X[i0, 1], per) + wrap(X[i2, 1] - X[i0, 1], per))
                  / 3.0, (X[i0, 2] + X[i1, 2] + X[i2, 2]) / 3.0, G, gp, per, out)
        return
    shadow_at((X[i0, 0] + X[i1, 0] + X[i2, 0]) / 3.0, (X[i0, 1] + X[i1, 1] + X[i2, 1]) / 3.0,
              (X[i0, 2] + X[i1, 2] + X[i2, 2]) / 3.0, G, gp, per, out)


#: Several impacts (docs/solver.md, "Several impacts"): ``gp[IMPACTS]`` = K, then K rows of
#: ``centre (3), reach, radius, block`` (block -1: the base grid), then ``nx`` of the base grid
#: and per extra block ``origin (3), cell, x offset, nx, ny, nz``; the blocks are stacked along
#: the grid's first axis after the base grid.  ``gp`` longer than ``IMPACTS``: several impacts.
IMPACTS = 5
ROWS = IMPACTS + 1
IMPACT_ROW = 6
BLOCK_ROW = 8


@njit(cache=True)
def nearest_impact(x0, x1, x2, gp):
    """Row of the impact nearest to a point in reaches (``gp`` with several impacts)."""
    best = np.inf
    k = 0
    for i in range(int(gp[IMPACTS])):
        b = ROWS + IMPACT_ROW * i
        d = np.sqrt((x0 - gp[b]) ** 2 + (x1 - gp[b + 1]) ** 2 + (x2 - gp[b + 2]) ** 2) / gp[b + 3]
        if d < best:
            best = d
            k = i
    return k


@njit(cache=True)
def radius_at(x0, x1, x2, gp):
    """The shadow radius at a point: ``gp[4]``, or with several impacts the radius of the
    impact nearest to the point in reaches (docs/solver.md, "Several impacts")."""
    if gp.shape[0] <= IMPACTS:
        return gp[4]
    return gp[ROWS + IMPACT_ROW * nearest_impact(x0, x1, x2, gp) + 4]


@njit(cache=True)
def radius_scale(x0, x1, x2, gp):
    """:func:`radius_at` over ``gp[4]``: 1.0 exactly with one shadow radius, so the world
    lengths the rules scale by it are unchanged bit for bit."""
    if gp.shape[0] <= IMPACTS:
        return 1.0
    return radius_at(x0, x1, x2, gp) / gp[4]


@njit(cache=True)
def _block(gp, j):
    """Origin (3), cell, x offset, nx, ny, nz of grid block ``j`` (-1: the base grid)."""
    if j < 0:
        base = ROWS + IMPACT_ROW * int(gp[IMPACTS])
        return gp[0], gp[1], gp[2], gp[3], 0, int(gp[base]), -1, -1
    b = ROWS + IMPACT_ROW * int(gp[IMPACTS]) + 1 + BLOCK_ROW * j
    return (gp[b], gp[b + 1], gp[b + 2], gp[b + 3], int(gp[b + 4]), int(gp[b + 5]),
            int(gp[b + 6]), int(gp[b + 7]))


@njit(cache=True)
def _block_at(x0, x1, x2, G, ox, oy, oz, cs, off, nx, ny, nz, out):
    """Add a block's trilinear value at a point to out[6]."""
    u0 = (x0 - ox) / cs - 0.5
    u1 = (x1 - oy) / cs - 0.5
    u2 = (x2 - oz) / cs - 0.5
    i0 = min(max(int(np.floor(u0)), 0), nx - 2)
    i1 = min(max(int(np.floor(u1)), 0), ny - 2)
    i2 = min(max(int(np.floor(u2)), 0), nz - 2)
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
                    out[q] += w * G[off + i0 + a, i1 + b, i2 + c, q]


@njit(cache=True)
def _blocks_at(x0, x1, x2, G, gp, out):
    """Released stress at a point with several impacts: the sum over the base grid and every
    impact's block (each holds the deposits of the cracks nearest its impact)."""
    n_blocks = 0
    for i in range(int(gp[IMPACTS])):
        n_blocks = max(n_blocks, int(gp[ROWS + IMPACT_ROW * i + 5]) + 1)
    for j in range(-1, n_blocks):
        ox, oy, oz, cs, off, nx, ny, nz = _block(gp, j)
        if ny < 0:
            ny = G.shape[1]
            nz = G.shape[2]
        _block_at(x0, x1, x2, G, ox, oy, oz, cs, off, nx, ny, nz, out)


@njit(cache=True)
def shadow_add(s, p0, p1, p2, amount, n0, n1, n2):
    """Deposit ``amount * n n^T * k(r)`` with a compact kernel around p into the grid of state
    ``s`` (its struct reference).

    ``k(r) = (1 - r²/R²)² / (16 R / 15)`` for ``r < R`` (R = ``gp[4]``, or with several
    impacts that of the impact nearest to p: :func:`radius_at`): its integral across a
    straight line is 1, so a long crack whose segments each deposit ``length x normal stress``
    releases exactly its normal stress on the crack line, fading to nothing at distance R.
    """
    G, gp = s.G, s.gp
    if G.shape[0] < 2:
        return
    if gp.shape[0] > IMPACTS:
        k = nearest_impact(p0, p1, p2, gp)
        row = ROWS + IMPACT_ROW * k
        ox, oy, oz, cs, off, nx, ny, nz = _block(gp, int(gp[row + 5]))
        if ny < 0:
            ny = G.shape[1]
            nz = G.shape[2]
        _deposit(p0, p1, p2, amount, n0, n1, n2, G, ox, oy, oz, cs, gp[row + 4], off, nx, ny,
                 nz)
        return
    cs = gp[3]
    rk = gp[4]
    norm = amount / (16.0 * rk / 15.0)
    lo0 = max(int(np.floor((p0 - rk - gp[0]) / cs)), 0)
    hi0 = min(int(np.floor((p0 + rk - gp[0]) / cs)), G.shape[0] - 1)
    lo1 = max(int(np.floor((p1 - rk - gp[1]) / cs)), 0)
    hi1 = min(int(np.floor((p1 + rk - gp[1]) / cs)), G.shape[1] - 1)
    nx, ny = G.shape[0], G.shape[1]
    if s.period != 0.0:
        # Periodic plate (the grid spans one period): every image of the kernel, cells mod n.
        lo0 = int(np.floor((p0 - rk - gp[0]) / cs))
        hi0 = int(np.floor((p0 + rk - gp[0]) / cs))
        lo1 = int(np.floor((p1 - rk - gp[1]) / cs))
        hi1 = int(np.floor((p1 + rk - gp[1]) / cs))
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
                ii = i % nx
                jj = j % ny
                G[ii, jj, k, 0] += w * t00
                G[ii, jj, k, 1] += w * t01
                G[ii, jj, k, 2] += w * t02
                G[ii, jj, k, 3] += w * t11
                G[ii, jj, k, 4] += w * t12
                G[ii, jj, k, 5] += w * t22


@njit(cache=True)
def _deposit(p0, p1, p2, amount, n0, n1, n2, G, ox, oy, oz, cs, rk, off, nx, ny, nz):
    """:func:`shadow_add` into one block (origin, cell ``cs``, kernel radius ``rk``, first
    row ``off``, dims ``nx, ny, nz``)."""
    norm = amount / (16.0 * rk / 15.0)
    lo0 = max(int(np.floor((p0 - rk - ox) / cs)), 0)
    hi0 = min(int(np.floor((p0 + rk - ox) / cs)), nx - 1)
    lo1 = max(int(np.floor((p1 - rk - oy) / cs)), 0)
    hi1 = min(int(np.floor((p1 + rk - oy) / cs)), ny - 1)
    lo2 = max(int(np.floor((p2 - rk - oz) / cs)), 0)
    hi2 = min(int(np.floor((p2 + rk - oz) / cs)), nz - 1)
    t = (n0 * n0, n0 * n1, n0 * n2, n1 * n1, n1 * n2, n2 * n2)
    for i in range(lo0, hi0 + 1):
        d0 = ox + (i + 0.5) * cs - p0
        for j in range(lo1, hi1 + 1):
            d1 = oy + (j + 0.5) * cs - p1
            for k in range(lo2, hi2 + 1):
                d2 = oz + (k + 0.5) * cs - p2
                r2 = (d0 * d0 + d1 * d1 + d2 * d2) / (rk * rk)
                if r2 >= 1.0:
                    continue
                w = norm * (1.0 - r2) * (1.0 - r2)
                for q in range(6):
                    G[off + i, j, k, q] += w * t[q]


@njit(cache=True)
def _periodic_at(u0, u1, u2, G, out):
    """:func:`shadow_at` on a periodic plate: x and y cells wrap around (grid coordinates)."""
    i0 = int(np.floor(u0))
    i1 = int(np.floor(u1))
    i2 = min(max(int(np.floor(u2)), 0), G.shape[2] - 2)
    w0 = u0 - i0
    w1 = u1 - i1
    w2 = min(max(u2 - i2, 0.0), 1.0)
    nx, ny = G.shape[0], G.shape[1]
    for a in range(2):
        wa = w0 if a else 1.0 - w0
        ia = (i0 + a) % nx
        for b in range(2):
            wb = w1 if b else 1.0 - w1
            ib = (i1 + b) % ny
            for c in range(2):
                w = wa * wb * (w2 if c else 1.0 - w2)
                if w == 0.0:
                    continue
                for q in range(6):
                    out[q] += w * G[ia, ib, i2 + c, q]
