"""The compiled crack loop of the iben solver (docs/solver.md, "The loop").

:func:`run` advances the loop by a chunk of steps.  A step is either a growth step (nothing
fails: the material dries a step further) or a crack event at the most critical node:
:func:`pick` it, cut it (:mod:`crackbake.simulate.solver.iben.cut`), :func:`record` the
segments and cast their shadow, :func:`update_ring`, :func:`end_near_tips`,
:func:`push_residual`, relax the region, :func:`update_region` and :func:`cross_shells`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.constants import CROSS_CLEAR, GROWTH_REF_STEPS
from crackbake.simulate.solver.iben.cut import (
    choose_tips,
    crack_plane,
    crossings,
    drop_back_cuts,
    has_room,
    normal_stress,
    open_node,
    split_tips,
)
from crackbake.simulate.solver.iben.element import face_update
from crackbake.simulate.solver.iben.heap import heap_pop
from crackbake.simulate.solver.iben.relax import region, relax
from crackbake.simulate.solver.iben.rules import bridge, footprint_fails, near_other, smooth_dir
from crackbake.simulate.solver.iben.separation import node_update
from crackbake.simulate.solver.iben.shadow import radius_scale, shadow_add
from crackbake.simulate.solver.iben.state import (
    ABORTED,
    BRIDGED,
    CRACKS,
    CROSSED,
    DEPOSITS,
    DONE,
    DRIED,
    EVENTS,
    FACES,
    FIRST_CRACK,
    FULL,
    GROWTH_STEPS,
    HEAP,
    IDLE,
    MORE,
    NODES,
    NUC_EDGE,
    NUC_NEAR,
    NUC_VETOED,
    REFRESHED,
    SATURATED,
    SEGS,
    STAMP,
    STEP,
    TIPS_NEAR,
    WIDEN,
)
from crackbake.simulate.solver.iben.structs import state_ref, work_ref
from crackbake.simulate.solver.iben.update import key, push
from crackbake.simulate.solver.iben.vec import dot3, norm3, wrap
from crackbake.simulate.solver.topology import on_boundary

_WIDEN = 2  # crack_event: the table needs widening
# Constants passed to other kernels are numpy scalars: a plain -1 or True is typed as a literal,
# and numba compiles the callee once more for it (node_update three times: 9 % of the I&O
# kernels' compile time).
_NO_CRACK = np.int64(-1)


@njit(cache=True, nogil=True)
def run(s, p, w, chunk):
    """Advance the crack loop on state ``s`` (a State) with parameters ``p`` (LoopParams) and
    scratch ``w`` (a Work) by at most ``chunk`` steps; see :func:`loop`."""
    return loop(state_ref(s), p, work_ref(w), chunk)


@njit(cache=True, inline="always")
def loop(s, p, w, chunk):
    """Advance the crack loop on state ``s`` (its struct reference) by at most ``chunk`` steps.

    Returns ``MORE`` (chunk done), ``DONE`` (finished), ``DRIED`` (a drying step grew the
    stress: recompute faces and nodes, re-queue them and call again), ``FULL`` (the state
    arrays need more room: grow them and call again) or ``WIDEN`` (the node -> face table is
    too narrow for the next event: widen it and call again).
    """
    cnt = s.cnt
    done = 0
    while True:
        if cnt[STEP] >= p.max_steps:
            return DONE
        if done >= chunk:
            return MORE
        if (cnt[NODES] + 32 > s.X.shape[0] or cnt[FACES] + 16 > s.F.shape[0]
                or cnt[SEGS] + 16 > s.segp.shape[0] or cnt[CRACKS] + 2 > s.clen.shape[0]):
            return FULL
        if cnt[HEAP] == 0 and p.lig_rad > 0:
            bridge_arrested(s, p, w)
        if cnt[HEAP] == 0:
            # With the crack budget spent and the field at rest, more drying would only
            # lengthen existing cracks step after step: stop.
            return DRIED if dry(s, p) else DONE
        c = pick(s, p, w)
        if c >= 0:
            event = crack_event(s, p, w, c)
            if event == _WIDEN:
                return WIDEN
            done += event


@njit(cache=True, inline="always")
def _node_update(s, w, p, n, raw):
    node_update(s, n, raw, p.grain, p.seed, w.sc, w.acc, w.ev)


@njit(cache=True, inline="always")
def _update_faces(s, w, faces, count):
    """Recompute ``faces[:count]``."""
    fr, r6 = w.fr, w.r6
    for i in range(count):
        face_update(s, faces[i], fr, r6)


@njit(cache=True, inline="always")
def _scale(s, n):
    """The shadow radius at node ``n`` over the grid's (1.0 with one radius): the world
    lengths of the rules follow the nearest impact's radius (docs/solver.md)."""
    return radius_scale(s.X[n, 0], s.X[n, 1], s.X[n, 2], s.gp)


@njit(cache=True, inline="always")
def _bridge(s, p, w, n):
    """Ligament failure at free tip ``n`` (:func:`crackbake.simulate.solver.iben.rules.bridge`)."""
    cid = s.crack_of[n]
    if bridge(s, w, n, cid, p.lig_rad * _scale(s, n), p.lig_cos, s.clen[cid]):
        s.cnt[BRIDGED] += 1
        return True
    return False


@njit(cache=True, inline="always")
def bridge_arrested(s, p, w):
    """At rest: before the material dries further (or the run ends), tips that were arrested
    short of a crack another crack has since approached may break through."""
    cnt = s.cnt
    for n in range(cnt[NODES]):
        if s.crack_of[n] >= 0 and not s.dead[n] and s.lchk[n] != cnt[EVENTS] + 1:
            s.lchk[n] = cnt[EVENTS] + 1
            if _bridge(s, p, w, n):
                s.nevl[n] = cnt[DEPOSITS]
                push(s, n, p.tip_first)


@njit(cache=True, inline="always")
def dry(s, p):
    """Quasi-static shrinkage: nothing fails, so the material dries a step further (the
    stress grows here; the caller recomputes faces and nodes on threads and re-queues them:
    ``DRIED``); returns False when the run ends instead.

    It ends without growth, with the crack budget spent, or once the material has dried longer
    without a crack event than the fresh material took to crack, plus GROWTH_REF_STEPS
    (saturated: no place is left where a crack may start or grow).
    """
    cnt = s.cnt
    if not (s.GR.shape[0] > 1 and cnt[CRACKS] < p.max_cracks):
        return False
    if cnt[IDLE] > max(cnt[FIRST_CRACK], 0) + GROWTH_REF_STEPS:
        cnt[SATURATED] = 1
        return False
    cnt[IDLE] += 1
    S, GR = s.S, s.GR
    for f in range(cnt[FACES]):
        for i in range(3):
            for j in range(3):
                S[f, i, j] += GR[f, i, j]
    cnt[STEP] += 1
    cnt[GROWTH_STEPS] += 1
    return True


@njit(cache=True, inline="always")
def pick(s, p, w):
    """Pop the most critical node; -1 when it no longer fails or may not crack now.

    The heap is lazy: a node whose shadow grew since it was evaluated is refreshed and
    re-queued if it no longer is the most critical.  A new crack must also pass the footprint
    test (localized fields).
    """
    cnt = s.cnt
    _top, c, ver = heap_pop(s.hk, s.hnode, s.hv, cnt)
    if ver != s.nver[c] or s.dead[c] or not s.val[c] > s.taun[c]:
        return -1
    nucleate = s.crack_of[c] < 0
    if nucleate and (cnt[CRACKS] >= p.max_cracks or s.nonuc[c]):
        # The crack budget is spent (only existing cracks may grow), or c lies beside one.
        return -1
    if s.G.shape[0] >= 2 and s.nevl[c] != cnt[DEPOSITS]:
        _update_faces(s, w, s.NF[c], s.NFc[c])
        _node_update(s, w, p, c, not nucleate)
        s.nevl[c] = cnt[DEPOSITS]
        cnt[REFRESHED] += 1
        if not nucleate and not s.val[c] > s.taun[c] and p.lig_rad > 0:
            _bridge(s, p, w, c)
        if not s.val[c] > s.taun[c]:
            s.nver[c] += 1
            return -1
        if cnt[HEAP] > 0 and key(s.val, s.taun, s.crack_of, c, p.tip_first) < s.hk[0]:
            push(s, c, p.tip_first)
            return -1
    if nucleate and p.nuc_rad > 0:
        if not footprint_fails(s, w, c, p.nuc_rad):
            s.nver[c] += 1
            cnt[NUC_VETOED] += 1
            return -1
    return c


@njit(cache=True, inline="always")
def crack_event(s, p, w, c):
    """Cut node ``c`` and update everything around it; returns 1 when a crack event happened,
    0 when ``c`` is refused (or marked dead when it cannot be cut), ``_WIDEN`` when the node
    -> face table has no room for the event's splits (``c`` is queued again, unchanged)."""
    cnt = s.cnt
    nucleate = s.crack_of[c] < 0
    if not crack_plane(s, w, c):
        s.dead[c] = True
        return 0
    if nucleate and p.near_rad > 0:
        # No new crack right beside an existing one (permanently: cracks never heal), nor
        # where the near-crack rule would end both its tips at once; such starts only
        # multiplied short cracks as the mesh refined.
        near = near_other(s, w, c, _NO_CRACK, w.geo[2, 0], w.geo[2, 1], w.geo[2, 2],
                          p.near_rad * _scale(s, c), p.near_cos, p.nuc_any)
        if near > 0:
            s.nver[c] += 1
            cnt[NUC_NEAR] += 1
            if near == 1:
                s.nonuc[c] = True
            return 0
    sig_n = normal_stress(s, w, c)
    crossings(s, w, c)
    choose_tips(s, p, w, c)
    drop_back_cuts(s, p, w, c)
    nt = (w.tip[0] >= 0) + (w.tip[1] >= 0)
    interior = not on_boundary(s.F, s.NF, s.NFc, c)
    if nt < (2 if interior else 1):
        s.dead[c] = True
        cnt[ABORTED] += 1
        return 0
    if not has_room(s, w, c):
        push(s, c, p.tip_first)
        return _WIDEN
    split_tips(s, w)
    nsplit, ncen = open_node(s, w, c)
    if nsplit == 0:
        s.dead[c] = True
        cnt[ABORTED] += 1
        return 0
    cnt[STAMP] += 1
    stamp = cnt[STAMP]
    cid, excess = record(s, p, w, c, nucleate, interior, sig_n)
    nrf = update_ring(s, w, ncen, nsplit, stamp)
    end_near_tips(s, p, w, cid)
    push_residual(s, p, w, cid, excess)
    # Fine relaxation: grow the region by rings, then damped Jacobi passes.
    nrf, nrn = region(s, w, nrf, stamp, p.rings)
    if p.nrelax > 0 and p.rate > 0:
        relax(s, w, nrf, nrn, stamp, p.nrelax, p.rate)
        _update_faces(s, w, w.regf, nrf)
    elif s.G.shape[0] >= 2:
        # The new shadow reaches the whole region: refresh its faces.
        _update_faces(s, w, w.regf, nrf)
    update_region(s, p, w, nrn)
    cross_shells(s, p, w, c, cid, excess)
    cnt[STEP] += 1
    cnt[EVENTS] += 1
    if cnt[FIRST_CRACK] < 0:
        cnt[FIRST_CRACK] = cnt[GROWTH_STEPS]
    cnt[IDLE] = 0
    return 1


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def record(s, p, w, c, nucleate, interior, sig_n):
    """Record the event's segments and the crack they extend (a new one when ``nucleate``);
    cast their stress shadow.  Returns the crack and the excess separation of ``c``."""
    cnt, X, pid, pdir = s.cnt, s.X, s.pid, s.pdir
    xc0, xc1, xc2 = w.geo[0, 0], w.geo[0, 1], w.geo[0, 2]
    nc0, nc1, nc2 = w.geo[1, 0], w.geo[1, 1], w.geo[1, 2]
    cid = s.crack_of[c]
    if cid < 0:
        cid = cnt[CRACKS]
        cnt[CRACKS] += 1
        if not interior:
            cnt[NUC_EDGE] += 1
        s.corig[cid, 0] = xc0
        s.corig[cid, 1] = xc1
        s.corig[cid, 2] = xc2
        s.corig[cid, 3] = cnt[STEP]
        s.corig[cid, 4] = 0.0 if interior else 1.0
    dir_len = p.dir_len * _scale(s, c)
    release = s.val[c] / s.hn[c]
    excess = s.val[c] - s.taun[c]
    s.crack_of[c] = -1
    for side in range(2):
        t = w.tip[side]
        if t < 0:
            continue
        af = -1
        for j in range(s.NFc[t]):
            f = s.NF[t, j]
            for q in range(3):
                if pid[s.F[f, q]] == pid[c]:
                    af = s.AF[f]
        k = cnt[SEGS]
        cnt[SEGS] += 1
        s.segp[k, 0] = pid[c]
        s.segp[k, 1] = pid[t]
        s.seg_alive[k] = True
        s.seg_info[k, 0] = af
        s.seg_info[k, 1] = cnt[STEP]
        s.seg_info[k, 2] = release
        s.segof[pid[c]] = k
        s.segof[pid[t]] = k
        s.pcid[pid[c]] = cid
        s.pcid[pid[t]] = cid
        # A new crack's first segments start its direction afresh (c may lie on another).
        smooth_dir(pid[c], pid[t], wrap(X[t, 0] - xc0, s.period),
                   wrap(X[t, 1] - xc1, s.period), X[t, 2] - xc2,
                   0.0 if nucleate else dir_len, pdir)
        d0 = wrap(X[t, 0] - xc0, s.period)
        d1 = wrap(X[t, 1] - xc1, s.period)
        d2 = X[t, 2] - xc2
        seglen = norm3(d0, d1, d2)
        w.segl[side] = seglen
        s.clen[cid] += seglen
        if s.G.shape[0] >= 2 and sig_n > 0.0:
            shadow_add(s, xc0 + 0.5 * d0, xc1 + 0.5 * d1, xc2 + 0.5 * d2,
                       p.gain * seglen * sig_n, nc0, nc1, nc2)
            cnt[DEPOSITS] += 1
    pc = pid[c]
    if pdir[pc, 0] == 0.0 and pdir[pc, 1] == 0.0 and pdir[pc, 2] == 0.0:
        pdir[pc, 0], pdir[pc, 1], pdir[pc, 2] = w.geo[2, 0], w.geo[2, 1], w.geo[2, 2]
    return cid, excess


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def update_ring(s, w, ncen, nsplit, stamp):
    """Stamp and recompute the faces around the event's centres (``w.regf``; returns their
    count); the split nodes start without residual."""
    rho, NF, NFc, fst, centers, regf = s.rho, s.NF, s.NFc, s.fst, w.centers, w.regf
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
    _update_faces(s, w, w.regf, nrf)
    return nrf


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def end_near_tips(s, p, w, cid):
    """Localized fields: a free tip running alongside another crack ends there (once its crack
    is a world length long: a younger one would stay a resolution-sized stub).  Sets
    ``w.near_end``; whether it rather breaks through is decided after the region's update."""
    w.near_end[0] = False
    w.near_end[1] = False
    if not p.tip_near:
        return
    for side in range(2):
        t = w.tip[side]
        if t >= 0 and w.free_tip[side]:
            near_rad = p.near_rad * _scale(s, t)
            if s.clen[cid] < near_rad:
                continue
            q = s.pid[t]
            if near_other(s, w, t, cid, s.pdir[q, 0], s.pdir[q, 1], s.pdir[q, 2], near_rad,
                          p.near_cos, 0.0) > 0:
                w.near_end[side] = True


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def push_residual(s, p, w, cid, excess):
    """Make the free tips crack tips and push ``a_eff excess n n^T`` to their residual.

    ``alpha`` is the share carried over a step of ``tip_len``: per step it is
    ``alpha^(step / tip_len)``, so the momentum lasts a world distance.
    """
    nc = w.geo[1]
    for side in range(2):
        t = w.tip[side]
        if t >= 0 and w.free_tip[side]:
            s.crack_of[t] = cid
            s.tipn[t, 0], s.tipn[t, 1], s.tipn[t, 2] = nc[0], nc[1], nc[2]
            if s.clen[cid] < p.max_len:
                a_eff = (p.alpha ** min(w.segl[side] / p.tip_len, 1.0) if p.tip_len > 0.0
                         else p.alpha)
                for i in range(3):
                    for j in range(3):
                        s.rho[t, i, j] += a_eff * excess * nc[i] * nc[j]


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def update_region(s, p, w, nrn):
    """Recompute the region's nodes, apply the tip rules to this event's tips (ligament
    failure, near-crack end) and re-queue the nodes."""
    rho, val, crack_of, taun, nevl, cnt = s.rho, s.val, s.crack_of, s.taun, s.nevl, s.cnt
    sc, acc, ev, regn, tip, near_end = w.sc, w.acc, w.ev, w.regn, w.tip, w.near_end
    grain, seed = p.grain, p.seed
    for i in range(nrn):
        n = regn[i]
        node_update(s, n, crack_of[n] >= 0, grain, seed, sc, acc, ev)
        nevl[n] = cnt[DEPOSITS]
        # Only this event's tips: an older arrested tip was looked at when it stopped, and
        # looking again at every nearby event would cost a search per event.
        mine = n == tip[0] or n == tip[1]
        ended = (n == tip[0] and near_end[0]) or (n == tip[1] and near_end[1])
        if mine and crack_of[n] >= 0 and (ended or not val[n] > taun[n]) and p.lig_rad > 0:
            if _bridge(s, p, w, n):
                ended = False
        if ended:
            # The near-crack rule ends this tip like one that met a crack.
            crack_of[n] = -1
            for a in range(3):
                for b in range(3):
                    rho[n, a, b] = 0.0
            node_update(s, n, np.bool_(False), grain, seed, sc, acc, ev)
            cnt[TIPS_NEAR] += 1
        push(s, n, p.tip_first)


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def cross_shells(s, p, w, c, cid, excess):
    """Touching shells crack as one surface: a tip of this event at a node whose point has a
    mate on another shell (``State.mate``, within a sim edge) starts the crack there too.

    The mate becomes a tip of the same crack, with the crack's heading and normal projected
    into its shell's tangent plane (``pdir``, ``tipn``) and the residual a tip would get, so
    it cuts as the tip would have; not where a crack already runs near the mate (that shell
    cracked there already: its own tip carries on; a crack never bounces back).  Tips that met
    a crack or were ended by the near-crack rule do not cross; tips that met the boundary do.
    """
    X, pid, mate, nrm, area, NF, NFc = s.X, s.pid, s.mate, s.nrm, s.area, s.NF, s.NFc
    nc = w.geo[1]
    for side in range(2):
        t = w.tip[side]
        if t < 0:
            continue
        if not ((w.free_tip[side] and s.crack_of[t] == cid) or (not w.free_tip[side]
                                                                 and s.onb[t])):
            continue
        m = mate[pid[t]]
        if m < 0 or s.dead[m] or s.crack_of[m] >= 0 or s.pcid[pid[m]] >= 0:
            continue
        # The mate's shell normal: its faces' area-weighted normals.
        u0 = u1 = u2 = 0.0
        for j in range(NFc[m]):
            f = NF[m, j]
            u0 += area[f] * nrm[f, 0]
            u1 += area[f] * nrm[f, 1]
            u2 += area[f] * nrm[f, 2]
        lu = norm3(u0, u1, u2)
        if lu == 0.0:
            continue
        u0, u1, u2 = u0 / lu, u1 / lu, u2 / lu
        d0, d1, d2 = X[t, 0] - X[c, 0], X[t, 1] - X[c, 1], X[t, 2] - X[c, 2]
        k = dot3(d0, d1, d2, u0, u1, u2)
        d0, d1, d2 = d0 - k * u0, d1 - k * u1, d2 - k * u2
        k = dot3(nc[0], nc[1], nc[2], u0, u1, u2)
        n0, n1, n2 = nc[0] - k * u0, nc[1] - k * u1, nc[2] - k * u2
        ld, ln = norm3(d0, d1, d2), norm3(n0, n1, n2)
        if ld == 0.0 or ln < 1e-6:
            continue
        d0, d1, d2, n0, n1, n2 = d0 / ld, d1 / ld, d2 / ld, n0 / ln, n1 / ln, n2 / ln
        near_rad = p.near_rad * _scale(s, m)
        if near_other(s, w, m, _NO_CRACK, d0, d1, d2, near_rad, p.near_cos,
                      max(p.nuc_any, CROSS_CLEAR * s.hn[m])) > 0:
            continue
        s.crack_of[m] = cid
        q = pid[m]
        s.pdir[q, 0], s.pdir[q, 1], s.pdir[q, 2] = d0, d1, d2
        s.tipn[m, 0], s.tipn[m, 1], s.tipn[m, 2] = n0, n1, n2
        if s.clen[cid] < p.max_len and excess > 0.0:
            a_eff = (p.alpha ** min(w.segl[side] / p.tip_len, 1.0) if p.tip_len > 0.0
                     else p.alpha)
            nn = (n0, n1, n2)
            for i in range(3):
                for j in range(3):
                    s.rho[m, i, j] += a_eff * excess * nn[i] * nn[j]
        if s.G.shape[0] >= 2:
            _update_faces(s, w, NF[m], NFc[m])
        _node_update(s, w, p, m, np.bool_(True))
        s.nevl[m] = s.cnt[DEPOSITS]
        s.cnt[CROSSED] += 1
        push(s, m, p.tip_first)
