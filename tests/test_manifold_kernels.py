"""The union-find fan kernel behind
:func:`crackbake.simulate.simmesh.manifold.split_nonmanifold`."""

from __future__ import annotations

import numpy as np

from crackbake.simulate.simmesh.manifold import duplicate_faces, split_nonmanifold
from crackbake.simulate.simmesh.manifold_kernels import fan_split


def test_unjoined_corners_each_keep_or_copy_their_vertex_in_corner_order():
    # Corners 0, 1, 2 hold vertex 0, corner 3 vertex 1.  Nothing joined: corner 0 keeps
    # vertex 0, corners 1 and 2 become new vertices 2 and 3 (in corner order).
    a = np.array([0, 0, 0, 1], np.int64)
    none = np.zeros(0, np.int64)
    vertex, extra = fan_split(a, none, none, 2)
    assert vertex.tolist() == [0, 2, 3, 1]
    assert extra.tolist() == [0, 0]
    # Joining corners 2 and 0 puts them in one fan (root 0): only corner 1 is copied.
    vertex, extra = fan_split(a, np.array([2]), np.array([0]), 2)
    assert vertex.tolist() == [0, 2, 0, 1]
    assert extra.tolist() == [0]


def test_a_chain_of_joins_is_one_fan_whatever_the_order():
    a = np.zeros(6, np.int64)
    rows, cols = np.array([5, 3, 1, 4]), np.array([4, 2, 3, 2])  # {1,2,3,4,5} and {0}
    vertex, extra = fan_split(a, rows, cols, 1)
    assert vertex.tolist() == [0, 1, 1, 1, 1, 1]
    assert extra.tolist() == [0]


def test_bow_tie_vertex_is_split_and_a_closed_fan_is_not():
    # Two triangles touching at vertex 0 only (a bow tie): its second fan gets vertex 5.
    bow = np.array([[0, 1, 2], [0, 3, 4]])
    faces, origin, n_cut = split_nonmanifold(bow, 5)
    assert faces.tolist() == [[0, 1, 2], [5, 3, 4]]
    assert origin.tolist() == [0, 1, 2, 3, 4, 0] and n_cut == 0
    # A closed fan of six faces around vertex 0 (a hexagon) stays as it is.
    ring = np.array([[0, 1 + i, 1 + (i + 1) % 6] for i in range(6)])
    faces, origin, n_cut = split_nonmanifold(ring, 7)
    assert np.array_equal(faces, ring) and origin.tolist() == list(range(7)) and n_cut == 0


def test_duplicate_faces_flag_later_copies_with_either_sort():
    # Vertex counts below and above the one-key limit (n**3 < 2**63) take different sorts.
    for offset in (0, 3_000_000):
        f = np.array([[0, 1, 2], [2, 0, 1], [3, 4, 5], [1, 0, 2], [5, 4, 6], [4, 5, 3]]) + offset
        assert duplicate_faces(f).tolist() == [False, True, False, True, False, True]
    assert duplicate_faces(np.zeros((0, 3), np.int64)).shape == (0,)


def test_sorted_sides_is_the_stable_sort_by_edge():
    """The bucket kernel gives numpy's stable argsort of the edge keys, each side's edge rank and
    the per-edge counts, on random faces with repeated, reversed and crowded edges."""
    from crackbake.simulate.simmesh.manifold_kernels import sorted_sides

    rng = np.random.default_rng(7)
    n_v = 40
    faces = rng.integers(0, n_v, (300, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                  & (faces[:, 0] != faces[:, 2])]
    faces = np.concatenate([faces, faces[:20, ::-1], faces[:5]])
    a = faces.ravel()
    b = faces[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * n_v + np.maximum(a, b)
    uniq, inv, count = np.unique(key, return_inverse=True, return_counts=True)
    got_inv, got_count, by_edge = sorted_sides(a, b, n_v)
    np.testing.assert_array_equal(by_edge, np.argsort(key, kind="stable"))
    np.testing.assert_array_equal(got_inv, inv)
    np.testing.assert_array_equal(got_count, count)
    assert count.max() > 2
