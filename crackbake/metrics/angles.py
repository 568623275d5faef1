"""Junction angles of a crack network: how far a pattern has gone from T-junctions to Y-junctions.

At a junction where three cracks meet, the three angles between them add up to 360 degrees.  A
crack that grew into an older one meets it near 90 degrees while the older one runs straight
through: a T, whose largest angle is 180.  Where the three meet symmetrically (old mud, basalt
columns) all three are 120: a Y.  :func:`junction_angles` gives the **largest** of the three at
every degree-3 junction, so one number per junction runs from 180 (perfect T) down to 120
(perfect Y); its mean over a network is the measure Goehring et al. (Soft Matter 2010) follow
over drying cycles.

Each crack's direction is taken from the junction to the point ``scale`` further along it (arc
length, clamped to half the edge so that the two junctions of a short edge do not read each
other's end), and the three directions are projected into their best-fitting plane (the surface
tangent plane at the junction), so the measure works on a curved surface as on a plate.
"""

from __future__ import annotations

import numpy as np

from crackbake.graph import network_graph, node_chains
from crackbake.network import CrackNetwork

__all__ = ["ANGLE_SCALE_REL", "junction_angles", "mean_junction_angle", "relaxation_time"]

#: Default ``scale`` of :func:`junction_angles`: this fraction of the median edge length (the
#: arc between two junctions or a junction and a tip).
ANGLE_SCALE_REL = 0.25


def _at_arc(points: np.ndarray, s: float) -> np.ndarray:
    """The point at arc length ``s`` along the polyline ``points`` (N, 3), clamped to its end."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(seg)]
    s = min(max(s, 0.0), arc[-1])
    return np.array([np.interp(s, arc, points[:, k]) for k in range(3)])


def junction_angles(network: CrackNetwork, scale: float | None = None) -> np.ndarray:
    """The largest of the three angles at every degree-3 junction, degrees.

    Parameters
    ----------
    network : CrackNetwork
        Polylines meeting at shared points (how both solvers write junctions).
    scale : float, optional
        Arc length along each crack over which its direction is taken, mesh units; default
        :data:`ANGLE_SCALE_REL` x the median edge length.

    Returns
    -------
    (J,) float64
        120 for a symmetric Y, 180 for a T (two cracks in one line, the third anywhere), more
        than 180 where all three leave on one side of a line (a through-crack bent at the
        junction away from its stem).  Empty when the network has no junction of degree 3.
    """
    g = network_graph(network)
    chains, degree = node_chains(g)
    if not chains:
        return np.zeros(0)
    pos = g.positions
    lengths = np.array([np.linalg.norm(np.diff(pos[c], axis=0), axis=1).sum() for c in chains])
    if scale is None:
        scale = ANGLE_SCALE_REL * float(np.median(lengths))
    arms: dict[int, list[np.ndarray]] = {}
    for c, length in zip(chains, lengths, strict=True):
        s = min(float(scale), 0.5 * float(length))
        for end in (c, c[::-1]):
            if degree[end[0]] == 3:
                arms.setdefault(int(end[0]), []).append(_at_arc(pos[end], s) - pos[end[0]])
    nodes = [j for j, a in arms.items() if len(a) == 3]
    if not nodes:
        return np.zeros(0)
    v = np.array([arms[j] for j in nodes])  # (J, 3 arms, xyz)
    v /= np.maximum(np.linalg.norm(v, axis=2, keepdims=True), 1e-300)
    normal = np.linalg.svd(v)[2][:, 2]  # the plane the three directions lie closest to
    e1 = v[:, 0] - np.einsum("jk,jk->j", v[:, 0], normal)[:, None] * normal
    e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-300)
    e2 = np.cross(normal, e1)
    theta = np.sort(np.arctan2(np.einsum("jak,jk->ja", v, e2), np.einsum("jak,jk->ja", v, e1)),
                    axis=1)
    gaps = np.diff(np.c_[theta, theta[:, :1] + 2 * np.pi], axis=1)
    return np.degrees(gaps.max(axis=1))


def mean_junction_angle(network: CrackNetwork, scale: float | None = None) -> float:
    """Mean of :func:`junction_angles` (NaN without junctions), degrees."""
    a = junction_angles(network, scale)
    return float(a.mean()) if len(a) else float("nan")


def relaxation_time(generations, angles, limit: float = 120.0) -> float:
    """Relaxation time, in generations, of the mean junction angle over drying cycles.

    Fits ``angle(n) = limit + (angle(n0) - limit) * exp(-(n - n0) / tau)``, the form Goehring et
    al. fit (angles relaxing to the 120 degrees of a Y), by least squares on
    ``log(angle - limit)``.

    Parameters
    ----------
    generations : (K,) array-like
        Cycle numbers n (1 = the first drying), K >= 2.
    angles : (K,) array-like
        Mean junction angle at each, degrees; values at or below ``limit`` carry no information
        on the rate and are left out.
    limit : float
        The angle the pattern relaxes to, degrees.

    Returns
    -------
    float
        tau in generations; ``inf`` when the angle does not fall, NaN with under two usable
        points.
    """
    n = np.asarray(generations, np.float64)
    d = np.asarray(angles, np.float64) - limit
    ok = np.isfinite(d) & (d > 0)
    if ok.sum() < 2:
        return float("nan")
    slope = np.polyfit(n[ok], np.log(d[ok]), 1)[0]
    # A slope within rounding of 0 is a flat series, not a relaxation of 1e16 generations.
    return float(-1.0 / slope) if slope < -1e-9 else float("inf")
