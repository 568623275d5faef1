"""Numba kernel of :mod:`.collapse`: shortest-edge collapses in rounds, on the faces in place."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def collapse_rounds(v, f, target, share, close, max_rounds):  # pragma: no cover - numba
    """Collapse edges of ``f`` to their midpoints until at most ``target`` faces are left (or
    within ``close`` of it, or ``max_rounds`` rounds).

    Each round sorts the live edges by length and walks the shortest ``share`` of them in
    order, collapsing each whose ends no collapse of this round has moved, that keeps the
    surface manifold (the link condition; no interior edge joining two border vertices; no
    edge of more than two faces) and turns no face over.  ``v`` (V, 3) and ``f`` (F, 3) change
    in place.  Returns the live-face mask (F,).
    """
    n_v = len(v)
    m = len(f)
    alive = np.ones(m, np.bool_)
    moved = np.zeros(n_v, np.int64)  # round that last moved each vertex
    tag_a = np.zeros(n_v, np.int64)
    cnt_a = np.zeros(n_v, np.int64)
    tag_b = np.zeros(n_v, np.int64)
    cnt_b = np.zeros(n_v, np.int64)
    lo = np.zeros(n_v, np.int64)  # faces around vertex x: pool[lo[x]:hi[x]] (some dead)
    hi = np.zeros(n_v, np.int64)
    # a round's lists, then each collapse's merged list (a vertex merges once a round, and a
    # face is in the merged lists of at most its three corners)
    pool = np.empty(6 * m, np.int64)
    tag = 0
    n_alive = m
    ea = np.empty(3 * m, np.int64)
    eb = np.empty(3 * m, np.int64)
    el = np.empty(3 * m, np.float64)
    stamp = np.full(n_v, -1, np.int64)
    twin = np.zeros((m, 3), np.bool_)  # a live face's edge c -> c + 1 is also run down
    for rnd in range(1, max_rounds + 1):
        if n_alive - target <= close * target:
            break
        hi[:] = 0
        for t in range(m):
            if alive[t]:
                for c in range(3):
                    hi[f[t, c]] += 1
        total = 0
        for x in range(n_v):
            lo[x] = total
            total += hi[x]
            hi[x] = lo[x]
        for t in range(m):
            if alive[t]:
                for c in range(3):
                    x = f[t, c]
                    pool[hi[x]] = t
                    hi[x] += 1
        end = total
        _twins(f, pool, lo, hi, rnd * n_v, stamp, twin)
        k = 0
        for t in range(m):
            if not alive[t]:
                continue
            for c in range(3):
                a = f[t, c]
                b = f[t, (c + 1) % 3]
                # each edge once: from the face where it runs up, or from its only face
                if a > b and twin[t, c]:
                    continue
                ea[k] = min(a, b)
                eb[k] = max(a, b)
                dx = v[b, 0] - v[a, 0]
                dy = v[b, 1] - v[a, 1]
                dz = v[b, 2] - v[a, 2]
                el[k] = dx * dx + dy * dy + dz * dz
                k += 1
        n_cand = min(k, max(1, int(share * k)))
        # the shortest n_cand edges, shortest first (ties by position, a stable sort)
        cut = np.partition(el[:k], n_cand - 1)[n_cand - 1]
        pick = np.flatnonzero(el[:k] <= cut)
        order = pick[np.argsort(el[pick], kind="mergesort")][:n_cand]
        done = 0
        for j in range(len(order)):
            a = ea[order[j]]
            b = eb[order[j]]
            if moved[a] == rnd or moved[b] == rnd:
                continue
            tag += 1
            border_a, bad_a = _ring(f, alive, pool, lo, hi, a, tag, tag_a, cnt_a)
            border_b, bad_b = _ring(f, alive, pool, lo, hi, b, tag, tag_b, cnt_b)
            if bad_a or bad_b or tag_a[b] != tag:
                continue
            n_ab = cnt_a[b]
            if n_ab == 2 and border_a and border_b:
                continue  # would pinch the surface at a vertex
            shared = 0
            for q in range(lo[a], hi[a]):
                t = pool[q]
                if alive[t]:
                    for c in range(3):
                        w = f[t, c]
                        if w != a and w != b and tag_b[w] == tag and cnt_b[w] > 0:
                            shared += 1
                            cnt_b[w] = -cnt_b[w]  # each shared neighbour once
            if shared != n_ab:
                continue
            mx = 0.5 * (v[a, 0] + v[b, 0])
            my = 0.5 * (v[a, 1] + v[b, 1])
            mz = 0.5 * (v[a, 2] + v[b, 2])
            if _any_turns(v, f, alive, pool, lo, hi, a, b, mx, my, mz):
                continue
            new_lo = end
            for q in range(lo[a], hi[a]):
                t = pool[q]
                if not alive[t]:
                    continue
                if f[t, 0] == b or f[t, 1] == b or f[t, 2] == b:
                    alive[t] = False
                    n_alive -= 1
                else:
                    pool[end] = t
                    end += 1
            for q in range(lo[b], hi[b]):
                t = pool[q]
                if not alive[t]:
                    continue
                for c in range(3):
                    if f[t, c] == b:
                        f[t, c] = a
                pool[end] = t
                end += 1
            lo[a] = new_lo
            hi[a] = end
            hi[b] = lo[b]
            v[a, 0] = mx
            v[a, 1] = my
            v[a, 2] = mz
            moved[a] = rnd
            moved[b] = rnd
            done += 1
            if n_alive <= target:
                break
        if done == 0:
            break
    return alive


@njit(cache=True, nogil=True)
def _twins(f, pool, lo, hi, base, stamp, twin):  # pragma: no cover - numba
    """For every live face's edge a -> b (corner c -> c + 1) with a > b, whether a live face
    has b -> a: ``twin[t, c]``.  Vertex by vertex (each b's faces are read twice, close
    together) instead of a search of b's faces per edge; ``pool`` holds only live faces.
    ``base`` differs per call by at least the vertex count: no stamp of an earlier call
    matches."""
    for x in range(len(lo)):
        key = base + x
        for q in range(lo[x], hi[x]):
            t = pool[q]
            c = 0 if f[t, 0] == x else (1 if f[t, 1] == x else 2)
            stamp[f[t, (c + 1) % 3]] = key  # x -> y
        for q in range(lo[x], hi[x]):
            t = pool[q]
            c = 0 if f[t, 0] == x else (1 if f[t, 1] == x else 2)
            p = (c + 2) % 3
            w = f[t, p]  # edge w -> x at corner p
            if w > x:
                twin[t, p] = stamp[w] == key


@njit(cache=True, nogil=True)
def _ring(f, alive, pool, lo, hi, a, tag, tags, cnt):  # pragma: no cover - numba
    """Count, per neighbour w of ``a``, the live faces holding both (``cnt[w]``, valid where
    ``tags[w] == tag``).  Returns (a lies on a border, an edge at a has over two faces)."""
    for q in range(lo[a], hi[a]):
        t = pool[q]
        if alive[t]:
            for c in range(3):
                w = f[t, c]
                if w == a:
                    continue
                if tags[w] != tag:
                    tags[w] = tag
                    cnt[w] = 0
                cnt[w] += 1
    border = False
    bad = False
    for q in range(lo[a], hi[a]):
        t = pool[q]
        if alive[t]:
            for c in range(3):
                w = f[t, c]
                if w != a:
                    if cnt[w] == 1:
                        border = True
                    elif cnt[w] > 2:
                        bad = True
    return border, bad


@njit(cache=True, nogil=True)
def _any_turns(v, f, alive, pool, lo, hi, a, b, mx, my, mz):  # pragma: no cover - numba
    """A live face around a or b that keeps its area turns over (or flattens) when its corner a
    or b moves to m."""
    for end in (a, b):
        for q in range(lo[end], hi[end]):
            t = pool[q]
            if not alive[t]:
                continue
            i0 = f[t, 0]
            i1 = f[t, 1]
            i2 = f[t, 2]
            if (i0 == a or i1 == a or i2 == a) and (i0 == b or i1 == b or i2 == b):
                continue  # vanishes with the edge
            if _turns(v, i0, i1, i2, end, mx, my, mz):
                return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _turns(v, i0, i1, i2, end, mx, my, mz):  # pragma: no cover - numba
    """Face (i0, i1, i2) turns over (or flattens) when its corner ``end`` moves to m."""
    ax, ay, az = v[i0, 0], v[i0, 1], v[i0, 2]
    bx, by, bz = v[i1, 0], v[i1, 1], v[i1, 2]
    cx, cy, cz = v[i2, 0], v[i2, 1], v[i2, 2]
    n0 = _normal(ax, ay, az, bx, by, bz, cx, cy, cz)
    if i0 == end:
        ax, ay, az = mx, my, mz
    elif i1 == end:
        bx, by, bz = mx, my, mz
    else:
        cx, cy, cz = mx, my, mz
    n1 = _normal(ax, ay, az, bx, by, bz, cx, cy, cz)
    return n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2] <= 0.0


@njit(cache=True, nogil=True, inline="always")
def _normal(ax, ay, az, bx, by, bz, cx, cy, cz):  # pragma: no cover - numba
    ux, uy, uz = bx - ax, by - ay, bz - az
    wx, wy, wz = cx - ax, cy - ay, cz - az
    return (uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx)


@njit(cache=True, nogil=True)
def border_edges(f, n_v):  # pragma: no cover - numba
    """The edges (B, 2) used by exactly one face of ``f`` (F, 3), low index first, sorted
    (as ``geometry.edges`` with a count of 1 gives them): each edge listed under its low
    vertex and each vertex's few high ends sorted in place, instead of one sort of all 3F
    keys."""
    start = np.zeros(n_v + 1, np.int64)
    for t in range(len(f)):
        for c in range(3):
            start[min(f[t, c], f[t, (c + 1) % 3]) + 1] += 1
    for x in range(n_v):
        start[x + 1] += start[x]
    fill = start[:-1].copy()
    high = np.empty(3 * len(f), np.int64)
    for t in range(len(f)):
        for c in range(3):
            a = f[t, c]
            b = f[t, (c + 1) % 3]
            lo_ = min(a, b)
            high[fill[lo_]] = max(a, b)
            fill[lo_] += 1
    out = np.empty((3 * len(f), 2), np.int64)
    n = 0
    for x in range(n_v):
        s0 = start[x]
        s1 = start[x + 1]
        for i in range(s0 + 1, s1):  # insertion sort: a vertex has a handful of high ends
            y = high[i]
            j = i - 1
            while j >= s0 and high[j] > y:
                high[j + 1] = high[j]
                j -= 1
            high[j + 1] = y
        i = s0
        while i < s1:
            j = i + 1
            while j < s1 and high[j] == high[i]:
                j += 1
            if j - i == 1:
                out[n, 0] = x
                out[n, 1] = high[i]
                n += 1
            i = j
    return out[:n].copy()
