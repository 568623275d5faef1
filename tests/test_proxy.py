"""The simulation proxy (crackbake/simulate/simmesh/proxy.py): an asset far denser than the
simulation needs is simulated on a decimated stand-in and the cracks moved back onto the asset.

Checked on spot and on the open and non-manifold variants of test_open_meshes (real files, the
real command): the proxy's sim mesh is well shaped, its nodes lie near the asset and its border
nodes on the asset's border, the cracks lie in asset faces and reach open borders, and a dense
asset simulated on a proxy gives the same kind of network as its coarse original.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from crackbake.cli import main
from crackbake.errors import CrackbakeWarning
from crackbake.geometry import SurfaceIndex, edges
from crackbake.io.mesh import load_mesh
from crackbake.io.sidecar import read_sidecar
from crackbake.metrics.cells import network_stats
from crackbake.simulate.simmesh import build_simmesh
from crackbake.simulate.simmesh.proxy import PROXY_MIN_FACES, proxy_limit
from tests.test_open_meshes import KINDS, SPOT, _assert_valid_network, _write_variant


@pytest.fixture(scope="module")
def meshes(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("proxy")
    out = {"closed": SPOT}
    for kind in KINDS:
        out[kind] = folder / f"spot_{kind}.obj"
        _write_variant(kind, out[kind])
    return out


def _subdivided_spot(levels: int, path: Path) -> Path:
    """Spot split 4**levels times at its edge midpoints, UVs interpolated, as an OBJ."""
    mesh = load_mesh(SPOT)
    v, f, t = mesh.vertices, mesh.faces, mesh.uv
    for _ in range(levels):
        v, f, attr = trimesh.remesh.subdivide(v, f, vertex_attributes={"uv": t})
        t = attr["uv"]
    rows = [f"v {a:.9g} {b:.9g} {c:.9g}" for a, b, c in v]
    rows += [f"vt {a:.9g} {b:.9g}" for a, b in t]
    rows += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in f + 1]
    path.write_text("\n".join(rows) + "\n")
    return path


def _quality(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """4 sqrt(3) area / sum of squared edges: 1 for equilateral, 0 for degenerate."""
    q = v[f]
    area = 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
    return 4.0 * np.sqrt(3.0) * area / (np.linalg.norm(q[:, [1, 2, 0]] - q, axis=2) ** 2).sum(1)


def _border_distance(mesh, points: np.ndarray) -> np.ndarray:
    """Distance of each point to the mesh's open border (its edges used by one face)."""
    import igl

    e, count = edges(mesh.faces, len(mesh.vertices))
    border = np.ascontiguousarray(e[count == 1])
    tree = igl.AABB()
    tree.init(mesh.vertices, border)
    d2, _, _ = tree.squared_distance(mesh.vertices, border, np.ascontiguousarray(points))
    return np.sqrt(d2)


def test_the_automatic_limit():
    assert proxy_limit(100_000) == 2 * 100_000
    assert proxy_limit(20_000) == PROXY_MIN_FACES
    assert proxy_limit(400_000) == 800_000
    assert build_simmesh(load_mesh(SPOT), target_faces=2000).proxy is None  # 5,856 < 200k


@pytest.mark.parametrize("kind", ("closed", *KINDS))
def test_proxy_sim_mesh(meshes, kind):
    mesh = load_mesh(meshes[kind])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CrackbakeWarning)  # duplicated / fin name the repair
        sim = build_simmesh(mesh, target_faces=3000, seed=1, proxy_above=0)
        again = build_simmesh(mesh, target_faces=3000, seed=1, proxy_above=0)
    assert sim.proxy is not None
    assert np.array_equal(sim.vertices, again.vertices) and np.array_equal(sim.faces, again.faces)
    assert 0.8 * 3000 < len(sim.faces) < 1.3 * 3000
    # Well shaped: the shortest-edge decimation leaves no needles (quadric decimation left
    # 7% of faces below 0.1).
    assert np.percentile(_quality(sim.vertices, sim.faces), 1) > 0.3
    assert 0 <= sim.asset_face.min() and sim.asset_face.max() < len(mesh.faces)
    # Each node maps to its closest asset point, a small fraction of an edge away.
    at = np.einsum("nk,nka->na", sim.node_bary, mesh.vertices[mesh.faces[sim.node_face]])
    gap = np.linalg.norm(at - sim.vertices, axis=1)
    assert gap.max() < 0.5 * sim.edge_length
    direct = SurfaceIndex(mesh.vertices, mesh.faces).closest(sim.vertices)[2]
    assert np.allclose(np.linalg.norm(direct - sim.vertices, axis=1), gap, atol=1e-12)
    if kind in ("half", "holes"):  # border nodes sit on the asset's own border
        assert sim.boundary.sum() > 20
        assert _border_distance(mesh, sim.vertices[sim.boundary]).max() < 1e-9 * mesh.diagonal


def _run(mesh: Path, out: Path, *args: str) -> dict:
    res = CliRunner().invoke(main, [str(mesh), *args, "--res", "256", "--formats", "png,stress",
                                    "-q", "--json", "-o", str(out)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


@pytest.mark.parametrize("method", ("iben", "thesis"))
def test_cracks_grown_on_a_proxy_lie_on_the_asset_and_reach_its_border(meshes, tmp_path, method):
    mesh = load_mesh(meshes["half"])
    _run(meshes["half"], tmp_path, "--preset", "mud", "--method", method, "--sim-proxy",
         "always", "--sim-faces", "8000", "--seed", "2")
    assert json.loads((tmp_path / "cracks.json").read_text())["params"]["sim_proxy_faces"] > 0
    _assert_valid_network(meshes["half"], tmp_path)
    net = read_sidecar(tmp_path / "cracks.json", mesh)
    ends = np.array([p for c in net.cracks for p in (c.points[0], c.points[-1])])
    on_border = _border_distance(mesh, ends) < 1e-6 * mesh.diagonal
    assert on_border.sum() >= 5


def test_glass_impact_on_a_proxy(meshes, tmp_path):
    _run(meshes["closed"], tmp_path, "--preset", "glass", "--impact", "0.334,0.044,0.287",
         "--sim-proxy", "always", "--sim-faces", "20000")
    assert _assert_valid_network(meshes["closed"], tmp_path) > 10


def test_never_keeps_the_asset_faces(tmp_path):
    dense = _subdivided_spot(2, tmp_path / "spot_sub2.obj")  # 93,696 faces
    summary = _run(dense, tmp_path / "out", "--preset", "mud", "--sim-proxy", "never",
                   "--sim-faces", "5000")
    params = json.loads((tmp_path / "out" / "cracks.json").read_text())["params"]
    assert params["sim_proxy_faces"] == 0
    assert params["sim_faces_built"] >= 93_000  # refining never coarsens
    assert summary["cracks"]["cracks"] > 0


def test_a_dense_asset_on_a_proxy_cracks_like_its_coarse_original(tmp_path):
    """Spot subdivided twice (16x the faces, same shape and UVs) on a proxy against spot itself
    refined, same sim size and preset: counts, length, cells and the stress within a few tens
    of percent (different meshes, so different random patterns: the kind must match)."""
    dense = _subdivided_spot(2, tmp_path / "spot_sub2.obj")
    rows = {}
    for name, path, mode in (("proxy", dense, "always"), ("asset", SPOT, "never")):
        out = tmp_path / name
        _run(path, out, "--preset", "mud", "--sim-proxy", mode, "--sim-faces", "20000")
        params = json.loads((out / "cracks.json").read_text())["params"]
        assert (params["sim_proxy_faces"] > 0) == (mode == "always")
        _assert_valid_network(path, out)
        net = read_sidecar(out / "cracks.json", load_mesh(path))
        spot = load_mesh(SPOT)  # cells measured on one surface for both
        st = network_stats([c.points for c in net.cracks], [c.width for c in net.cracks],
                           spot.vertices, spot.faces)
        import OpenImageIO as oiio

        img = oiio.ImageBuf(str(out / f"{path.stem}_stress.exr"))
        names = list(img.spec().channelnames)
        px = img.get_pixels(oiio.FLOAT)
        inside = px[..., names.index("stress0.sep.V")] >= 0
        p1 = px[..., names.index("stress0.p1.V")][inside]
        assert np.isfinite(p1).all()
        rows[name] = (len(net.cracks), st.length, st.mean_cell_area, float(np.median(p1)))
    for k, tol in enumerate((0.35, 0.2, 0.4, 0.15)):
        a, b = rows["proxy"][k], rows["asset"][k]
        assert abs(a - b) <= tol * abs(b), (k, rows)


@pytest.mark.slow
def test_auto_uses_a_proxy_above_the_limit(tmp_path):
    """Spot subdivided three times (374,784 faces > 200k) goes to a proxy unasked."""
    dense = _subdivided_spot(3, tmp_path / "spot_sub3.obj")
    _run(dense, tmp_path / "out", "--preset", "crackle", "--sim-faces", "20000")
    params = json.loads((tmp_path / "out" / "cracks.json").read_text())["params"]
    assert 0 < params["sim_proxy_faces"] <= 21_000
    assert params["sim_faces_built"] < 30_000
    _assert_valid_network(dense, tmp_path / "out")


def _sphere_surface():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    return np.asarray(sphere.vertices, np.float64), np.asarray(sphere.faces, np.int64)


def test_a_surface_built_ahead_answers_as_the_one_built_here():
    # A cached proxy run builds the asset's AABB tree in a child process while it solves
    # (crackbake.closest_worker): its one answer is libigl's, bit for bit, and it is gone after.
    v, f = _sphere_surface()
    here = SurfaceIndex(v, f)
    ahead = SurfaceIndex(v, f, ahead=True)
    proc = ahead._worker.proc
    rng = np.random.default_rng(3)
    for pts in (rng.normal(size=(500, 3)), rng.normal(size=(40, 3)) * 3):
        for a, b in zip(ahead.closest(pts), here.closest(pts), strict=True):
            assert np.array_equal(a, b)
        assert proc.poll() == 0 and ahead._worker is None  # later queries: a tree built here
    assert ahead._tree is not None


def test_a_failed_or_unused_worker_leaves_no_process_and_the_same_answers():
    import os
    import signal

    v, f = _sphere_surface()
    pts = np.random.default_rng(4).normal(size=(100, 3))
    expected = SurfaceIndex(v, f).closest(pts)
    broken = SurfaceIndex(v, f, ahead=True)
    proc = broken._worker.proc
    os.killpg(proc.pid, signal.SIGKILL)  # dies before the query: the tree is built here
    for a, b in zip(broken.closest(pts), expected, strict=True):
        assert np.array_equal(a, b)
    assert proc.poll() is not None
    unused = SurfaceIndex(v, f, ahead=True)  # a run that grew no cracks
    proc = unused._worker.proc
    unused.stop_worker()
    assert proc.poll() is not None and unused._worker is None
