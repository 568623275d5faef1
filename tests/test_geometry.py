"""Geometry helpers the mesh load relies on: numpy's face cross products equal the numba
kernel's bit for bit, and the hash grouping of positions welds exactly what the lexsort welds;
the memo computes one sim mesh's edges, shells and centroids once per run, never stale when an
array's contents change."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from crackbake import geometry
from crackbake.geometry import (
    SurfaceIndex,
    content_key,
    corner_mean,
    edges,
    face_cross,
    face_cross_numpy,
    memo,
    position_groups,
    shared_edges,
    shared_shells,
    weld_by_position,
    welded_vertex_normals,
)
from crackbake.simulate.stress.geodesic import _snap


@pytest.mark.parametrize("shape", [(3000, 3), (3000, 3, 2), (2000, 3, 3), (0, 3)])
def test_corner_mean_equals_numpy_mean_bit_for_bit(shape):
    # Signed zeros, infinities and NaN mixed in: numpy sums from +0, so three -0.0 average to
    # +0.0, and an inf beside a -inf is NaN.
    rng = np.random.default_rng(5)
    a = rng.normal(size=shape) * 10.0 ** rng.integers(-300, 300, size=shape)
    odd = rng.random(shape) < 0.3
    a[odd] = rng.choice([0.0, -0.0, np.inf, -np.inf, 5e-324, -1e308, np.nan], size=odd.sum())
    with np.errstate(all="ignore"):
        assert corner_mean(a).tobytes() == a.mean(axis=1).tobytes()
    assert corner_mean(np.full((4, 3), -0.0)).tobytes() == np.zeros(4).tobytes()
    with np.errstate(all="ignore"):
        f32 = a.astype(np.float32)
        assert corner_mean(f32).tobytes() == f32.mean(axis=1).tobytes()


def test_numpy_face_cross_equals_the_kernel_bit_for_bit():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(500, 3)) * rng.choice([1e-6, 1.0, 1e6], size=(500, 1))
    f = rng.integers(0, 500, size=(2000, 3))
    assert face_cross_numpy(v, f).tobytes() == face_cross(v, f).tobytes()


def test_position_groups_weld_like_the_lexsort():
    rng = np.random.default_rng(4)
    p = rng.integers(-3, 4, size=(5000, 3)).astype(np.float64) * 0.5  # many repeats
    p[::7] *= -1.0  # zeros of both signs: equal positions
    groups = position_groups(p)
    _, _, inverse = weld_by_position(p, np.zeros((0, 3), np.int64))
    # the same partition: group numbers map one to one
    pairs = np.unique(np.stack([groups, inverse], 1), axis=0)
    assert len(pairs) == len(np.unique(groups)) == len(np.unique(inverse))


def test_welded_normals_from_source_lines_are_the_same_bits():
    """Welding an OBJ's v lines (fewer) instead of the split vertices gives the same sums."""
    rng = np.random.default_rng(5)
    positions = rng.normal(size=(300, 3))
    positions[1::10] = positions[::10]  # duplicate lines
    source = rng.integers(0, 300, size=900)  # split vertices, several per line
    faces = rng.integers(0, 900, size=(1500, 3))
    vertices = positions[source]
    cross = face_cross(vertices, faces)
    by_position = welded_vertex_normals(vertices, faces)
    by_line = welded_vertex_normals(vertices, faces, cross, (positions, source))
    assert by_line.tobytes() == by_position.tobytes()


def _grid(n=6, shift=0.0):
    """A flat n x n grid of squares, two triangles each: vertices (N, 3), faces (M, 3)."""
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    vertices = np.column_stack([x.ravel() + shift, y.ravel(), np.zeros(x.size)])
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n + 1, i.ravel() + n + 2
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return vertices, faces.astype(np.int64)


def test_content_key_follows_contents_dtype_and_shape():
    _, faces = _grid()
    assert content_key(faces) == content_key(faces.copy())
    changed = faces.copy()
    changed[3, 1] += 1
    assert content_key(changed) != content_key(faces)
    assert content_key(faces.astype(np.int32)) != content_key(faces)
    assert content_key(faces.reshape(-1)) != content_key(faces)
    # A strided view hashes as its own contents.
    assert content_key(faces[::2]) == content_key(np.ascontiguousarray(faces[::2]))


def test_shared_edges_equal_edges_read_only_and_computed_once():
    _, faces = _grid()
    n = int(faces.max()) + 1
    calls = []

    def counted():
        calls.append(1)
        return edges(faces, n)

    first = memo("test-edges", counted, faces, n)
    again = memo("test-edges", counted, faces.copy(), n)
    assert len(calls) == 1 and again is first
    e, uses = shared_edges(faces, n)
    want_e, want_uses = edges(faces, n)
    np.testing.assert_array_equal(e, want_e)
    np.testing.assert_array_equal(uses, want_uses)
    with pytest.raises(ValueError):
        e[0, 0] = 5  # shared by every caller: read-only


def test_memo_recomputes_for_changed_contents_and_stays_bounded():
    _, faces = _grid()
    n = int(faces.max()) + 1
    before = shared_shells(faces, n)
    assert before.max() == 0  # one piece
    # Two separate grids: the cached answer for the first mesh must not be reused.
    v2, f2 = _grid(shift=100.0)
    both = np.concatenate([faces, f2 + n])
    shells = shared_shells(both, 2 * n)
    assert shells.max() == 1
    assert (shells[:n] != shells[n:2 * n]).all()
    for k in range(geometry.MEMO_SIZE + 3):
        memo("test-bound", lambda k=k: (np.full(3, k),), k)
    assert len(geometry._memo) <= geometry.MEMO_SIZE


def test_snap_is_the_same_with_the_memo():
    vertices, faces = _grid()
    vertices = vertices + 0.01 * np.sin(np.arange(vertices.size)).reshape(-1, 3)

    class Sim:
        pass

    sim = Sim()
    sim.vertices, sim.faces = vertices, faces
    point = np.array([2.3, 3.7, 0.4])
    got = _snap(sim, point)
    # The same sim mesh snapped again (the star check after the stress field): same answer.
    again = _snap(sim, point)
    for a, b in zip(got, again, strict=True):
        np.testing.assert_array_equal(a, b)
    # Independently: the closest point over every face, by brute force.
    tri = vertices[faces]
    q, _ = geometry.closest_on_triangles(point, tri[:, 0], tri[:, 1], tri[:, 2])
    k = int(np.argmin(np.linalg.norm(q - point, axis=1)))
    np.testing.assert_allclose(got[0], q[k], atol=1e-12)
    assert got[1] == k
    np.testing.assert_array_equal(got[3], tri.mean(axis=1))


def test_impact_distance_reuses_the_patch_solver_bit_for_bit():
    from types import SimpleNamespace

    from crackbake.simulate.stress.geodesic import impact_distance

    vertices, faces = _grid(12)
    vertices[:, 2] = 0.3 * np.sin(vertices[:, 0]) * np.cos(0.7 * vertices[:, 1])  # curved
    sim = SimpleNamespace(vertices=vertices, faces=faces, edge_length=1.0)
    point = np.array([6.2, 5.9, 0.0])
    geometry._memo.clear()
    first = impact_distance(sim, point, max_distance=4.0)[0]
    solvers = [k for k in geometry._memo if k[0] == "fast marching"]
    assert len(solvers) == 1
    # The star check measures again from the snapped point: the same patch, its solver reused.
    nudged = point + [0.0, 0.0, 1e-9]
    reused = impact_distance(sim, nudged, max_distance=4.0)[0]
    assert [k for k in geometry._memo if k[0] == "fast marching"] == solvers
    geometry._memo.clear()
    fresh = impact_distance(sim, nudged, max_distance=4.0)[0]
    np.testing.assert_array_equal(reused, fresh)
    assert np.isfinite(first).sum() > 20 and np.isinf(first).any()  # the reach cut the patch


def test_forget_empties_the_memo_and_a_run_leaves_nothing(tmp_path):
    _, faces = _grid()
    shared_edges(faces, int(faces.max()) + 1)
    assert geometry._memo
    geometry.forget()
    assert not geometry._memo


def test_a_pickled_surface_index_answers_the_same_without_its_tree():
    rng = np.random.default_rng(1)
    vertices = rng.normal(size=(200, 3))
    faces = rng.integers(0, 200, (300, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                  & (faces[:, 0] != faces[:, 2])]
    index = SurfaceIndex(vertices, faces)
    copy = pickle.loads(pickle.dumps(index))
    points = rng.normal(size=(50, 3))
    for a, b in zip(index.closest(points), copy.closest(points), strict=True):
        assert np.array_equal(a, b)
