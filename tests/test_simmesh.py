"""Simulation mesh: conforming refinement inside asset faces, welded, with an exact map back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import plate_mesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.geometry import welded_vertex_normals
from crackbake.io.mesh import Mesh, load_mesh
from crackbake.simulate.simmesh import SimMesh, asset_barycentric, build_simmesh, target_edge_length

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


# --- generated meshes -----------------------------------------------------------------------


def _mesh(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    normals = welded_vertex_normals(vertices, faces)
    return Mesh(vertices=vertices, faces=faces, uv=None, normals=normals)


def _grid_faces(nu: int, nv: int, wrap_u: bool, wrap_v: bool) -> np.ndarray:
    """Two triangles per cell of an (nu x nv) grid of cells, vertices indexed i * rows + j."""
    rows = nv if wrap_v else nv + 1
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    i, j = i.ravel(), j.ravel()
    i1 = (i + 1) % nu if wrap_u else i + 1
    j1 = (j + 1) % nv if wrap_v else j + 1
    a, b, c, d = i * rows + j, i1 * rows + j, i1 * rows + j1, i * rows + j1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def plate(cells: int, size: float = 2.0, wobble: float = 0.0, seed: int = 0) -> Mesh:
    """Flat square plate in z=0, 2 * cells^2 triangles; ``wobble`` moves inner vertices."""
    return plate_mesh(cells, size, wobble, seed, uv=False)


def torus(nu: int, nv: int, bump: float = 0.0, major: float = 1.0, minor: float = 0.4) -> Mesh:
    """Closed torus with 2 * nu * nv triangles, optionally bumpy."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False),
                       np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")
    r = minor * (1.0 + bump * np.sin(5 * u) * np.sin(3 * v))
    x = (major + r * np.cos(v)) * np.cos(u)
    y = (major + r * np.cos(v)) * np.sin(u)
    z = r * np.sin(v)
    return _mesh(np.stack([x.ravel(), y.ravel(), z.ravel()], 1), _grid_faces(nu, nv, True, True))


def box() -> Mesh:
    """Closed unit cube, 12 outward-facing triangles."""
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))]
    return _mesh(v, np.array(faces))


# --- helpers --------------------------------------------------------------------------------


def _areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    p = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def _angles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    p = vertices[faces]
    out = []
    for i in range(3):
        a = p[:, (i + 1) % 3] - p[:, i]
        b = p[:, (i + 2) % 3] - p[:, i]
        cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        out.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return np.stack(out, 1)


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (E, 2) and how many faces use each."""
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def _edge_lengths(sim: SimMesh) -> np.ndarray:
    e, _ = _edges(sim.faces)
    return np.linalg.norm(sim.vertices[e[:, 1]] - sim.vertices[e[:, 0]], axis=1)


def _n_components(sim: SimMesh) -> int:
    e, _ = _edges(sim.faces)
    n = len(sim.vertices)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[0]


@pytest.fixture(scope="module")
def bumpy() -> Mesh:
    return torus(60, 24, bump=0.15)


@pytest.fixture(scope="module")
def bumpy_sim(bumpy) -> SimMesh:
    return build_simmesh(bumpy, target_faces=20_000, seed=3)


# --- tests ----------------------------------------------------------------------------------


def test_area_conserved(bumpy, bumpy_sim):
    asset = _areas(bumpy.vertices, bumpy.faces).sum()
    sim = _areas(bumpy_sim.vertices, bumpy_sim.faces).sum()
    assert abs(sim - asset) <= 1e-9 * asset
    # ...and per asset face, so no sim face strays into a neighbour.
    per_face = np.bincount(bumpy_sim.asset_face, _areas(bumpy_sim.vertices, bumpy_sim.faces),
                           minlength=len(bumpy.faces))
    np.testing.assert_allclose(per_face, _areas(bumpy.vertices, bumpy.faces), rtol=1e-9)


def test_sim_faces_lie_in_their_asset_face(bumpy, bumpy_sim):
    sim = bumpy_sim
    centroid = sim.vertices[sim.faces].mean(axis=1)
    bary = asset_barycentric(bumpy, sim.asset_face, centroid)
    assert (bary >= -1e-9).all() and (bary <= 1 + 1e-9).all()
    back = np.einsum("ij,ijk->ik", bary, bumpy.vertices[bumpy.faces[sim.asset_face]])
    assert np.abs(back - centroid).max() <= 1e-9 * bumpy.diagonal  # in the face's plane
    # Every node of a sim face lies in that asset face too (closed triangle).
    for k in range(3):
        b = asset_barycentric(bumpy, sim.asset_face, sim.vertices[sim.faces[:, k]])
        assert (b >= -1e-9).all()


def test_node_map_reproduces_positions(bumpy, bumpy_sim):
    sim = bumpy_sim
    corners = bumpy.vertices[bumpy.faces[sim.node_face]]
    back = np.einsum("ij,ijk->ik", sim.node_bary, corners)
    assert np.abs(back - sim.vertices).max() <= 1e-12 * bumpy.diagonal
    assert (sim.node_bary >= -1e-12).all()
    np.testing.assert_allclose(sim.node_bary.sum(axis=1), 1.0, atol=1e-12)


def test_orientation_follows_asset(bumpy, bumpy_sim):
    sim = bumpy_sim
    p = sim.vertices[sim.faces]
    n_sim = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    q = bumpy.vertices[bumpy.faces[sim.asset_face]]
    n_asset = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    assert (np.einsum("ij,ij->i", n_sim, n_asset) > 0).all()


def test_min_angle(bumpy, bumpy_sim):
    sim = bumpy_sim
    sim_min = _angles(sim.vertices, sim.faces).min(axis=1)
    asset_min = _angles(bumpy.vertices, bumpy.faces).min(axis=1)[sim.asset_face]
    ok = asset_min >= 20.0
    assert ok.mean() > 0.9  # the test means something
    assert sim_min[ok].min() >= 20.0 - 1e-6


def test_min_angle_with_thin_asset_faces():
    # A wobbly plate has faces of many shapes, some with angles below 20 degrees.
    mesh = plate(12, wobble=0.9, seed=5)
    sim = build_simmesh(mesh, target_faces=5_000, seed=1)
    sim_min = _angles(sim.vertices, sim.faces).min(axis=1)
    asset_min = _angles(mesh.vertices, mesh.faces).min(axis=1)[sim.asset_face]
    assert (asset_min < 20).any()
    assert sim_min[asset_min >= 20.0].min() >= 20.0 - 1e-6
    asset_area = _areas(mesh.vertices, mesh.faces).sum()
    np.testing.assert_allclose(_areas(sim.vertices, sim.faces).sum(), asset_area, rtol=1e-9)


def test_plate_independent_of_asset_triangulation():
    coarse = build_simmesh(plate(1), target_faces=8_000, seed=0)
    fine_mesh = plate(32, wobble=0.5)  # 2,048 irregular triangles
    fine = build_simmesh(fine_mesh, target_faces=8_000, seed=0)
    assert coarse.edge_length == pytest.approx(fine.edge_length)
    assert abs(len(fine.faces) / len(coarse.faces) - 1) <= 0.15
    lc, lf = _edge_lengths(coarse), _edge_lengths(fine)
    assert np.median(lf) == pytest.approx(np.median(lc), rel=0.05)
    # The asset's edges are constraint lines, so the fine plate's lengths spread wider
    # (coefficient of variation ~0.25 against ~0.12), but not by much.
    for q in (10, 90):
        assert np.percentile(lf, q) == pytest.approx(np.percentile(lc, q), rel=0.25)
    ac = _angles(coarse.vertices, coarse.faces).min(axis=1)
    af = _angles(fine.vertices, fine.faces).min(axis=1)
    # Shapes: the 2-triangle plate is the more regular (median min angle ~52 against ~40 deg).
    assert np.median(af) >= 35.0 and np.median(ac) >= 35.0


@pytest.mark.parametrize("make", [box, lambda: torus(30, 12, bump=0.1)], ids=["box", "torus"])
def test_closed_asset_gives_closed_manifold(make):
    mesh = make()
    sim = build_simmesh(mesh, target_faces=3_000, seed=2)
    _, counts = _edges(sim.faces)
    assert (counts == 2).all()
    assert not sim.boundary.any()
    assert _n_components(sim) == 1
    # Euler characteristic survives: 2 for the box (sphere), 0 for the torus.
    e, _ = _edges(sim.faces)
    chi_asset = len(np.unique(mesh.faces)) - len(_edges(mesh.faces)[0]) + len(mesh.faces)
    assert len(sim.vertices) - len(e) + len(sim.faces) == chi_asset


def test_open_plate_boundary_flags():
    sim = build_simmesh(plate(3), target_faces=2_000, seed=0)
    xy = sim.vertices[:, :2]
    on_rim = ((np.abs(xy) < 1e-12) | (np.abs(xy - 2.0) < 1e-12)).any(axis=1)
    np.testing.assert_array_equal(sim.boundary, on_rim)
    _, counts = _edges(sim.faces)
    assert set(np.unique(counts)) == {1, 2}


def test_uv_seams_are_welded():
    mesh = load_mesh(SPOT)
    assert len(np.unique(mesh.vertices, axis=0)) < len(mesh.vertices)  # it has seams
    sim = build_simmesh(mesh, target_faces=20_000, seed=0)
    assert _n_components(sim) == 1
    assert not sim.boundary.any()
    _, counts = _edges(sim.faces)
    assert (counts == 2).all()
    assert abs(len(sim.faces) / 20_000 - 1) <= 0.2


def test_deterministic_for_a_seed(bumpy, bumpy_sim):
    again = build_simmesh(bumpy, target_faces=20_000, seed=3)
    np.testing.assert_array_equal(again.vertices, bumpy_sim.vertices)
    np.testing.assert_array_equal(again.faces, bumpy_sim.faces)
    np.testing.assert_array_equal(again.asset_face, bumpy_sim.asset_face)
    other = build_simmesh(bumpy, target_faces=20_000, seed=4)
    assert len(other.vertices) != len(bumpy_sim.vertices) or not np.array_equal(
        other.vertices, bumpy_sim.vertices)


def test_jitter_makes_it_irregular():
    regular = build_simmesh(plate(1), target_faces=4_000, seed=0, jitter=0.0)
    jittered = build_simmesh(plate(1), target_faces=4_000, seed=0, jitter=0.3)
    assert np.std(_edge_lengths(jittered)) > np.std(_edge_lengths(regular))


def test_finer_asset_is_kept(bumpy):
    h = 1.2 * np.linalg.norm(bumpy.vertices[bumpy.faces][:, [1, 2, 0]]
                             - bumpy.vertices[bumpy.faces], axis=2).max()
    sim = build_simmesh(bumpy, detail=h)
    assert len(sim.faces) == len(bumpy.faces)
    np.testing.assert_array_equal(np.sort(sim.asset_face), np.arange(len(bumpy.faces)))
    np.testing.assert_allclose(sim.vertices[sim.faces], bumpy.vertices[bumpy.faces[sim.asset_face]])
    assert sim.edge_length == h


@pytest.mark.parametrize("target", [10_000, 20_000, 60_000])
def test_face_count_near_target(bumpy, target):
    sim = build_simmesh(bumpy, target_faces=target, seed=0)
    assert abs(len(sim.faces) / target - 1) <= 0.2


def test_detail_sets_edge_length(bumpy):
    sim = build_simmesh(bumpy, detail=0.05, target_faces=None)
    assert sim.edge_length == 0.05
    assert np.median(_edge_lengths(sim)) == pytest.approx(0.05, rel=0.15)
    assert target_edge_length(bumpy, 10_000) > target_edge_length(bumpy, 40_000)


def test_asset_barycentric_round_trip(bumpy):
    rng = np.random.default_rng(0)
    faces = rng.integers(0, len(bumpy.faces), 50)
    bary = rng.dirichlet(np.ones(3), 50)
    pts = np.einsum("ij,ijk->ik", bary, bumpy.vertices[bumpy.faces[faces]])
    np.testing.assert_allclose(asset_barycentric(bumpy, faces, pts), bary, atol=1e-12)


def test_zero_area_faces_are_dropped():
    mesh = plate(2)
    v = np.vstack([mesh.vertices, [[0.5, 0.0, 0.0]]])  # on the rim, collinear with two corners
    f = np.vstack([mesh.faces, [[0, 3, len(v) - 1]]])
    sim = build_simmesh(_mesh(v, f), target_faces=1_000)
    assert not np.isin(len(f) - 1, sim.asset_face)
    np.testing.assert_allclose(_areas(sim.vertices, sim.faces).sum(), 4.0, rtol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"detail": 0.0}, "--detail"),
        ({"detail": -1.0}, "--detail"),
        ({"detail": float("nan")}, "--detail"),
        ({"target_faces": 50}, "at least 100"),
        ({"detail": 1e-5}, "would have about"),
        ({"target_faces": 30_000_000}, "would have about"),
        ({"jitter": 0.9}, "jitter"),
    ],
)
def test_validation(kwargs, words):
    with pytest.raises(CrackbakeError, match=words) as info:
        build_simmesh(box(), **kwargs)
    assert "\n" not in str(info.value)


# --- non-manifold and duplicated input ---------------------------------------------------------


def _assert_manifold(sim: SimMesh) -> None:
    """Every sim edge has one or two faces and every node one fan of faces."""
    from crackbake.simulate.simmesh.manifold import split_nonmanifold

    faces, origin, n_cut = split_nonmanifold(sim.faces, len(sim.vertices))
    assert n_cut == 0 and len(origin) == len(sim.vertices)
    assert np.array_equal(faces, sim.faces)


def _fin_plate() -> Mesh:
    """A 4x4 plate with a vertical triangle standing on one inner edge (three faces on it)."""
    plate = plate_mesh(4, uv=False)
    a, b = plate.faces[9][:2]
    apex = 0.5 * (plate.vertices[a] + plate.vertices[b]) + [0.0, 0.0, 0.4]
    v = np.vstack([plate.vertices, apex])
    f = np.vstack([plate.faces, [[a, b, len(plate.vertices)]]])
    return _mesh(v, f)


def test_fin_is_simulated_as_its_own_patch_with_a_warning():
    mesh = _fin_plate()
    with pytest.warns(CrackbakeWarning, match="not manifold .*1 edge"):
        sim = build_simmesh(mesh, target_faces=2000, seed=0)
    _assert_manifold(sim)
    # The plate runs on through the edge (it stays joined there); the fin comes off with its
    # own copies of the edge's nodes, an open boundary of the fin.
    a, b = mesh.faces[9][:2]
    d = mesh.vertices[b] - mesh.vertices[a]
    t = (sim.vertices - mesh.vertices[a]) @ d / (d @ d)
    on_edge = (np.abs(np.cross(sim.vertices - mesh.vertices[a], d)).max(axis=1) < 1e-12) & (
        t >= 0) & (t <= 1)
    fin_nodes = np.zeros(len(sim.vertices), bool)
    fin_nodes[sim.faces[sim.asset_face == len(mesh.faces) - 1].ravel()] = True
    assert (on_edge & fin_nodes).sum() >= 3
    assert (on_edge & fin_nodes).sum() == (on_edge & ~fin_nodes).sum()
    assert sim.boundary[on_edge & fin_nodes].all()
    assert not sim.boundary[on_edge & ~fin_nodes].any()
    # The fin (its own asset face) still has sim faces, mapped back exactly.
    fin = sim.asset_face == len(mesh.faces) - 1
    assert fin.sum() > 10
    back = np.einsum("nk,nkd->nd", sim.node_bary,
                     mesh.vertices[mesh.faces[sim.node_face]])
    assert np.abs(back - sim.vertices).max() < 1e-12


def test_bow_tie_vertex_is_split():
    # Two triangles touching at one vertex (the origin).
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    mesh = _mesh(v, np.array([[0, 1, 2], [0, 3, 4]]))
    with pytest.warns(CrackbakeWarning, match="1 vertex"):
        sim = build_simmesh(mesh, target_faces=400, seed=0)
    _assert_manifold(sim)
    assert np.count_nonzero(np.all(sim.vertices == 0.0, axis=1)) == 2


def test_duplicated_faces_are_left_out_of_the_simulation_with_a_warning():
    plate = plate_mesh(4, uv=False)
    faces = np.vstack([plate.faces, plate.faces[[3, 7]], plate.faces[[5]][:, ::-1]])
    mesh = _mesh(plate.vertices, faces)
    with pytest.warns(CrackbakeWarning, match="3 duplicated face"):
        sim = build_simmesh(mesh, detail=0.03, seed=0)
    _assert_manifold(sim)
    assert not np.isin(sim.asset_face, [32, 33, 34]).any()
    clean = build_simmesh(plate, detail=0.03, seed=0)
    assert len(clean.faces) == len(sim.faces)


def test_clean_meshes_do_not_warn_and_stay_manifold():
    import warnings

    spot = load_mesh(Path(__file__).parent.parent / "examples" / "spot.obj")
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        sim = build_simmesh(spot, target_faces=5000, seed=0)
    _assert_manifold(sim)
