"""How connected the network revealed by ``crack.time`` is while it grows.

A shader that reveals every crack point with ``time <= t`` (segments interpolated, as the bake
interpolates them) shows, at each moment ``t``, a part of the network.  For an impact, that part
should hang together with the crack at the impact: an isolated piece popping up mid-air reads as
noise in an animation.  :func:`growth_curve` measures the share of the revealed length that is
connected to the impact (or, without one, to the largest revealed piece) for ``t`` in [0, 1].

Junctions: polylines end on each other (iben ends every polyline at a junction, and thesis ends a
crack on a point *inside* an earlier one), so points at the same position are one node of the
graph (:func:`crackbake.graph.network_graph` merges them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from crackbake.graph import NetworkGraph, impact_sources, network_graph, source_nodes
from crackbake.network import CrackNetwork

__all__ = ["GrowthCurve", "NetworkGraph", "growth_curve", "impact_sources", "network_graph",
           "source_nodes"]

@dataclass(frozen=True)
class GrowthCurve:
    """Revealed and connected length over time.

    Attributes
    ----------
    t : (K,) float64
        Sample times in [0, 1].
    revealed : (K,) float64
        Length with ``time <= t`` (partial segments interpolated), mesh units.
    connected : (K,) float64
        The part of ``revealed`` connected to the reference (the impact's node(s), or the
        largest revealed component when there is no impact), mesh units.
    mode : str
        ``"impact"`` or ``"largest"``: what ``connected`` is connected to.
    """

    t: np.ndarray
    revealed: np.ndarray
    connected: np.ndarray
    mode: str

    @property
    def share(self) -> np.ndarray:
        """connected / revealed per sample (NaN where nothing is revealed)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.revealed > 0, self.connected / self.revealed, np.nan)

    @property
    def weighted_mean(self) -> float:
        """Share weighted by the revealed length: sum(connected) / sum(revealed) over samples."""
        total = float(self.revealed.sum())
        return float(self.connected.sum() / total) if total > 0 else float("nan")

    def min_after(self, t0: float = 0.1) -> float:
        """Smallest share over the samples with ``t >= t0`` and something revealed."""
        s = self.share[(self.t >= t0) & (self.revealed > 0)]
        return float(s.min()) if len(s) else float("nan")

    def summary(self) -> dict:
        """``{"mode", "weighted_mean", "min_t>=0.1", "share_at": {t: share}}`` for reports."""
        marks = {}
        for m in (0.1, 0.25, 0.5, 0.75, 1.0):
            k = int(np.argmin(np.abs(self.t - m)))
            marks[f"{m:g}"] = round(float(self.share[k]), 4)
        return {"mode": self.mode, "weighted_mean": round(self.weighted_mean, 4),
                "min_t>=0.1": round(self.min_after(0.1), 4), "share_at": marks}


def growth_curve(network: CrackNetwork, impacts: list[dict] | None = None,
                 samples: int = 101) -> GrowthCurve:
    """Share of the length revealed at time t that is connected to the impact, for t in [0, 1].

    Parameters
    ----------
    network : CrackNetwork
    impacts : list of dict or None
        ``[{"point": [x, y, z], "radius": r}]`` (mesh units); default the network's own
        ``impacts``.  With none, the reference is the largest revealed component (by length)
        at each t.
    samples : int
        Number of evenly spaced sample times, >= 2.

    Returns
    -------
    GrowthCurve
        At each t, a segment is revealed whole when both end times are <= t, from its earlier
        end over the fraction ``(t - t_a) / (t_b - t_a)`` when only one is; whole segments join
        their nodes, a partial one hangs on its earlier node.  The impact's component is the one
        holding each impact's :func:`source_nodes` node (nothing is connected before that node
        is revealed).
    """
    g = network_graph(network)
    src = impact_sources(g, network.impacts if impacts is None else impacts)
    mode = "impact" if len(src) else "largest"
    ts = np.linspace(0.0, 1.0, int(samples))
    revealed, connected = np.zeros(len(ts)), np.zeros(len(ts))
    n = len(g.positions)
    ta, tb = g.seg_time[:, 0], g.seg_time[:, 1]
    lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
    early = np.where(ta <= tb, g.seg_node[:, 0], g.seg_node[:, 1])
    for k, t in enumerate(ts):  # one vectorised pass per sample time
        full = hi <= t
        part = (lo <= t) & ~full
        frac = np.where(part, (t - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0)
        u, v = g.seg_node[full, 0], g.seg_node[full, 1]
        adj = coo_matrix((np.ones(len(u)), (u, v)), shape=(n, n))
        ncomp, label = connected_components(adj, directed=False)
        comp_len = np.bincount(label[u], g.seg_len[full], minlength=ncomp).astype(np.float64)
        comp_len += np.bincount(label[early[part]], (frac * g.seg_len)[part], minlength=ncomp)
        revealed[k] = comp_len.sum()
        if mode == "impact":
            # A source node that nothing revealed touches yet carries no length.
            connected[k] = comp_len[np.unique(label[src])].sum()
        else:
            connected[k] = comp_len.max() if ncomp else 0.0
    return GrowthCurve(t=ts, revealed=revealed, connected=connected, mode=mode)
