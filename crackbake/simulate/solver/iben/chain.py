"""Crack polylines from the recorded segments."""

from __future__ import annotations

import numpy as np

from crackbake.simulate.solver import CrackPath, SolverParams


def crack_graph(segp: np.ndarray) -> dict[int, list[int]]:
    """Point id -> indices of the segments touching it."""
    adj: dict[int, list[int]] = {}
    for s, (a, b) in enumerate(segp.tolist()):
        adj.setdefault(a, []).append(s)
        adj.setdefault(b, []).append(s)
    return adj


def chain(segp, info, X, onb, steps, params: SolverParams, X0,
          period: float = 0.0) -> list[CrackPath]:
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
    diag = (float(np.linalg.norm(X0.max(0) - X0.min(0))) if not period
            else float(np.hypot(period, period)))
    width = params.crack_width if params.crack_width is not None else 1e-3 * diag
    total = max(steps, 1)
    out = []
    for pts, segs in chains:
        p = X[np.asarray(pts)]
        if period:
            # Periodic plate: unwrap to a continuous path (points may leave [0, period)).
            d = np.diff(p, axis=0)
            d[:, :2] -= period * np.floor(d[:, :2] / period + 0.5)
            p = np.concatenate([p[:1], p[:1] + np.cumsum(d, axis=0)])
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
