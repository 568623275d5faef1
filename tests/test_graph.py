"""Network graph helpers (crackbake.graph): edges between junctions."""

from __future__ import annotations

import numpy as np

from crackbake.graph import network_graph, node_chains
from crackbake.network import Crack, CrackNetwork


def net(*polylines) -> CrackNetwork:
    cracks = []
    for k, p in enumerate(polylines):
        p = np.c_[np.asarray(p, float), np.zeros(len(p))]
        n = len(p)
        cracks.append(Crack(id=k, points=p, faces=np.zeros(n), time=np.zeros(n),
                            width=np.ones(n), depth=np.ones(n)))
    return CrackNetwork(cracks=cracks, mesh={})


def test_a_t_junction_has_three_edges_and_a_loop_one():
    # Through-crack split at the junction (as the solver writes it) plus a stem of 3 points.
    g = network_graph(net([(0, 0), (0.5, 0), (1, 0)], [(1, 0), (2, 0)], [(1, 0), (1, 1), (1, 2)],
                          [(1, 2), (2, 3), (1, 4), (0, 3), (1, 2)]))
    chains, degree = node_chains(g)
    ends = sorted(tuple(sorted(map(tuple, g.positions[[c[0], c[-1]], :2]))) for c in chains)
    assert ends == [((0, 0), (1, 0)), ((1, 0), (1, 2)), ((1, 0), (2, 0)), ((1, 2), (1, 2))]
    assert sorted(len(c) for c in chains) == [2, 3, 3, 5]
    junction = np.flatnonzero((g.positions[:, :2] == (1, 0)).all(axis=1))[0]
    assert degree[junction] == 3 and np.bincount(degree).tolist() == [0, 2, 5, 2]  # 9 nodes
