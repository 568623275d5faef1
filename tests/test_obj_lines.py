"""OBJ polylines of a crack network (crackbake.io.obj_lines)."""

from __future__ import annotations

import numpy as np

from crackbake.io.obj_lines import write_obj
from crackbake.network import Crack, CrackNetwork


def _crack(cid: int, points) -> Crack:
    n = len(points)
    return Crack(id=cid, points=points, faces=np.zeros(n, np.int64), time=np.linspace(0, 1, n),
                 width=np.zeros(n), depth=np.zeros(n))  # fmt: skip


def tiny_network() -> CrackNetwork:
    """Crack 7 (3 points) then crack 2 (2 points), in that order."""
    return CrackNetwork(
        cracks=[
            _crack(7, [[0.2, 0.1, 0.0], [0.5, 0.1, 0.0], [0.9, 0.4, 0.0]]),
            _crack(2, [[0.1, 0.5, 0.0], [0.1, 0.9, 0.0]]),
        ],
        mesh={},
    )


def random_network(seed: int) -> CrackNetwork:
    """Awkward floats (full mantissas, tiny, negative zero) to prove exact coordinates."""
    rng = np.random.default_rng(seed)
    cracks = []
    for cid in (0, 3, 1):
        pts = rng.uniform(0, 1, (int(rng.integers(2, 9)), 3))
        pts[0, 2] = -0.0
        pts[-1, 0] = 1e-300
        cracks.append(_crack(cid, pts))
    return CrackNetwork(cracks=cracks, mesh={})


def test_obj_lines(tmp_path):
    net = tiny_network()
    path = tmp_path / "cracks.obj"
    write_obj(net, path)
    lines = path.read_text().splitlines()
    objects = [ln.split()[1] for ln in lines if ln.startswith("o ")]
    verts = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    polylines = [[int(i) for i in ln.split()[1:]] for ln in lines if ln.startswith("l ")]
    assert objects == ["crack_7", "crack_2"]
    assert verts.shape == (5, 3) and len(polylines) == 2
    np.testing.assert_array_equal(verts, np.concatenate([c.points for c in net.cracks]))
    assert polylines == [[1, 2, 3], [4, 5]]
    # Each polyline's vertices are the crack's points, in order (OBJ indices are 1-based).
    for crack, poly in zip(net.cracks, polylines, strict=True):
        np.testing.assert_array_equal(verts[np.array(poly) - 1], crack.points)


def test_obj_coordinates_round_trip_exactly(tmp_path):
    net = random_network(2)
    write_obj(net, tmp_path / "r.obj")
    verts = [
        ln.split()[1:]
        for ln in (tmp_path / "r.obj").read_text().splitlines()
        if ln.startswith("v ")
    ]
    np.testing.assert_array_equal(
        np.array(verts, dtype=np.float64), np.concatenate([c.points for c in net.cracks])
    )
