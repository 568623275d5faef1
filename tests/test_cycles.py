"""Drying cycles (crackbake.simulate.cycles): T-junctions relax toward Y, the cells stay."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import plate_mesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from crackbake.geometry import SurfaceIndex
from crackbake.graph import network_graph
from crackbake.metrics.angles import junction_angles, mean_junction_angle, relaxation_time
from crackbake.metrics.cells import cell_areas
from crackbake.metrics.growth import growth_curve
from crackbake.network import Crack, CrackNetwork
from crackbake.simulate.cycles import redry

ROOT = Path(__file__).resolve().parents[1]


def _crack(k, points, surface):
    points = np.c_[points, np.zeros(len(points))]
    face = surface.closest(points)[0]
    n = len(points)
    return Crack(id=k, points=points, faces=face, time=np.linspace(0, 1, n), width=np.ones(n),
                 depth=np.ones(n))


def brick_network(mesh, k: int = 5, step: float = 0.01) -> CrackNetwork:
    """A brick wall of T-junctions on the unit plate, written as the solver writes junctions:
    every horizontal crack split at each junction, the pieces sharing the junction's point."""
    surface = SurfaceIndex(mesh.vertices, mesh.faces)
    ys = np.arange(1, k) / k
    stems = {}  # row line -> x where a vertical piece meets it
    pieces = []
    for j in range(k):
        xs = np.arange(1, k) / k + (0.5 / k if j % 2 else 0.0)
        xs = xs[xs < 1]
        for x in xs:
            y0, y1 = j / k, (j + 1) / k
            t = np.linspace(y0, y1, int(round((y1 - y0) / step)) + 1)
            pieces.append(np.c_[np.full(len(t), x), t])
            for y in (y0, y1):
                if 0 < y < 1:
                    stems.setdefault(round(y * k), []).append(x)
    for i, y in enumerate(ys, start=1):
        cuts = np.r_[0.0, np.sort(stems[i]), 1.0]
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            t = np.linspace(a, b, max(int(round((b - a) / step)), 1) + 1)
            pieces.append(np.c_[t, np.full(len(t), y)])
    cracks = [_crack(k, p, surface) for k, p in enumerate(pieces)]
    return CrackNetwork(cracks=cracks, mesh={"source": "plate.obj"})


def components(network: CrackNetwork) -> int:
    g = network_graph(network)
    n = len(g.positions)
    u, v = g.seg_node.T
    return connected_components(coo_matrix((np.ones(len(u)), (u, v)), (n, n)))[0]


@pytest.fixture(scope="module")
def plate():
    return plate_mesh(8)


@pytest.fixture(scope="module")
def brick(plate):
    return brick_network(plate)


def test_one_cycle_is_the_network_itself(brick, plate):
    assert redry(brick, plate.vertices, plate.faces, 1) is brick


def test_brick_t_junctions_relax_toward_y(brick, plate):
    ns = [1, 2, 3, 4, 6, 8]
    nets = [redry(brick, plate.vertices, plate.faces, n, seed=2) for n in ns]
    means = [mean_junction_angle(x) for x in nets]
    assert means[0] == pytest.approx(180.0, abs=1e-6)  # every junction of a brick wall is a T
    assert all(a > b for a, b in zip(means, means[1:], strict=False))
    assert means[-1] <= 135.0
    assert 2.0 <= relaxation_time(ns, means) <= 8.0
    assert junction_angles(nets[-1]).min() >= 119.0  # never past the Y


def test_cycles_keep_cells_points_attributes_and_surface(brick, plate):
    out = redry(brick, plate.vertices, plate.faces, 8, seed=2)
    assert [c.id for c in out.cracks] == [c.id for c in brick.cracks]
    for a, b in zip(brick.cracks, out.cracks, strict=True):
        assert len(a.points) == len(b.points)
        for name in ("time", "width", "depth"):
            assert np.array_equal(getattr(a, name), getattr(b, name))
    pts = np.concatenate([c.points for c in out.cracks])
    faces = np.concatenate([c.faces for c in out.cracks])
    assert np.abs(pts[:, 2]).max() < 1e-12 and (pts[:, :2] >= -1e-12).all()
    # Each point lies in the face recorded for it.
    tri = plate.vertices[plate.faces[faces]]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    for i in range(3):
        e = tri[:, (i + 1) % 3] - tri[:, i]
        side = e[:, 0] * (pts[:, 1] - tri[:, i, 1]) - e[:, 1] * (pts[:, 0] - tri[:, i, 0])
        assert (side * np.sign(cross) >= -1e-9).all()
    moved = np.linalg.norm(pts - np.concatenate([c.points for c in brick.cracks]), axis=1)
    assert moved.max() > 0.02  # the vertices moved (as in the experiment) ...
    # ... and the cells are the same cells: same count and areas within a few per cent.
    before = cell_areas(plate.vertices, plate.faces, [c.points for c in brick.cracks])
    after = cell_areas(plate.vertices, plate.faces, [c.points for c in out.cracks])
    assert len(before) == len(after) == 5 * 5  # 5 rows, each cut by 4 pieces into 5 bricks
    assert np.abs(np.sort(after) / np.sort(before) - 1).max() < 0.15
    assert components(out) == components(brick) == 1


def test_a_network_without_junctions_warns_and_stays(plate):
    from crackbake.errors import CrackbakeWarning

    surface = SurfaceIndex(plate.vertices, plate.faces)
    t = np.linspace(0.1, 0.9, 30)
    lone = CrackNetwork(cracks=[_crack(0, np.c_[t, t], surface)], mesh={})
    with pytest.warns(CrackbakeWarning, match="--cycles 4 changed nothing"):
        assert redry(lone, plate.vertices, plate.faces, 4) is lone


def test_cycles_are_deterministic_and_seeded(brick, plate):
    a = redry(brick, plate.vertices, plate.faces, 4, seed=1)
    b = redry(brick, plate.vertices, plate.faces, 4, seed=1)
    c = redry(brick, plate.vertices, plate.faces, 4, seed=2)
    pa, pb, pc = (np.concatenate([k.points for k in x.cracks]) for x in (a, b, c))
    assert np.array_equal(pa, pb) and not np.array_equal(pa, pc)


def test_growth_map_of_an_evolved_network_stays_connected(brick, plate):
    out = redry(brick, plate.vertices, plate.faces, 8, seed=2)
    before, after = growth_curve(brick), growth_curve(out)
    assert after.min_after(0.1) == pytest.approx(before.min_after(0.1), abs=0.02)
    assert after.weighted_mean == pytest.approx(before.weighted_mean, abs=0.02)


def _mud(mesh, sim_faces: int, seed: int, cycles: int = 1):
    from crackbake.params import RunParams
    from crackbake.pipeline import solve

    params, relative = RunParams(mesh=Path(mesh.source), preset="mud", sim_faces=sim_faces,
                                 seed=seed, cycles=cycles).resolved()
    return solve(mesh, params, relative, {})[0]


def _check_mud(net, mesh, seed):
    ns = [1, 2, 4, 6, 8]
    nets = [redry(net, mesh.vertices, mesh.faces, n, seed=seed) for n in ns]
    means = [mean_junction_angle(x) for x in nets]
    assert means[0] >= 160.0
    assert means[-1] <= 135.0
    assert 2.0 <= relaxation_time(ns, means) <= 8.0
    assert components(nets[-1]) == components(net)
    # The growth map reveals the evolved network as it revealed the first (same times, same
    # graph; only the geometry moved).
    before, after = growth_curve(net), growth_curve(nets[-1])
    assert after.weighted_mean == pytest.approx(before.weighted_mean, abs=0.02)
    assert after.min_after(0.1) == pytest.approx(before.min_after(0.1), abs=0.05)
    return nets


@pytest.mark.slow  # a real mud solve: ~6 s on a quiet machine, minutes on a loaded one
def test_mud_on_a_plate_relaxes_from_t_to_y(tmp_path):
    from crackbake.io.mesh import load_mesh
    from crackbake.precompile import plate_obj

    mesh = load_mesh(plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0))
    net = _mud(mesh, 4000, 1)
    nets = _check_mud(net, mesh, 1)
    before = cell_areas(mesh.vertices, mesh.faces, [c.points for c in net.cracks])
    after = cell_areas(mesh.vertices, mesh.faces, [c.points for c in nets[-1].cracks])
    assert abs(len(after) - len(before)) <= max(2, 0.05 * len(before))
    # The run's own --cycles 8: the solved network taken through the same 7 re-dryings.
    run = _mud(mesh, 4000, 1, cycles=8)
    assert np.array_equal(np.concatenate([c.points for c in run.cracks]),
                          np.concatenate([c.points for c in nets[-1].cracks]))


@pytest.mark.slow
def test_mud_on_spot_relaxes_from_t_to_y():
    from crackbake.io.mesh import load_mesh

    mesh = load_mesh(ROOT / "examples" / "spot.obj")
    _check_mud(_mud(mesh, 20000, 0), mesh, 0)


@pytest.mark.parametrize(("args", "says"), [
    (["--preset", "mud", "--cycles", "0"], "--cycles 0 is out of range"),
    (["--impact", "0.5,0.5,0", "--cycles", "3"], "has no shrinkage"),
])
def test_bad_cycles_are_refused_in_one_line(tmp_path, args, says):
    from click.testing import CliRunner

    from crackbake.cli import main
    from crackbake.precompile import plate_obj

    mesh = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, [str(mesh), *args, "-o", str(out), "-q"])
    assert r.exit_code == 2, r.output
    assert says in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()


def test_cycles_with_a_given_network_are_refused(tmp_path):
    from crackbake.errors import CrackbakeError
    from crackbake.params import RunParams

    side = tmp_path / "cracks.json"
    side.write_text("{}")
    with pytest.raises(CrackbakeError, match="drop --cycles"):
        RunParams(mesh=tmp_path / "m.obj", cracks=side, cycles=4).validate()
    with pytest.raises(CrackbakeError, match="not a whole number"):
        RunParams(mesh=tmp_path / "m.obj", preset="mud", cycles=2.5).validate()
    RunParams(mesh=tmp_path / "m.obj", cracks=side, cycles=1).validate()  # the default passes
