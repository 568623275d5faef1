"""Touching shells crack together in the iben solver (issue 18 §3; docs/solver.md, "Small
pieces and touching shells"): a crack tip that reaches a node with a mate on another shell
(``solve.py::_mates``) continues on that shell (``loop.py::cross_shells``)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from crackbake.io.mesh import load_mesh
from crackbake.metrics.star import polylines
from crackbake.params import Impact, RunParams
from crackbake.pipeline import solve
from crackbake.simulate.solver.iben.solve import _mates

TOP = 0.025  # the big plate's top face
HAIR = 0.002  # the small plate's gap above it (a tenth of a sim edge)


def _plates(path: Path, gap: float) -> Path:
    """A 2 x 2 x 0.05 plate with a 0.6 x 0.6 x 0.05 plate lying ``gap`` above it."""
    big = trimesh.creation.box(extents=(2.0, 2.0, 0.05))
    small = trimesh.creation.box(extents=(0.6, 0.6, 0.05))
    small.apply_translation((0.55, 0.0, 2 * TOP + gap))
    trimesh.util.concatenate([big, small]).export(path)
    return path


def _solve(path: Path, method: str = "iben"):
    params = RunParams(mesh=path, preset="glass", seed=0, sim_faces=40000, method=method,
                       impacts=(Impact((0.0, 0.0, TOP), 0.5),)).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        network, _, solved = solve(load_mesh(path), resolved, relative, {})
    return network, solved


def _on_small(network) -> tuple[list[np.ndarray], np.ndarray]:
    """The polylines reaching the small plate, and the big plate's crack points."""
    paths = polylines(network)
    small = [p[p[:, 2] > TOP + 0.5 * HAIR] for p in paths]
    big = np.concatenate([p[p[:, 2] <= TOP + 0.5 * HAIR] for p in paths])
    return [p for p in small if len(p) >= 2], big


def test_mates_join_shells_within_a_sim_edge():
    a = trimesh.creation.box(extents=(1.0, 1.0, 1.0)).subdivide().subdivide()
    b = a.copy()
    b.apply_translation((1.0 + 0.01, 0.0, 0.0))  # touching faces 0.01 apart
    both = trimesh.util.concatenate([a, b])
    X, F = np.asarray(both.vertices, float), np.asarray(both.faces, np.int64)
    mate = _mates(X, F, 0.1)
    na = len(a.vertices)
    has = np.flatnonzero(mate >= 0)
    assert len(has) > 0
    # Only across the contact, to the other shell, within the link, and the nearest there.
    assert np.all(np.abs(X[has, 0] - 0.5 - 0.005) < 0.1)
    assert np.all((has < na) != (mate[has] < na))
    assert np.all(np.linalg.norm(X[has] - X[mate[has]], axis=1) <= 0.1)
    for i in has:
        other = np.arange(na, len(X)) if i < na else np.arange(na)
        assert np.linalg.norm(X[i] - X[mate[i]]) == np.linalg.norm(X[other] - X[i], axis=1).min()
    # One shell, or shells apart by more than the link: no mates.
    assert np.all(_mates(np.asarray(a.vertices, float), np.asarray(a.faces, np.int64), 0.1) < 0)
    assert np.all(_mates(X, F, 0.005) < 0)


def test_cracks_cross_onto_a_touching_plate(tmp_path):
    network, solved = _solve(_plates(tmp_path / "plates.obj", HAIR))
    assert solved.result.stats["shell_crossings"] > 0
    small, big = _on_small(network)
    h = float(solved.sim.edge_length)
    # The small plate's cracks continue the big plate's: most of their length runs right over
    # a big-plate crack (in plan), and they start at it.  Before the solver crossed shells,
    # its cracks started from its own stress, 42 % of their length over a big-plate crack.
    tree = cKDTree(big[:, :2])
    over = total = 0.0
    starts = 0
    for p in small:
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        d, _ = tree.query(0.5 * (p[1:, :2] + p[:-1, :2]))
        over += seg[d < 1.5 * h].sum()
        total += seg.sum()
        starts += bool(tree.query(p[[0, -1], :2])[0].min() < 1.5 * h)
    assert total > 1.0
    assert over > 0.75 * total
    assert starts >= 8
    # The small plate's top face cracks too (the crossed cracks run round its rim).
    assert len(np.concatenate(small)[np.concatenate(small)[:, 2] > 3 * TOP - 0.001]) > 10
    # Deterministic: the same run gives the same network.
    again, _ = _solve(tmp_path / "plates.obj")
    assert len(polylines(again)) == len(polylines(network))
    for p, q in zip(polylines(again), polylines(network), strict=True):
        np.testing.assert_array_equal(p, q)


def test_a_plate_held_off_gets_no_cracks(tmp_path):
    # 0.2 above the big plate (several sim edges): no mates, no stress, no cracks.
    network, solved = _solve(_plates(tmp_path / "apart.obj", 0.2))
    assert solved.result.stats["shell_crossings"] == 0
    pts = np.concatenate(polylines(network))
    assert len(pts) > 100
    assert not np.any(pts[:, 2] > TOP + 0.1)


def _sheets(path: Path, gap: float) -> Path:
    """Two 1 x 2 sheets in z = 0 meeting edge to edge along x = 0 (``gap`` apart)."""
    quads = [trimesh.Trimesh([[x0, -1, 0], [x0 + 1, -1, 0], [x0 + 1, 1, 0], [x0, 1, 0]],
                             [[0, 1, 2], [0, 2, 3]]) for x0 in (-1.0, gap)]
    trimesh.util.concatenate(quads).export(path)
    return path


def test_cracks_cross_a_seam_between_sheets(tmp_path):
    # Sheets meeting edge to edge (armour plates, tiles): a crack reaching the seam ends on the
    # boundary of its sheet and goes on across it.  Before, the other sheet cracked from its
    # own stress along the seam: 2 of 8 arms reaching the seam went on across it.
    path = _sheets(tmp_path / "seam.obj", HAIR)
    params = RunParams(mesh=path, preset="glass", seed=0, sim_faces=40000,
                       impacts=(Impact((-0.3, 0.0, 0.0), 0.5),)).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        network, _, solved = solve(load_mesh(path), resolved, relative, {})
    h = float(solved.sim.edge_length)
    paths = polylines(network)
    ends = [(e, (p[:, 0] < 0.5 * HAIR).all()) for p in paths for e in (p[0], p[-1])]
    left = np.array([e[1] for e, is_left in ends if is_left and e[0] > -0.5 * h])
    right = np.array([e[1] for e, is_left in ends if not is_left and e[0] < HAIR + 0.5 * h])
    assert len(left) >= 6 and len(right) > 0
    went_on = sum(np.abs(right - y).min() < 1.5 * h for y in left)
    # Seeds 0-2 at the position grain: 8/10, 5/7, 5/8 ends went on, the solver crossed 6, 5
    # and 6 times (a crossing whose polyline runs on across the seam leaves no end there).
    assert went_on >= 0.6 * len(left)
    # and the solver's crossing carried them, not cracks of the other sheet's own that happen to
    # end near them
    assert solved.result.stats["shell_crossings"] >= 0.5 * len(left)
