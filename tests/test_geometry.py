"""Geometry helpers the mesh load relies on: numpy's face cross products equal the numba
kernel's bit for bit, and the hash grouping of positions welds exactly what the lexsort welds."""

from __future__ import annotations

import numpy as np

from crackbake.geometry import (
    face_cross,
    face_cross_numpy,
    position_groups,
    weld_by_position,
    welded_vertex_normals,
)


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
