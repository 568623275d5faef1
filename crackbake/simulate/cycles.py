"""Wetting and drying cycles: a shrinkage network re-cracked along its own cracks, T toward Y.

Goehring, Conroy, Akhter, Clegg & Routh ("Evolving mud-crack patterns", Soft Matter 2010) wetted
and dried layers of bentonite 25 times.  Rewetting closes the cracks but does not heal them
fully, so every new drying cracks the layer again along the previous pattern; the order in which
the cracks open changes from one drying to the next, and where the cracks meet, the junctions
drift: the angles between cracks go from 90 degrees (T-junctions, a young crack meeting an older
one square) toward 120 (Y-junctions) with a relaxation time of about 4 generations.

:func:`redry` applies that to a solved network (docs/solver.md, "Drying cycles"):

* the pattern is kept as a graph: edges (crack runs between junctions) and junctions, so every
  drying re-opens the same cells (the cracks are seeded along the previous ones);
* near a re-opening junction the healed layer is stressed about equally in every direction (no
  crack there yet sets a direction), and the three cracks joining there meet where they cost the
  least new crack length: the Fermat point of three *anchors*, the points a reach ``R`` along
  each edge beyond which the cracks follow their old paths.  At the Fermat point the three meet
  at 120 degrees (or, for a corner of 120 degrees or more, the corner itself);
* a crack can only stray so far from the weakened old path in one drying, and a junction whose
  cracks re-open in the old order has no reason to move at all: each junction moves a random
  fraction (uniform in ``[0, 2 m]``, ``m`` the mobility) of the way to its Fermat point, so the
  pattern relaxes over generations, not in one drying;
* the arms follow: a point at arc ``t`` from the junction moves by ``(1 - t / R)`` of the
  junction's step (the crack's own wiggles are kept), then everything moved is put back on the
  surface (closest point), so the same code runs on a plate and on a curved mesh.

The topology (cells, crack ids, point counts) and every point's time, width and depth are kept,
so the growth time map reveals the evolved network exactly as connected as the first one; only
positions (and the faces holding them) change.  Cost: O(points near junctions) per cycle, far
below one solve.
"""

from __future__ import annotations

import warnings

import numpy as np

from crackbake.errors import CrackbakeWarning
from crackbake.graph import network_graph, node_chains
from crackbake.network import Crack, CrackNetwork
from crackbake.params.ranges import CYCLES_MAX

__all__ = ["CYCLES_MAX", "MOBILITY", "REACH_REL", "redry"]

#: Mean fraction of the way to its relaxed (Fermat) position a junction moves per drying; with
#: the junctions' anchors themselves drifting as neighbours move, the mean angle relaxes with a
#: time of about 4 generations (benchmarks/bench_cycles.py), Goehring et al.'s figure.
MOBILITY = 0.3
#: Reach R of a junction along each edge, as a fraction of the median edge length (capped at
#: :data:`ARM_SHARE` of the edge itself): about the layer thickness for mud, whose cells are a
#: few thicknesses across.
REACH_REL = 0.45
#: Largest share of an edge one junction moves, so the two ends of an edge never overlap.
ARM_SHARE = 0.4
#: Seed stream of the cycles' random fractions (apart from the solver's own streams).
_STREAM = 0x0C7C1E5


def _fermat(anchors: np.ndarray, start: np.ndarray, iterations: int = 40) -> np.ndarray:
    """Fermat point (least summed distance) of each triangle, Weiszfeld's iteration.

    Parameters
    ----------
    anchors : (J, 3, 3) float64
        Three points per junction.
    start : (J, 3) float64
        Starting guesses (the junctions).

    Returns
    -------
    (J, 3) float64
        The point where the three directions meet at 120 degrees, or the triangle's corner whose
        angle is 120 degrees or more (where the iteration converges to that corner).
    """
    x = start.copy()
    scale = np.linalg.norm(anchors[:, 0] - anchors[:, 1], axis=1) + 1e-300
    for _ in range(iterations):
        d = np.linalg.norm(anchors - x[:, None, :], axis=2)
        w = 1.0 / np.maximum(d, 1e-9 * scale[:, None])
        x = np.einsum("ja,jak->jk", w, anchors) / w.sum(axis=1, keepdims=True)
    return x


def _arms(chains: list[np.ndarray], degree: np.ndarray) -> dict[int, list[np.ndarray]]:
    """The three edges of every degree-3 junction, each as its node run leaving the junction."""
    arms: dict[int, list[np.ndarray]] = {}
    for c in chains:
        for end in (c, c[::-1]):
            if degree[end[0]] == 3:
                arms.setdefault(int(end[0]), []).append(end)
    return {j: a for j, a in arms.items() if len(a) == 3}


def redry(
    network: CrackNetwork,
    vertices: np.ndarray,
    faces: np.ndarray,
    cycles: int,
    seed: int = 0,
    mobility: float = MOBILITY,
    reach_rel: float = REACH_REL,
) -> CrackNetwork:
    """The network after ``cycles`` dryings in all (the first is the solve that made it).

    Parameters
    ----------
    network : CrackNetwork
        A solved shrinkage network (junctions as shared points), on the mesh below.
    vertices, faces : (V, 3) float64, (F, 3) int64
        The surface the cracks lie on (the asset mesh its ``faces`` index).
    cycles : int
        Dryings, >= 1; 1 returns ``network`` itself.
    seed : int
        Random seed of the junctions' per-drying moves.
    mobility : float
        Mean fraction of the way to its Fermat point a junction moves per drying (0..0.5).
    reach_rel : float
        Reach of a junction along its edges, fraction of the median edge length.

    Returns
    -------
    CrackNetwork
        Same cracks, ids, point counts, times, widths and depths; moved points and their faces.
    """
    if cycles <= 1 or not network.cracks:
        return network
    from crackbake.geometry import SurfaceIndex

    g = network_graph(network)
    chains, degree = node_chains(g)
    arms = _arms(chains, degree)
    if not arms:
        warnings.warn(
            f"--cycles {cycles} changed nothing: the network has no junction where three cracks "
            "meet (its cracks close no cells); give more cracks (a lower --toughness or a higher "
            "--max-cracks) or drop --cycles",
            CrackbakeWarning,
            stacklevel=2,
        )
        return network
    pos = g.positions.copy()
    lengths = [float(np.linalg.norm(np.diff(pos[c], axis=0), axis=1).sum()) for c in chains]
    reach_abs = reach_rel * float(np.median(lengths))
    nodes = np.array(sorted(arms), np.int64)
    runs = [arms[int(j)][k] for j in nodes for k in range(3)]  # junction-major, 3 arms each
    # The runs flattened once: every drying measures and moves them with whole-array steps.
    flat = np.concatenate(runs)
    count = np.array([len(r) for r in runs], np.int64)
    first = np.r_[0, np.cumsum(count)[:-1]]
    run_of = np.repeat(np.arange(len(runs)), count)
    junction_of = run_of // 3
    rng = np.random.default_rng([int(seed), _STREAM])
    surface = SurfaceIndex(vertices, faces)
    node_face = np.full(len(pos), -1, np.int64)
    for _ in range(cycles - 1):
        p = pos[flat]
        step_len = np.r_[0.0, np.linalg.norm(np.diff(p, axis=0), axis=1)]
        step_len[first] = 0.0
        arc = np.cumsum(step_len)
        arc -= arc[first][run_of]
        reach = np.minimum(reach_abs, ARM_SHARE * arc[first + count - 1])
        r = reach[run_of]
        beyond = np.flatnonzero(arc >= r)  # each run's last point is beyond its reach
        hit = beyond[np.searchsorted(run_of[beyond], np.arange(len(runs)))]
        hit = np.maximum(hit, first + 1)
        span = np.maximum(arc[hit] - arc[hit - 1], 1e-300)
        t = np.clip((reach - arc[hit - 1]) / span, 0.0, 1.0)[:, None]
        anchors = (1.0 - t) * p[hit - 1] + t * p[hit]
        target = _fermat(anchors.reshape(-1, 3, 3), pos[nodes])
        step = rng.uniform(0.0, 2.0 * mobility, len(nodes))[:, None] * (target - pos[nodes])
        inner = (arc > 0) & (arc < r)
        moved = np.concatenate([nodes, flat[inner]])
        weight = np.concatenate([np.ones(len(nodes)), 1.0 - arc[inner] / r[inner]])
        who = np.concatenate([np.arange(len(nodes)), junction_of[inner]])
        pos[moved] += weight[:, None] * step[who]
        face, _, on = surface.closest(pos[moved])
        pos[moved] = on
        node_face[moved] = face
    points = pos[g.point_node]
    new_face = node_face[g.point_node]
    cracks, at = [], 0
    for c in network.cracks:
        k = len(c.points)
        f = new_face[at:at + k]
        cracks.append(Crack(id=c.id, points=points[at:at + k], faces=np.where(f >= 0, f, c.faces),
                            time=c.time, width=c.width, depth=c.depth))
        at += k
    return CrackNetwork(cracks=cracks, mesh=network.mesh, params=network.params,
                        impacts=network.impacts, solver_steps=network.solver_steps)
