"""Linear-triangle FEM pieces shared by both crack methods (vectorised numpy).

Stress is stored per face as a symmetric 3x3 **world-space** tensor lying in the face's plane
(``S @ n == 0``), tension positive.  That is the paper's 2x2 per-face stress written as
``Fr @ sigma @ Fr.T`` with ``Fr = [u v]`` the face frame; keeping it in world space means a child
triangle made by a split inherits its parent's tensor unchanged (the rotation of Iben & O'Brien
§A6.5 is then implicit) and no per-face frame has to be carried.

Node forces follow O'Brien & Hodgins 1999 at rest: ``f_i = -A * S @ g_i`` with ``g_i`` the world
gradient of barycentric coordinate ``i``; the separation tensor is
``0.5 * (-m(sum f+) + sum m(f+) + m(sum f-) - sum m(f-))`` with ``m(a) = a a^T / |a|``.
The formulas and where they come from: docs/method.md, "The formulas".
"""

from __future__ import annotations

import numpy as np


def face_geometry(
    vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Areas, unit normals and barycentric gradients of triangles.

    Parameters
    ----------
    vertices : (N, 3) float64
    faces : (M, 3) int64

    Returns
    -------
    area : (M,) float64
        Mesh units squared.
    normal : (M, 3) float64
        Unit normals (zero for degenerate faces).
    grad : (M, 3, 3) float64
        ``grad[e, i]`` is the world gradient of barycentric coordinate ``i`` of face ``e``
        (1 / mesh units), lying in the face plane; the three sum to zero.
    """
    from crackbake.geometry_kernels import face_geometry_kernel  # numba: where first used

    twice_area, normal, grad = face_geometry_kernel(
        np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(faces, np.int64))
    return 0.5 * twice_area, normal, grad


def face_frames(normal: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Orthonormal in-plane frames ``Fr = [u v]`` per face, (M, 3, 2); u along edge 0->1."""
    p = vertices[faces]
    u = p[:, 1] - p[:, 0]
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    v = np.cross(normal, u)
    return np.stack([u, v], axis=2)


def split_tension(
    stress: np.ndarray, frames: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split in-plane stress tensors into tensile and compressive parts.

    Parameters
    ----------
    stress : (M, 3, 3) float64
        World-space in-plane stress per face.
    frames : (M, 3, 2) float64
        In-plane orthonormal frames (:func:`face_frames`).

    Returns
    -------
    plus, minus : (M, 3, 3) float64
        ``stress = plus + minus``; ``plus`` keeps the positive principal stresses.
    eigenvalues : (M, 2) float64
        Principal stresses, largest first.
    directions : (M, 3) float64
        World direction of the largest principal stress.
    """
    s2 = np.einsum("eai,eab,ebj->eij", frames, stress, frames)
    a, b, c = s2[:, 0, 0], 0.5 * (s2[:, 0, 1] + s2[:, 1, 0]), s2[:, 1, 1]
    mean = 0.5 * (a + c)
    radius = np.sqrt((0.5 * (a - c)) ** 2 + b**2)
    l1, l2 = mean + radius, mean - radius
    theta = 0.5 * np.arctan2(2 * b, a - c)  # angle of the l1 eigenvector in the frame
    e1 = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    e2 = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    w1 = np.einsum("eab,eb->ea", frames, e1)
    w2 = np.einsum("eab,eb->ea", frames, e2)
    o1 = np.einsum("ea,eb->eab", w1, w1)
    o2 = np.einsum("ea,eb->eab", w2, w2)
    plus = np.maximum(l1, 0)[:, None, None] * o1 + np.maximum(l2, 0)[:, None, None] * o2
    minus = np.minimum(l1, 0)[:, None, None] * o1 + np.minimum(l2, 0)[:, None, None] * o2
    return plus, minus, np.stack([l1, l2], axis=1), w1


def node_forces(area: np.ndarray, grad: np.ndarray, stress: np.ndarray) -> np.ndarray:
    """Force each face exerts on each of its nodes, (M, 3, 3): ``f[e, i] = -A_e S_e g_ei``."""
    return -area[:, None, None] * np.einsum("eab,eib->eia", stress, grad)


def outer_over_norm(a: np.ndarray) -> np.ndarray:
    """``m(a) = a a^T / |a|`` over the last axis, with ``m(0) = 0``; shape (..., 3, 3)."""
    n = np.linalg.norm(a, axis=-1)
    safe = np.where(n > 0, n, 1.0)
    return np.einsum("...a,...b->...ab", a, a) / safe[..., None, None] * (n > 0)[..., None, None]


def separation_tensors(
    faces: np.ndarray, f_plus: np.ndarray, f_minus: np.ndarray, n_nodes: int
) -> np.ndarray:
    """Separation tensor per node, (N, 3, 3).

    Parameters
    ----------
    faces : (M, 3) int64
    f_plus, f_minus : (M, 3, 3) float64
        Per (face, corner) forces from the tensile and compressive stress.
    n_nodes : int
    """
    fp = f_plus.reshape(-1, 3)
    fm = f_minus.reshape(-1, 3)
    # One sparse (node x corner) sum for all twenty-four columns: far faster than np.add.at.
    gather = corner_incidence(faces, n_nodes)
    cols = np.concatenate(
        [fp, fm, outer_over_norm(fp).reshape(-1, 9), outer_over_norm(fm).reshape(-1, 9)], axis=1
    )
    sums = gather @ cols
    sum_fp, sum_fm = sums[:, 0:3], sums[:, 3:6]
    sum_mp, sum_mm = sums[:, 6:15].reshape(-1, 3, 3), sums[:, 15:24].reshape(-1, 3, 3)
    return 0.5 * (-outer_over_norm(sum_fp) + sum_mp + outer_over_norm(sum_fm) - sum_mm)


def corner_incidence(faces: np.ndarray, n_nodes: int):
    """Sparse (N, 3M) matrix summing per-corner rows onto their nodes."""
    from scipy.sparse import csr_matrix

    idx = faces.reshape(-1)
    return csr_matrix(
        (np.ones(len(idx)), (idx, np.arange(len(idx)))), shape=(n_nodes, len(idx))
    )
