"""``--method thesis``: the 2023 NCCA MSc variant (Tan-Mulligan) of Iben & O'Brien's cracks.

What it does (method.md §C, with the published file's defects fixed):

1. Node forces and separation tensors are computed **once** from the initial stress
   (:mod:`crackbake.simulate.solver.fem`; the radial/hoop field and its unit vectors are the stress
   module's business, and the compressive terms of the separation tensor carry their correct
   signs there).  Each node gets its largest eigenvalue ``v+`` and eigenvector ``n+``.
2. A crack starts at the un-cracked node with the largest ``v+`` (if it exceeds the toughness
   ``tau``) and grows **both ends to the end**, alternating one step per end: each step moves to
   the neighbouring vertex (over the welded sim edges) best aligned with the crack heading; there
   is no remeshing, so cracks follow mesh edges and look jagged, as the thesis says.
3. The old tip's ``v+`` is reduced by ``tau``; the new tip's separation tensor gets
   ``tip_factor * (v+ - tau) * o o^T`` with ``o`` the crack's opening direction (the heading
   turned 90 degrees in the tangent plane, i.e. the tip's ``n+`` of Iben & O'Brien §A7), and its
   ``v+``/``n+`` are re-evaluated at once (the shipped file only refreshed them after the loop).
4. A tip stops at the mesh boundary, on reaching a node of an earlier crack (a T-junction: it
   steps there and ends), when its node's ``v+ <= tau``, or when the crack has used its step
   budget (``max_crack_length / edge_length`` steps, 25 like the thesis when unset).
5. Between cracks, scalar relaxation of ``v+``: each pass a node keeps ``(1 - relax_share) v+``
   and shares the rest equally with its neighbours, ``relax_steps`` passes, restricted to the
   nodes within ``relax_steps`` rings of the new crack so a crack costs O(its length), not
   O(mesh).  Eigenvectors are not relaxed (as in the thesis).
6. Up to ``max_cracks`` cracks, ``max_steps`` tip steps in all.

Two small deviations from the thesis, both to keep cracks on course without remeshing: the
heading is blended towards the local eigenvector's perpendicular in proportion to the tensor's
anisotropy (an isotropic tensor's eigenvector is noise), and the step choice corrects the
sideways drift that accumulates from snapping to edges (aim point back on the ideal line).

The stress field is unchanged by this method; ``separation`` is the final ``v+ / tau``.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable

import numpy as np
from numba import njit

from crackbake.errors import CrackbakeError
from crackbake.simulate.solver import CrackPath, SolverParams, SolverResult
from crackbake.simulate.solver.fem import (
    face_frames,
    face_geometry,
    node_forces,
    separation_tensors,
    split_tension,
)

#: Steps per crack when ``max_crack_length`` is unset (the thesis' loop count).
DEFAULT_CRACK_STEPS = 25

# End kinds of a crack tip (stats and width taper).
END_FREE, END_JUNCTION, END_BOUNDARY = 0, 1, 2

_BLOCK = 256  # nodes per block of the blocked arg-max (start-node selection)


# --------------------------------------------------------------------------------------------
# Shared helpers (also meant for the iben method and its tests)
# --------------------------------------------------------------------------------------------


def relative_toughness(values: np.ndarray, boundary: np.ndarray, toughness: float) -> float:
    """Absolute failure threshold ``tau`` from the relative ``--toughness``.

    Separation values scale with stress x edge length (method.md §B2), so ``tau`` is given
    relative to a reference separation of this field on this mesh: the **mean of the positive
    ``v+`` over interior nodes** (the typical value of a loaded node; boundary nodes are left out
    because their unbalanced forces make them unrepresentative, and unloaded nodes because a
    local field such as an impact would otherwise dilute the reference with zeros).

    Parameters
    ----------
    values : (N,) float64
        Largest separation eigenvalue per node (force units).
    boundary : (N,) bool
        Mesh-boundary nodes.
    toughness : float
        Relative toughness (``SolverParams.toughness``); 1 means "a typical loaded node".

    Returns
    -------
    float
        ``tau`` in the units of ``values``; ``inf`` when no node is loaded (nothing can fail).
    """
    values = np.asarray(values, dtype=np.float64)
    boundary = np.asarray(boundary, dtype=bool)
    loaded = values[(~boundary) & (values > 0)]
    if loaded.size == 0:  # e.g. a mesh that is all boundary: fall back to every node
        loaded = values[values > 0]
    if loaded.size == 0:
        return float("inf")
    return float(toughness) * float(loaded.mean())


def turning_angle_per_length(points: np.ndarray) -> float:
    """Mean turning angle per unit length of a polyline, radians per mesh unit.

    Sum of the absolute angles between consecutive segments divided by the total length: 0 for a
    straight line, about ``pi / (2 h)`` for a staircase of edge length ``h``.  Zero-length segments
    are skipped.

    Parameters
    ----------
    points : (N, 3) float64
        Polyline vertices, mesh units.

    Returns
    -------
    float
        Radians per mesh unit (0 for fewer than 3 points or zero length).
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        return 0.0
    seg = np.diff(p, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 0
    seg, length = seg[keep], length[keep]
    total = float(length.sum())
    if len(seg) < 2 or total <= 0:
        return 0.0
    unit = seg / length[:, None]
    cosang = np.clip(np.einsum("ia,ia->i", unit[:-1], unit[1:]), -1.0, 1.0)
    return float(np.arccos(cosang).sum() / total)


# --------------------------------------------------------------------------------------------
# Mesh helpers
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _adjacency(faces: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, (N, 3); bincount is much faster than ``np.add.at``."""
    p = vertices[faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # 2 A n
    n = len(vertices)
    idx = faces.reshape(-1)
    out = np.empty((n, 3))
    for a in range(3):
        out[:, a] = np.bincount(idx, weights=np.repeat(cross[:, a], 3), minlength=n)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return out / np.where(norm > 0, norm, 1.0)


# --------------------------------------------------------------------------------------------
# The sequential growth loop
# --------------------------------------------------------------------------------------------


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
def _grow(
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
    out_node = np.empty(cap, dtype=np.int64)
    out_order = np.empty(cap, dtype=np.int64)
    out_open = np.empty(cap)
    out_face = np.empty(cap, dtype=np.int64)
    crack_ptr = np.zeros(max_cracks + 1, dtype=np.int64)
    ends = np.zeros((max_cracks, 2), dtype=np.int64)
    crack_steps = np.zeros(max_cracks, dtype=np.int64)

    # Per-end buffers for the crack being grown.
    buf_node = np.empty((2, steps_per_crack + 1), dtype=np.int64)
    buf_order = np.empty((2, steps_per_crack + 1), dtype=np.int64)
    buf_open = np.empty((2, steps_per_crack + 1))
    buf_len = np.zeros(2, dtype=np.int64)

    # Relaxation work space: BFS stamp, region list, per-node delta.
    stamp = np.zeros(n, dtype=np.int64)
    region = np.empty(n, dtype=np.int64)
    delta = np.zeros(n)

    n_out = 0
    n_cracks = 0
    total_steps = 0
    heading = np.zeros((2, 3))
    drift = np.zeros(2)
    pending = np.zeros(2)
    alive = np.zeros(2, dtype=np.bool_)
    tip = np.zeros(2, dtype=np.int64)
    end_kind = np.zeros(2, dtype=np.int64)

    attempt = 0
    while n_cracks < max_cracks and total_steps < max_steps:
        attempt += 1
        # --- start node: un-cracked node with the largest v+ (blocked arg-max) ---
        for b in range(n_blocks):
            if dirty[b]:
                _refresh_block(b, n, value, cracked, block_max, block_arg)
                dirty[b] = False
        best_b = np.argmax(block_max)
        if block_max[best_b] <= tau:
            break  # no node fails any more
        s = block_arg[best_b]

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
                    continue
                j = best
                step_vec = x[j] - x[c]
                drift[e] += step_vec[0] * side[0] + step_vec[1] * side[1] + step_vec[2] * side[2]
                steps += 1
                total_steps += 1
                k = buf_len[e]
                buf_node[e, k] = j
                buf_order[e, k] = steps
                buf_len[e] = k + 1
                tip[e] = j
                if cracked[j]:
                    # T-junction (an earlier crack, or this one's other end): end here.
                    buf_open[e, k] = np.nan
                    alive[e] = False
                    end_kind[e] = END_JUNCTION
                    continue
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
                # New heading: towards the local eigenvector's perpendicular, weighted by how
                # anisotropic the tensor is (an isotropic tensor's eigenvector is noise).
                tj, tjl = _unit(_cross(normal[j], vec))
                if tjl > 0 and lam > 0:
                    if tj[0] * d[0] + tj[1] * d[1] + tj[2] * d[2] < 0:
                        tj = -tj
                    aniso = min(max((lam - lam2) / lam, 0.0), 1.0)
                    nd = d + aniso * tj
                else:
                    nd = d.copy()
                nd = (
                    nd
                    - (nd[0] * normal[j, 0] + nd[1] * normal[j, 1] + nd[2] * normal[j, 2])
                    * normal[j]
                )
                nd, ndl = _unit(nd)
                if ndl > 0:
                    heading[e] = nd
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

        npts = 1 + buf_len[0] + buf_len[1]
        if npts >= 2:
            # Polyline: end 1 (reversed) ... start ... end 0.
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
            n_out = p
            ends[n_cracks, 0] = end_kind[1] if buf_len[1] > 0 else END_FREE
            ends[n_cracks, 1] = end_kind[0] if buf_len[0] > 0 else END_FREE
            if buf_len[1] == 0 and boundary[s]:
                ends[n_cracks, 0] = END_BOUNDARY
            if buf_len[0] == 0 and boundary[s]:
                ends[n_cracks, 1] = END_BOUNDARY
            crack_steps[n_cracks] = steps
            n_cracks += 1
            crack_ptr[n_cracks] = n_out
        # (a start node that could not move stays cracked and is simply not reported)

        # --- local scalar relaxation of v+ around this crack ---
        if relax_steps > 0 and relax_share > 0 and npts >= 1:
            mark = attempt
            n_reg = 0
            first = n_out - npts if npts >= 2 else 0
            if npts >= 2:
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
            for _ring in range(relax_steps):
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
            for _pass in range(relax_steps):
                for r in range(n_reg):
                    i = region[r]
                    deg = ptr[i + 1] - ptr[i]
                    if deg == 0:
                        continue
                    give = relax_share * value[i]
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

    return (
        crack_ptr[: n_cracks + 1],
        out_node[:n_out],
        out_order[:n_out],
        out_open[:n_out],
        out_face[:n_out],
        ends[:n_cracks],
        crack_steps[:n_cracks],
        total_steps,
    )


# --------------------------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------------------------


def _taper(
    points: np.ndarray, width: np.ndarray, free_first: bool, free_last: bool, length: float
) -> np.ndarray:
    """Scale widths linearly to 0 over ``length`` (mesh units) from each free end."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    ramp = min(length, 0.5 * total) if total > 0 else 0.0
    scale = np.ones(len(points))
    if ramp > 0:
        if free_first:
            scale = np.minimum(scale, s / ramp)
        if free_last:
            scale = np.minimum(scale, (total - s) / ramp)
    else:
        if free_first:
            scale[0] = 0.0
        if free_last:
            scale[-1] = 0.0
    return width * np.clip(scale, 0.0, 1.0)


def solve_thesis(
    sim,
    field,
    params: SolverParams,
    progress: Callable[[str], None] | None = None,
) -> SolverResult:
    """Grow cracks with the MSc-thesis method (module docstring).

    Parameters
    ----------
    sim : SimMesh
        ``vertices (N, 3)``, ``faces (M, 3)``, ``asset_face (M,)``, ``boundary (N,)``,
        ``edge_length`` (mean sim edge, mesh units).
    field : StressField
        ``stress (M, 3, 3)``: world-space in-plane stress per sim face, tension positive.
        ``growth``/``weight``/``impacts`` are not used by this method (the field never evolves).
    params : SolverParams
        Uses ``toughness``, ``tip_factor``, ``relax_share``, ``relax_steps``, ``max_cracks``,
        ``max_steps``, ``max_crack_length``, ``crack_width``, ``depth_ratio``.  ``relax_rate`` and
        ``seed`` are unused: the method is deterministic (ties go to the lowest node index).
    progress : callable, optional
        Called with short status messages.

    Returns
    -------
    SolverResult
        One :class:`CrackPath` per crack through sim nodes; the sim mesh and stress unchanged;
        ``separation`` = final ``v+ / tau``.  ``stats`` holds counts, ``tau`` and timings.
    """
    say = progress or (lambda _msg: None)
    if not params.toughness > 0:
        raise CrackbakeError(f"toughness must be > 0 (got {params.toughness}); try 1")
    for name in ("tip_factor", "relax_share"):
        if not 0.0 <= getattr(params, name) <= 1.0:
            raise CrackbakeError(f"{name} must be in 0..1 (got {getattr(params, name)})")
    t0 = _time.perf_counter()
    x = np.ascontiguousarray(sim.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(sim.faces, dtype=np.int64)
    # The compiled loop does no bounds checks: refuse bad indices here rather than crash there.
    if faces.size and (faces.min() < 0 or faces.max() >= len(x)):
        raise ValueError("sim.faces index outside sim.vertices")
    asset_face = np.asarray(sim.asset_face, dtype=np.int64)
    boundary = np.ascontiguousarray(sim.boundary, dtype=np.bool_)
    stress = np.asarray(field.stress, dtype=np.float64)
    n = len(x)
    h = float(sim.edge_length)

    # Forces and separation tensors, once (method.md §A3-A5).
    area, fnormal, grad = face_geometry(x, faces)
    frames = face_frames(fnormal, x, faces)
    plus, minus, _, _ = split_tension(stress, frames)
    sep = separation_tensors(
        faces, node_forces(area, grad, plus), node_forces(area, grad, minus), n
    )
    sep = np.ascontiguousarray(sep)
    w, vecs = np.linalg.eigh(sep)
    value = np.ascontiguousarray(w[:, 2])
    second = np.ascontiguousarray(w[:, 1])
    vector = np.ascontiguousarray(vecs[:, :, 2])
    tau = relative_toughness(value, boundary, params.toughness)
    normal = _vertex_normals(x, faces)
    ptr, nbr, edge_face = _adjacency(faces, n)
    t_setup = _time.perf_counter() - t0
    say(f"thesis solver: {n} nodes, {len(faces)} faces, tau={tau:.4g}")

    if params.max_crack_length is None:
        steps_per_crack = DEFAULT_CRACK_STEPS
    else:
        steps_per_crack = max(1, int(round(params.max_crack_length / max(h, 1e-300))))
    steps_per_crack = min(steps_per_crack, max(n, 1))

    t1 = _time.perf_counter()
    if np.isfinite(tau) and params.max_cracks > 0 and n > 0:
        crack_ptr, node, order, opening, seg_face, ends, crack_steps, total = _grow(
            x,
            normal,
            ptr,
            nbr,
            edge_face,
            boundary,
            sep,
            value,
            vector,
            second,
            float(tau),
            float(params.tip_factor),
            float(params.relax_share),
            int(params.relax_steps),
            int(params.max_cracks),
            int(steps_per_crack),
            int(params.max_steps),
            h if h > 0 else 1.0,
        )
    else:
        crack_ptr = np.zeros(1, dtype=np.int64)
        node = order = seg_face = np.zeros(0, dtype=np.int64)
        opening = np.zeros(0)
        ends = np.zeros((0, 2), dtype=np.int64)
        crack_steps = np.zeros(0, dtype=np.int64)
        total = 0
    t_grow = _time.perf_counter() - t1

    # Widths: v+ when the crack passed, tapered at free tips, then normalised so the widest
    # point of all cracks gets crack_width (after the taper, so that width is really reached).
    lo, hi = x.min(axis=0) if n else np.zeros(3), x.max(axis=0) if n else np.zeros(3)
    width_max = (
        params.crack_width
        if params.crack_width is not None
        else 1e-3 * float(np.linalg.norm(hi - lo))
    )
    n_cracks = len(crack_ptr) - 1
    raw: list[np.ndarray] = []
    for k in range(n_cracks):
        a, b = crack_ptr[k], crack_ptr[k + 1]
        op = opening[a:b].copy()
        # A T-junction end did not crack with this crack: it takes its neighbour's opening.
        if not np.isfinite(op[0]):
            op[0] = op[1] if len(op) > 1 else 0.0
        if not np.isfinite(op[-1]):
            op[-1] = op[-2] if len(op) > 1 else 0.0
        op = np.where(np.isfinite(op), np.maximum(op, 0.0), 0.0)
        raw.append(
            _taper(x[node[a:b]], op, ends[k, 0] == END_FREE, ends[k, 1] == END_FREE, 4.0 * h)
        )
    ref = max((float(r.max()) for r in raw), default=0.0)
    cracks: list[CrackPath] = []
    for k in range(n_cracks):
        a, b = crack_ptr[k], crack_ptr[k + 1]
        width = width_max * raw[k] / ref if ref > 0 else np.zeros(b - a)
        steps_k = max(int(crack_steps[k]), 1)
        tm = (k + order[a:b] / (steps_k + 1.0)) / n_cracks
        cracks.append(
            CrackPath(
                points=x[node[a:b]].copy(),
                asset_faces=asset_face[seg_face[a:b]],
                time=tm.astype(np.float64),
                width=width,
                depth=params.depth_ratio * width,
            )
        )

    sep_rel = value / tau if np.isfinite(tau) and tau > 0 else np.zeros(n)
    turning = [turning_angle_per_length(c.points) for c in cracks if len(c.points) >= 3]
    stats = {
        "method": "thesis",
        "tau": float(tau),
        "tau_reference": float(tau / params.toughness),
        "cracks": n_cracks,
        "points": int(len(node)),
        "steps_per_crack": int(steps_per_crack),
        "ends_free": int((ends == END_FREE).sum()),
        "ends_junction": int((ends == END_JUNCTION).sum()),
        "ends_boundary": int((ends == END_BOUNDARY).sum()),
        "turning_per_length": float(np.mean(turning)) if turning else 0.0,
        "time_setup_s": t_setup,
        "time_grow_s": t_grow,
    }
    say(f"thesis solver: {n_cracks} cracks, {int(total)} steps in {t_setup + t_grow:.2f} s")
    return SolverResult(
        cracks=cracks,
        vertices=x,
        faces=faces,
        asset_face=asset_face,
        stress_initial=stress,
        stress_final=stress,
        separation=sep_rel,
        steps=int(total),
        stats=stats,
    )
