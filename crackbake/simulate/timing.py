"""``crack.time`` that grows an impact's cracks continuously out of the impact.

The solvers time each point by the step that cracked it.  Around an impact that physical order
has pieces that start away from the impact and join the star later (iben nucleates a crack where
the stress peaks and its tips run into the arms; thesis grows one crack after another from the
node of highest separation), so a shader revealing ``time <= t`` shows segments popping up
mid-air.  :func:`grow_from_impacts` re-times the part of the network connected to an impact as a
front running along the cracks from where the impact's first crack started:

    T(source) = the component's earliest time,
    T(v) = min over neighbours u of  t(v)                 if T(u) <= t(v),
                                     T(u) + |uv| / speed  otherwise.

A point that a neighbour reached no later than it cracked keeps its physical time t (so where
the physical order already grows out of the impact, nothing changes); a piece that cracked
before it was joined waits for the front and then grows from the junction.  ``speed`` is the
median tip speed of the physical order (segment length over its time step), so the front moves
as the cracks did.  Every point then has a neighbour revealed no later (the one the front came
from), hence the revealed network stays connected to the impact at every t.  Pieces never joined
to an impact, and networks without one (mud, crackle: cracks there do appear everywhere at once),
keep their times.  All times are divided by ``max(1, max T)`` to stay in [0, 1].
"""

from __future__ import annotations

import heapq

import numpy as np
from numba import njit

from crackbake.graph import NetworkGraph, impact_sources, network_graph
from crackbake.nearest import components
from crackbake.network import Crack, CrackNetwork

__all__ = ["arrival_times", "front_speed", "grow_from_impacts"]


@njit(cache=True, nogil=True)
def _arrival(ptr, nbr, cost, t_node, start):  # pragma: no cover - compiled
    """Label-setting (Dijkstra) pass of T(v) = min over neighbours u of f(T(u)), with
    f(x) = t(v) when x <= t(v) and x + cost(u, v) otherwise.

    ``start`` (N,) holds the sources' times and inf elsewhere; f is nondecreasing and never
    below x, so popping the smallest label first is exact.  Ties pop by node.
    """
    T = start.copy()
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for v in range(len(T)):
        if T[v] < np.inf:
            heap.append((T[v], np.int64(v)))
    heapq.heapify(heap)
    while heap:
        d, u = heapq.heappop(heap)
        if d > T[u]:
            continue
        for e in range(ptr[u], ptr[u + 1]):
            v = nbr[e]
            # Already reached when it cracked: keep its physical time; else wait for the front.
            cand = t_node[v] if d <= t_node[v] else d + cost[e]
            if cand < T[v]:
                T[v] = cand
                heapq.heappush(heap, (cand, v))
    return T


def front_speed(graph: NetworkGraph, mask: np.ndarray | None = None) -> float:
    """Median tip speed of the physical order, mesh units per unit time.

    Segment length over the time between its ends, over the segments (``mask``) whose ends
    differ in time; the total length (the front crosses it all in unit time) when none do.
    """
    dt = np.abs(graph.seg_time[:, 1] - graph.seg_time[:, 0])
    keep = dt > 0 if mask is None else (dt > 0) & mask
    if not np.any(keep):
        total = float(graph.seg_len.sum() if mask is None else graph.seg_len[mask].sum())
        return max(total, 1e-300)
    return float(np.median(graph.seg_len[keep] / dt[keep]))


def arrival_times(graph: NetworkGraph, sources: np.ndarray) -> np.ndarray:
    """T per node (the module's front, from ``sources``); NaN on nodes no source reaches.

    Parameters
    ----------
    graph : NetworkGraph
    sources : (K,) int64
        Source nodes; each starts at the earliest node time of its connected component.

    Returns
    -------
    (N,) float64
        Not normalised (may exceed 1).
    """
    n = len(graph.positions)
    u, v = graph.seg_node[:, 0], graph.seg_node[:, 1]
    label = components(n, np.stack([u, v], axis=1))
    reached = np.isin(label, label[sources])
    earliest = np.full(label.max() + 1 if n else 0, np.inf)
    np.minimum.at(earliest, label, graph.node_time)
    start = np.full(n, np.inf)
    start[sources] = earliest[label[sources]]
    speed = front_speed(graph, reached[u])
    # CSR adjacency, both directions of every segment.
    src = np.concatenate([u, v])
    dst = np.concatenate([v, u])
    order = np.argsort(src, kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))]).astype(np.int64)
    cost = np.concatenate([graph.seg_len, graph.seg_len])[order] / speed
    T = _arrival(ptr, dst[order].astype(np.int64), cost, graph.node_time, start)
    return np.where(reached & np.isfinite(T), T, np.nan)


def grow_from_impacts(network: CrackNetwork) -> CrackNetwork:
    """The network with ``crack.time`` re-timed to grow out of its impacts (module docstring).

    Points, faces, widths and depths are unchanged; a network without impacts or cracks comes
    back as it is.  Deterministic; O(S log S) in the number of segments.
    """
    if not network.impacts or not network.cracks:
        return network
    g = network_graph(network)
    sources = impact_sources(g, network.impacts)
    T = arrival_times(g, sources)
    old = np.concatenate([c.time for c in network.cracks])
    new = T[g.point_node]
    new = np.where(np.isnan(new), old, new)
    new = new / max(1.0, float(new.max()))
    cracks, at = [], 0
    for c in network.cracks:  # one slice per crack
        k = len(c.points)
        cracks.append(Crack(id=c.id, points=c.points, faces=c.faces,
                            time=np.clip(new[at:at + k], 0.0, 1.0), width=c.width,
                            depth=c.depth))
        at += k
    return CrackNetwork(cracks=cracks, mesh=network.mesh, params=network.params,
                        impacts=network.impacts, solver_steps=network.solver_steps)
