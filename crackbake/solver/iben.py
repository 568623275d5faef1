"""The ``iben`` crack solver: Iben & O'Brien, "Generating Surface Crack Patterns" (2006/2009).

Algorithm (../shared/research/method.md §A, gaps resolved as in §B):

1. Setup (once, compiled loops over all faces / nodes): per-face geometry, the principal split of
   the world in-plane stress into tension and compression, per-corner forces
   ``f = -A S± g`` and per-node separation tensors
   ``ς = ½(−m(Σf⁺) + Σm(f⁺) + m(Σf⁻) − Σm(f⁻)) + ρ`` (ρ a persistent residual), their largest
   eigenpair ``(v⁺, n̂⁺)``; failing nodes go into a max-heap with lazy invalidation.
2. Loop (compiled, sequential): pop the node with the largest ``v⁺/τ``; cut the plane through it
   normal to ``n̂⁺`` (projected on the tangent plane) through its triangle fan, splitting the two
   crossed opposite edges or snapping to a vertex when the cut runs within ``SNAP_DEG`` of an edge
   (``SNAP_BOUNDARY_DEG`` when that vertex lies on a crack or the boundary, or ``t`` within
   ``SNAP_T`` of an end); split the node along the cut; recompute forces and ``ς`` of the changed
   1-ring; push ``α(v⁺ − τ) n̂n̂ᵀ`` to the new free tips (not to tips that met a crack or the
   boundary: those cracks are finished); relax the stress ``relax_steps`` times inside
   ``RELAX_RINGS`` rings of the change; re-queue the changed nodes.  The work per step is local,
   so it does not grow with the mesh.
3. Shrinkage growth (``field.growth``) is applied quasi-statically: whenever no node fails, the
   growth is added to every face (one solver step), and the loop resumes.  Drying is slow
   compared with cracking, so cracks run until the field is at rest before it grows again.

Toughness is resolution independent: a node's separation scales with its edge length h, so the
failure test compares ``v⁺ / h_n`` with ``τ = toughness × P90`` where ``P90`` is the 90th
percentile of the initial ``v⁺ / h_n`` over interior nodes with positive separation.  Each node
also gets a seeded flaw factor (±``FLAW`` relative), the material's imperfections.

Known limitation: the relaxation is local in *rings* (so a step costs the same at any mesh size),
so the stress shadow around a crack, and with it the crack spacing, scales with the simulation
edge length: halving it gives about 1.6-1.8x the crack length on the test plates.

Relaxation (method.md §A8 with the stability fix of §B5): per pass, each node inside the region
moves by ``d = relax_rate · F_net / K`` with ``K = Σ A|g|²`` the diagonal stiffness (a damped
Jacobi step of the equilibrium, so the rate is resolution independent), and each face adds
``sym(Σ_i d_i g_iᵀ)``, capped at ``RELAX_CAP`` of its stress norm per pass.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable

import numpy as np
from numba import njit

from crackbake.errors import CrackbakeError
from crackbake.solver import CrackPath, SolverParams, SolverResult
from crackbake.solver.fem import (
    face_frames,
    face_geometry,
    largest_eigen,
    node_forces,
    separation_tensors,
    split_tension,
)
from crackbake.solver.topology import (
    face_update,
    heap_pop,
    heap_push,
    node_update,
    on_boundary,
    separate,
    split_edge,
    spoke_count,
)

SNAP_DEG = 15.0
"""Snap the cut to an existing vertex when it runs within this angle of an edge (degrees)."""
SNAP_BOUNDARY_DEG = 25.0
"""Same, when the vertex lies on a crack or the mesh boundary (ends cracks cleanly there)."""
SNAP_T = 0.12
"""Snap when the crossing is this close (fraction of the edge) to an end: avoids slivers."""
RELAX_RINGS = 3
"""Rings of faces around a crack event that the local relaxation touches."""
RELAX_CAP = 0.1
"""Largest relative change of a face's stress in one relaxation pass."""
REF_PERCENTILE = 90.0
"""Percentile of the initial normalised separation that toughness 1 corresponds to."""
FLAW = 0.25
"""Relative spread of the seeded toughness (material flaws)."""
FLAW_WAVELENGTH = 0.1
"""Flaw wavelength relative to the bounding-box diagonal."""
FLAW_WAVES = 12
GROWTH_REF_STEPS = 20
"""With no initial stress, toughness 1 is the separation of this many growth steps."""
EXTRA_DEGREE = 24
"""Room for faces a node may gain by edge splits around it (node -> face table width)."""

# Indices into the counter array shared by the kernels.
_HEAP, _NN, _NF, _NS, _STEP, _EVENTS, _STAMP, _NCRACK, _ABORT, _GROW = range(10)


@njit(cache=True)
def _setup(nn, nf, X, F, S, area, nrm, grad, fp, fm, NF, NFc, rho, val, vec):
    for f in range(nf):
        for k in range(3):
            n = F[f, k]
            NF[n, NFc[n]] = f
            NFc[n] += 1
    for f in range(nf):
        face_update(f, X, F, S, area, nrm, grad, fp, fm)
    for n in range(nn):
        node_update(n, F, NF, NFc, fp, fm, rho, val, vec)


@njit(cache=True)
def _rebuild_heap(hk, hn, hv, cnt, val, taun, nver, dead):
    cnt[_HEAP] = 0
    for n in range(cnt[_NN]):
        if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
            heap_push(hk, hn, hv, cnt, val[n] / taun[n], n, nver[n])


@njit(cache=True)
def _push(n, hk, hn, hv, cnt, val, taun, nver, dead):
    nver[n] += 1
    if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
        if not heap_push(hk, hn, hv, cnt, val[n] / taun[n], n, nver[n]):
            _rebuild_heap(hk, hn, hv, cnt, val, taun, nver, dead)


@njit(cache=True)
def _angle(u, v):
    nu = np.sqrt(u @ u)
    nv = np.sqrt(v @ v)
    if nu == 0.0 or nv == 0.0:
        return 0.0
    return np.arccos(min(1.0, max(-1.0, (u @ v) / (nu * nv))))


@njit(cache=True)
def _run(X, F, S, AF, GR, area, nrm, grad, fp, fm, NF, NFc, rho, val, vec, taun, hn, pid, onb,
         crack_of, nver, dead, fst, nst, hk, hn_, hv, segp, seg_alive, seg_info, clen, cnt,
         prm, max_events, max_steps, chunk):
    """Advance the crack loop by at most ``chunk`` crack events; returns 1 when finished."""
    alpha, rate, nrelax, max_len = prm[0], prm[1], int(prm[2]), prm[3]
    snap, snap_b, snap_t, rings = prm[4], prm[5], prm[6], int(prm[7])
    W = NF.shape[1]
    ncap = X.shape[0]
    mcap = F.shape[0]
    regf = np.empty(200000, np.int64)
    regn = np.empty(400000, np.int64)
    disp = np.zeros((ncap, 3))
    buf = np.empty(4, np.int64)
    done = 0
    while True:
        if cnt[_EVENTS] >= max_events or cnt[_STEP] >= max_steps:
            return 1
        if done >= chunk:
            return 0
        if cnt[_NN] + 16 > ncap or cnt[_NF] + 8 > mcap or cnt[_NS] + 8 > segp.shape[0]:
            return 1
        if cnt[_HEAP] == 0:
            if GR.shape[0] > 1:
                # Quasi-static shrinkage: nothing fails, so the material dries a step further.
                for f in range(cnt[_NF]):
                    S[f] += GR[f]
                    face_update(f, X, F, S, area, nrm, grad, fp, fm)
                for n in range(cnt[_NN]):
                    node_update(n, F, NF, NFc, fp, fm, rho, val, vec)
                    nver[n] += 1
                _rebuild_heap(hk, hn_, hv, cnt, val, taun, nver, dead)
                cnt[_STEP] += 1
                cnt[_GROW] += 1
                continue
            return 1
        _key, c, ver = heap_pop(hk, hn_, hv, cnt)
        if ver != nver[c] or dead[c] or not val[c] > taun[c]:
            continue
        # ---- crack plane: n-hat projected on the tangent plane; t runs along the crack.
        xc = X[c].copy()
        vn = np.zeros(3)
        for j in range(NFc[c]):
            f = NF[c, j]
            vn += area[f] * nrm[f]
        lvn = np.sqrt(vn @ vn)
        if lvn == 0.0:
            dead[c] = True
            continue
        vn /= lvn
        nc = vec[c] - (vec[c] @ vn) * vn
        lnc = np.sqrt(nc @ nc)
        if lnc < 1e-6:
            dead[c] = True
            continue
        nc /= lnc
        tc = np.cross(vn, nc)
        # ---- the crossed opposite edge on each side (+t, -t).
        sa = np.full(2, -1, np.int64)
        sb = np.full(2, -1, np.int64)
        st = np.zeros(2)
        sd = np.full(2, np.inf)
        for j in range(NFc[c]):
            f = NF[c, j]
            k = 0
            while F[f, k] != c:
                k += 1
            a = F[f, (k + 1) % 3]
            b = F[f, (k + 2) % 3]
            da = (X[a] - xc) @ nc
            db = (X[b] - xc) @ nc
            if da == db or da * db > 0:
                continue
            tt = da / (da - db)
            p = X[a] + tt * (X[b] - X[a])
            along = (p - xc) @ tc
            side = 0 if along > 0 else 1
            dist = np.sqrt((p - xc) @ (p - xc))
            if dist < sd[side]:
                sd[side] = dist
                sa[side] = a
                sb[side] = b
                st[side] = tt
        # ---- snap or split, per side.
        tip = np.full(2, -1, np.int64)
        split = np.zeros(2, np.bool_)
        for side in range(2):
            if sa[side] < 0:
                continue
            a, b, tt = sa[side], sb[side], st[side]
            p = X[a] + tt * (X[b] - X[a])
            ang_a = _angle(p - xc, X[a] - xc)
            ang_b = _angle(p - xc, X[b] - xc)
            thr_a = snap_b if on_boundary(F, NF, NFc, a) else snap
            thr_b = snap_b if on_boundary(F, NF, NFc, b) else snap
            snap_a = ang_a < thr_a or tt < snap_t
            snap_bb = ang_b < thr_b or tt > 1.0 - snap_t
            if snap_a and (not snap_bb or ang_a <= ang_b):
                x = a
            elif snap_bb:
                x = b
            else:
                x = -1
            if x >= 0:
                # Cutting along an edge that is already a crack side or boundary adds nothing.
                if spoke_count(F, NF, NFc, c, x) == 2:
                    tip[side] = x
            else:
                tip[side] = a
                split[side] = True
        if tip[0] >= 0 and tip[1] >= 0 and not split[0] and not split[1] and tip[0] == tip[1]:
            tip[1] = -1
        nt = (tip[0] >= 0) + (tip[1] >= 0)
        interior = not on_boundary(F, NF, NFc, c)
        ok = nt >= (2 if interior else 1)
        # Room in the node -> face table for the faces the splits add.
        if NFc[c] + 2 > W:
            ok = False
        for side in range(2):
            if split[side]:
                a, b = sa[side], sb[side]
                for j in range(NFc[a]):
                    f = NF[a, j]
                    if F[f, 0] == b or F[f, 1] == b or F[f, 2] == b:
                        for q in range(3):
                            if NFc[F[f, q]] + 2 > W:
                                ok = False
        if not ok:
            dead[c] = True
            cnt[_ABORT] += 1
            continue
        for side in range(2):
            if split[side]:
                tip[side] = split_edge(sa[side], sb[side], st[side], X, F, S, AF, GR, NF, NFc,
                                       pid, onb, hn, taun, rho, crack_of, nver, segp,
                                       seg_alive, seg_info, cnt)
        for side in range(2):
            if split[side]:
                # The separation of a node scales with its own edge lengths: measure the new
                # node's, or its fan (smaller than its parents') would make it artificially tough.
                p = tip[side]
                hsum = 0.0
                hcnt = 0
                for j in range(NFc[p]):
                    f = NF[p, j]
                    for q in range(3):
                        if F[f, q] != p:
                            d = X[F[f, q]] - X[p]
                            hsum += np.sqrt(d @ d)
                            hcnt += 1
                if hcnt > 0:
                    scale = (hsum / hcnt) / hn[p]
                    hn[p] *= scale
                    taun[p] *= scale
        # ---- open the crack: split the node along the cut edges.
        nsplit = separate(c, tip[0], tip[1], X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of,
                          nver, cnt, buf)
        if nsplit == 0:
            dead[c] = True
            cnt[_ABORT] += 1
            continue
        cnt[_STAMP] += 1
        stamp = cnt[_STAMP]
        centers = np.full(12, -1, np.int64)
        ncen = 0
        centers[ncen] = c
        ncen += 1
        for q in range(nsplit):
            centers[ncen] = buf[q]
            ncen += 1
        free_tip = np.zeros(2, np.bool_)
        for side in range(2):
            if tip[side] < 0:
                continue
            centers[ncen] = tip[side]
            ncen += 1
            # A tip that lay on a boundary is pinched by the cut: mend it; its crack is finished.
            m = separate(tip[side], -1, -1, X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of,
                         nver, cnt, buf)
            free_tip[side] = m == 0
            for q in range(m):
                if ncen < centers.shape[0]:
                    centers[ncen] = buf[q]
                    ncen += 1
        # ---- record the segments and the crack they extend.
        cid = crack_of[c]
        if cid < 0:
            cid = cnt[_NCRACK]
            cnt[_NCRACK] += 1
        release = val[c] / hn[c]
        excess = val[c] - taun[c]
        crack_of[c] = -1
        for side in range(2):
            t = tip[side]
            if t < 0:
                continue
            af = -1
            for j in range(NFc[t]):
                f = NF[t, j]
                for q in range(3):
                    if pid[F[f, q]] == pid[c]:
                        af = AF[f]
            s = cnt[_NS]
            cnt[_NS] += 1
            segp[s, 0] = pid[c]
            segp[s, 1] = pid[t]
            seg_alive[s] = True
            seg_info[s, 0] = af
            seg_info[s, 1] = cnt[_STEP]
            seg_info[s, 2] = release
            d = X[t] - xc
            clen[cid] += np.sqrt(d @ d)
        # ---- recompute the changed faces and nodes (1-ring of the centres).
        nrf = 0
        for q in range(ncen):
            n = centers[q]
            if q <= nsplit:
                rho[n] = 0.0
            for j in range(NFc[n]):
                f = NF[n, j]
                if fst[f] != stamp:
                    fst[f] = stamp
                    regf[nrf] = f
                    nrf += 1
        for i in range(nrf):
            face_update(regf[i], X, F, S, area, nrm, grad, fp, fm)
        for side in range(2):
            t = tip[side]
            if t >= 0 and free_tip[side]:
                crack_of[t] = cid
                if clen[cid] < max_len:
                    for i in range(3):
                        for j in range(3):
                            rho[t, i, j] += alpha * excess * nc[i] * nc[j]
        # ---- local relaxation: grow the region by rings, then damped Jacobi passes.
        lo = 0
        hi = nrf
        for _ring in range(rings):
            for i in range(lo, hi):
                f = regf[i]
                for q in range(3):
                    n = F[f, q]
                    for j in range(NFc[n]):
                        g = NF[n, j]
                        if fst[g] != stamp and nrf < regf.shape[0]:
                            fst[g] = stamp
                            regf[nrf] = g
                            nrf += 1
            lo = hi
            hi = nrf
        nrn = 0
        for i in range(nrf):
            f = regf[i]
            for q in range(3):
                n = F[f, q]
                if nst[n] != stamp and nrn < regn.shape[0]:
                    nst[n] = stamp
                    regn[nrn] = n
                    nrn += 1
        if nrelax > 0 and rate > 0:
            for _pass in range(nrelax):
                for i in range(nrn):
                    n = regn[i]
                    free = True
                    fn = np.zeros(3)
                    kn = 0.0
                    for j in range(NFc[n]):
                        f = NF[n, j]
                        if fst[f] != stamp:
                            free = False
                            break
                        k = 0
                        while F[f, k] != n:
                            k += 1
                        g = grad[f, k]
                        fn -= area[f] * (S[f] @ g)
                        kn += area[f] * (g @ g)
                    if free and kn > 0:
                        disp[n] = rate * fn / kn
                    else:
                        disp[n] = 0.0
                for i in range(nrf):
                    f = regf[i]
                    nf_ = nrm[f]
                    m = np.zeros((3, 3))
                    for q in range(3):
                        d = disp[F[f, q]]
                        d = d - (d @ nf_) * nf_
                        g = grad[f, q]
                        for a in range(3):
                            for b in range(3):
                                m[a, b] += d[a] * g[b]
                    ds = 0.5 * (m + m.T)
                    nds = np.sqrt(np.sum(ds * ds))
                    ns = np.sqrt(np.sum(S[f] * S[f]))
                    if nds > RELAX_CAP * ns:
                        ds *= RELAX_CAP * ns / nds
                    S[f] += ds
            for i in range(nrn):
                disp[regn[i]] = 0.0
            for i in range(nrf):
                face_update(regf[i], X, F, S, area, nrm, grad, fp, fm)
        else:
            # Without relaxation only the 1-ring changed, but the extra rings are harmless.
            pass
        for i in range(nrn):
            n = regn[i]
            node_update(n, F, NF, NFc, fp, fm, rho, val, vec)
            _push(n, hk, hn_, hv, cnt, val, taun, nver, dead)
        cnt[_STEP] += 1
        cnt[_EVENTS] += 1
        done += 1


def _edges_boundary(faces: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Boundary flag per node (N,) and the unique undirected edges (E, 2)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    bnd = np.zeros(n_nodes, bool)
    bnd[uniq[counts == 1].ravel()] = True
    return bnd, uniq


def _flaw(seed: int, points: np.ndarray) -> np.ndarray:
    """Seeded toughness factors per node, a smooth world-space field in [1 - FLAW, 1 + FLAW].

    The flaws live in world space (a sum of plane waves of wavelength ``FLAW_WAVELENGTH`` x the
    bounding-box diagonal), not per node: cracks then start at the same weak spots whatever the
    simulation resolution, which keeps the crack count resolution independent.
    """
    rng = np.random.default_rng(seed)
    diag = float(np.linalg.norm(points.max(0) - points.min(0))) or 1.0
    k = 2 * np.pi / (FLAW_WAVELENGTH * diag)
    dirs = rng.normal(size=(FLAW_WAVES, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, FLAW_WAVES)
    noise = np.cos(k * points @ dirs.T + phase).sum(1) / np.sqrt(FLAW_WAVES / 2)
    return 1.0 + FLAW * np.tanh(noise)


def _reference_from(X0, F0, stress, h_node, bnd) -> float:
    """REF_PERCENTILE of v+/h over interior nodes for a (tensile) stress field, via fem.py."""
    area, normal, grad = face_geometry(X0, F0)
    plus, minus, _, _ = split_tension(stress, face_frames(normal, X0, F0))
    sep = separation_tensors(F0, node_forces(area, grad, plus), node_forces(area, grad, minus),
                             len(X0))
    v = largest_eigen(sep)[0] / np.maximum(h_node, 1e-300)
    pool = v[(~bnd) & (v > 0)]
    return float(np.percentile(pool, REF_PERCENTILE)) if len(pool) else 0.0


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
    progress : callable(str), optional
        Receives a one-line status now and then.

    Returns
    -------
    SolverResult
        ``stats`` holds ``tau`` (separation per unit edge length at toughness 1 x toughness),
        ``events``, ``cracks`` (crack ids), ``aborted``, ``growth_steps``, ``seconds``.
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
    max_events = int(min(params.max_cracks, params.max_steps))
    ncap = n0 + 10 * max_events + 64
    mcap = m0 + 4 * max_events + 16
    scap = 6 * max_events + 16

    bnd, edges = _edges_boundary(F0, n0)
    elen = np.linalg.norm(X0[edges[:, 0]] - X0[edges[:, 1]], axis=1)
    hsum = np.bincount(edges.ravel(), np.repeat(elen, 2), minlength=n0)
    hcnt = np.bincount(edges.ravel(), minlength=n0)
    h_node = hsum / np.maximum(hcnt, 1)
    deg = np.bincount(F0.ravel(), minlength=n0)
    width = int(deg.max()) + EXTRA_DEGREE

    X = np.zeros((ncap, 3))
    X[:n0] = X0
    F = np.zeros((mcap, 3), np.int64)
    F[:m0] = F0
    S = np.zeros((mcap, 3, 3))
    S[:m0] = S0
    AF = np.zeros(mcap, np.int64)
    AF[:m0] = np.asarray(sim.asset_face, dtype=np.int64)
    GR = np.zeros((mcap if has_growth else 1, 3, 3))
    if has_growth:
        GR[:m0] = np.asarray(growth, dtype=np.float64)
    area = np.zeros(mcap)
    nrm = np.zeros((mcap, 3))
    grad = np.zeros((mcap, 3, 3))
    fp = np.zeros((mcap, 3, 3))
    fm = np.zeros((mcap, 3, 3))
    NF = np.zeros((ncap, width), np.int64)
    NFc = np.zeros(ncap, np.int64)
    rho = np.zeros((ncap, 3, 3))
    val = np.zeros(ncap)
    vec = np.zeros((ncap, 3))
    _setup(n0, m0, X, F, S, area, nrm, grad, fp, fm, NF, NFc, rho, val, vec)
    if np.any(area[:m0] <= 0):
        raise CrackbakeError("the simulation mesh has zero-area faces; clean the mesh first")

    hn = np.zeros(ncap)
    hn[:n0] = h_node
    norm_sep = val[:n0] / np.maximum(h_node, 1e-300)
    ref_pool = norm_sep[(~bnd) & (norm_sep > 0)]
    if len(ref_pool) == 0:
        ref_pool = norm_sep[norm_sep > 0]
    ref = float(np.percentile(ref_pool, REF_PERCENTILE)) if len(ref_pool) else 0.0
    if ref == 0.0 and has_growth:
        # No initial stress: toughness is relative to GROWTH_REF_STEPS steps of growth.
        ref = GROWTH_REF_STEPS * _reference_from(X0, F0, GR[:m0], h_node, bnd)
    tau = params.toughness * ref
    taun = np.zeros(ncap)
    taun[:n0] = tau * h_node * _flaw(params.seed, X0)
    pid = np.arange(ncap, dtype=np.int64)
    onb = np.zeros(ncap, bool)
    onb[:n0] = bnd
    crack_of = np.full(ncap, -1, np.int64)
    nver = np.zeros(ncap, np.int64)
    dead = np.zeros(ncap, bool)
    fst = np.zeros(mcap, np.int64)
    nst = np.zeros(ncap, np.int64)
    hcap = max(ncap, 1 << 16)
    hk = np.zeros(hcap)
    hnode = np.zeros(hcap, np.int64)
    hv = np.zeros(hcap, np.int64)
    segp = np.zeros((scap, 2), np.int64)
    seg_alive = np.zeros(scap, bool)
    seg_info = np.zeros((scap, 3))
    clen = np.zeros(max_events + 2)
    cnt = np.zeros(10, np.int64)
    cnt[_NN], cnt[_NF] = n0, m0
    max_len = np.inf if params.max_crack_length is None else float(params.max_crack_length)
    prm = np.array([
        params.tip_factor, params.relax_rate, params.relax_steps, max_len,
        np.radians(SNAP_DEG), np.radians(SNAP_BOUNDARY_DEG), SNAP_T, RELAX_RINGS,
    ], dtype=np.float64)
    if tau > 0:
        _rebuild_heap(hk, hnode, hv, cnt, val, taun, nver, dead)
    chunk = max(1, max_events // 20)
    while tau > 0:
        finished = _run(X, F, S, AF, GR, area, nrm, grad, fp, fm, NF, NFc, rho, val, vec, taun,
                        hn, pid, onb, crack_of, nver, dead, fst, nst, hk, hnode, hv, segp,
                        seg_alive, seg_info, clen, cnt, prm, max_events, int(params.max_steps),
                        chunk)
        if progress is not None:
            progress(f"iben: {int(cnt[_EVENTS])} crack events, {int(cnt[_STEP])} steps")
        if finished:
            break

    nn, nf, ns = int(cnt[_NN]), int(cnt[_NF]), int(cnt[_NS])
    steps = int(cnt[_STEP])
    alive = seg_alive[:ns]
    cracks = _chain(segp[:ns][alive], seg_info[:ns][alive], X, onb, steps, params, X0)
    sep = np.where(taun[:nn] > 0, val[:nn] / np.where(taun[:nn] > 0, taun[:nn], 1.0), 0.0)
    return SolverResult(
        cracks=cracks,
        vertices=X[:nn].copy(),
        faces=F[:nf].copy(),
        asset_face=AF[:nf].copy(),
        stress_initial=S0.copy(),
        stress_final=S[:nf].copy(),
        separation=sep,
        steps=steps,
        stats={
            "tau": float(tau),
            "events": int(cnt[_EVENTS]),
            "cracks": int(cnt[_NCRACK]),
            "paths": len(cracks),
            "aborted": int(cnt[_ABORT]),
            "growth_steps": int(cnt[_GROW]),
            "seconds": _time.perf_counter() - t0,
        },
    )


def crack_graph(segp: np.ndarray) -> dict[int, list[int]]:
    """Point id -> indices of the segments touching it."""
    adj: dict[int, list[int]] = {}
    for s, (a, b) in enumerate(segp.tolist()):
        adj.setdefault(a, []).append(s)
        adj.setdefault(b, []).append(s)
    return adj


def _chain(segp, info, X, onb, steps, params: SolverParams, X0) -> list[CrackPath]:
    """Chain crack segments into polylines between junctions and ends; width, depth, time.

    Point ``i`` of a path takes the asset face of segment ``i`` (the last point that of the last
    segment): every segment lies in one sim triangle, hence in one asset face, and its start point
    is in that face's closure.
    """
    if len(segp) == 0:
        return []
    adj = crack_graph(segp)
    used = np.zeros(len(segp), bool)
    chains: list[tuple[list[int], list[int]]] = []  # (point ids, segment ids)

    def walk(start_pt: int, s: int) -> tuple[list[int], list[int]]:
        pts, segs = [start_pt], []
        pt = start_pt
        while True:
            used[s] = True
            segs.append(s)
            a, b = segp[s]
            pt = b if a == pt else a
            pts.append(int(pt))
            nxt = [q for q in adj[pt] if not used[q]]
            if len(adj[pt]) != 2 or not nxt:
                return pts, segs
            s = nxt[0]

    for pt in sorted(adj):
        if len(adj[pt]) != 2:
            for s in adj[pt]:
                if not used[s]:
                    chains.append(walk(pt, s))
    for s in range(len(segp)):  # closed loops
        if not used[s]:
            chains.append(walk(int(segp[s][0]), s))

    rel = info[:, 2]
    wmax = float(rel.max()) if len(rel) and rel.max() > 0 else 1.0
    diag = float(np.linalg.norm(X0.max(0) - X0.min(0)))
    width = params.crack_width if params.crack_width is not None else 1e-3 * diag
    total = max(steps, 1)
    out = []
    for pts, segs in chains:
        p = X[np.asarray(pts)]
        sr = rel[segs] / wmax
        w = np.empty(len(pts))
        w[0], w[-1] = sr[0], sr[-1]
        w[1:-1] = 0.5 * (sr[:-1] + sr[1:])
        st = info[segs, 1]
        t = np.empty(len(pts))
        t[0], t[-1] = st[0], st[-1]
        t[1:-1] = np.minimum(st[:-1], st[1:])
        seglen = np.linalg.norm(np.diff(p, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seglen)])
        length = arc[-1]
        taper = max(0.25 * length, 1e-300)
        # Free tips (ends that are neither junctions nor on the mesh boundary) close to zero.
        for end, dist in ((pts[0], arc), (pts[-1], length - arc)):
            if len(adj[end]) == 1 and not onb[end]:
                w = w * np.clip(dist / taper, 0.0, 1.0)
        af = np.empty(len(pts), np.int64)
        af[:-1] = info[segs, 0].astype(np.int64)
        af[-1] = af[-2]
        out.append(CrackPath(points=p, asset_faces=af, time=t / total, width=w, depth=w))
    # The widest point opens exactly crack_width.
    top = max(float(c.width.max()) for c in out)
    scale = width / top if top > 0 else 0.0
    for c in out:
        c.width = c.width * scale
        c.depth = params.depth_ratio * c.width
    return out
