"""FEM kernels against closed forms derived by hand."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import largest_eigen

from crackbake.simulate.solver.fem import (
    face_frames,
    face_geometry,
    node_forces,
    outer_over_norm,
    separation_tensors,
    split_tension,
)


def grid(n: int, h: float = 1.0, z_rot: float = 0.0):
    """n x n squares of edge h, each split along its diagonal; optionally tilted out of plane."""
    x, y = np.meshgrid(np.arange(n + 1) * h, np.arange(n + 1) * h, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    if z_rot:
        r = np.array([[1, 0, 0], [0, np.cos(z_rot), -np.sin(z_rot)],
                      [0, np.sin(z_rot), np.cos(z_rot)]])
        v = v @ r.T
    return v, f


def in_plane_identity(normal):
    return np.eye(3)[None] - np.einsum("ea,eb->eab", normal, normal)


def test_geometry_gradients_reproduce_linear_functions():
    v, f = grid(3, 0.5, z_rot=0.4)
    area, normal, grad = face_geometry(v, f)
    assert area == pytest.approx(np.full(len(f), 0.125))
    assert np.allclose(grad.sum(axis=1), 0)
    # grad of a linear function phi(x) = a.x is P a, recovered exactly from its nodal values.
    a = np.array([0.3, -1.2, 2.0])
    phi = v @ a
    g = np.einsum("ei,eia->ea", phi[f], grad)
    proj = a - np.einsum("ea,a->e", normal, a)[:, None] * normal
    assert np.allclose(g, proj)


def test_uniform_tension_splits_and_forces_balance_inside():
    v, f = grid(6, 1.0, z_rot=0.3)
    area, normal, grad = face_geometry(v, f)
    s = 2.5
    stress = s * in_plane_identity(normal)
    frames = face_frames(normal, v, f)
    plus, minus, eig, _ = split_tension(stress, frames)
    assert np.allclose(plus, stress) and np.allclose(minus, 0)
    assert np.allclose(eig, s)
    forces = node_forces(area, grad, stress)
    net = np.zeros((len(v), 3))
    np.add.at(net, f.reshape(-1), forces.reshape(-1, 3))
    interior = np.array([i for i in range(len(v)) if 0 < i // 7 < 6 and 0 < i % 7 < 6])
    assert np.allclose(net[interior], 0, atol=1e-12)  # uniform stress: interior equilibrium
    sep = separation_tensors(f, forces, np.zeros_like(forces), len(v))
    value, vec = largest_eigen(sep)
    # Uniform tension pulls every interior node apart: positive separation, in the plane.
    assert (value[interior] > 0).all()
    assert np.allclose(np.einsum("na,a->n", vec[interior], normal[0]), 0, atol=1e-9)
    # Scales linearly with stress and edge length (the reason toughness is given relative).
    v2, f2 = grid(6, 2.0, z_rot=0.3)
    a2, n2, g2 = face_geometry(v2, f2)
    sep2 = separation_tensors(
        f2, node_forces(a2, g2, s * in_plane_identity(n2)), np.zeros((len(f2), 3, 3)), len(v2)
    )
    assert largest_eigen(sep2)[0][interior] == pytest.approx(2 * value[interior])


def test_directional_tension_opens_across_its_direction():
    v, f = grid(6)
    area, normal, grad = face_geometry(v, f)
    d = np.array([1.0, 0.0, 0.0])
    stress = np.broadcast_to(np.outer(d, d), (len(f), 3, 3)).copy()
    plus, minus, eig, direction = split_tension(stress, face_frames(normal, v, f))
    assert np.allclose(eig[:, 0], 1) and np.allclose(eig[:, 1], 0)
    assert np.allclose(np.abs(direction @ d), 1)
    sep = separation_tensors(f, node_forces(area, grad, plus), node_forces(area, grad, minus),
                             len(v))
    value, vec = largest_eigen(sep)
    centre = 3 * 7 + 3
    # The crack plane's normal is the tension direction: cracks run across x.
    assert abs(vec[centre] @ d) == pytest.approx(1, abs=1e-9)


def test_compression_is_split_off():
    v, f = grid(2)
    area, normal, grad = face_geometry(v, f)
    stress = np.broadcast_to(np.diag([1.0, -3.0, 0.0]), (len(f), 3, 3)).copy()
    plus, minus, eig, _ = split_tension(stress, face_frames(normal, v, f))
    assert np.allclose(plus, np.diag([1.0, 0, 0])) and np.allclose(minus, np.diag([0, -3.0, 0]))
    assert np.allclose(eig, [[1.0, -3.0]] * len(f))


def test_outer_over_norm():
    a = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]])
    m = outer_over_norm(a)
    assert np.allclose(m[0], np.outer(a[0], a[0]) / 5.0) and np.allclose(m[1], 0)


def _face_geometry_numpy(vertices, faces):
    # The vectorised numpy form the one-pass kernel replaced (the formulas of the docstring).
    p = vertices[faces]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    twice_area = np.linalg.norm(cross, axis=1)
    safe = np.where(twice_area > 0, twice_area, 1.0)
    normal = cross / safe[:, None]
    normal[twice_area == 0] = 0.0
    grad = np.empty_like(p)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        grad[:, i] = np.cross(normal, p[:, k] - p[:, j]) / safe[:, None]
    grad[twice_area == 0] = 0.0
    return 0.5 * twice_area, normal, grad


def test_face_geometry_gives_the_numpy_bits():
    """The one-pass kernel gives the very float64 bits of the numpy form: the solver's
    golden runs and every stress map depend on them.  Scales over six decades, degenerate
    faces (repeated index, coincident points) and a NaN vertex."""
    rng = np.random.default_rng(7)
    v = rng.normal(size=(400, 3)) * 10.0 ** rng.uniform(-3, 3, size=(400, 1))
    f = rng.integers(0, 400, size=(2000, 3))
    f[:5, 1] = f[:5, 0]
    v[f[5:10, 2]] = v[f[5:10, 0]]
    v[f[10, 0]] = np.nan
    want = _face_geometry_numpy(v, f)
    got = face_geometry(v, f)
    for w, g in zip(want, got, strict=True):
        assert g.shape == w.shape and g.dtype == np.float64
        assert np.array_equal(g.view(np.int64), w.view(np.int64))
    assert np.isnan(got[1][10]).all() and (got[1][:5] == 0).all() and (got[2][5:10] == 0).all()
