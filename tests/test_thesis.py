"""The MSc-thesis crack method on jittered plates with hand-made stress fields."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import sim_plate

from crackbake.simulate.solver import SolverParams
from crackbake.simulate.solver.thesis import (
    relative_toughness,
    solve_thesis,
    turning_angle_per_length,
)


def plate(n: int, seed: int = 0) -> SimpleNamespace:
    """The conftest sim plate (jitter 0.3) with boundary flags, the mean edge length, and asset
    faces on a coarse 4x4 grid over it, so asset boundaries cross it."""
    sim = sim_plate(n, jitter=0.3, seed=seed)
    v, faces = sim.vertices, sim.faces
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    cell = np.minimum((v[faces].mean(1)[:, :2] * 4).astype(np.int64), 3)
    sim.boundary = ~((v[:, :2] > 1e-9) & (v[:, :2] < 1 - 1e-9)).all(1)
    sim.edge_length = float(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean())
    sim.asset_face = cell[:, 0] * 4 + cell[:, 1]
    sim.node_face = np.zeros(len(v), dtype=np.int64)
    sim.node_bary = np.zeros((len(v), 3))
    return sim


def directional_field(sim, direction=(1.0, 0.0, 0.0), s: float = 1.0) -> SimpleNamespace:
    d = np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    m = len(sim.faces)
    stress = np.broadcast_to(s * np.outer(d, d), (m, 3, 3)).copy()
    return SimpleNamespace(
        stress=stress, growth=np.zeros_like(stress), weight=np.ones(m), impacts=[]
    )


def impact_field(sim, centre, radius: float) -> SimpleNamespace:
    """Glass impact: w (r r^T + 1.25 c c^T), w = 2 cos(d / r) inside pi r / 2 (docs/method.md)."""
    cen = sim.vertices[sim.faces].mean(1)
    rel = cen - np.asarray(centre)
    dist = np.linalg.norm(rel, axis=1)
    w = np.where(dist <= np.pi * radius / 2, 2 * np.cos(dist / radius), 0.0)
    r = rel / np.maximum(dist, 1e-12)[:, None]
    c = np.cross(np.array([0.0, 0.0, 1.0]), r)
    stress = w[:, None, None] * (
        np.einsum("ea,eb->eab", r, r) + 1.25 * np.einsum("ea,eb->eab", c, c)
    )
    m = len(sim.faces)
    return SimpleNamespace(
        stress=stress,
        growth=np.zeros_like(stress),
        weight=np.ones(m),
        impacts=[{"centre": centre, "radius": radius}],
    )


def node_index(sim, points):
    lookup = {tuple(p): i for i, p in enumerate(sim.vertices)}
    return np.array([lookup[tuple(p)] for p in points])


def check_contract(sim, res):
    m = len(sim.faces)
    assert res.vertices.shape == sim.vertices.shape and np.array_equal(res.faces, sim.faces)
    assert np.array_equal(res.asset_face, sim.asset_face)
    assert res.stress_initial.shape == (m, 3, 3)
    assert np.array_equal(res.stress_final, res.stress_initial)
    assert res.separation.shape == (len(sim.vertices),)
    # Edge -> incident sim faces, to check that each segment lies in its recorded asset face.
    edge_faces: dict[tuple[int, int], set[int]] = {}
    for e, f in enumerate(sim.faces):
        for k in range(3):
            a, b = sorted((int(f[k]), int(f[(k + 1) % 3])))
            edge_faces.setdefault((a, b), set()).add(int(sim.asset_face[e]))
    for c in res.cracks:
        n = len(c.points)
        assert n >= 2
        for arr in (c.asset_faces, c.time, c.width, c.depth):
            assert arr.shape == (n,)
        assert np.isfinite(c.width).all() and (c.width >= 0).all()
        assert ((c.time >= 0) & (c.time <= 1)).all()
        nodes = node_index(sim, c.points)
        for i in range(n - 1):
            a, b = sorted((int(nodes[i]), int(nodes[i + 1])))
            assert c.asset_faces[i] in edge_faces[(a, b)]
        assert c.asset_faces[-1] == c.asset_faces[-2]
    widths = np.concatenate([c.width for c in res.cracks]) if res.cracks else np.zeros(0)
    if widths.size:
        diag = np.linalg.norm(np.ptp(sim.vertices, axis=0))
        assert widths.max() == pytest.approx(1e-3 * diag)  # default crack_width


def crack_nodes(sim, res):
    return [node_index(sim, c.points) for c in res.cracks]


def test_helpers():
    assert turning_angle_per_length(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]])) == 0
    stairs = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 1, 0], [2, 2, 0.0]])
    assert turning_angle_per_length(stairs) == pytest.approx(3 * np.pi / 2 / 4)
    v = np.array([0.0, 2.0, 4.0, 10.0, -1.0])
    b = np.array([False, False, False, True, False])
    assert relative_toughness(v, b, 1.5) == pytest.approx(1.5 * 3.0)
    assert relative_toughness(np.zeros(3), np.zeros(3, bool), 1.0) == np.inf


def test_impact_cracks_start_near_the_impact():
    sim = plate(40)
    centre, radius = np.array([0.4, 0.55, 0.0]), 0.12
    res = solve_thesis(
        sim, impact_field(sim, centre, radius), SolverParams(method="thesis", max_cracks=20)
    )
    check_contract(sim, res)
    assert len(res.cracks) >= 3
    starts = np.array([c.points[np.argmin(c.time)] for c in res.cracks])
    d = np.linalg.norm(starts - centre, axis=1)
    assert d[0] < radius  # the first crack opens where the field peaks
    assert (d < np.pi * radius / 2 + 2 * sim.edge_length).all()  # none outside the loaded disc
    # Start times follow crack order.
    assert np.all(np.diff([c.time.min() for c in res.cracks]) > 0)


def test_directional_tension_cracks_run_perpendicular():
    sim = plate(40)
    res = solve_thesis(
        sim,
        directional_field(sim, (1.0, 0.0, 0.0)),
        SolverParams(method="thesis", max_cracks=15, max_crack_length=0.5),
    )
    check_contract(sim, res)
    assert len(res.cracks) >= 5
    for c in res.cracks:
        span = c.points[-1] - c.points[0]
        # Tension along x opens cracks along y.
        assert abs(span[0]) < 0.35 * abs(span[1]), span
    total = sum(np.linalg.norm(np.diff(c.points, axis=0), axis=1).sum() for c in res.cracks)
    assert total > 3.0


def test_limits_respected():
    sim = plate(40)
    field = directional_field(sim, (1.0, 0.3, 0.0))
    res = solve_thesis(
        sim, field, SolverParams(method="thesis", max_cracks=4, max_crack_length=0.2)
    )
    assert len(res.cracks) == 4
    steps = int(round(0.2 / sim.edge_length))
    for c in res.cracks:
        assert len(c.points) <= steps + 1
    assert res.steps <= 4 * steps
    res = solve_thesis(sim, field, SolverParams(method="thesis", max_cracks=50, max_steps=30))
    assert res.steps <= 30
    # Default length: 25 steps per crack, like the thesis.
    res = solve_thesis(sim, field, SolverParams(method="thesis", max_cracks=3))
    assert max(len(c.points) for c in res.cracks) <= 26


def test_cracks_end_at_cracks_and_boundary_without_crossing():
    sim = plate(30)
    res = solve_thesis(
        sim,
        directional_field(sim, (1.0, 0.2, 0.0)),
        SolverParams(method="thesis", max_cracks=60, max_crack_length=3.0, toughness=0.5),
    )
    check_contract(sim, res)
    nodes = crack_nodes(sim, res)
    assert len(nodes) >= 10
    owners: dict[int, list[tuple[int, bool]]] = {}
    for k, ns in enumerate(nodes):
        assert len(set(ns.tolist())) == len(ns) or ns[0] == ns[-1]  # no self-revisit inside
        for i, v in enumerate(ns):
            owners.setdefault(int(v), []).append((k, i in (0, len(ns) - 1)))
    for v, users in owners.items():
        interior = [k for k, is_end in users if not is_end]
        assert len(interior) <= 1, (v, users)  # a node is inside at most one crack
    # Long cracks across the plate end at the boundary or on other cracks.
    ends = res.stats["ends_boundary"] + res.stats["ends_junction"]
    assert res.stats["ends_boundary"] > 0 and res.stats["ends_junction"] > 0
    assert ends >= res.stats["ends_free"]
    for ns in nodes:
        assert not sim.boundary[ns[1:-1]].any()  # boundary nodes only as ends


def test_deterministic():
    sim = plate(30, seed=3)
    field = impact_field(sim, np.array([0.5, 0.5, 0.0]), 0.2)
    p = SolverParams(method="thesis", max_cracks=30, seed=7)
    a, b = solve_thesis(sim, field, p), solve_thesis(sim, field, p)
    assert len(a.cracks) == len(b.cracks)
    for ca, cb in zip(a.cracks, b.cracks, strict=True):
        for name in ("points", "asset_faces", "time", "width", "depth"):
            assert np.array_equal(getattr(ca, name), getattr(cb, name))
    assert np.array_equal(a.separation, b.separation)


def test_turning_angle_is_jagged_but_bounded():
    sim = plate(40)
    res = solve_thesis(
        sim,
        directional_field(sim, (1.0, 0.0, 0.0)),
        SolverParams(method="thesis", max_cracks=15, max_crack_length=0.5),
    )
    rate = np.mean([turning_angle_per_length(c.points) for c in res.cracks])
    # Edge-following cracks turn every step, but not like a staircase (pi/2 per edge).
    assert 0 < rate * sim.edge_length < np.pi / 2


def test_width_tapers_at_free_tips():
    sim = plate(40)
    res = solve_thesis(
        sim,
        impact_field(sim, np.array([0.5, 0.5, 0.0]), 0.15),
        SolverParams(method="thesis", max_cracks=10, crack_width=0.01),
    )
    widths = np.concatenate([c.width for c in res.cracks])
    assert widths.max() == pytest.approx(0.01)
    free = res.stats["ends_free"]
    zeros = sum(int(c.width[0] == 0) + int(c.width[-1] == 0) for c in res.cracks)
    assert zeros >= free > 0
    for c in res.cracks:
        assert np.allclose(c.depth, 0.5 * c.width)


def test_curved_surface_cracks_follow_the_surface():
    # Half-cylinder of radius 0.5 around z; axial tension opens cracks running around it.
    sim = plate(40)
    x, y = sim.vertices[:, 0].copy(), sim.vertices[:, 1].copy()
    sim.vertices = np.column_stack([0.5 * np.cos(np.pi * x), 0.5 * np.sin(np.pi * x), y])
    res = solve_thesis(
        sim,
        directional_field(sim, (0.0, 0.0, 1.0)),
        SolverParams(method="thesis", max_cracks=10, max_crack_length=1.0),
    )
    check_contract(sim, res)
    assert len(res.cracks) >= 3
    for c in res.cracks:
        assert np.ptp(c.points[:, 2]) < 0.35 * np.linalg.norm(c.points[-1] - c.points[0])


def test_bad_parameters_are_refused():
    from crackbake.errors import CrackbakeError

    sim = plate(6)
    field = directional_field(sim)
    for bad in ({"toughness": 0.0}, {"tip_factor": 1.5}, {"relax_share": -0.1}):
        with pytest.raises(CrackbakeError):
            solve_thesis(sim, field, SolverParams(method="thesis", **bad))
