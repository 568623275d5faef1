"""The impact's stress-shadow radius follows the geodesic circle round it (issue 12 §1): the
contour length, the shadow on a flat plate and round a thin capsule, and the finer sim mesh a
thin feature asks for."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from conftest import make_mesh, sim_plate

from crackbake.io.mesh import load_mesh
from crackbake.params import Impact, RunParams
from crackbake.pipeline import solve
from crackbake.simulate.stress import ImpactSource, impact_detail, iso_length, stress_field
from crackbake.simulate.stress.fields import (
    IMPACT_REFINE_MAX,
    IMPACT_SHADOW_ARMS,
    IMPACT_SHADOW_MIN_EDGES,
)

A = 0.1  # capsule radius
N_AROUND = 48  # capsule sections round the axis


def _capsule(edge: float = 0.02):
    """A capsule of radius A along z (pole at z = 1 + A), subdivided to ``edge``; its top pole."""
    t = trimesh.creation.capsule(height=2.0, radius=A, count=[N_AROUND, N_AROUND])
    v, f = trimesh.remesh.subdivide_to_size(t.vertices, t.faces, max_edge=edge)
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


def _sim(v, f, edge):
    return SimpleNamespace(vertices=v, faces=f, asset_face=np.arange(len(f)), edge_length=edge)


def test_iso_length_of_a_flat_circle():
    sim = sim_plate(120)
    d = np.linalg.norm(sim.vertices - [0.5, 0.5, 0.0], axis=1)
    for r in (0.1, 0.3):
        # Chords of a circle through 1/120 triangles: short by well under 1 %.
        assert iso_length(sim.vertices, sim.faces, d, r) == pytest.approx(2 * np.pi * r, rel=0.01)
    d[0] = np.inf  # a far node the distance never reached changes nothing near the circle
    assert iso_length(sim.vertices, sim.faces, d, 0.3) == pytest.approx(2 * np.pi * 0.3, rel=0.01)
    assert iso_length(sim.vertices, sim.faces, d, 5.0) == 0.0  # no face reaches that level


def test_shadow_follows_a_thin_feature():
    v, f = _capsule()
    mesh = make_mesh(v, f)
    pole = v[np.argmax(v[:, 2])]
    reach = 1.0  # its 0.3-reach circle lies on the cylinder: 0.3 > pi A / 2 from the pole
    src = ImpactSource(tuple(pole), 2 * reach / np.pi)
    circle = 2 * N_AROUND * A * np.sin(np.pi / N_AROUND)  # the capsule's polygon
    field = stress_field(_sim(v, f, 0.01), mesh, [src])
    assert field.shadow_radius == pytest.approx(circle / IMPACT_SHADOW_ARMS, rel=0.02)
    assert field.shadow_radius < 0.5 * 0.12 * reach  # the flat value, 0.12 reach, left behind
    # Never below 2 sim edges (a coarser sim mesh).
    assert stress_field(_sim(v, f, 0.03), mesh, [src]).shadow_radius == pytest.approx(0.06)
    # A default-size sim mesh too coarse for that spacing asks for a finer one, at most 2x.
    assert impact_detail(field, 0.01) is None
    want = field.shadow_radius / IMPACT_SHADOW_MIN_EDGES
    assert impact_detail(field, 0.013) == pytest.approx(want)
    assert impact_detail(field, 0.05) == pytest.approx(0.05 / IMPACT_REFINE_MAX)


def test_flat_impact_keeps_its_shadow_and_sim():
    # The 0.3-reach circle (radius 0.094) spans 11 sim edges: fast marching's distance runs
    # long by too little to pull its length below 15 x 0.12 reach (0.955 of 2 pi x 0.094).
    sim = sim_plate(120)
    mesh = make_mesh(sim.vertices, sim.faces)
    field = stress_field(sim, mesh, [ImpactSource((0.5, 0.5, 0), 0.2)])
    assert field.shadow_radius == 0.12 * 0.5 * np.pi * 0.2
    assert impact_detail(field, sim.edge_length) is None


def test_run_refines_only_a_default_size_sim_mesh(tmp_path):
    # A thin capsule beside a broad 3 x 3 square: the default 100k sim faces give edges of
    # about 0.015, so the capsule's shadow (0.042) spans under 3 of them.
    v, f = _capsule(0.05)
    sq = np.array([[-1.5, -1.5, -2.0], [1.5, -1.5, -2.0], [1.5, 1.5, -2.0], [-1.5, 1.5, -2.0]])
    path = tmp_path / "capsule.obj"
    trimesh.Trimesh(np.concatenate([v, sq]), np.concatenate([f, len(v) + np.array(
        [[0, 1, 2], [0, 2, 3]])]), process=False).export(path)
    mesh = load_mesh(path)
    pole = tuple(v[np.argmax(v[:, 2])])
    edges = {}
    for name, size in (("default", {}), ("given", {"sim_faces": 20000})):
        params = RunParams(mesh=path, preset="glass", impacts=(Impact(pole, 0.6),), max_steps=50,
                           **size).validate()
        resolved, relative = params.resolved()
        assert relative["sim_size_set"] == bool(size)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, _, solved = solve(mesh, resolved, relative, {})
        sim = solved.sim
        edges[name] = (sim.edge_at(pole), solved.field.shadow_radius, sim.edge_length,
                       sim.edge_at(sq[0]))
    # Default: the capsule's circle (0.63 / 15 = 0.042) over 4 edges, the 2x cap not reached,
    # round the impact only: the square keeps the default edge.
    edge, shadow, coarse, far = edges["default"]
    assert edge == pytest.approx(shadow / IMPACT_SHADOW_MIN_EDGES, rel=0.1)
    assert far == coarse > 1.2 * edge
    # Given by the user: kept as asked even though the shadow spans fewer edges.
    edge, shadow, _, _ = edges["given"]
    assert shadow / edge < IMPACT_SHADOW_MIN_EDGES
