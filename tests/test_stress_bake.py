"""Stress-field bake (crackbake.bake.stress): tensors in the texel's tangent frame, principal
values and directions, separation, seams; the real solvers end to end.

The reference values are derived analytically from the UV layout: a plane of two unit squares
whose UV islands are a rotated copy and a mirrored, rotated copy, so each island's tangent frame
and each texel's world position are known in closed form.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from crackbake.bake.stress import bake_stress, initial_separation
from crackbake.bake.uv import UVMesh
from crackbake.errors import CrackbakeError
from crackbake.simulate.simmesh import build_simmesh
from tests.conftest import make_mesh, plate_mesh

RES = 256
SCALE = 0.3  # UV size of a unit square


def _rot(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


# Island map uv = centre + SCALE * J (p - origin), p = world (x, y); J conformal (+-det 1).
ISLANDS = [
    {"centre": np.array([0.27, 0.5]), "origin": np.array([0.5, 0.5]), "J": _rot(30.0)},
    {"centre": np.array([0.73, 0.5]), "origin": np.array([1.5, 0.5]),
     "J": np.diag([-1.0, 1.0]) @ _rot(-50.0)},  # mirrored: w = -1
]


def _frame(island: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """World e1 (+u), e2 (+v) and bitangent sign w of an island, from dp/duv = J^-1 / SCALE."""
    inv = np.linalg.inv(island["J"])
    e1 = np.append(inv[:, 0] / np.linalg.norm(inv[:, 0]), 0.0)
    e2 = np.append(inv[:, 1] / np.linalg.norm(inv[:, 1]), 0.0)
    w = float(np.sign(np.dot(np.cross([0.0, 0.0, 1.0], e1), e2)))
    return e1, e2, w


def _two_islands():
    """Asset (two unit squares side by side in z = 0, a UV seam at x = 1), UV mesh, tangents."""
    quad = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    xy = np.concatenate([quad, quad + [1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    uv = np.concatenate([isl["centre"] + SCALE * (xy[4 * k:4 * k + 4] - isl["origin"])
                         @ isl["J"].T for k, isl in enumerate(ISLANDS)])
    vertices = np.column_stack([xy, np.zeros(8)])
    mesh = make_mesh(vertices, faces, uv)
    tangents = np.zeros((8, 4))
    for k, isl in enumerate(ISLANDS):
        e1, _, w = _frame(isl)
        tangents[4 * k:4 * k + 4] = np.append(e1, w)
    uvmesh = UVMesh(vertices=vertices, faces=faces, uv=uv, normals=mesh.normals,
                    vertex_map=np.arange(8), method="kept", overlap_fraction=0.0, padding_px=0)
    return mesh, uvmesh, tangents


def _texel_world(res: int = RES):
    """World (x, y) of every texel centre per island (row 0 = v = 1) and its island mask."""
    r, c = np.mgrid[0:res, 0:res]
    uv = np.stack([(c + 0.5) / res, 1.0 - (r + 0.5) / res], axis=-1)
    out = []
    for k, isl in enumerate(ISLANDS):
        p = (uv - isl["centre"]) / SCALE @ np.linalg.inv(isl["J"]).T + isl["origin"]
        inner = ((p[..., 0] > k) & (p[..., 0] < k + 1) & (p[..., 1] > 0) & (p[..., 1] < 1))
        out.append((p, inner))
    return out


def _directional(d, s: float) -> np.ndarray:
    d = np.asarray(d, np.float64) / np.linalg.norm(d)
    return s * np.outer(d, d)


def _result(sim, stress0: np.ndarray, stress1: np.ndarray, sep: np.ndarray, tau: float = 2.0):
    """SolverResult-like inputs on ``sim`` (no splits: final mesh = initial mesh)."""
    return SimpleNamespace(vertices=sim.vertices, faces=sim.faces, asset_face=sim.asset_face,
                           stress_initial=stress0, stress_final=stress1, separation=sep,
                           stats={"tau": tau, "method": "thesis"})


@pytest.fixture(scope="module")
def islands():
    mesh, uvmesh, tangents = _two_islands()
    sim = build_simmesh(mesh, detail=0.06, seed=2)
    return mesh, uvmesh, tangents, sim


def test_uniform_field_in_rotated_and_mirrored_island_frames(gl_ctx, islands):
    _, uvmesh, tangents, sim = islands
    m = len(sim.faces)
    d0, d1 = np.array([1.0, 2.0, 0.0]), np.array([-3.0, 1.0, 0.0])
    s0 = np.broadcast_to(_directional(d0, 2.5), (m, 3, 3)).copy()
    s1 = np.broadcast_to(_directional(d1, -1.5) + _directional(d0, 0.5), (m, 3, 3)).copy()
    maps = bake_stress(uvmesh, _result(sim, s0, s1, np.zeros(len(sim.vertices))), RES,
                       tangents=tangents, ctx=gl_ctx)
    assert maps.inside.sum() > 0.15 * RES * RES
    for k, (_, inner) in enumerate(_texel_world()):
        e1, e2, w = _frame(ISLANDS[k])
        assert w == (1.0 if k == 0 else -1.0)
        sel = inner & maps.inside
        assert sel.sum() > 0.9 * inner.sum()
        for field, s in ((maps.stress0, s0[0]), (maps.stress, s1[0])):
            local = np.array([[e1 @ s @ e1, e1 @ s @ e2], [e2 @ s @ e1, e2 @ s @ e2]])
            vals, vecs = np.linalg.eigh(local)
            lead = vecs[:, 1] * np.sign(vecs[0, 1])
            np.testing.assert_allclose(field.xx[sel], local[0, 0], atol=2e-5)
            np.testing.assert_allclose(field.yy[sel], local[1, 1], atol=2e-5)
            np.testing.assert_allclose(field.xy[sel], local[0, 1], atol=2e-5)
            np.testing.assert_allclose(field.p1[sel], vals[1], atol=2e-5)
            np.testing.assert_allclose(field.p2[sel], vals[0], atol=2e-5)
            np.testing.assert_allclose(field.dir[sel], np.broadcast_to(lead, (sel.sum(), 2)),
                                       atol=1e-4)
    # A pure uniaxial tension 2.5 along d0: principal values 2.5 and 0 in every frame.
    assert np.allclose(maps.stress0.p1[maps.inside], 2.5, atol=2e-5)
    assert np.allclose(maps.stress0.p2[maps.inside], 0.0, atol=2e-5)
    # Gutters are filled from the islands: no background value left anywhere.
    assert np.allclose(maps.stress0.p1, 2.5, atol=2e-5)
    assert (maps.stress0.p1 >= maps.stress0.p2).all()


def test_fields_continuous_in_the_world_across_a_uv_seam(gl_ctx, islands):
    _, uvmesh, tangents, sim = islands
    x, y = sim.vertices[:, 0], sim.vertices[:, 1]
    sep = 0.3 + x + 0.5 * y  # linear: interpolation reproduces it exactly
    c = sim.vertices[sim.faces].mean(axis=1)
    d0, d1 = _directional([1.0, 0.0, 0.0], 1.0), _directional([1.0, 1.0, 0.0], 1.0)
    smooth = (1.0 + c[:, 0])[:, None, None] * d0 + (0.5 * c[:, 1])[:, None, None] * d1
    res = 1024  # texels 0.0033 world units wide: neighbours across the seam nearly coincide
    maps = bake_stress(uvmesh, _result(sim, smooth, smooth, sep), res, tangents=tangents,
                       ctx=gl_ctx)
    near_seam = []
    for k, (p, inner) in enumerate(_texel_world(res)):
        e1, e2, _ = _frame(ISLANDS[k])
        sel = inner & maps.inside
        px, py = p[..., 0][sel], p[..., 1][sel]
        np.testing.assert_allclose(maps.stress.sep[sel], 0.3 + px + 0.5 * py, atol=2e-4)
        f = maps.stress
        world = (f.xx[sel, None, None] * np.outer(e1, e1) + f.yy[sel, None, None] * np.outer(e2, e2)
                 + f.xy[sel, None, None] * (np.outer(e1, e2) + np.outer(e2, e1)))
        expected = (1.0 + px)[:, None, None] * d0 + (0.5 * py)[:, None, None] * d1
        # Nodal (area-weighted) averaging of a per-face field: off by about the edge length
        # times the gradient (<= 0.06 here) in the interior; boundary nodes lean inwards.
        interior = (np.abs(px - 1.0) < 0.9) & (py > 0.1) & (py < 0.9)
        assert np.abs(world - expected)[interior].max() < 0.06
        band = (np.abs(px - 1.0) < 0.004) & (py > 0.1) & (py < 0.9)
        # What nodal averaging left over: continuous on the surface, seam or not.
        near_seam.append((py[band], (world - expected)[band]))
    # The same world point seen from either island: the same residual.
    (ya, wa), (yb, wb) = near_seam
    assert len(ya) > 20 and len(yb) > 20
    j = np.abs(ya[:, None] - yb[None, :]).argmin(axis=1)
    close = np.abs(ya - yb[j]) < 0.003
    assert close.sum() > 50
    assert np.abs(wa[close] - wb[j[close]]).max() < 0.006


def test_initial_separation_matches_nodes_and_is_baked(gl_ctx, islands):
    _, uvmesh, tangents, sim = islands
    m = len(sim.faces)
    s0 = np.broadcast_to(_directional([1.0, 0.0, 0.0], 3.0), (m, 3, 3)).copy()
    res = _result(sim, s0, s0, np.zeros(len(sim.vertices)), tau=1.5)
    nodal = initial_separation(sim.vertices, sim.faces, s0, res.stats)
    # Boundary nodes of a uniform field carry its unbalanced force: |f| = A S g summed, and
    # the separation v+ = 0.5 sum m(f+) - ... is positive and proportional to the strength.
    assert (nodal >= -1e-12).all() and nodal.max() > 0
    double = initial_separation(sim.vertices, sim.faces, 2 * s0, res.stats)
    np.testing.assert_allclose(double, 2 * nodal, rtol=1e-9, atol=1e-12)
    iben = initial_separation(sim.vertices, sim.faces, s0, {"tau": 1.5})
    assert np.isfinite(iben).all() and iben.max() > nodal.max()  # divided by tau * h, h < 1
    # The thesis solver's own starting separation (before its relaxation moves it): the same.
    from crackbake.simulate.solver.thesis.driver import _separation

    np.testing.assert_allclose(nodal, _separation(sim.vertices, sim.faces, s0)[1] / 1.5,
                               rtol=1e-12, atol=1e-12)
    # Passed as the final field, it bakes the same map as the one derived for the initial one.
    res.separation = nodal
    maps = bake_stress(uvmesh, res, 128, tangents=tangents, ctx=gl_ctx)
    np.testing.assert_allclose(maps.stress0.sep, maps.stress.sep, atol=1e-6)


def test_refuses_missing_tangents_and_a_foreign_sim_mesh(gl_ctx, islands):
    _, uvmesh, tangents, sim = islands
    m = len(sim.faces)
    z = np.zeros((m, 3, 3))
    with pytest.raises(CrackbakeError, match="tangents"):
        bake_stress(uvmesh, _result(sim, z, z, np.zeros(len(sim.vertices))), 64, ctx=gl_ctx)
    moved = SimpleNamespace(**vars(sim))
    moved.vertices = sim.vertices + [0.0, 0.3, 0.0]
    with pytest.raises(CrackbakeError, match="outside the asset face"):
        bake_stress(uvmesh, _result(moved, z, z, np.zeros(len(sim.vertices))), 64,
                    tangents=tangents, ctx=gl_ctx)


@pytest.mark.parametrize("method", ["iben", "thesis"])
def test_real_solver_on_a_plate_end_to_end(gl_ctx, method):
    from crackbake.simulate.solver import SolverParams
    from crackbake.simulate.solver.iben import solve_iben
    from crackbake.simulate.solver.thesis import solve_thesis
    from crackbake.simulate.stress import ShrinkSource, stress_field

    mesh = plate_mesh(2)
    sim = build_simmesh(mesh, target_faces=3000, seed=1)
    field = stress_field(sim, mesh, [ShrinkSource(strength=2.0)], seed=1)
    solve = solve_iben if method == "iben" else solve_thesis
    result = solve(sim, field, SolverParams(method=method, seed=1, max_cracks=20))
    assert result.cracks
    uvmesh = UVMesh(vertices=mesh.vertices, faces=mesh.faces, uv=mesh.uv, normals=mesh.normals,
                    vertex_map=np.arange(len(mesh.vertices)), method="kept",
                    overlap_fraction=0.0, padding_px=0)
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(mesh.vertices), 1))  # uv = (x, y)
    maps = bake_stress(uvmesh, result, 128, tangents=tangents, initial=sim, ctx=gl_ctx)
    assert maps.inside.all()  # the plate fills its UV square
    # Initial shrinkage 2 (I - n n^T): xx = yy = 2, xy = 0 everywhere, any direction.
    np.testing.assert_allclose(maps.stress0.xx, 2.0, atol=1e-5)
    np.testing.assert_allclose(maps.stress0.yy, 2.0, atol=1e-5)
    np.testing.assert_allclose(maps.stress0.xy, 0.0, atol=1e-5)
    assert (maps.stress.p1 >= maps.stress.p2).all()
    # A unit direction wherever p1 > p2, and (0, 0) where the stress has none (the same every
    # way: p1 = p2, as in the untouched shrinkage field).
    for f in (maps.stress0, maps.stress):
        has = f.p1 - f.p2 > 1e-4
        np.testing.assert_allclose(np.linalg.norm(f.dir[has], axis=-1), 1.0, atol=1e-5)
        none = (f.xx == f.yy) & (f.xy == 0)
        assert (f.dir[none] == 0).all()
    if method == "thesis":
        assert none.mean() > 0.5  # thesis keeps the shrinkage field: mostly no direction
    if method == "iben":
        # Cracks released stress: the final field is lower on average than the initial one.
        assert maps.stress.p1.mean() < maps.stress0.p1.mean() - 0.05
        assert np.isfinite(maps.stress0.sep).all() and maps.stress0.sep.max() > 0
    else:
        # thesis keeps its stress (it relaxes the scalar separation only).
        np.testing.assert_allclose(maps.stress.xx, maps.stress0.xx, atol=1e-6)
        assert (maps.stress.sep >= 0).all() and (maps.stress0.sep > 0).any()


def test_rows_prepared_on_another_thread_bake_the_same_maps(gl_ctx):
    # The pipeline computes stress_rows on a thread while the crack bake runs.
    from concurrent.futures import ThreadPoolExecutor

    from crackbake.bake.stress import stress_rows
    from crackbake.simulate.solver import SolverParams
    from crackbake.simulate.solver.iben import solve_iben
    from crackbake.simulate.stress import ShrinkSource, stress_field

    mesh = plate_mesh(2)
    sim = build_simmesh(mesh, target_faces=3000, seed=2)
    field = stress_field(sim, mesh, [ShrinkSource(strength=2.0)], seed=2)
    result = solve_iben(sim, field, SolverParams(seed=2, max_cracks=20))
    uvmesh = UVMesh(vertices=mesh.vertices, faces=mesh.faces, uv=mesh.uv, normals=mesh.normals,
                    vertex_map=np.arange(len(mesh.vertices)), method="kept",
                    overlap_fraction=0.0, padding_px=0)
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(mesh.vertices), 1))
    with ThreadPoolExecutor(1) as pool:
        rows = pool.submit(stress_rows, uvmesh, result, tangents, sim).result()
    ahead = bake_stress(uvmesh, result, 96, tangents=tangents, initial=sim, ctx=gl_ctx,
                        rows=rows)
    here = bake_stress(uvmesh, result, 96, tangents=tangents, initial=sim, ctx=gl_ctx)
    assert np.array_equal(ahead.inside, here.inside) and ahead.inside.any()
    for name in ("stress0", "stress"):
        a, b = getattr(ahead, name), getattr(here, name)
        for channel in ("xx", "yy", "xy", "p1", "p2", "dir", "sep"):
            assert np.array_equal(getattr(a, channel), getattr(b, channel)), (name, channel)


def test_initial_field_carried_onto_the_split_mesh_exactly(gl_ctx):
    """iben splits edges and nodes; the initial field drawn through the final mesh must be the
    same picture as drawn through the initial mesh (it is piecewise linear on both)."""
    from crackbake.simulate.solver import SolverParams
    from crackbake.simulate.solver.iben import solve_iben
    from crackbake.simulate.stress import ImpactSource, stress_field

    mesh = plate_mesh(2)
    sim = build_simmesh(mesh, target_faces=3000, seed=3)
    field = stress_field(sim, mesh, [ImpactSource(point=(0.4, 0.55, 0.0), radius=0.2)], seed=3)
    result = solve_iben(sim, field, SolverParams(seed=3, max_cracks=10))
    assert len(result.vertices) > len(sim.vertices)  # there were splits
    uvmesh = UVMesh(vertices=mesh.vertices, faces=mesh.faces, uv=mesh.uv, normals=mesh.normals,
                    vertex_map=np.arange(len(mesh.vertices)), method="kept",
                    overlap_fraction=0.0, padding_px=0)
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(mesh.vertices), 1))
    split = bake_stress(uvmesh, result, 192, tangents=tangents, initial=sim, ctx=gl_ctx)
    unsplit = SimpleNamespace(vertices=sim.vertices, faces=sim.faces, asset_face=sim.asset_face,
                              stress_initial=result.stress_initial,
                              stress_final=result.stress_initial,
                              separation=np.zeros(len(sim.vertices)), stats=result.stats,
                              separation_initial=result.separation_initial)
    # iben reports the separation it started from (with its flaws), one value per initial node.
    assert result.separation_initial.shape == (len(sim.vertices),)
    whole = bake_stress(uvmesh, unsplit, 192, tangents=tangents, ctx=gl_ctx)
    scale = float(np.abs(whole.stress0.p1).max())
    assert scale > 1.0  # the impact peaks at 2 x strength
    for name in ("xx", "yy", "xy", "p1", "p2", "sep"):
        np.testing.assert_allclose(getattr(split.stress0, name), getattr(whole.stress0, name),
                                   atol=1e-4 * scale, err_msg=name)
    # ... while the final field differs where the cracks released it.
    assert np.abs(split.stress.p1 - whole.stress0.p1).max() > 0.1 * scale


def test_reported_initial_separation_and_gutter_limit(gl_ctx, islands):
    _, uvmesh, tangents, sim = islands
    m, n = len(sim.faces), len(sim.vertices)
    s = np.broadcast_to(_directional([0.0, 1.0, 0.0], 1.0), (m, 3, 3)).copy()
    res = _result(sim, s, s, np.zeros(n))
    res.separation_initial = 0.25 + sim.vertices[:, 1]  # a solver that reports it: used as is
    maps = bake_stress(uvmesh, res, 128, tangents=tangents, dilate_px=2, ctx=gl_ctx)
    p, inner = _texel_world(128)[0]
    sel = inner & maps.inside
    np.testing.assert_allclose(maps.stress0.sep[sel], 0.25 + p[..., 1][sel], atol=2e-4)
    # Gutter texels farther than 2 texels from an island keep the zero background.
    from scipy.ndimage import distance_transform_edt

    far = distance_transform_edt(~maps.inside) > 2.5
    assert far.any()
    assert (maps.stress0.p1[far] == 0).all() and (maps.stress0.sep[far] == 0).all()
    near = ~maps.inside & (distance_transform_edt(~maps.inside) <= 2.0)
    assert np.allclose(maps.stress0.p1[near], 1.0, atol=1e-5)


def _wavy_uvmesh():
    """A 6 x 6 plate, bumped, with one face of no area and two faces copied by UV wraps."""
    mesh = plate_mesh(6)
    v = mesh.vertices.copy()
    v[:, 2] = 0.1 * np.sin(3 * v[:, 0]) * np.cos(2 * v[:, 1])
    n = len(v)
    # A face of no area (three corners at one point) with a UV triangle of its own.
    v = np.vstack([v, np.tile([0.5, 0.5, 0.3], (3, 1))])
    f = np.vstack([mesh.faces, [[n, n + 1, n + 2]]])
    uv = np.vstack([mesh.uv, [[0.1, 0.1], [0.3, 0.1], [0.1, 0.3]]])
    normals = np.vstack([mesh.normals, np.tile([0.0, 0.0, 1.0], (3, 1))])
    return UVMesh(vertices=v, faces=f, uv=uv, normals=normals,
                  vertex_map=np.arange(len(v)), method="kept", overlap_fraction=0.0,
                  padding_px=0, wraps=np.array([[3, 1, 0], [len(f) - 1, 0, -1], [40, -1, 1]],
                                               np.int64))


def test_vertex_rows_are_the_unindexed_rows_of_the_asset_faces():
    # The indexed draw of a proxy's stress bake: data[index] holds, bit for bit, the rows
    # draw_data and wrapped_rows give for the asset's own faces (the unindexed draw's buffer).
    from crackbake.bake.stress import vertex_rows, wrapped_rows
    from crackbake.bake.stress_fields import draw_data

    uvmesh = _wavy_uvmesh()
    rng = np.random.default_rng(2)
    n = len(uvmesh.vertices)
    tangents = np.column_stack([rng.normal(size=(n, 3)), np.sign(rng.normal(size=n))])
    nodal = rng.normal(size=(n, 14))
    faces = np.arange(len(uvmesh.faces))
    want = wrapped_rows(draw_data(uvmesh, tangents, uvmesh.vertices, uvmesh.faces, faces, nodal),
                        faces, uvmesh.wraps)
    data, index = vertex_rows(uvmesh, tangents, nodal, uvmesh.wraps)
    assert index.dtype == np.uint32 and len(index) == len(want)
    assert len(data) < len(want)  # shared rows
    assert data[index].view(np.uint32).tolist() == want.view(np.uint32).tolist()


def test_indexed_stress_draw_gives_the_unindexed_pictures(gl_ctx):
    from crackbake.bake.stress import _render, vertex_rows

    uvmesh = _wavy_uvmesh()
    rng = np.random.default_rng(3)
    n = len(uvmesh.vertices)
    tangents = np.column_stack([rng.normal(size=(n, 3)), np.ones(n)])
    nodal = np.abs(rng.normal(size=(n, 14)))
    data, index = vertex_rows(uvmesh, tangents, nodal, uvmesh.wraps)
    indexed = _render(gl_ctx, data, 64, 32, {}, index)
    soup = _render(gl_ctx, np.ascontiguousarray(data[index]), 64, 32, {})
    assert indexed["inside"].any()
    for name, image in soup.items():
        assert np.array_equal(image, indexed[name], equal_nan=True), name


def test_at_points_interpolates_the_closest_point_as_the_einsum_did():
    from crackbake.bake.stress import at_points
    from crackbake.geometry import SurfaceIndex

    uvmesh = _wavy_uvmesh()
    v, f = np.asarray(uvmesh.vertices), np.asarray(uvmesh.faces, np.int64)
    rng = np.random.default_rng(4)
    nodal = rng.normal(size=(len(v), 14))
    points = rng.random((500, 3)) * [1.0, 1.0, 0.2] - [0.0, 0.0, 0.1]
    face, bary, _ = SurfaceIndex(v, f).closest(points)
    want = np.einsum("kc,kcn->kn", bary, nodal[f[face]])
    assert at_points(v, f, nodal, points).view(np.int64).tolist() == want.view(np.int64).tolist()
    # At a vertex of the surface, the vertex's own values.
    np.testing.assert_allclose(at_points(v, f, nodal, v[:36]), nodal[:36], atol=1e-12)
