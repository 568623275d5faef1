"""Compiled kernels of the thesis method: welded adjacency and the sequential growth loop.

:func:`grow` grows cracks one after another (the method in
:mod:`crackbake.simulate.solver.thesis`); its stages are named ``@njit`` helpers: picking the
start node (a blocked arg-max), one tip step, writing a finished polyline, and the local scalar
relaxation of ``v+`` around it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# End kinds of a crack tip (stats and width taper).
END_FREE, END_JUNCTION, END_BOUNDARY = 0, 1, 2

_BLOCK = 256  # nodes per block of the blocked arg-max (start-node selection)


@njit(cache=True)
def adjacency(faces: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Welded vertex adjacency (CSR) and, per directed edge, the lowest incident face index.

    Returns ``(ptr (N+1,), nbr (E,), edge_face (E,))``; the neighbours of node ``i`` are
    ``nbr[ptr[i]:ptr[i+1]]``.  Faces are visited in order, so the first face recorded for an edge
    is its lowest-index face: one consistent choice for both directions.
    """
    m = faces.shape[0]
    cap = np.zeros(n_nodes + 1, dtype=np.int64)
    for e in range(m):
        for k in range(3):
            cap[faces[e, k] + 1] += 2  # each corner brings two edges (upper bound on degree)
    for i in range(n_nodes):
        cap[i + 1] += cap[i]
    tmp_nbr = np.empty(cap[n_nodes], dtype=np.int64)
    tmp_face = np.empty(cap[n_nodes], dtype=np.int64)
    deg = np.zeros(n_nodes, dtype=np.int64)
    for e in range(m):
        for k in range(3):
            a = faces[e, k]
            for o in (1, 2):
                b = faces[e, (k + o) % 3]
                base = cap[a]
                found = False
                for s in range(deg[a]):
                    if tmp_nbr[base + s] == b:
                        found = True
                        break
                if not found:
                    tmp_nbr[base + deg[a]] = b
                    tmp_face[base + deg[a]] = e
                    deg[a] += 1
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    for i in range(n_nodes):
        ptr[i + 1] = ptr[i] + deg[i]
    nbr = np.empty(ptr[n_nodes], dtype=np.int64)
    edge_face = np.empty(ptr[n_nodes], dtype=np.int64)
    for i in range(n_nodes):
        for s in range(deg[i]):
            nbr[ptr[i] + s] = tmp_nbr[cap[i] + s]
            edge_face[ptr[i] + s] = tmp_face[cap[i] + s]
    return ptr, nbr, edge_face


@njit(cache=True)
def _unit(a: np.ndarray) -> tuple[np.ndarray, float]:
    n = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n > 0:
        return a / n, n
    return a * 0.0, 0.0


@njit(cache=True)
def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


@njit(cache=True)
def _eigen(sep: np.ndarray, i: int) -> tuple[float, float, np.ndarray]:
    """Largest, middle eigenvalue and the largest's unit eigenvector of node ``i``'s tensor."""
    w, vec = np.linalg.eigh(np.ascontiguousarray(sep[i]))
    return w[2], w[1], vec[:, 2].copy()


@njit(cache=True)
def _edge_face(ptr: np.ndarray, nbr: np.ndarray, edge_face: np.ndarray, a: int, b: int) -> int:
    for s in range(ptr[a], ptr[a + 1]):
        if nbr[s] == b:
            return edge_face[s]
    return -1


@njit(cache=True)
def _refresh_block(
    b: int,
    n: int,
    value: np.ndarray,
    cracked: np.ndarray,
    block_max: np.ndarray,
    block_arg: np.ndarray,
) -> None:
    best = -np.inf
    arg = -1
    for i in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
        if not cracked[i] and value[i] > best:
            best = value[i]
            arg = i
    block_max[b] = best
    block_arg[b] = arg



@njit(cache=True)
def _pick_start(n, value, cracked, dirty, block_max, block_arg, tau: float) -> int:
    """Un-cracked node with the largest ``v+`` above ``tau``, or -1 (blocked arg-max)."""
    for b in range(len(dirty)):
        if dirty[b]:
            _refresh_block(b, n, value, cracked, block_max, block_arg)
            dirty[b] = False
    best_b = np.argmax(block_max)
    if block_max[best_b] <= tau:
        return -1  # no node fails any more
    return block_arg[best_b]


@njit(cache=True)
def _step_tip(e, order, x, normal, ptr, nbr, boundary, sep, value, vector, second, cracked,
              dirty, adjust, tips, bufs, tau: float, tip_factor: float, h: float) -> bool:
    """Move end ``e`` one vertex along its heading; False when it has nowhere to go.

    ``tips`` = (heading, drift, pending, alive, tip, end_kind), ``bufs`` = (node, order,
    opening, length) of the crack being grown; ``order`` is the step number of the new point.
    """
    heading, drift, pending, alive, tip, end_kind = tips
    buf_node, buf_order, buf_open, buf_len = bufs
    c = tip[e]
    d = heading[e]
    side, _ = _unit(_cross(normal[c], d))
    # Aim back towards the ideal line to cancel the drift from snapping to edges.
    corr = min(max(drift[e] / h, -1.0), 1.0)
    aim, _ = _unit(d - corr * side)
    best = -1
    best_cos = 0.0  # only forward neighbours (within 90 degrees)
    for q in range(ptr[c], ptr[c + 1]):
        j = nbr[q]
        if boundary[c] and boundary[j]:
            continue  # a crack along the mesh boundary would open nothing
        w, wl = _unit(x[j] - x[c])
        if wl <= 0:
            continue
        cs = w[0] * aim[0] + w[1] * aim[1] + w[2] * aim[2]
        if cs > best_cos:
            best_cos = cs
            best = j
    if best < 0:
        alive[e] = False
        return False
    j = best
    step_vec = x[j] - x[c]
    drift[e] += step_vec[0] * side[0] + step_vec[1] * side[1] + step_vec[2] * side[2]
    k = buf_len[e]
    buf_node[e, k] = j
    buf_order[e, k] = order
    buf_len[e] = k + 1
    tip[e] = j
    if cracked[j]:
        # T-junction (an earlier crack, or this one's other end): end here.
        buf_open[e, k] = np.nan
        alive[e] = False
        end_kind[e] = END_JUNCTION
        return True
    # Residual to the new tip along the opening direction, then re-evaluate it.
    o, ol = _unit(_cross(normal[j], d))
    amount = tip_factor * pending[e]
    if ol > 0 and amount > 0:
        for a in range(3):
            for bb in range(3):
                sep[j, a, bb] += amount * o[a] * o[bb]
    lam, lam2, vec = _eigen(sep, j)
    value[j] = lam + adjust[j]
    second[j] = lam2
    vector[j] = vec
    cracked[j] = True
    dirty[j // _BLOCK] = True
    buf_open[e, k] = value[j]
    heading[e] = _new_heading(d, normal[j], vec, lam, lam2, heading[e])
    if boundary[j]:
        alive[e] = False
        end_kind[e] = END_BOUNDARY
    elif value[j] <= tau:
        alive[e] = False
        end_kind[e] = END_FREE
    else:
        pending[e] = value[j] - tau
        value[j] -= tau
        adjust[j] -= tau
    return True


@njit(cache=True)
def _new_heading(d, nj, vec, lam: float, lam2: float, old):
    """Heading after a step: towards the local eigenvector's perpendicular, weighted by how
    anisotropic the tensor is (an isotropic tensor's eigenvector is noise); ``old`` when that
    leaves nothing in the tangent plane."""
    tj, tjl = _unit(_cross(nj, vec))
    if tjl > 0 and lam > 0:
        if tj[0] * d[0] + tj[1] * d[1] + tj[2] * d[2] < 0:
            tj = -tj
        aniso = min(max((lam - lam2) / lam, 0.0), 1.0)
        nd = d + aniso * tj
    else:
        nd = d.copy()
    nd = nd - (nd[0] * nj[0] + nd[1] * nj[1] + nd[2] * nj[2]) * nj
    nd, ndl = _unit(nd)
    if ndl > 0:
        return nd
    return old


@njit(cache=True)
def _write_polyline(s, start_open, bufs, end_kind, boundary, ptr, nbr, edge_face, outs,
                    n_out, ends, crack_steps, crack_ptr, n_cracks, steps) -> int:
    """Append crack ``n_cracks`` (end 1 reversed ... start ... end 0) to the output arrays
    ``outs`` = (node, order, opening, seg_face); returns the new output length."""
    buf_node, buf_order, buf_open, buf_len = bufs
    out_node, out_order, out_open, out_face = outs
    base = n_out
    p = base
    for k in range(buf_len[1] - 1, -1, -1):
        out_node[p] = buf_node[1, k]
        out_order[p] = buf_order[1, k]
        out_open[p] = buf_open[1, k]
        p += 1
    out_node[p] = s
    out_order[p] = 0
    out_open[p] = start_open
    p += 1
    for k in range(buf_len[0]):
        out_node[p] = buf_node[0, k]
        out_order[p] = buf_order[0, k]
        out_open[p] = buf_open[0, k]
        p += 1
    for q in range(base, p - 1):
        out_face[q] = _edge_face(ptr, nbr, edge_face, out_node[q], out_node[q + 1])
    out_face[p - 1] = out_face[p - 2]
    ends[n_cracks, 0] = end_kind[1] if buf_len[1] > 0 else END_FREE
    ends[n_cracks, 1] = end_kind[0] if buf_len[0] > 0 else END_FREE
    if buf_len[1] == 0 and boundary[s]:
        ends[n_cracks, 0] = END_BOUNDARY
    if buf_len[0] == 0 and boundary[s]:
        ends[n_cracks, 1] = END_BOUNDARY
    crack_steps[n_cracks] = steps
    crack_ptr[n_cracks + 1] = p
    return p


@njit(cache=True)
def _relax_region(mark, first, n_out, s, out_node, stamp, region, ptr, nbr, rings) -> int:
    """Nodes within ``rings`` rings of the crack ``out_node[first:n_out]`` (or of node ``s``
    when ``first == n_out``) into ``region``, stamped ``mark``; returns their count."""
    n_reg = 0
    if first < n_out:
        for q in range(first, n_out):
            i = out_node[q]
            if stamp[i] != mark:
                stamp[i] = mark
                region[n_reg] = i
                n_reg += 1
    else:
        stamp[s] = mark
        region[0] = s
        n_reg = 1
    lo = 0
    for _ring in range(rings):
        hi = n_reg
        for r in range(lo, hi):
            i = region[r]
            for q in range(ptr[i], ptr[i + 1]):
                j = nbr[q]
                if stamp[j] != mark:
                    stamp[j] = mark
                    region[n_reg] = j
                    n_reg += 1
        lo = hi
    return n_reg


@njit(cache=True)
def _relax(region, n_reg, ptr, nbr, value, adjust, delta, dirty, passes, share_rate) -> None:
    """Scalar relaxation of ``v+`` over ``region``: each pass a node keeps
    ``(1 - share_rate) v+`` and shares the rest equally with its neighbours."""
    for _pass in range(passes):
        for r in range(n_reg):
            i = region[r]
            deg = ptr[i + 1] - ptr[i]
            if deg == 0:
                continue
            give = share_rate * value[i]
            delta[i] -= give
            share = give / deg
            for q in range(ptr[i], ptr[i + 1]):
                delta[nbr[q]] += share
        # Jacobi update: apply to the region and its one-ring, then clear.
        for r in range(n_reg):
            i = region[r]
            for q in range(ptr[i], ptr[i + 1] + 1):
                y = i if q == ptr[i + 1] else nbr[q]
                dl = delta[y]
                if dl != 0.0:
                    value[y] += dl
                    adjust[y] += dl
                    delta[y] = 0.0
                    dirty[y // _BLOCK] = True
