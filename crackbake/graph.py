"""A crack network as a graph: coincident polyline points merged into nodes, segments as edges.

Both solvers end a polyline on another crack's point (iben at every junction, thesis on a point
*inside* an earlier crack), so points at the same position are one node.  The graph is what
:func:`crackbake.simulate.timing.grow_from_impacts` re-times a network on and what
:func:`crackbake.metrics.growth.growth_curve` measures; it lives here, beside
:mod:`crackbake.network`, so the simulation does not depend on the metrics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackbake.network import CrackNetwork

__all__ = ["MERGE_REL", "NetworkGraph", "impact_sources", "network_graph", "node_chains",
           "source_nodes"]

#: Points closer than this fraction of the network's bounding-box diagonal are one node.
MERGE_REL = 1e-9


@dataclass(frozen=True, eq=False)
class NetworkGraph:
    """The network as a graph over merged points.

    Attributes
    ----------
    positions : (N, 3) float64
        One position per node, mesh units.
    point_node : (P,) int64
        Node of every polyline point, cracks concatenated in order.
    seg_node : (S, 2) int64
        The two nodes of every segment (crack order, then along each crack).
    seg_time : (S, 2) float64
        ``crack.time`` at each end of every segment, as the polylines hold it.
    seg_len : (S,) float64
        Segment lengths, mesh units.
    seg_point : (S,) int64
        Index (into the concatenated points) of each segment's first point.
    node_time : (N,) float64
        Earliest ``crack.time`` of each node's points (when that place first cracked).
    """

    positions: np.ndarray
    point_node: np.ndarray
    seg_node: np.ndarray
    seg_time: np.ndarray
    seg_len: np.ndarray
    seg_point: np.ndarray
    node_time: np.ndarray


def network_graph(network: CrackNetwork) -> NetworkGraph:
    """Merge coincident points of ``network`` into nodes and list its segments.

    Points are merged when they round to the same cell of size ``MERGE_REL`` x the bounding-box
    diagonal (exact duplicates, which is how both solvers write junctions, always merge).
    """
    cracks = network.cracks
    if not cracks:
        z = np.zeros((0, 2), np.int64)
        return NetworkGraph(np.zeros((0, 3)), np.zeros(0, np.int64), z, np.zeros((0, 2)),
                            np.zeros(0), np.zeros(0, np.int64), np.zeros(0))
    pts = np.concatenate([c.points for c in cracks])
    times = np.concatenate([c.time for c in cracks])
    counts = np.array([len(c.points) for c in cracks], np.int64)
    diag = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    q = max(diag, 1e-300) * MERGE_REL
    keys = np.round((pts - pts.min(0)) / q).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel().astype(np.int64)
    start = np.ones(len(pts), bool)
    start[np.cumsum(counts) - 1] = False
    ia = np.flatnonzero(start)
    node_time = np.full(len(first), np.inf)
    np.minimum.at(node_time, inverse, times)
    return NetworkGraph(
        positions=pts[first],
        point_node=inverse,
        seg_node=np.stack([inverse[ia], inverse[ia + 1]], 1),
        seg_time=np.stack([times[ia], times[ia + 1]], 1),
        seg_len=np.linalg.norm(pts[ia + 1] - pts[ia], axis=1),
        seg_point=ia,
        node_time=node_time,
    )


def source_nodes(graph: NetworkGraph, points, radii=None) -> np.ndarray:
    """The node where the crack of each impact starts: (K,) int64.

    Of the nodes within ``radii[k]`` (straight-line) of ``points[k]``, the one that cracked
    first (ties: the nearest); the nearest node when none is that close or ``radii`` is None.
    The node nearest an impact is often a late crack passing by (the first crack of an impact
    starts where the stress peaks, a little off the point), hence the earliest within reach.

    Parameters
    ----------
    graph : NetworkGraph
    points : (K, 3) array-like
        Impact points, mesh units.
    radii : (K,) array-like or None
        Impact radii, mesh units.
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if len(graph.positions) == 0 or len(p) == 0:
        return np.zeros(0, np.int64)
    d = np.linalg.norm(graph.positions[None, :, :] - p[:, None, :], axis=2)
    out = np.argmin(d, axis=1).astype(np.int64)
    if radii is not None:
        for k, r in enumerate(np.asarray(radii, np.float64).reshape(-1)):  # K impacts: few
            near = np.flatnonzero(d[k] <= r)
            if len(near):
                out[k] = near[np.lexsort((d[k, near], graph.node_time[near]))[0]]
    return out


def impact_sources(graph: NetworkGraph, impacts: list[dict]) -> np.ndarray:
    """:func:`source_nodes` of a network's ``impacts`` (``[{"point", "radius", ...}]``)."""
    if not impacts:
        return np.zeros(0, np.int64)
    return source_nodes(graph, [i["point"] for i in impacts],
                        [float(i.get("radius", 0.0)) for i in impacts])


def node_chains(graph: NetworkGraph) -> tuple[list[np.ndarray], np.ndarray]:
    """The network's edges between junctions: maximal runs of nodes of degree 2.

    Each chain starts and ends at a node whose degree (distinct neighbours) is not 2: a junction,
    a free tip or a crack ending on the mesh boundary.  Loops made only of degree-2 nodes (a
    closed crack with no junction) are left out.

    Returns
    -------
    chains : list of (K_i,) int64
        Node indices along each chain, K_i >= 2, each chain listed once (from its lower-numbered
        end, a loop from a junction back to itself once in either direction).
    degree : (N,) int64
        Distinct neighbours of every node.
    """
    n = len(graph.positions)
    e = np.sort(graph.seg_node, axis=1)
    e = e[e[:, 0] != e[:, 1]]
    e = np.unique(e, axis=0) if len(e) else e.reshape(0, 2)
    degree = np.bincount(e.ravel(), minlength=n).astype(np.int64)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    order = np.argsort(src, kind="stable")
    dst = dst[order]
    ptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))]).astype(np.int64)
    used = set()
    chains = []
    for start in np.flatnonzero(degree != 2):  # junctions and tips: a few per cell
        for first in dst[ptr[start]:ptr[start + 1]]:
            if (int(start), int(first)) in used:
                continue
            walk = [int(start), int(first)]
            while degree[walk[-1]] == 2:
                a, b = dst[ptr[walk[-1]]:ptr[walk[-1] + 1]]
                walk.append(int(b if a == walk[-2] else a))
            used.add((walk[-1], walk[-2]))  # the same chain walked from its other end
            used.add((walk[0], walk[1]))
            chains.append(np.array(walk, np.int64))
    return chains, degree
