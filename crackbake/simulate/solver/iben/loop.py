"""The compiled crack loop of the iben solver."""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.simulate.solver.iben.constants import (
    _ABORT,
    _BRIDGE,
    _DEP,
    _DONE,
    _EVENTS,
    _FIRST,
    _FULL,
    _GROW,
    _HEAP,
    _IDLE,
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
    _STAMP,
    _STEP,
    _TIP_NEAR,
    GROWTH_REF_STEPS,
    NEAR_QUEUE,
    RELAX_RINGS,
)
from crackbake.simulate.solver.iben.relax import _relax
from crackbake.simulate.solver.iben.rules import _bridge, _footprint_fails, _near_other, _smooth_dir
from crackbake.simulate.solver.iben.update import (
    _angle,
    _key,
    _push,
    _rebuild_heap,
    _scratch,
    _update_all,
)
from crackbake.simulate.solver.topology import (
    face_update,
    heap_pop,
    node_update,
    on_boundary,
    separate,
    shadow_add,
    split_edge,
    spoke_count,
)


@njit(cache=True)
def _run(X, F, S, AF, GR, area, nrm, grad, pr, NF, NFc, rho, val, vec, taun, hn, pid, onb,
         crack_of, nver, dead, nonuc, fst, nst, nevl, segof, pcid, pdir, tipn, lchk, hk, hn_, hv,
         segp, seg_alive, seg_info, clen, corig, G, gp, cnt, prm, max_cracks, max_steps, chunk):
    """Advance the crack loop by at most ``chunk`` steps.

    Returns ``_MORE`` (chunk done), ``_DONE`` (finished) or ``_FULL`` (the state arrays need more
    room: grow them and call again).
    """
    alpha, rate, nrelax, max_len = prm[0], prm[1], int(prm[2]), prm[3]
    snap, snap_b, snap_t, rings = prm[4], prm[5], prm[6], int(prm[7])
    gain, back, tip_first = prm[8], prm[9], prm[10] > 0
    grain, seed = prm[11], int(prm[12])
    near_rad, near_cos = prm[13], prm[14]
    nuc_rad = prm[15]
    dir_len = prm[16]
    tip_len = prm[17]
    tip_near = prm[18] > 0
    lig_rad, lig_cos = prm[19], prm[20]
    nuc_any = RELAX_RINGS * tip_len
    shadow = G.shape[0] >= 2
    W = NF.shape[1]
    ncap = X.shape[0]
    mcap = F.shape[0]
    regf = np.empty(65536, np.int64)
    regn = np.empty(65536, np.int64)
    disp = np.zeros((ncap, 3))
    buf = np.empty(8, np.int64)
    par = np.empty(W, np.int64)
    comp = np.empty(W, np.int64)
    fbuf = np.empty(W, np.int64)
    centers = np.empty(24, np.int64)
    sc, acc, ev, fr, r6 = _scratch()
    sa = np.empty(2, np.int64)
    sb = np.empty(2, np.int64)
    st = np.empty(2)
    sd = np.empty(2)
    tip = np.empty(2, np.int64)
    split = np.empty(2, np.bool_)
    free_tip = np.empty(2, np.bool_)
    near_end = np.empty(2, np.bool_)
    segl = np.empty(2)
    vst = np.zeros(ncap if near_rad > 0 or nuc_rad > 0 or lig_rad > 0 else 1, np.int64)
    vstamp = 0
    queue = np.empty(NEAR_QUEUE, np.int64)
    done = 0
    while True:
        if cnt[_STEP] >= max_steps:
            return _DONE
        if done >= chunk:
            return _MORE
        if (cnt[_NN] + 32 > ncap or cnt[_NF] + 16 > mcap or cnt[_NS] + 16 > segp.shape[0]
                or cnt[_NCRACK] + 2 > clen.shape[0]):
            return _FULL
        if cnt[_HEAP] == 0 and lig_rad > 0:
            # At rest: before the material dries further (or the run ends), tips that were
            # arrested short of a crack another crack has since approached may break through.
            for n in range(cnt[_NN]):
                if crack_of[n] >= 0 and not dead[n] and lchk[n] != cnt[_EVENTS] + 1:
                    lchk[n] = cnt[_EVENTS] + 1
                    vstamp += 1
                    if _bridge(n, crack_of[n], lig_rad, lig_cos, X, F, NF, NFc, nrm, area, pid,
                               pcid, pdir, onb, val, vec, taun, vst, vstamp, queue,
                               clen[crack_of[n]]):
                        cnt[_BRIDGE] += 1
                        nevl[n] = cnt[_DEP]
                        _push(n, hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
        if cnt[_HEAP] == 0:
            # With the crack budget spent and the field at rest, more drying would only lengthen
            # existing cracks step after step: stop (otherwise only max_steps would end the run).
            if GR.shape[0] > 1 and cnt[_NCRACK] < max_cracks:
                # Quasi-static shrinkage: nothing fails, so the material dries a step further;
                # unless it has dried longer without a crack event than the fresh material took
                # to crack, plus GROWTH_REF_STEPS: then no place is left where a crack may
                # start or grow (saturated), and only max_steps would end the run.
                if cnt[_IDLE] > max(cnt[_FIRST], 0) + GROWTH_REF_STEPS:
                    cnt[_SATURATED] = 1
                    return _DONE
                cnt[_IDLE] += 1
                nn, nf = cnt[_NN], cnt[_NF]
                for f in range(nf):
                    S[f] += GR[f]
                _update_all(nn, nf, X, F, S, area, nrm, grad, pr, NF, NFc, rho, val, vec,
                            crack_of, G, gp, grain, seed, tipn)
                for n in range(nn):
                    nver[n] += 1
                    nevl[n] = cnt[_DEP]
                _rebuild_heap(hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
                cnt[_STEP] += 1
                cnt[_GROW] += 1
                done += 1
                continue
            return _DONE
        _top, c, ver = heap_pop(hk, hn_, hv, cnt)
        if ver != nver[c] or dead[c] or not val[c] > taun[c]:
            continue
        nucleate = crack_of[c] < 0
        if nucleate and (cnt[_NCRACK] >= max_cracks or nonuc[c]):
            # The crack budget is spent (only existing cracks may grow), or c lies beside one.
            continue
        if shadow and nevl[c] != cnt[_DEP]:
            # Lazy heap: the shadow grew since this node was evaluated; refresh and re-check.
            for j in range(NFc[c]):
                face_update(NF[c, j], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
            node_update(c, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec, not nucleate,
                        grain, seed, sc, acc, ev, G, gp, tipn)
            nevl[c] = cnt[_DEP]
            cnt[_REFRESH] += 1
            if not nucleate and not val[c] > taun[c] and lig_rad > 0:
                vstamp += 1
                if _bridge(c, crack_of[c], lig_rad, lig_cos, X, F, NF, NFc, nrm, area, pid, pcid,
                           pdir, onb, val, vec, taun, vst, vstamp, queue, clen[crack_of[c]]):
                    cnt[_BRIDGE] += 1
            if not val[c] > taun[c]:
                nver[c] += 1
                continue
            if cnt[_HEAP] > 0 and _key(c, val, taun, crack_of, tip_first) < hk[0]:
                _push(c, hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
                continue
        if nucleate and nuc_rad > 0:
            vstamp += 1
            if not _footprint_fails(c, nuc_rad, X, F, NF, NFc, val, taun, hn, dead, vst,
                                    vstamp, queue):
                nver[c] += 1
                cnt[_NUC_VETO] += 1
                continue
        # ---- crack plane: n-hat projected on the tangent plane; t runs along the crack.
        xc0, xc1, xc2 = X[c, 0], X[c, 1], X[c, 2]
        vn0 = vn1 = vn2 = 0.0
        asum = 0.0
        for j in range(NFc[c]):
            f = NF[c, j]
            vn0 += area[f] * nrm[f, 0]
            vn1 += area[f] * nrm[f, 1]
            vn2 += area[f] * nrm[f, 2]
            asum += area[f]
        lvn = np.sqrt(vn0 * vn0 + vn1 * vn1 + vn2 * vn2)
        if lvn == 0.0:
            dead[c] = True
            continue
        vn0 /= lvn
        vn1 /= lvn
        vn2 /= lvn
        e0, e1, e2 = vec[c, 0], vec[c, 1], vec[c, 2]
        en = e0 * vn0 + e1 * vn1 + e2 * vn2
        nc0 = e0 - en * vn0
        nc1 = e1 - en * vn1
        nc2 = e2 - en * vn2
        lnc = np.sqrt(nc0 * nc0 + nc1 * nc1 + nc2 * nc2)
        if lnc < 1e-6:
            dead[c] = True
            continue
        nc0 /= lnc
        nc1 /= lnc
        nc2 /= lnc
        tc0 = vn1 * nc2 - vn2 * nc1
        tc1 = vn2 * nc0 - vn0 * nc2
        tc2 = vn0 * nc1 - vn1 * nc0
        if nucleate and near_rad > 0:
            # No new crack right beside an existing one (permanently: cracks never heal), nor
            # where the near-crack rule would end both its tips at once (see the module
            # docstring); such starts only multiplied short cracks as the mesh refined.
            vstamp += 1
            near = _near_other(c, -1, tc0, tc1, tc2, near_rad, near_cos, nuc_any, X, F, NF,
                               NFc, pid, pcid, pdir, vst, vstamp, queue)
            if near > 0:
                nver[c] += 1
                cnt[_NUC_NEAR] += 1
                if near == 1:
                    nonuc[c] = True
                continue
        # Normal stress across the cut (effective, so overlapping shadows do not double count).
        sig_n = 0.0
        for j in range(NFc[c]):
            f = NF[c, j]
            p = pr[f]
            a1 = p[2] * nc0 + p[3] * nc1 + p[4] * nc2
            a2 = p[5] * nc0 + p[6] * nc1 + p[7] * nc2
            sig_n += area[f] * (p[0] * a1 * a1 + p[1] * a2 * a2)
        sig_n = max(sig_n / asum, 0.0) if asum > 0 else 0.0
        # ---- the crossed opposite edge on each side (+t, -t).
        for side in range(2):
            sa[side] = -1
            sb[side] = -1
            st[side] = 0.0
            sd[side] = np.inf
        for j in range(NFc[c]):
            f = NF[c, j]
            k = 0
            while F[f, k] != c:
                k += 1
            a = F[f, (k + 1) % 3]
            b = F[f, (k + 2) % 3]
            da = (X[a, 0] - xc0) * nc0 + (X[a, 1] - xc1) * nc1 + (X[a, 2] - xc2) * nc2
            db = (X[b, 0] - xc0) * nc0 + (X[b, 1] - xc1) * nc1 + (X[b, 2] - xc2) * nc2
            if da == db or da * db > 0:
                continue
            tt = da / (da - db)
            p0 = X[a, 0] + tt * (X[b, 0] - X[a, 0]) - xc0
            p1 = X[a, 1] + tt * (X[b, 1] - X[a, 1]) - xc1
            p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
            along = p0 * tc0 + p1 * tc1 + p2 * tc2
            side = 0 if along > 0 else 1
            dist = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            if dist < sd[side]:
                sd[side] = dist
                sa[side] = a
                sb[side] = b
                st[side] = tt
        # ---- snap or split, per side.
        for side in range(2):
            tip[side] = -1
            split[side] = False
            if sa[side] < 0:
                continue
            a, b, tt = sa[side], sb[side], st[side]
            p0 = X[a, 0] + tt * (X[b, 0] - X[a, 0]) - xc0
            p1 = X[a, 1] + tt * (X[b, 1] - X[a, 1]) - xc1
            p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
            ang_a = _angle(p0, p1, p2, X[a, 0] - xc0, X[a, 1] - xc1, X[a, 2] - xc2)
            ang_b = _angle(p0, p1, p2, X[b, 0] - xc0, X[b, 1] - xc1, X[b, 2] - xc2)
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
        # A cut that runs back along a crack or boundary edge at c would fork the crack behind
        # its tip (a stub); cracks only grow forward from there.
        for side in range(2):
            if tip[side] < 0 or sa[side] < 0:
                continue
            a, b, tt = sa[side], sb[side], st[side]
            p0 = X[a, 0] + tt * (X[b, 0] - X[a, 0]) - xc0
            p1 = X[a, 1] + tt * (X[b, 1] - X[a, 1]) - xc1
            p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
            for j in range(NFc[c]):
                f = NF[c, j]
                for q in range(3):
                    y = F[f, q]
                    if y != c and y != tip[side] and spoke_count(F, NF, NFc, c, y) == 1:
                        if _angle(p0, p1, p2, X[y, 0] - xc0, X[y, 1] - xc1,
                                  X[y, 2] - xc2) < back:
                            tip[side] = -1
                            split[side] = False
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
                                       seg_alive, seg_info, segof, cnt)
                nevl[tip[side]] = -1
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
                        y = F[f, q]
                        if y != p:
                            hsum += np.sqrt((X[y, 0] - X[p, 0]) ** 2 + (X[y, 1] - X[p, 1]) ** 2
                                            + (X[y, 2] - X[p, 2]) ** 2)
                            hcnt += 1
                if hcnt > 0:
                    scale = (hsum / hcnt) / hn[p]
                    hn[p] *= scale
                    taun[p] *= scale
        # ---- open the crack: split the node along the cut edges.
        nsplit = separate(c, tip[0], tip[1], X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of,
                          nver, cnt, buf, par, comp, fbuf)
        if nsplit == 0:
            dead[c] = True
            cnt[_ABORT] += 1
            continue
        cnt[_STAMP] += 1
        stamp = cnt[_STAMP]
        ncen = 0
        centers[ncen] = c
        ncen += 1
        for q in range(nsplit):
            centers[ncen] = buf[q]
            ncen += 1
        for side in range(2):
            free_tip[side] = False
            if tip[side] < 0:
                continue
            centers[ncen] = tip[side]
            ncen += 1
            # A tip that lay on a boundary is pinched by the cut: mend it; its crack is finished.
            m = separate(tip[side], -1, -1, X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of,
                         nver, cnt, buf, par, comp, fbuf)
            free_tip[side] = m == 0
            for q in range(m):
                if ncen < centers.shape[0]:
                    centers[ncen] = buf[q]
                    ncen += 1
        # ---- record the segments and the crack they extend; cast their stress shadow.
        cid = crack_of[c]
        if cid < 0:
            cid = cnt[_NCRACK]
            cnt[_NCRACK] += 1
            if not interior:
                cnt[_NUC_EDGE] += 1
            corig[cid, 0] = xc0
            corig[cid, 1] = xc1
            corig[cid, 2] = xc2
            corig[cid, 3] = cnt[_STEP]
            corig[cid, 4] = 0.0 if interior else 1.0
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
            segof[pid[c]] = s
            segof[pid[t]] = s
            pcid[pid[c]] = cid
            pcid[pid[t]] = cid
            # A new crack's first segments start its direction afresh (c may lie on another).
            _smooth_dir(pid[c], pid[t], X[t, 0] - xc0, X[t, 1] - xc1, X[t, 2] - xc2,
                        0.0 if nucleate else dir_len, pdir)
            d0 = X[t, 0] - xc0
            d1 = X[t, 1] - xc1
            d2 = X[t, 2] - xc2
            seglen = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            segl[side] = seglen
            clen[cid] += seglen
            if shadow and sig_n > 0.0:
                shadow_add(xc0 + 0.5 * d0, xc1 + 0.5 * d1, xc2 + 0.5 * d2,
                           gain * seglen * sig_n, nc0, nc1, nc2, G, gp)
                cnt[_DEP] += 1
        pc = pid[c]
        if pdir[pc, 0] == 0.0 and pdir[pc, 1] == 0.0 and pdir[pc, 2] == 0.0:
            pdir[pc, 0], pdir[pc, 1], pdir[pc, 2] = tc0, tc1, tc2
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
            face_update(regf[i], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
        near_end[0] = False
        near_end[1] = False
        if tip_near and clen[cid] >= near_rad:
            # Localized fields: a free tip running alongside another crack ends there (once
            # its crack is a world length long: a younger one would stay a resolution-sized
            # stub).
            for side in range(2):
                t = tip[side]
                if t >= 0 and free_tip[side]:
                    vstamp += 1
                    p = pid[t]
                    if _near_other(t, cid, pdir[p, 0], pdir[p, 1], pdir[p, 2], near_rad,
                                   near_cos, 0.0, X, F, NF, NFc, pid, pcid, pdir, vst, vstamp,
                                   queue) > 0:
                        # Ended, unless it is converging on that crack: then it breaks
                        # through to it (decided below, after the region's update).
                        near_end[side] = True
        for side in range(2):
            t = tip[side]
            if t >= 0 and free_tip[side]:
                crack_of[t] = cid
                tipn[t, 0], tipn[t, 1], tipn[t, 2] = nc0, nc1, nc2
                if clen[cid] < max_len:
                    # alpha is the share carried over a step of tip_len: per step it is
                    # alpha^(step / tip_len), so the momentum lasts a world distance.
                    a_eff = (alpha ** min(segl[side] / tip_len, 1.0) if tip_len > 0.0
                             else alpha)
                    for i in range(3):
                        ni = nc0 if i == 0 else (nc1 if i == 1 else nc2)
                        for j in range(3):
                            nj = nc0 if j == 0 else (nc1 if j == 1 else nc2)
                            rho[t, i, j] += a_eff * excess * ni * nj
        # ---- fine relaxation: grow the region by rings, then damped Jacobi passes.
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
            _relax(nrelax, rate, regf, nrf, regn, nrn, stamp, fst, F, S, NF, NFc, area, nrm,
                   grad, disp)
            for i in range(nrf):
                face_update(regf[i], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
        elif shadow:
            # The new shadow reaches the whole region: refresh its faces.
            for i in range(nrf):
                face_update(regf[i], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
        for i in range(nrn):
            n = regn[i]
            node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec,
                        crack_of[n] >= 0, grain, seed, sc, acc, ev, G, gp, tipn)
            nevl[n] = cnt[_DEP]
            # Only this event's tips: an older arrested tip was looked at when it stopped, and
            # looking again at every nearby event would cost a search per event.
            mine = n == tip[0] or n == tip[1]
            ended = (n == tip[0] and near_end[0]) or (n == tip[1] and near_end[1])
            if mine and crack_of[n] >= 0 and (ended or not val[n] > taun[n]) and lig_rad > 0:
                vstamp += 1
                if _bridge(n, crack_of[n], lig_rad, lig_cos, X, F, NF, NFc, nrm, area, pid,
                           pcid, pdir, onb, val, vec, taun, vst, vstamp, queue,
                           clen[crack_of[n]]):
                    cnt[_BRIDGE] += 1
                    ended = False
            if ended:
                # The near-crack rule ends this tip like one that met a crack.
                crack_of[n] = -1
                for i in range(3):
                    for j in range(3):
                        rho[n, i, j] = 0.0
                node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec, False,
                            grain, seed, sc, acc, ev, G, gp, tipn)
                cnt[_TIP_NEAR] += 1
            _push(n, hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
        cnt[_STEP] += 1
        cnt[_EVENTS] += 1
        if cnt[_FIRST] < 0:
            cnt[_FIRST] = cnt[_GROW]
        cnt[_IDLE] = 0
        done += 1
