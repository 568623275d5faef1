"""The sequential growth loop of the thesis method, compiled (stages in
:mod:`crackbake.simulate.solver.thesis.kernels`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.thesis.kernels import (
    _BLOCK,
    END_FREE,
    _cross,
    _pick_start,
    _relax,
    _relax_region,
    _step_tip,
    _unit,
    _write_polyline,
)


@njit(cache=True, nogil=True)
def grow(
    x: np.ndarray,
    normal: np.ndarray,
    ptr: np.ndarray,
    nbr: np.ndarray,
    edge_face: np.ndarray,
    boundary: np.ndarray,
    sep: np.ndarray,
    value: np.ndarray,
    vector: np.ndarray,
    second: np.ndarray,
    tau: float,
    tip_factor: float,
    relax_share: float,
    relax_steps: int,
    max_cracks: int,
    steps_per_crack: int,
    max_steps: int,
    h: float,
):
    """Grow cracks one after another; ``sep``, ``value``, ``vector``, ``second`` are updated.

    Returns
    -------
    crack_ptr : (K+1,) int64
        Points of crack ``k`` are ``crack_ptr[k]:crack_ptr[k+1]`` in the arrays below.
    node : (P,) int64
        Sim node of each point, in polyline order (end 1 ... start ... end 0).
    order : (P,) int64
        Step of the crack at which the point cracked (start 0).
    opening : (P,) float64
        ``v+`` of the node when the crack passed (before the ``tau`` reduction); NaN for a
        T-junction end, which did not crack with this crack.
    seg_face : (P,) int64
        Sim face of the segment leaving each point (last point: its incoming segment).
    ends : (K, 2) int64
        End kind (END_*) of the polyline's first and last point.
    steps : (K,) int64
        Steps taken per crack.
    total_steps : int
    """
    n = x.shape[0]
    cracked = np.zeros(n, dtype=np.bool_)
    adjust = np.zeros(n)  # scalar changes of v+ not carried by the tensor (relaxation, -tau)
    n_blocks = (n + _BLOCK - 1) // _BLOCK
    block_max = np.empty(n_blocks)
    block_arg = np.empty(n_blocks, dtype=np.int64)
    dirty = np.ones(n_blocks, dtype=np.bool_)

    cap = min(max_cracks * (steps_per_crack + 2), n + 2 * max_cracks, max_steps + 2 * max_cracks)
    cap = max(cap, 1)
    outs = (np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap),
            np.empty(cap, dtype=np.int64))  # node, order, opening, seg_face
    crack_ptr = np.zeros(max_cracks + 1, dtype=np.int64)
    ends = np.zeros((max_cracks, 2), dtype=np.int64)
    crack_steps = np.zeros(max_cracks, dtype=np.int64)
    # Per-end buffers for the crack being grown: node, order, opening, length.
    bufs = (np.empty((2, steps_per_crack + 1), dtype=np.int64),
            np.empty((2, steps_per_crack + 1), dtype=np.int64),
            np.empty((2, steps_per_crack + 1)), np.zeros(2, dtype=np.int64))
    # Relaxation work space: BFS stamp, region list, per-node delta.
    stamp = np.zeros(n, dtype=np.int64)
    region = np.empty(n, dtype=np.int64)
    delta = np.zeros(n)
    # Per-end tip state: heading, drift, pending excess, alive, tip node, end kind.
    tips = (np.zeros((2, 3)), np.zeros(2), np.zeros(2), np.zeros(2, dtype=np.bool_),
            np.zeros(2, dtype=np.int64), np.zeros(2, dtype=np.int64))
    heading, drift, pending, alive, tip, end_kind = tips
    buf_len = bufs[3]

    n_out = 0
    n_cracks = 0
    total_steps = 0
    attempt = 0
    while n_cracks < max_cracks and total_steps < max_steps:
        attempt += 1
        s = _pick_start(n, value, cracked, dirty, block_max, block_arg, tau)
        if s < 0:
            break
        # Crack direction: perpendicular to the separation eigenvector in the tangent plane.
        t, tl = _unit(_cross(normal[s], vector[s]))
        if tl < 1e-9:  # eigenvector along the normal (degenerate): any tangent will do
            t, tl = _unit(x[nbr[ptr[s]]] - x[s])
        cracked[s] = True
        dirty[s // _BLOCK] = True
        excess = value[s] - tau
        value[s] -= tau
        adjust[s] -= tau
        for e in range(2):
            heading[e] = t if e == 0 else -t
            drift[e] = 0.0
            pending[e] = excess
            alive[e] = True
            tip[e] = s
            end_kind[e] = END_FREE
            buf_len[e] = 0
        start_open = excess + tau
        steps = 0
        if boundary[s]:
            # A crack starting on the mesh boundary grows inwards only: growing both ways
            # would leave the boundary node inside the crack.
            inward = np.zeros(3)
            for q in range(ptr[s], ptr[s + 1]):
                inward += x[nbr[q]] - x[s]
            d0 = heading[0][0] * inward[0] + heading[0][1] * inward[1] + heading[0][2] * inward[2]
            alive[1 if d0 >= 0 else 0] = False

        while (alive[0] or alive[1]) and steps < steps_per_crack and total_steps < max_steps:
            for e in range(2):
                if not alive[e] or steps >= steps_per_crack or total_steps >= max_steps:
                    continue
                if _step_tip(e, steps + 1, x, normal, ptr, nbr, boundary, sep, value, vector,
                             second, cracked, dirty, adjust, tips, bufs, tau, tip_factor, h):
                    steps += 1
                    total_steps += 1

        npts = 1 + buf_len[0] + buf_len[1]
        if npts >= 2:
            n_out = _write_polyline(s, start_open, bufs, end_kind, boundary, ptr, nbr, edge_face,
                                    outs, n_out, ends, crack_steps, crack_ptr, n_cracks, steps)
            n_cracks += 1
        # (a start node that could not move stays cracked and is simply not reported)

        # --- local scalar relaxation of v+ around this crack ---
        if relax_steps > 0 and relax_share > 0 and npts >= 1:
            first = n_out - npts if npts >= 2 else n_out
            n_reg = _relax_region(attempt, first, n_out, s, outs[0], stamp, region, ptr, nbr,
                                  relax_steps)
            _relax(region, n_reg, ptr, nbr, value, adjust, delta, dirty, relax_steps, relax_share)

    return (
        crack_ptr[: n_cracks + 1],
        outs[0][:n_out],
        outs[1][:n_out],
        outs[2][:n_out],
        outs[3][:n_out],
        ends[:n_cracks],
        crack_steps[:n_cracks],
        total_steps,
    )
