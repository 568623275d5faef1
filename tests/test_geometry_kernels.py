"""The numba kernels of :mod:`crackbake.geometry_kernels` against the numpy they replace."""

from __future__ import annotations

import numpy as np
import trimesh

from crackbake.geometry import face_cross
from crackbake.geometry_kernels import (
    area_centre_kernel,
    closed_oriented_kernel,
    eye_view_kernel,
    facing_sum_kernel,
    solid_faces_kernel,
)


def _sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3)


def test_face_cross_is_twice_the_area_times_the_normal():
    m = _sphere()
    cross = face_cross(m.vertices, m.faces)
    np.testing.assert_allclose(np.linalg.norm(cross, axis=1), 2 * m.area_faces, rtol=1e-12)
    np.testing.assert_allclose(cross / np.linalg.norm(cross, axis=1)[:, None], m.face_normals,
                               atol=1e-12)


def test_facing_sum_equals_the_einsum_sum_bit_for_bit():
    # The preview direction's scores must not change with the kernel: same values, same bits.
    rng = np.random.default_rng(3)
    for n in (1, 7, 5000):
        cross = rng.normal(size=(n, 3))
        dirs = rng.normal(size=(17, 3))
        facing = np.einsum("fi,ci->fc", cross, dirs)
        want = np.maximum(facing, 0).sum(axis=0)
        assert np.array_equal(facing_sum_kernel(cross, dirs), want)


def test_facing_sum_of_a_closed_surface_is_its_projected_area_twice():
    # A closed convex surface seen from any direction shows its silhouette: the positive
    # parts of n.d A sum to the projected area, pi r^2 for a (nearly round) sphere; the cross
    # products are 2 A n.
    m = _sphere()
    d = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])
    got = facing_sum_kernel(face_cross(m.vertices, m.faces), d)
    np.testing.assert_allclose(got / 2, np.pi, rtol=0.02)
    assert facing_sum_kernel(np.zeros((0, 3)), d).tolist() == [0.0, 0.0]


def test_area_centre_matches_the_area_weighted_centroid():
    rng = np.random.default_rng(4)
    v = rng.normal(size=(50, 3))
    f = rng.integers(0, 50, size=(80, 3))
    cross = face_cross(v, f)
    w = np.linalg.norm(cross, axis=1)
    want = (w @ v[f].mean(axis=1)) / w.sum()
    np.testing.assert_allclose(area_centre_kernel(v, f, cross), want, rtol=1e-12, atol=1e-14)
    # A sphere moved by t has its centre at t; a half sphere's lies off its base.
    m = _sphere()
    t = np.array([1.0, -2.0, 0.5])
    faces = np.asarray(m.faces, np.int64)
    got = area_centre_kernel(m.vertices + t, faces, face_cross(m.vertices, faces))
    np.testing.assert_allclose(got, t, atol=1e-9)
    top = faces[m.vertices[faces].mean(axis=1)[:, 2] > 0]
    got = area_centre_kernel(m.vertices, top, face_cross(m.vertices, top))
    assert 0.45 < got[2] < 0.55 and np.abs(got[:2]).max() < 1e-9  # a shell's centroid: r/2


def test_solid_faces_match_the_numpy_test_value_for_value():
    # The sim mesh's zero-area filter: identical to the numpy expression it replaced, so the
    # faces kept (and every sim mesh) are unchanged.  Sliver and collapsed faces included.
    rng = np.random.default_rng(5)
    v = rng.normal(size=(300, 3))
    v[10] = v[11]  # a face on 10, 11 and anything has a zero edge
    v[20] = 0.5 * (v[21] + v[22])  # a collinear face
    v[30] = v[31] + 1e-7 * rng.normal(size=3)  # slivers near the threshold
    f = rng.integers(0, 300, size=(2000, 3))
    f[:4] = [[10, 11, 5], [20, 21, 22], [30, 31, 40], [1, 1, 2]]
    for rel in (1e-12, 1e-6, 1e-3):
        tri = v[f]
        edge = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)
        want = np.linalg.norm(face_cross(v, f), axis=1) > rel * edge.max(axis=1) ** 2
        got = solid_faces_kernel(v, f, rel)
        assert np.array_equal(got, want)
    assert not got[:2].any() and not got[3]


def _groups(v):
    from crackbake.geometry import position_groups

    return position_groups(np.ascontiguousarray(v, np.float64))


def test_closed_oriented_accepts_a_closed_surface_split_at_seams_only():
    s = trimesh.creation.icosphere(2)
    v, f = np.asarray(s.vertices), np.asarray(s.faces, np.int64)
    assert closed_oriented_kernel(f, _groups(v))
    # Every face given its own corners (a UV-seam split everywhere): welded by position, closed.
    sv, sf = v[f.ravel()], np.arange(3 * len(f), dtype=np.int64).reshape(-1, 3)
    assert closed_oriented_kernel(sf, _groups(sv))
    assert not closed_oriented_kernel(f[1:], _groups(v))  # a hole
    flipped = f.copy()
    flipped[0] = flipped[0, ::-1]  # one face wound the other way
    assert not closed_oriented_kernel(flipped, _groups(v))
    doubled = np.vstack([f, f[:1]])  # an edge of three faces
    assert not closed_oriented_kernel(doubled, _groups(v))
    pinched = f.copy()
    pinched[0, 1] = pinched[0, 0]  # a face repeating a corner
    assert not closed_oriented_kernel(pinched, _groups(v))


def test_eye_view_gives_volume_winding_and_a_distance_bound():
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))  # wound counter-clockwise outside
    v, f = np.asarray(box.vertices), np.asarray(box.faces, np.int64)
    volume, winding, near = eye_view_kernel(v, f, np.array([5.0, 0.0, 0.0]))
    assert np.isclose(volume, 6 * 8.0) and abs(winding) < 1e-9
    assert 0 < near <= 4.0  # the box is 4 from the eye; the bound never exceeds it
    volume, winding, _ = eye_view_kernel(v, f[:, ::-1], np.array([0.2, 0.1, -0.3]))
    assert np.isclose(volume, -6 * 8.0) and np.isclose(winding, -1.0)  # inside, turned out
