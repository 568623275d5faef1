"""The iben driver: set up the state, run the compiled loop in chunks, collect the result."""

from __future__ import annotations

import logging
import time
from types import SimpleNamespace

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.geometry import shared_edges
from crackbake.simulate.solver import SolverParams, SolverResult
from crackbake.simulate.solver.iben import constants as C
from crackbake.simulate.solver.iben.calibration import (
    flaw,
    footprint_factor,
    percentile_ref,
    shadow_grid,
    surface_wide,
)
from crackbake.simulate.solver.iben.chain import chain
from crackbake.simulate.solver.iben.loop import run
from crackbake.simulate.solver.iben.state import (
    ABORTED,
    BRIDGED,
    CRACKS,
    CROSSED,
    DONE,
    DRIED,
    EVENTS,
    FACES,
    FIRST_CRACK,
    FULL,
    GROWTH_STEPS,
    MORE,
    N_COUNTERS,
    NODES,
    NUC_EDGE,
    NUC_NEAR,
    NUC_VETOED,
    REFRESHED,
    SATURATED,
    SEGS,
    STEP,
    TIPS_NEAR,
    WIDEN,
    LoopParams,
    State,
    grow,
    grown,
    widen,
    work,
)
from crackbake.simulate.solver.iben.update import incidence, rebuild, requeue_all, update_all

logger = logging.getLogger(__name__)


def solve_iben(sim, field, params: SolverParams) -> SolverResult:
    """Grow cracks with the Iben & O'Brien hybrid method (docs/solver.md).

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

    Returns
    -------
    SolverResult
        ``stats`` holds ``tau`` (separation per unit edge length at toughness 1 x toughness),
        ``events``, ``cracks`` (distinct cracks started), ``aborted``, ``growth_steps``,
        ``refreshed`` (lazy heap re-evaluations), ``edge_starts`` (cracks started on a crack
        or the boundary), ``nucleations_vetoed`` (refused by the footprint test),
        ``nucleations_near`` (refused beside an existing crack), ``tips_ended_near`` (by the
        near-crack rule), ``ligaments_broken`` (steps a tip took through a ligament),
        ``shell_crossings`` (cracks carried onto a touching shell, ``loop.cross_shells``),
        ``tips_arrested`` (free tips left below the toughness), ``shadow_radius``,
        ``impact_steps`` (with several impacts, the step each one landed at, in order),
        ``stopped`` (why the run ended: ``max steps``, ``max cracks``, ``saturated`` or
        ``at rest``), ``loop_seconds`` (the crack loop alone), ``seconds``; and
        ``origins``, where and when each crack started and its length.
        Progress goes to this module's logger (INFO, at most every ``PROGRESS_SECONDS``).
    """
    params.validate()
    t0 = time.perf_counter()
    s, mesh = _setup(sim, field, params)
    cal = _calibrate(s, mesh, params)
    cal.sep0 = _relative(s.val[: mesh.n0], s.taun[: mesh.n0])  # before the loop changes them
    stages = _stage_impacts(s, mesh, cal, field, params)
    p = _loop_params(s, mesh, cal, params)
    t_loop = time.perf_counter()
    mesh.landed = [0] if stages else []
    s = _run_chunks(s, p, mesh.has_growth, stages, mesh.landed) if cal.tau > 0 else s
    loop_seconds = time.perf_counter() - t_loop
    return _result(s, mesh, cal, params, loop_seconds, t0)


def _setup(sim, field, params: SolverParams) -> tuple[State, SimpleNamespace]:
    """The initial state: the mesh with room for a few thousand events (grown on demand),
    faces and nodes evaluated; and the initial mesh's own figures."""
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
    room = int(min(params.max_steps, C.INITIAL_ROOM)) + 16
    ncap, mcap, scap = n0 + 10 * room, m0 + 4 * room, 6 * room
    edge, uses = shared_edges(F0, n0)  # the stress field and the star check ask too
    bnd = np.zeros(n0, bool)
    bnd[edge[uses == 1].ravel()] = True
    period = float(getattr(sim, "period", 0.0) or 0.0)
    elen = np.linalg.norm(_wrapped(X0[edge[:, 0]] - X0[edge[:, 1]], period), axis=1)
    hsum = np.bincount(edge.ravel(), np.repeat(elen, 2), minlength=n0)
    hcnt = np.bincount(edge.ravel(), minlength=n0)
    h_node = hsum / np.maximum(hcnt, 1)
    width = int(np.bincount(F0.ravel(), minlength=n0).max()) + C.EXTRA_DEGREE
    G, gp = shadow_grid(X0, period, getattr(field, "shadow_radius", None),
                        getattr(field, "shadow_max", None))
    G, gp = _impact_grids(G, gp, X0, field, period)
    clen = np.zeros(min(1024, room))
    cnt = np.zeros(N_COUNTERS, np.int64)
    cnt[FIRST_CRACK] = -1
    cnt[NODES], cnt[FACES] = n0, m0
    zi = lambda cap: np.zeros(cap, np.int64)  # noqa: E731
    s = State(
        X=grown(X0, ncap), F=grown(F0, mcap), S=grown(S0, mcap),
        AF=grown(np.asarray(sim.asset_face, dtype=np.int64), mcap),
        GR=(grown(np.asarray(growth, dtype=np.float64), mcap) if has_growth
            else np.zeros((1, 3, 3))),
        area=np.zeros(mcap), nrm=np.zeros((mcap, 3)), grad=np.zeros((mcap, 3, 3)),
        pr=np.zeros((mcap, 8)), fst=zi(mcap), NF=np.zeros((ncap, width), np.int64),
        NFc=zi(ncap), rho=np.zeros((ncap, 3, 3)), val=np.zeros(ncap), vec=np.zeros((ncap, 3)),
        taun=np.zeros(ncap), hn=grown(h_node, ncap), pid=np.arange(ncap, dtype=np.int64),
        onb=grown(bnd, ncap), crack_of=np.full(ncap, -1, np.int64), nver=zi(ncap),
        dead=np.zeros(ncap, bool), nonuc=np.zeros(ncap, bool), nst=zi(ncap), nevl=zi(ncap),
        lchk=zi(ncap), tipn=np.zeros((ncap, 3)), segof=np.full(ncap, -1, np.int64),
        pcid=np.full(ncap, -1, np.int64), pdir=np.zeros((ncap, 3)),
        mate=np.concatenate([_mates(X0, F0, float(getattr(sim, "edge_length", 0.0)
                                                  or elen.mean()), period),
                             np.full(ncap - n0, -1, np.int64)]),
        hk=np.zeros(ncap + 65536), hnode=zi(ncap + 65536), hv=zi(ncap + 65536),
        segp=np.zeros((scap, 2), np.int64), seg_alive=np.zeros(scap, bool),
        seg_info=np.zeros((scap, 3)), clen=clen, corig=np.zeros((len(clen), 5)), G=G, gp=gp,
        period=period, gq=_grain_quantum(X0), gn0=int(n0), cnt=cnt,
    )
    incidence(m0, s.F, s.NF, s.NFc)
    mesh = SimpleNamespace(X0=X0, F0=F0, S0=S0, n0=n0, m0=m0, bnd=bnd, h_node=h_node,
                           has_growth=has_growth, seed=params.seed % (1 << 52),
                           asset_face=None)
    _update_all(s, mesh, s.S)
    if np.any(s.area[:m0] <= 0):
        raise CrackbakeError("the simulation mesh has zero-area faces; clean the mesh first")
    return s, mesh


def _grain_quantum(X0: np.ndarray) -> float:
    """The unit initial nodes hash their rest point in (``State.gq``): 2**-24 of the bounding-box
    diagonal, so the grain at a point is the same at any mesh scale, and the same with or
    without other impacts' refined balls (they add no extreme points)."""
    return float(np.linalg.norm(X0.max(0) - X0.min(0)) or 1.0) * 2.0 ** -24


def _mates(X0: np.ndarray, F0: np.ndarray, link: float, period: float = 0.0) -> np.ndarray:
    """Per node, the nearest node of another shell within ``link`` (a sim edge), else -1.

    Separate shells that touch or interpenetrate (a nail on a finger, a plate lying on another)
    crack as one surface: a crack tip at a node with a mate continues on the mate's shell
    (``loop.py::cross_shells``).  One KD-tree pair query over the mesh, at set-up only; a mesh
    of one shell (or a periodic plate) gets no mates.

    Parameters
    ----------
    X0 : (N, 3) float
        Node positions.
    F0 : (M, 3) int
        Faces.
    link : float
        Largest gap bridged, world units.

    Returns
    -------
    (N,) int64
        The mate of each node, -1 where none.
    """
    from crackbake.geometry import shared_shells

    n = len(X0)
    mate = np.full(n, -1, np.int64)
    if period or link <= 0.0 or n == 0:
        return mate
    shell = shared_shells(F0, n)
    if shell.max() == 0:
        return mate
    from scipy.spatial import cKDTree  # only for separate shells: scipy is 0.35 s of imports

    pairs = cKDTree(X0).query_pairs(link, output_type="ndarray")
    pairs = pairs[shell[pairs[:, 0]] != shell[pairs[:, 1]]]
    if len(pairs) == 0:
        return mate
    a = np.concatenate([pairs[:, 0], pairs[:, 1]])
    b = np.concatenate([pairs[:, 1], pairs[:, 0]])
    dist = np.linalg.norm(X0[a] - X0[b], axis=1)
    # Nearest first, ties by index: the same mate whatever order the tree returns pairs in.
    order = np.lexsort((b, dist, a))
    a, b = a[order], b[order]
    first = np.ones(len(a), bool)
    first[1:] = a[1:] != a[:-1]
    mate[a[first]] = b[first]
    return mate


def _wrapped(d: np.ndarray, period: float) -> np.ndarray:
    """Minimum image of the in-plane differences ``d`` (K, 3) on a periodic plate (``period``
    0: ``d`` itself)."""
    if period == 0.0:
        return d
    d = d.copy()
    d[:, :2] -= period * np.floor(d[:, :2] / period + 0.5)
    return d


def _update_all(s: State, mesh: SimpleNamespace, stress: np.ndarray, nn: int | None = None,
                nf: int | None = None) -> None:
    """Recompute the initial (or the first nn / nf) faces and nodes of ``s`` with ``stress``."""
    update_all(s._replace(S=stress), mesh.n0 if nn is None else nn,
               mesh.m0 if nf is None else nf, C.GRAIN, mesh.seed)


def _calibrate(s: State, mesh: SimpleNamespace, params: SolverParams) -> SimpleNamespace:
    """Toughness per node (relative to the initial field, with flaws and the footprint
    factor), and whether the field is localized (docs/solver.md, "Resolution independence")."""
    n0, h_node, bnd = mesh.n0, mesh.h_node, mesh.bnd
    ref = percentile_ref(s.val[:n0] / np.maximum(h_node, 1e-300), bnd)
    if ref == 0.0 and mesh.has_growth:
        # No initial stress: toughness is relative to GROWTH_REF_STEPS steps of growth.
        # The compiled kernels measure it, so the reference is the separation the loop sees.
        _update_all(s, mesh, s.GR)
        ref = C.GROWTH_REF_STEPS * percentile_ref(s.val[:n0] / np.maximum(h_node, 1e-300), bnd)
        _update_all(s, mesh, s.S)
    tau = params.toughness * ref
    norm0 = s.val[:n0] / np.maximum(h_node, 1e-300)
    if ref == 0.0 and mesh.has_growth:
        _update_all(s, mesh, s.GR)
        norm0 = s.val[:n0] / np.maximum(h_node, 1e-300)
        _update_all(s, mesh, s.S)
    fac = flaw(params.seed, mesh.X0) * footprint_factor(mesh.X0, norm0, bnd)
    s.taun[:] = grown(tau * h_node * fac, len(s.taun))
    mesh.fac = fac
    # The near-crack rule is for localized fields only (the footprint factor's criterion).
    return SimpleNamespace(tau=tau, localized=not surface_wide(norm0, bnd))


def _loop_params(s: State, mesh: SimpleNamespace, cal: SimpleNamespace,
                 params: SolverParams) -> LoopParams:
    X0, F0 = mesh.X0, mesh.F0
    radius = float(s.gp[4])
    near_rad = C.NEAR_REL * radius
    nuc_rad = 0.0 if not cal.localized else C.NUC_FOOTPRINT_REL * float(
        np.linalg.norm(X0.max(0) - X0.min(0)))
    # The tip factor's reference step: the edge of an equilateral triangle of a
    # TIP_REF_FACES-face mesh of this surface (about the default simulation's edge length).
    per = s.period
    total_area = 0.5 * float(np.linalg.norm(
        np.cross(_wrapped(X0[F0[:, 1]] - X0[F0[:, 0]], per),
                 _wrapped(X0[F0[:, 2]] - X0[F0[:, 0]], per)), axis=1).sum())
    tip_len = (float(np.sqrt(4.0 * total_area / (np.sqrt(3.0) * C.TIP_REF_FACES)))
               if C.TIP_REF_FACES else 0.0)
    max_len = np.inf if params.max_crack_length is None else float(params.max_crack_length)
    return LoopParams(
        alpha=float(params.tip_factor), rate=float(params.relax_rate),
        nrelax=int(params.relax_steps), max_len=float(max_len),
        snap=float(np.radians(C.SNAP_DEG)), snap_b=float(np.radians(C.SNAP_BOUNDARY_DEG)),
        snap_t=float(C.SNAP_T), rings=int(C.RELAX_RINGS), gain=float(C.SHADOW_GAIN),
        back=float(np.radians(C.BACK_DEG)), tip_first=bool(C.TIP_FIRST), grain=float(C.GRAIN),
        seed=int(mesh.seed), near_rad=float(near_rad),
        near_cos=float(np.cos(np.radians(C.NEAR_PAR_DEG))), nuc_rad=float(nuc_rad),
        dir_len=float(C.DIR_SMOOTH * near_rad), tip_len=tip_len, tip_near=bool(cal.localized),
        lig_rad=float(C.LIGAMENT_REL * radius),
        lig_cos=float(np.cos(np.radians(C.LIGAMENT_CONE_DEG))),
        nuc_any=float(C.RELAX_RINGS * tip_len), max_cracks=int(params.max_cracks),
        max_steps=int(params.max_steps),
    )


def _impact_grids(G: np.ndarray, gp: np.ndarray, X0: np.ndarray, field,
                  period: float) -> tuple[np.ndarray, np.ndarray]:
    """The shadow grid with one block per impact radius, when several impacts ask for
    different radii (docs/solver.md, "Several impacts"); else ``G, gp`` themselves.

    Each crack deposits its release into the block of the impact nearest to it (in reaches),
    with that impact's radius and a cell of a third of it, as it would alone; a face reads the
    sum of all blocks.  The base grid (the smallest radius, finest cells) comes first; the
    layout of ``gp`` is in :mod:`.shadow` (``IMPACT_ROW``, ``BLOCK_ROW``).
    """
    shadows = list(getattr(field, "impact_shadows", None) or [])
    impacts = list(getattr(field, "impacts", None) or [])
    if period > 0.0 or len(shadows) < 2 or len(shadows) != len(impacts) or G.shape[0] < 2:
        return G, gp
    diag = float(np.linalg.norm(X0.max(0) - X0.min(0))) or 1.0
    cap = getattr(field, "shadow_max", None)
    cap = C.SHADOW_REL * diag if cap is None else float(cap)
    radii = [min(float(r), cap) for r in shadows]
    if max(radii) == min(radii):
        return G, gp
    blocks: dict[float, tuple] = {}  # radius -> (block, grid, its gp)
    rows = []
    for imp, r in zip(impacts, radii, strict=True):
        block = -1
        if r > gp[4]:
            if r not in blocks:
                Gk, gpk = shadow_grid(X0, 0.0, r, cap)
                if Gk.shape[1] <= G.shape[1] and Gk.shape[2] <= G.shape[2]:
                    blocks[r] = (len(blocks), Gk, gpk)
            if r in blocks:
                block = blocks[r][0]
            else:
                r = float(gp[4])
        rows.append([*imp["point"], 0.5 * np.pi * float(imp["radius"]), r, float(block)])
    table = [float(len(rows)), *np.asarray(rows, np.float64).ravel(), float(G.shape[0])]
    stacked = [G]
    offset = G.shape[0]
    for _, Gk, gpk in sorted(blocks.values(), key=lambda b: b[0]):
        pad = np.zeros((Gk.shape[0], G.shape[1], G.shape[2], 6))
        pad[:, :Gk.shape[1], :Gk.shape[2]] = Gk
        stacked.append(pad)
        table += [*gpk[:4], float(offset), *(float(x) for x in Gk.shape[:3])]
        offset += Gk.shape[0]
    return np.concatenate(stacked), np.concatenate([gp, np.asarray(table, np.float64)])


def _stage_impacts(s: State, mesh: SimpleNamespace, cal: SimpleNamespace, field,
                   params: SolverParams) -> list[np.ndarray]:
    """Several impacts land one after the other (docs/solver.md, "Several impacts").

    The first impact's share of the stress (and whatever else the field holds) is loaded now;
    the others' are returned, (M0, 3, 3) each in impact order, for :func:`_run_chunks` to add
    once the cracks are at rest.  Each impact's toughness is calibrated on its own share, so a
    star's toughness does not depend on the other impacts; faces are tracked by their initial
    sim face through the splits (``s.AF``, mapped back to the asset in :func:`_result`).
    """
    share = getattr(field, "impact_share", None)
    if share is None or len(share) < 2:
        return []
    share = np.asarray(share, dtype=np.float64)
    n0, m0, h_node, bnd = mesh.n0, mesh.m0, mesh.h_node, mesh.bnd
    loads = [mesh.S0 * share[k][:, None, None] for k in range(len(share))]
    # Per impact the toughness of that impact alone; nodes mix them by their faces' shares.
    tau_node = np.zeros(n0)
    weight = np.zeros(n0)
    count = np.maximum(np.bincount(mesh.F0.ravel(), minlength=n0), 1)
    for k, load in enumerate(loads):
        _update_all(s, mesh, load)
        ref = percentile_ref(s.val[:n0] / np.maximum(h_node, 1e-300), bnd)
        tau_k = params.toughness * ref if ref > 0.0 else cal.tau
        node_share = np.bincount(mesh.F0.ravel(), np.repeat(share[k], 3), minlength=n0) / count
        tau_node += node_share * tau_k
        weight += node_share
    tau_node += np.clip(1.0 - weight, 0.0, None) * cal.tau
    s.taun[:n0] = tau_node * h_node * mesh.fac
    s.S[:m0] = mesh.S0 - sum(loads[1:])
    mesh.asset_face = s.AF[:m0].copy()
    s.AF[:m0] = np.arange(m0)
    _update_all(s, mesh, s.S)
    return loads[1:]


def _run_chunks(s: State, p: LoopParams, has_growth: bool,
                stages: list[np.ndarray] | None = None, landed: list | None = None) -> State:
    """Run the compiled loop to its end in chunks of about a tenth of a second (so progress
    stays responsive without a clock inside the compiled loop); grow the state when full.
    Each of ``stages`` (per initial sim face, through ``s.AF``) is added to the stress once
    the loop is done, and the loop runs on; the step it lands at is appended to ``landed``."""
    stages = list(stages or [])
    rebuild(s, bool(C.TIP_FIRST))
    w = work(s)
    chunk = 64
    last_msg = time.perf_counter()
    while True:
        t_call = time.perf_counter()
        code = run(s, p, w, chunk)
        now = time.perf_counter()
        if code == FULL or code == WIDEN:
            s = grow(s, has_growth) if code == FULL else widen(s, C.EXTRA_DEGREE)
            w = work(s)
            continue
        if code == DRIED:
            nn, nf = int(s.cnt[NODES]), int(s.cnt[FACES])
            update_all(s, nn, nf, p.grain, p.seed)
            requeue_all(s, p.tip_first)
            code = MORE
        if now - t_call < 0.05:
            chunk = min(chunk * 2, 1 << 20)
        elif now - t_call > 0.2:
            chunk = max(chunk // 2, 16)
        if now - last_msg >= C.PROGRESS_SECONDS and code == MORE:
            logger.info("iben: %d crack events, %d cracks, %d/%d steps", s.cnt[EVENTS],
                        s.cnt[CRACKS], s.cnt[STEP], p.max_steps)
            last_msg = now
        if code == DONE and stages and s.cnt[STEP] < p.max_steps:
            nf = int(s.cnt[FACES])
            s.S[:nf] += stages.pop(0)[s.AF[:nf]]
            if landed is not None:
                landed.append(int(s.cnt[STEP]))
            update_all(s, int(s.cnt[NODES]), nf, p.grain, p.seed)
            requeue_all(s, p.tip_first)
            continue
        if code == DONE:
            return s


def _relative(val: np.ndarray, taun: np.ndarray) -> np.ndarray:
    """Separation per node relative to its toughness (0 where it has none)."""
    return np.where(taun > 0, val / np.where(taun > 0, taun, 1.0), 0.0)


def _result(s: State, mesh: SimpleNamespace, cal: SimpleNamespace, params: SolverParams,
            loop_seconds: float, t0: float) -> SolverResult:
    cnt = s.cnt
    nn, nf, ns = int(cnt[NODES]), int(cnt[FACES]), int(cnt[SEGS])
    # Bring every face and node up to date with the final shadow (the heap was lazy).
    _update_all(s, mesh, s.S, nn, nf)
    steps = int(cnt[STEP])
    alive = s.seg_alive[:ns]
    info = s.seg_info[:ns][alive]
    asset_face = s.AF[:nf].copy()
    if mesh.asset_face is not None:  # staged impacts tracked the initial sim faces
        asset_face = mesh.asset_face[asset_face]
        info = info.copy()
        af = info[:, 0].astype(np.int64)
        info[:, 0] = np.where(af >= 0, mesh.asset_face[np.maximum(af, 0)], -1)
    cracks = chain(s.segp[:ns][alive], info, s.X, s.onb, steps, params,
                   mesh.X0, s.period)
    sep = _relative(s.val[:nn], s.taun[:nn])
    pr = s.pr[:nf]
    # Effective stress (what the cracks left): l1 d1 d1^T + l2 d2 d2^T.
    s_final = (pr[:, 0, None, None] * np.einsum("ea,eb->eab", pr[:, 2:5], pr[:, 2:5])
               + pr[:, 1, None, None] * np.einsum("ea,eb->eab", pr[:, 5:8], pr[:, 5:8]))
    ncrack = int(cnt[CRACKS])
    return SolverResult(
        cracks=cracks, vertices=s.X[:nn].copy(), faces=s.F[:nf].copy(),
        asset_face=asset_face, stress_initial=mesh.S0.copy(), stress_final=s_final,
        separation=sep, separation_initial=cal.sep0, steps=steps,
        origins=np.column_stack([s.corig[:ncrack], s.clen[:ncrack]]),
        stats={
            "tau": float(cal.tau),
            "events": int(cnt[EVENTS]),
            "cracks": ncrack,
            "paths": len(cracks),
            "aborted": int(cnt[ABORTED]),
            "growth_steps": int(cnt[GROWTH_STEPS]),
            "stopped": ("max steps" if steps >= params.max_steps
                        else "saturated" if cnt[SATURATED]
                        else "max cracks" if cnt[CRACKS] >= params.max_cracks
                        else "at rest"),
            "refreshed": int(cnt[REFRESHED]),
            "edge_starts": int(cnt[NUC_EDGE]),
            "nucleations_vetoed": int(cnt[NUC_VETOED]),
            "nucleations_near": int(cnt[NUC_NEAR]),
            "tips_ended_near": int(cnt[TIPS_NEAR]),
            "ligaments_broken": int(cnt[BRIDGED]),
            "shell_crossings": int(cnt[CROSSED]),
            "tips_arrested": int(np.count_nonzero(s.crack_of[:nn] >= 0)),
            "shadow_radius": float(s.gp[4]),
            "impact_steps": list(getattr(mesh, "landed", [])),
            "loop_seconds": loop_seconds,
            "seconds": time.perf_counter() - t0,
        },
    )
