"""Several impacts, small pieces and extremities (issue 18 §2, §3).

* Each star keeps the measures it has alone (``metrics.star`` per impact, on its own cracks):
  the impacts land one after the other, each with its own shadow radius and toughness, and a
  thin feature's finer sim mesh stays round it.
* Where stars overlap the later star's cracks stop at the earlier star's.
* An impact on a small separate piece is named in a warning.
* A finger (a capsule of radius 0.1 of the reach) hit at its tip gets a star wrapping it.

spot's impact points are extreme vertices of examples/spot.obj (Y up, head towards -Z): the
horn tip is its highest vertex, the ear tip its vertex of least x (the ears stick out
sideways), the flank a vertex in the middle of its +x side (see :data:`SPOT`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from crackbake.errors import CrackbakeWarning
from crackbake.io.mesh import load_mesh
from crackbake.metrics.star import impact_reach, polylines, star_metrics
from crackbake.params import Impact, RunParams
from crackbake.pipeline import solve
from crackbake.precompile import plate_obj
from crackbake.simulate.simmesh import Local, build_simmesh

ROOT = Path(__file__).resolve().parents[1]
SPOT_OBJ = ROOT / "examples" / "spot.obj"
TOL = 0.2  # issue 18: within +-20 % of the same impact alone


def _spot_points() -> dict[str, np.ndarray]:
    """spot's test points, found from the mesh: horn tip (highest vertex), ear tip (least x),
    flank (the +x side vertex nearest the body's middle height, behind the front legs)."""
    v = load_mesh(SPOT_OBJ).vertices
    side = v[(v[:, 2] > 0.15) & (v[:, 2] < 0.4) & (np.abs(v[:, 1]) < 0.15)]
    return {"horn": v[np.argmax(v[:, 1])], "ear": v[np.argmin(v[:, 0])],
            "flank": side[np.argmax(side[:, 0])]}


def _solve(path: Path, impacts, sim_faces: int | None = None, seed: int = 0, **kw):
    params = RunParams(mesh=path, preset="glass", seed=seed, sim_faces=sim_faces,
                       impacts=tuple(Impact(tuple(p), r) for p, r in impacts), **kw).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        network, _, solved = solve(load_mesh(path), resolved, relative, {})
    return network, solved


def _measure(network, solved, k: int, flat: bool) -> dict:
    imps = network.impacts
    others = [(o["point"], impact_reach(o["radius"])) for i, o in enumerate(imps) if i != k]
    sim = solved.sim
    return star_metrics(network, imps[k]["point"], impact_reach(imps[k]["radius"]),
                        None if flat else sim.vertices, None if flat else sim.faces,
                        others=others)


def _close(alone: dict, together: dict) -> None:
    assert together["arms"] == pytest.approx(alone["arms"], rel=TOL)
    assert together["straight_median"] == pytest.approx(alone["straight_median"], rel=TOL)
    # The tangential share of a small star is a noisy measure: the same impact alone spreads
    # over 0.17-0.37 (r 0.12) and 0.11-0.29 (r 0.08) with seeds 0-2, so it is held to that.
    assert together["tangential"] == pytest.approx(alone["tangential"], abs=0.1)
    assert together["beyond"] == pytest.approx(alone["beyond"], rel=TOL, abs=0.02)


def test_two_far_impacts_keep_their_stars(tmp_path):
    # Two impacts of different sizes (so different shadow radii) far apart on a plate: each
    # star's cracks get its own shadow radius, toughness and loading time.
    path = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    a, b = ((0.3, 0.5, 0.0), 0.12), ((0.76, 0.5, 0.0), 0.08)
    together, solved = _solve(path, [a, b], 30000)
    assert solved.result.stats["cracks"] > 8
    for k, imp in enumerate((a, b)):
        alone, solved_alone = _solve(path, [imp], 30000)
        m_alone = _measure(alone, solved_alone, 0, True)
        assert m_alone["arms"] >= 4
        _close(m_alone, _measure(together, solved, k, True))


def test_later_star_stops_at_the_earlier(tmp_path):
    # Two overlapping stars: the second impact lands once the first star is at rest, and its
    # cracks end on the first star's (junctions through which an earlier crack runs on).
    path = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    a, b = ((0.4, 0.5, 0.0), 0.12), ((0.6, 0.5, 0.0), 0.12)
    _, solved = _solve(path, [a, b], 30000)
    result = solved.result
    first, second = result.stats["impact_steps"]
    assert first == 0 < second
    switch = second / max(result.steps, 1)  # when the second impact landed
    early = [c for c in result.cracks if c.time.max() < switch]
    late = [c for c in result.cracks if c.time.min() >= switch]
    assert early and late
    ends: dict[tuple, int] = {}
    for c in early:
        for p in (c.points[0], c.points[-1]):
            ends[tuple(p.round(12))] = ends.get(tuple(p.round(12)), 0) + 1
    met = {tuple(p.round(12)) for c in late for p in (c.points[0], c.points[-1])
           if ends.get(tuple(p.round(12)), 0) >= 2}
    assert len(met) >= 2


def test_local_refinement_keeps_the_far_mesh():
    # A thin-feature refinement round one point leaves every node farther away exactly where
    # the uniform build puts it (so another impact's star there sees the same sim mesh).
    mesh = load_mesh(SPOT_OBJ)
    coarse = build_simmesh(mesh, target_faces=20000, seed=1)
    horn = _spot_points()["horn"]
    local = Local(centres=horn[None], radii=np.array([0.4]),
                  edges=np.array([coarse.edge_length / 2]))
    fine = build_simmesh(mesh, detail=coarse.edge_length, seed=1, local=local)
    assert len(fine.faces) > 1.2 * len(coarse.faces)
    assert fine.edge_at(horn) == coarse.edge_length / 2
    from scipy.spatial import cKDTree

    far = coarse.vertices[np.linalg.norm(coarse.vertices - horn, axis=1) > 0.6]
    d, _ = cKDTree(fine.vertices).query(far)
    assert d.max() < 1e-12
    near = np.linalg.norm(fine.vertices - horn, axis=1) < 0.3
    assert near.sum() > 3 * (np.linalg.norm(coarse.vertices - horn, axis=1) < 0.3).sum()


def test_small_piece_warns(tmp_path):
    # A plate and a small separate square beside it: an impact on the square is told so.
    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.02))
    chip = trimesh.creation.box(extents=(0.06, 0.06, 0.01))
    chip.apply_translation((0.7, 0.0, 0.0))
    path = tmp_path / "pieces.obj"
    trimesh.util.concatenate([plate, chip]).export(path)
    mesh = load_mesh(path)
    from crackbake.simulate.simmesh import build_simmesh as build
    from crackbake.simulate.stress import ImpactSource, stress_field

    sim = build(mesh, target_faces=20000)
    with pytest.warns(CrackbakeWarning, match=r"separate piece 0\.0\d+ across.*another --impact"):
        stress_field(sim, mesh, [ImpactSource((0.7, 0.0, 0.005), 0.1)])
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        stress_field(sim, mesh, [ImpactSource((0.0, 0.0, 0.01), 0.1)])


def _capsule_obj(path: Path, radius: float, length: float) -> tuple[Path, np.ndarray]:
    """A capsule of ``radius`` along z, ``length`` between its pole centres; its top pole."""
    t = trimesh.creation.capsule(height=length, radius=radius, count=[48, 48])
    t.export(path)
    v = np.asarray(t.vertices)
    return path, v[np.argmax(v[:, 2])]


@pytest.mark.slow
def test_finger_tip_star(tmp_path):
    # A capsule of radius 0.1 of the impact's reach, hit at its tip: a star wrapping it.
    reach = 1.0
    path, tip = _capsule_obj(tmp_path / "finger.obj", 0.1 * reach, 3.0 * reach)
    network, solved = _solve(path, [(tip, 2.0 * reach / np.pi)])
    m = _measure(network, solved, 0, False)
    assert m["arms"] >= 6
    assert m["radial_median"] >= 0.95


@pytest.mark.slow
def test_spot_flank_keeps_its_star_beside_the_horn():
    # The case of issue 18: spot's flank alone and with an impact on the horn tip.
    pts = _spot_points()
    flank, horn = (pts["flank"], None), (pts["horn"], None)
    together, solved = _solve(SPOT_OBJ, [flank, horn])
    for k, imp in enumerate((flank, horn)):
        alone, solved_alone = _solve(SPOT_OBJ, [imp])
        _close(_measure(alone, solved_alone, 0, False), _measure(together, solved, k, False))


def _plate_with_plate(path: Path, gap: float = 0.0) -> Path:
    """A 2 x 2 x 0.05 plate with a 0.6 x 0.6 x 0.05 plate lying on it (``gap`` above it)."""
    big = trimesh.creation.box(extents=(2.0, 2.0, 0.05))
    small = trimesh.creation.box(extents=(0.6, 0.6, 0.05))
    small.apply_translation((0.55, 0.0, 0.05 + gap))
    trimesh.util.concatenate([big, small]).export(path)
    return path


def test_touching_shells_crack_together(tmp_path):
    # Separate shells closer than a sim edge are one surface for the impact: its stress and
    # its star run from the big plate onto the small plate lying on it.
    from crackbake.simulate.stress import ImpactSource, stress_field

    path = _plate_with_plate(tmp_path / "plates.obj")
    mesh = load_mesh(path)
    sim = build_simmesh(mesh, target_faces=40000)
    on_small = sim.vertices[sim.faces].mean(axis=1)[:, 2] > 0.03
    src = ImpactSource((0.0, 0.0, 0.025), 0.5)
    field = stress_field(sim, mesh, [src])
    assert np.abs(field.stress[on_small]).max() > 0.5  # the impact's stress crossed over
    network, _ = _solve(path, [((0.0, 0.0, 0.025), 0.5)], 40000)
    pts = np.concatenate(polylines(network))
    top = pts[pts[:, 2] > 0.074]  # on the small plate's top face
    assert len(top) > 20
    # Most of its crack length runs radially from the impact, as on the big plate (a radial
    # segment's distance from the impact grows as fast as its length).
    radial = total = 0.0
    for p in polylines(network):
        q = p[p[:, 2] > 0.074]
        if len(q) < 2:
            continue
        seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
        grow = np.abs(np.diff(np.linalg.norm(q[:, :2], axis=1)))
        radial += seg[grow >= np.cos(np.radians(45.0)) * seg].sum()
        total += seg.sum()
    assert radial > 0.5 * total
    # A small plate held off the big one (a gap of several sim edges) is left alone.
    apart = _plate_with_plate(tmp_path / "apart.obj", gap=0.2)
    mesh = load_mesh(apart)
    sim = build_simmesh(mesh, target_faces=40000)
    far = sim.vertices[sim.faces].mean(axis=1)[:, 2] > 0.2
    assert not stress_field(sim, mesh, [src]).stress[far].any()


def _solve_warned(path: Path, impacts, sim_faces: int) -> tuple:
    """:func:`_solve` keeping the CrackbakeWarnings' texts."""
    params = RunParams(mesh=path, preset="glass", seed=0, sim_faces=sim_faces,
                       impacts=tuple(Impact(tuple(p), r) for p, r in impacts)).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        network, _, solved = solve(load_mesh(path), resolved, relative, {})
    said = [str(w.message) for w in caught if issubclass(w.category, CrackbakeWarning)]
    return network, solved, [s for s in said if s.startswith("no star formed")]


def test_no_star_warns_once(tmp_path):
    # An impact of 3 sim edges' radius on a plate cannot space a star's arms: the run says so in
    # one line, with the arms it measured and the fix.  The same plate hit with a radius the sim
    # mesh resolves grows a star and says nothing.
    path = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    network, solved, said = _solve_warned(path, [((0.5, 0.5, 0.0), 0.03)], 20000)
    arms = star_metrics(network, network.impacts[0]["point"],
                        impact_reach(network.impacts[0]["radius"]),
                        solved.sim.vertices, solved.sim.faces)["arms"]
    assert arms < 5
    assert len(said) == 1
    assert f"(0.5, 0.5, 0) {arms};" in said[0]
    assert "--detail" in said[0]

    network, solved, said = _solve_warned(path, [((0.5, 0.5, 0.0), 0.12)], 20000)
    arms = star_metrics(network, network.impacts[0]["point"],
                        impact_reach(network.impacts[0]["radius"]),
                        solved.sim.vertices, solved.sim.faces)["arms"]
    assert arms >= 5
    assert said == []


def test_no_star_names_only_the_starless_impact(tmp_path):
    # Two impacts, one resolved, one too small: only the second is named.
    path = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    _, _, said = _solve_warned(path, [((0.3, 0.5, 0.0), 0.12), ((0.8, 0.5, 0.0), 0.03)], 20000)
    assert len(said) == 1
    assert "at 1 impact(s)" in said[0] and "(0.8, 0.5, 0)" in said[0]
    assert "(0.3, 0.5, 0)" not in said[0]
