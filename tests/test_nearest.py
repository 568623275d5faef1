"""crackbake.nearest against scipy (the reference it replaces in the run path) and brute force."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from crackbake.nearest import components, nearest_k


@pytest.mark.parametrize("seed", range(5))
def test_components_label_pieces_as_scipy_does(seed):
    rng = np.random.default_rng(seed)
    for _ in range(40):
        n = int(rng.integers(1, 200))
        e = rng.integers(0, n, (int(rng.integers(0, 2 * n)), 2))
        ours = components(n, e)
        graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        count, theirs = connected_components(graph, directed=False)
        np.testing.assert_array_equal(ours, theirs)
        assert ours.dtype == theirs.dtype and ours.max() + 1 == count


def test_components_of_no_edges_are_the_nodes():
    np.testing.assert_array_equal(components(4, np.zeros((0, 2), np.int64)), [0, 1, 2, 3])
    assert len(components(0, np.zeros((0, 2), np.int64))) == 0


def _brute(points, queries, k):
    d = np.linalg.norm(points[None] - queries[:, None], axis=-1)  # (P, M)
    order = np.lexsort((np.broadcast_to(np.arange(len(points)), d.shape), d), axis=-1)[:, :k]
    return np.take_along_axis(d, order, axis=1), order


@pytest.mark.parametrize("shape", ["cloud", "plate", "grid", "line", "one point"])
@pytest.mark.parametrize("k", [1, 3, 8])
def test_nearest_k_is_exact_with_ties_by_index(shape, k):
    """Against brute force: the same distances, and equal ones in ascending index (a grid of
    points asked at grid points has many); queries inside and far outside the points' box."""
    rng = np.random.default_rng(k)
    points = {
        "cloud": lambda: rng.normal(size=(700, 3)),
        "plate": lambda: np.c_[rng.random((500, 2)), np.zeros(500)],
        "grid": lambda: np.stack(np.meshgrid(*[np.arange(8.0)] * 3), -1).reshape(-1, 3),
        "line": lambda: np.outer(rng.random(300), [1.0, 2.0, 3.0]),
        "one point": lambda: np.ones((max(k, 1), 3)),
    }[shape]()
    queries = np.concatenate([rng.normal(size=(150, 3)) * 3, np.round(rng.random((150, 3)) * 8),
                              points[:50]])  # fmt: skip
    d, i = nearest_k(points, queries, k)
    d_ref, i_ref = _brute(points, queries, k)
    np.testing.assert_allclose(d, d_ref, rtol=1e-12, atol=1e-12)
    sq = ((points[i] - queries[:, None]) ** 2).sum(-1)
    np.testing.assert_array_equal(sq, ((points[i_ref] - queries[:, None]) ** 2).sum(-1))
    # ties by index: where the squared distances tie, the indices ascend
    tied = sq[:, 1:] == sq[:, :-1]
    assert (i[:, 1:][tied] > i[:, :-1][tied]).all()


def test_nearest_k_finds_what_ckdtree_finds_on_a_sim_mesh_like_cloud():
    """The neighbours the stress bake asks for (8 nearest face centroids of the added nodes)
    equal cKDTree's, distances and indices, on a surface-like cloud without ties."""
    rng = np.random.default_rng(7)
    u, v = rng.random((2, 20000)) * 2 * np.pi
    points = np.c_[np.cos(u) * (2 + np.cos(v)), np.sin(u) * (2 + np.cos(v)), np.sin(v)]
    queries = points[rng.integers(0, len(points), 3000)] + rng.normal(size=(3000, 3)) * 0.01
    d, i = nearest_k(points, queries, 8)
    d_ref, i_ref = cKDTree(points).query(queries, k=8)
    np.testing.assert_array_equal(i, i_ref)
    np.testing.assert_allclose(d, d_ref, rtol=1e-14)


def test_nearest_k_refuses_more_neighbours_than_points_and_non_finite_ones():
    with pytest.raises(ValueError):
        nearest_k(np.zeros((2, 3)), np.zeros((1, 3)), 3)
    with pytest.raises(ValueError):
        nearest_k(np.array([[0.0, 0.0, np.nan], [1.0, 0.0, 0.0]]), np.zeros((1, 3)), 1)
    with pytest.raises(ValueError):
        nearest_k(np.zeros((2, 3)), np.array([[np.inf, 0.0, 0.0]]), 1)
