"""Entry point of the thesis method: the once-only FEM set-up, the compiled growth loop, and
the crack paths with their widths (the method is described in
:mod:`crackbake.simulate.solver.thesis`)."""

from __future__ import annotations

import logging
import time as _time

import numpy as np

from crackbake.geometry import vertex_normals
from crackbake.simulate.solver import CrackPath, SolverParams, SolverResult
from crackbake.simulate.solver.fem import (
    face_frames,
    face_geometry,
    node_forces,
    separation_tensors,
    split_tension,
)
from crackbake.simulate.solver.thesis.growth import grow
from crackbake.simulate.solver.thesis.kernels import (
    END_BOUNDARY,
    END_FREE,
    END_JUNCTION,
    adjacency,
)

logger = logging.getLogger(__name__)

#: Steps per crack when ``max_crack_length`` is unset (the thesis' loop count).
DEFAULT_CRACK_STEPS = 25


# --------------------------------------------------------------------------------------------
# Shared helpers (also meant for the iben method and its tests)
# --------------------------------------------------------------------------------------------


def relative_toughness(values: np.ndarray, boundary: np.ndarray, toughness: float) -> float:
    """Absolute failure threshold ``tau`` from the relative ``--toughness``.

    Separation values scale with stress x edge length (docs/method.md, "Resolution"), so ``tau`` is
    given relative to a reference separation of this field on this mesh: the **mean of the positive
    ``v+`` over interior nodes** (the typical value of a loaded node; boundary nodes are left out
    because their unbalanced forces make them unrepresentative, and unloaded nodes because a local
    field such as an impact would otherwise dilute the reference with zeros).

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


def _separation(x: np.ndarray, faces: np.ndarray, stress: np.ndarray):
    """Separation tensors (N, 3, 3) from the initial stress, once (docs/method.md, "The
    formulas"), and their largest eigenvalue (N,), middle eigenvalue (N,) and largest
    eigenvector (N, 3)."""
    area, fnormal, grad = face_geometry(x, faces)
    frames = face_frames(fnormal, x, faces)
    plus, minus, _, _ = split_tension(stress, frames)
    sep = separation_tensors(
        faces, node_forces(area, grad, plus), node_forces(area, grad, minus), len(x)
    )
    sep = np.ascontiguousarray(sep)
    w, vecs = np.linalg.eigh(sep)
    value = np.ascontiguousarray(w[:, 2])
    second = np.ascontiguousarray(w[:, 1])
    vector = np.ascontiguousarray(vecs[:, :, 2])
    return sep, value, second, vector


def _no_cracks():
    """What :func:`grow` returns when nothing can crack."""
    empty = np.zeros(0, dtype=np.int64)
    return (np.zeros(1, dtype=np.int64), empty, empty, np.zeros(0), empty,
            np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64), 0)


def _crack_paths(x, asset_face, params: SolverParams, h: float, crack_ptr, node, order,
                 opening, seg_face, ends, crack_steps) -> list[CrackPath]:
    """One :class:`CrackPath` per grown crack.

    Widths: ``v+`` when the crack passed, tapered at free tips, then normalised so the widest
    point of all cracks gets ``crack_width`` (after the taper, so that width is really reached).
    """
    n = len(x)
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
    return cracks


def solve_thesis(sim, field, params: SolverParams) -> SolverResult:
    """Grow cracks with the MSc-thesis method (:mod:`crackbake.simulate.solver.thesis`).

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

    Returns
    -------
    SolverResult
        One :class:`CrackPath` per crack through sim nodes; the sim mesh and stress unchanged;
        ``separation`` = final ``v+ / tau``.  ``stats`` holds counts, ``tau`` and timings.
        Progress goes to this module's logger.
    """
    params.validate()
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
    sep, value, second, vector = _separation(x, faces, stress)
    tau = relative_toughness(value, boundary, params.toughness)
    normal = vertex_normals(x, faces)
    ptr, nbr, edge_face = adjacency(faces, n)
    t_setup = _time.perf_counter() - t0
    logger.info("thesis solver: %d nodes, %d faces, tau=%.4g", n, len(faces), tau)

    if params.max_crack_length is None:
        steps_per_crack = DEFAULT_CRACK_STEPS
    else:
        steps_per_crack = max(1, int(round(params.max_crack_length / max(h, 1e-300))))
    steps_per_crack = min(steps_per_crack, max(n, 1))

    t1 = _time.perf_counter()
    grown = _no_cracks()
    sep_initial = value / tau if np.isfinite(tau) and tau > 0 else np.zeros(n)  # a copy
    if np.isfinite(tau) and params.max_cracks > 0 and n > 0:
        grown = grow(x, normal, ptr, nbr, edge_face, boundary, sep, value, vector, second,
                     float(tau), float(params.tip_factor), float(params.relax_share),
                     int(params.relax_steps), int(params.max_cracks), int(steps_per_crack),
                     int(params.max_steps), h if h > 0 else 1.0)
    crack_ptr, node, order, opening, seg_face, ends, crack_steps, total = grown
    t_grow = _time.perf_counter() - t1
    cracks = _crack_paths(x, asset_face, params, h, crack_ptr, node, order, opening, seg_face,
                          ends, crack_steps)

    sep_rel = value / tau if np.isfinite(tau) and tau > 0 else np.zeros(n)
    turning = [turning_angle_per_length(c.points) for c in cracks if len(c.points) >= 3]
    stats = {
        "method": "thesis",
        "tau": float(tau),
        "tau_reference": float(tau / params.toughness),
        "cracks": len(cracks),
        "points": int(len(node)),
        "steps_per_crack": int(steps_per_crack),
        "ends_free": int((ends == END_FREE).sum()),
        "ends_junction": int((ends == END_JUNCTION).sum()),
        "ends_boundary": int((ends == END_BOUNDARY).sum()),
        "turning_per_length": float(np.mean(turning)) if turning else 0.0,
        "time_setup_s": t_setup,
        "time_grow_s": t_grow,
    }
    logger.info("thesis solver: %d cracks, %d steps in %.2f s", len(cracks), int(total),
                t_setup + t_grow)
    return SolverResult(
        cracks=cracks,
        vertices=x,
        faces=faces,
        asset_face=asset_face,
        stress_initial=stress,
        stress_final=stress,
        separation=sep_rel,
        separation_initial=sep_initial,
        steps=int(total),
        stats=stats,
    )
