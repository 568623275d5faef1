"""The iben driver: set up the state, run the compiled loop in chunks, collect the result."""

from __future__ import annotations

import time as _time
from collections.abc import Callable

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.simulate.solver import SolverParams, SolverResult
from crackbake.simulate.solver.iben import constants as C
from crackbake.simulate.solver.iben.calibration import (
    _flaw,
    _footprint_factor,
    _percentile_ref,
    _shadow_grid,
    _surface_wide,
)
from crackbake.simulate.solver.iben.chain import _chain
from crackbake.simulate.solver.iben.constants import (
    _ABORT,
    _BRIDGE,
    _DONE,
    _EVENTS,
    _FIRST,
    _FULL,
    _GROW,
    _MORE,
    _NCRACK,
    _NF,
    _NN,
    _NS,
    _NUC_EDGE,
    _NUC_NEAR,
    _NUC_VETO,
    _REFRESH,
    _SATURATED,
    _STEP,
    _TIP_NEAR,
    BACK_DEG,
    DIR_SMOOTH,
    EXTRA_DEGREE,
    GRAIN,
    GROWTH_REF_STEPS,
    LIGAMENT_CONE_DEG,
    LIGAMENT_REL,
    NEAR_PAR_DEG,
    NEAR_REL,
    NUC_FOOTPRINT_REL,
    PROGRESS_SECONDS,
    RELAX_RINGS,
    SHADOW_GAIN,
    SNAP_BOUNDARY_DEG,
    SNAP_DEG,
    SNAP_T,
    TIP_FIRST,
    TIP_REF_FACES,
)
from crackbake.simulate.solver.iben.loop import _run
from crackbake.simulate.solver.iben.state import _RUN_ORDER, _grow, _grown
from crackbake.simulate.solver.iben.update import _incidence, _rebuild_heap, _update_all


def solve_iben(
    sim, field, params: SolverParams, progress: Callable[[str], None] | None = None
) -> SolverResult:
    """Grow cracks with the Iben & O'Brien hybrid method (see the module docstring).

    Parameters
    ----------
    sim : SimMesh-like
        ``vertices (N, 3)`` float64, ``faces (M, 3)`` int64, ``asset_face (M,)`` int64; a
        triangulated 2-manifold surface, possibly with boundary.
    field : StressField-like
        ``stress (M, 3, 3)`` world in-plane stress per face (tension positive); ``growth``
        ``(M, 3, 3)`` or None, added per quasi-static growth step.
    params : SolverParams
        ``max_cracks`` bounds the distinct cracks started, ``max_steps`` the solver steps.
    progress : callable(str), optional
        Receives a one-line status at most every ``PROGRESS_SECONDS``.

    Returns
    -------
    SolverResult
        ``stats`` holds ``tau`` (separation per unit edge length at toughness 1 x toughness),
        ``events``, ``cracks`` (distinct cracks started), ``aborted``, ``growth_steps``,
        ``refreshed`` (lazy heap re-evaluations), ``edge_starts`` (cracks started on a crack
        or the boundary), ``nucleations_vetoed`` (refused by the footprint test),
        ``nucleations_near`` (refused beside an existing crack), ``tips_ended_near`` (by the
        near-crack rule), ``ligaments_broken`` (steps a tip took through a ligament,
        :func:`_bridge`), ``tips_arrested`` (free tips left below the toughness),
        ``shadow_radius``, ``stopped`` (why the run ended: ``max steps``, ``max cracks``,
        ``saturated`` or ``at rest``), ``loop_seconds`` (the crack loop alone),
        ``seconds``; and
        ``origins``, where and when each crack started and its length.
    """
    _check(params)
    t0 = _time.perf_counter()
    X0 = np.ascontiguousarray(sim.vertices, dtype=np.float64)
    F0 = np.ascontiguousarray(sim.faces, dtype=np.int64)
    S0 = np.ascontiguousarray(field.stress, dtype=np.float64)
    n0, m0 = len(X0), len(F0)
    if m0 == 0 or S0.shape != (m0, 3, 3):
        raise CrackbakeError(
            f"stress field has shape {S0.shape} for {m0} simulation faces; rebuild the field"
        )
    growth = getattr(field, "growth", None)
    has_growth = growth is not None and bool(np.any(growth))
    # Initial room for a few thousand events; _grow doubles it on demand.
    room = int(min(params.max_steps, C.INITIAL_ROOM)) + 16
    ncap = n0 + 10 * room
    mcap = m0 + 4 * room
    scap = 6 * room

    bnd, edges = _edges_boundary(F0, n0)
    elen = np.linalg.norm(X0[edges[:, 0]] - X0[edges[:, 1]], axis=1)
    hsum = np.bincount(edges.ravel(), np.repeat(elen, 2), minlength=n0)
    hcnt = np.bincount(edges.ravel(), minlength=n0)
    h_node = hsum / np.maximum(hcnt, 1)
    deg = np.bincount(F0.ravel(), minlength=n0)
    width = int(deg.max()) + EXTRA_DEGREE

    st: dict = {}
    st["X"] = _grown(X0, ncap)
    st["F"] = _grown(F0, mcap)
    st["S"] = _grown(S0, mcap)
    st["AF"] = _grown(np.asarray(sim.asset_face, dtype=np.int64), mcap)
    st["GR"] = (_grown(np.asarray(growth, dtype=np.float64), mcap) if has_growth
                else np.zeros((1, 3, 3)))
    st["area"] = np.zeros(mcap)
    st["nrm"] = np.zeros((mcap, 3))
    st["grad"] = np.zeros((mcap, 3, 3))
    st["pr"] = np.zeros((mcap, 8))
    st["fst"] = np.zeros(mcap, np.int64)
    st["NF"] = np.zeros((ncap, width), np.int64)
    st["NFc"] = np.zeros(ncap, np.int64)
    st["rho"] = np.zeros((ncap, 3, 3))
    st["val"] = np.zeros(ncap)
    st["vec"] = np.zeros((ncap, 3))
    st["crack_of"] = np.full(ncap, -1, np.int64)
    st["tipn"] = np.zeros((ncap, 3))
    G, gp = _shadow_grid(X0)
    st["G"], st["gp"] = G, gp
    _incidence(m0, st["F"], st["NF"], st["NFc"])
    gseed = params.seed % (1 << 52)

    def update_all(nn: int, nf: int, stress: np.ndarray) -> None:
        _update_all(nn, nf, st["X"], st["F"], stress, st["area"], st["nrm"], st["grad"],
                    st["pr"], st["NF"], st["NFc"], st["rho"], st["val"], st["vec"],
                    st["crack_of"], G, gp, GRAIN, gseed, st["tipn"])

    update_all(n0, m0, st["S"])
    if np.any(st["area"][:m0] <= 0):
        raise CrackbakeError("the simulation mesh has zero-area faces; clean the mesh first")

    val = st["val"]
    st["hn"] = _grown(h_node, ncap)
    ref = _percentile_ref(val[:n0] / np.maximum(h_node, 1e-300), bnd)
    if ref == 0.0 and has_growth:
        # No initial stress: toughness is relative to GROWTH_REF_STEPS steps of growth.
        # The compiled kernels measure it, so the reference is the separation the loop sees.
        update_all(n0, m0, st["GR"])
        ref = GROWTH_REF_STEPS * _percentile_ref(val[:n0] / np.maximum(h_node, 1e-300), bnd)
        update_all(n0, m0, st["S"])
    tau = params.toughness * ref
    norm0 = val[:n0] / np.maximum(h_node, 1e-300)
    if ref == 0.0 and has_growth:
        update_all(n0, m0, st["GR"])
        norm0 = val[:n0] / np.maximum(h_node, 1e-300)
        update_all(n0, m0, st["S"])
    fac = _flaw(params.seed, X0) * _footprint_factor(X0, norm0, bnd)
    # The near-crack rule is for localized fields only (the footprint factor's criterion).
    localized = not _surface_wide(norm0, bnd)
    near_rad = NEAR_REL * float(gp[4])
    nuc_rad = 0.0 if not localized else NUC_FOOTPRINT_REL * float(
        np.linalg.norm(X0.max(0) - X0.min(0)))
    st["taun"] = _grown(tau * h_node * fac, ncap)
    # The tip factor's reference step: the edge of an equilateral triangle of a
    # TIP_REF_FACES-face mesh of this surface (about the default simulation's edge length).
    total_area = 0.5 * float(np.linalg.norm(
        np.cross(X0[F0[:, 1]] - X0[F0[:, 0]], X0[F0[:, 2]] - X0[F0[:, 0]]), axis=1).sum())
    tip_len = (float(np.sqrt(4.0 * total_area / (np.sqrt(3.0) * TIP_REF_FACES)))
               if TIP_REF_FACES else 0.0)
    st["pid"] = np.arange(ncap, dtype=np.int64)
    st["onb"] = _grown(bnd, ncap)
    for k in ("nver", "nst", "nevl", "lchk"):
        st[k] = np.zeros(ncap, np.int64)
    st["dead"] = np.zeros(ncap, bool)
    st["nonuc"] = np.zeros(ncap, bool)
    st["segof"] = np.full(ncap, -1, np.int64)
    st["pcid"] = np.full(ncap, -1, np.int64)
    st["pdir"] = np.zeros((ncap, 3))
    hcap = ncap + 65536
    st["hk"] = np.zeros(hcap)
    st["hnode"] = np.zeros(hcap, np.int64)
    st["hv"] = np.zeros(hcap, np.int64)
    st["segp"] = np.zeros((scap, 2), np.int64)
    st["seg_alive"] = np.zeros(scap, bool)
    st["seg_info"] = np.zeros((scap, 3))
    st["clen"] = np.zeros(min(1024, room))
    st["corig"] = np.zeros((len(st["clen"]), 5))
    cnt = np.zeros(20, np.int64)
    cnt[_FIRST] = -1
    cnt[_NN], cnt[_NF] = n0, m0
    st["cnt"] = cnt
    max_len = np.inf if params.max_crack_length is None else float(params.max_crack_length)
    st["prm"] = np.array([
        params.tip_factor, params.relax_rate, params.relax_steps, max_len,
        np.radians(SNAP_DEG), np.radians(SNAP_BOUNDARY_DEG), SNAP_T, RELAX_RINGS, SHADOW_GAIN,
        np.radians(BACK_DEG), float(TIP_FIRST), GRAIN, float(gseed),
        near_rad, np.cos(np.radians(NEAR_PAR_DEG)), nuc_rad, DIR_SMOOTH * near_rad,
        tip_len, float(localized), LIGAMENT_REL * float(gp[4]),
        np.cos(np.radians(LIGAMENT_CONE_DEG)),
    ], dtype=np.float64)
    if tau > 0:
        _rebuild_heap(st["hk"], st["hnode"], st["hv"], cnt, val, st["taun"], st["nver"],
                      st["dead"], st["crack_of"], TIP_FIRST)
    # Chunks are sized so a call takes about a tenth of a second: progress stays responsive
    # without a clock inside the compiled loop.
    chunk = 64
    last_msg = t_loop = _time.perf_counter()
    while tau > 0:
        t_call = _time.perf_counter()
        code = _run(*(st[k] for k in _RUN_ORDER), int(params.max_cracks),
                    int(params.max_steps), chunk)
        now = _time.perf_counter()
        if code == _FULL:
            _grow(st, has_growth)
            continue
        if now - t_call < 0.05:
            chunk = min(chunk * 2, 1 << 20)
        elif now - t_call > 0.2:
            chunk = max(chunk // 2, 16)
        if progress is not None and now - last_msg >= PROGRESS_SECONDS and code == _MORE:
            progress(f"iben: {int(cnt[_EVENTS])} crack events, {int(cnt[_NCRACK])} cracks, "
                     f"{int(cnt[_STEP])}/{params.max_steps} steps")
            last_msg = now
        if code == _DONE:
            break

    loop_seconds = _time.perf_counter() - t_loop
    nn, nf, ns = int(cnt[_NN]), int(cnt[_NF]), int(cnt[_NS])
    # Bring every face and node up to date with the final shadow (the heap was lazy).
    update_all(nn, nf, st["S"])
    steps = int(cnt[_STEP])
    alive = st["seg_alive"][:ns]
    X, taun, val = st["X"], st["taun"], st["val"]
    cracks = _chain(st["segp"][:ns][alive], st["seg_info"][:ns][alive], X, st["onb"], steps,
                    params, X0)
    sep = np.where(taun[:nn] > 0, val[:nn] / np.where(taun[:nn] > 0, taun[:nn], 1.0), 0.0)
    pr = st["pr"][:nf]
    # Effective stress (what the cracks left): l1 d1 d1^T + l2 d2 d2^T.
    s_final = (pr[:, 0, None, None] * np.einsum("ea,eb->eab", pr[:, 2:5], pr[:, 2:5])
               + pr[:, 1, None, None] * np.einsum("ea,eb->eab", pr[:, 5:8], pr[:, 5:8]))
    return SolverResult(
        cracks=cracks,
        vertices=X[:nn].copy(),
        faces=st["F"][:nf].copy(),
        asset_face=st["AF"][:nf].copy(),
        stress_initial=S0.copy(),
        stress_final=s_final,
        separation=sep,
        steps=steps,
        origins=np.column_stack([st["corig"][: int(cnt[_NCRACK])],
                                 st["clen"][: int(cnt[_NCRACK])]]),
        stats={
            "tau": float(tau),
            "events": int(cnt[_EVENTS]),
            "cracks": int(cnt[_NCRACK]),
            "paths": len(cracks),
            "aborted": int(cnt[_ABORT]),
            "growth_steps": int(cnt[_GROW]),
            "stopped": ("max steps" if steps >= params.max_steps
                        else "saturated" if cnt[_SATURATED]
                        else "max cracks" if cnt[_NCRACK] >= params.max_cracks
                        else "at rest"),
            "refreshed": int(cnt[_REFRESH]),
            "edge_starts": int(cnt[_NUC_EDGE]),
            "nucleations_vetoed": int(cnt[_NUC_VETO]),
            "nucleations_near": int(cnt[_NUC_NEAR]),
            "tips_ended_near": int(cnt[_TIP_NEAR]),
            "ligaments_broken": int(cnt[_BRIDGE]),
            "tips_arrested": int(np.count_nonzero(st["crack_of"][:nn] >= 0)),
            "shadow_radius": float(gp[4]),
            "loop_seconds": loop_seconds,
            "seconds": _time.perf_counter() - t0,
        },
    )


def _edges_boundary(faces: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Boundary flag per node (N,) and the unique undirected edges (E, 2)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    # One int64 key per edge: a 1-D unique is far faster than np.unique(axis=0).
    key = e[:, 0] * np.int64(n_nodes) + e[:, 1]
    uniq, counts = np.unique(key, return_counts=True)
    edges = np.stack([uniq // n_nodes, uniq % n_nodes], axis=1)
    bnd = np.zeros(n_nodes, bool)
    bnd[edges[counts == 1].ravel()] = True
    return bnd, edges
def _check(params: SolverParams) -> None:
    if not params.toughness > 0:
        raise CrackbakeError(f"toughness is {params.toughness}; it must be > 0 (try 1.0)")
    if not 0 <= params.tip_factor <= 1:
        raise CrackbakeError(f"tip factor is {params.tip_factor}; it must be in [0, 1] (try 0.75)")
    if params.relax_steps < 0 or not params.relax_rate >= 0:
        raise CrackbakeError("relax steps and relax rate must be >= 0 (try 3 and 0.1)")
    if params.max_cracks < 0 or params.max_steps < 0:
        raise CrackbakeError("max cracks and max steps must be >= 0")
    if params.max_crack_length is not None and not params.max_crack_length > 0:
        raise CrackbakeError(
            f"max crack length is {params.max_crack_length}; it must be > 0 mesh units"
        )
    if params.crack_width is not None and not params.crack_width > 0:
        raise CrackbakeError(f"crack width is {params.crack_width}; it must be > 0 mesh units")
    if not params.depth_ratio >= 0:
        raise CrackbakeError(f"depth ratio is {params.depth_ratio}; it must be >= 0")
