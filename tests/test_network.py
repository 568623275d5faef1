"""The crack network's data types (crackbake.network): segments, stats, the solver's network."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import plate_mesh, tiny_network

from crackbake.io.mesh import Mesh
from crackbake.network import CrackNetwork, from_solver, mesh_info, segments


def unit_square() -> Mesh:
    """Two triangles covering [0, 1]^2 at z = 0: face 0 below the diagonal, face 1 above."""
    return plate_mesh(1, name="square")


# --- segments and stats ---------------------------------------------------------------------


def test_segments_hand_derived():
    seg = segments(tiny_network())
    assert seg.a.shape == (3, 3) and seg.b.shape == (3, 3)
    assert seg.width.shape == seg.depth.shape == seg.time.shape == (3, 2)
    np.testing.assert_array_equal(seg.a, [[0.2, 0.1, 0], [0.5, 0.1, 0], [0.1, 0.5, 0]])
    np.testing.assert_array_equal(seg.b, [[0.5, 0.1, 0], [0.9, 0.4, 0], [0.1, 0.9, 0]])
    np.testing.assert_array_equal(seg.width, [[0.004, 0.002], [0.002, 0.0], [0.001, 0.003]])
    np.testing.assert_array_equal(seg.depth, [[0.002, 0.001], [0.001, 0.0], [0.0, 0.0015]])
    np.testing.assert_array_equal(seg.time, [[0.0, 0.5], [0.5, 1.0], [0.2, 0.6]])
    np.testing.assert_array_equal(seg.crack_id, [7, 7, 2])
    assert seg.crack_id.dtype == np.int64 and seg.a.dtype == np.float64


def test_segments_empty_network():
    seg = segments(CrackNetwork(cracks=[], mesh=mesh_info(unit_square())))
    assert seg.a.shape == (0, 3) and seg.width.shape == (0, 2) and seg.crack_id.shape == (0,)


def test_stats_hand_computed():
    stats = tiny_network().stats()
    assert list(stats) == ["cracks", "points", "total_length", "solver_steps"]
    assert stats["cracks"] == 2 and stats["points"] == 5 and stats["solver_steps"] == 11
    assert stats["total_length"] == pytest.approx(0.3 + 0.5 + 0.4, abs=1e-12)


def test_from_solver_numbers_cracks_and_clamps_values():
    paths = [
        SimpleNamespace(points=[[0.2, 0.1, 0.0], [0.6, 0.1, 0.0]], asset_faces=[0, 0],
                        time=[-0.1, 1.2], width=[0.01, -1e-9], depth=[0.005, -1e-9]),
        SimpleNamespace(points=[[0.5, 0.5, 0.0]], asset_faces=[1], time=[0.0], width=[0.0],
                        depth=[0.0]),  # one point: dropped
        SimpleNamespace(points=[[0.1, 0.5, 0.0], [0.1, 0.9, 0.0]], asset_faces=[1, 1],
                        time=[0.2, 0.6], width=[0.001, 0.003], depth=[0.0, 0.0015]),
    ]  # fmt: skip
    net = from_solver(paths, unit_square(), params={"seed": 3}, solver_steps=9)
    assert [c.id for c in net.cracks] == [0, 1]
    np.testing.assert_array_equal(net.cracks[0].time, [0.0, 1.0])
    np.testing.assert_array_equal(net.cracks[0].width, [0.01, 0.0])
    np.testing.assert_array_equal(net.cracks[0].depth, [0.005, 0.0])
    assert net.cracks[1].faces.dtype == np.int64
    assert net.mesh == mesh_info(unit_square()) and net.params == {"seed": 3}
    assert net.impacts == [] and net.solver_steps == 9
