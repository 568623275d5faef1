"""Per-node stress data for the stress bake (:mod:`crackbake.bake.stress`).

* :func:`initial_separation`: the initial field's separation, scaled as the solvers scale it.
* :func:`nodal_values`: per node, the area-weighted world tensor and the separation.
* :func:`on_final_mesh`: the initial field's node values carried onto the final (split) mesh,
  so one draw bakes both fields.
* :func:`draw_data`: the vertex buffer of sim triangles in UV space.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.errors import CrackbakeError
from crackbake.geometry import barycentric, edges, face_areas
from crackbake.simulate.solver.fem import (
    face_frames,
    face_geometry,
    node_forces,
    separation_tensors,
    split_tension,
)

# Barycentric slack before a sim corner counts as outside its asset face (relative).
_BARY_TOL = 1e-4
# Initial faces tried per point when carrying the initial field onto new nodes.
_CANDIDATES = 8


def initial_separation(vertices: np.ndarray, faces: np.ndarray, stress: np.ndarray,
                       stats: dict) -> np.ndarray:
    """The separation of the initial field per node, relative to the toughness, (N,).

    The largest eigenvalue ``v+`` of the paper's separation tensor (Iben & O'Brien; forces
    ``-A S+- g`` from the tensile / compressive parts, :mod:`crackbake.simulate.solver.fem`),
    scaled as each solver's failure test scales it: thesis ``v+ / tau``; iben ``v+ / (tau h_n)``
    with ``h_n`` the node's mean edge length.  ``tau`` is ``stats["tau"]``.  For thesis this is
    exactly the solver's ``separation`` (its field never changes); for iben it leaves out the
    solver's direction averaging, seeded flaws (+-FLAW) and footprint factor, so it is the
    nominal load of the fresh material: about 1 where it starts to fail.
    """
    tau = float(stats.get("tau", 0.0) or 0.0)
    n = len(vertices)
    if not (tau > 0 and np.isfinite(tau)) or len(faces) == 0:
        return np.zeros(n)
    area, normal, grad = face_geometry(vertices, faces)
    plus, minus, _, _ = split_tension(stress, face_frames(normal, vertices, faces))
    sep = separation_tensors(faces, node_forces(area, grad, plus), node_forces(area, grad, minus),
                             n)
    value = np.linalg.eigvalsh(sep)[:, -1]
    if stats.get("method") == "thesis":
        return value / tau
    e = edges(faces, n)[0]
    length = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    h = np.bincount(e.ravel(), np.repeat(length, 2), n) / np.maximum(np.bincount(e.ravel(),
                                                                                 minlength=n), 1)
    return np.where(h > 0, value / (tau * np.where(h > 0, h, 1.0)), 0.0)


def nodal_values(vertices: np.ndarray, faces: np.ndarray, stress: np.ndarray, sep: np.ndarray):
    """Per node: area-weighted mean world tensor (xx, yy, zz, xy, xz, yz) of its faces and
    ``sep`` (clamped to >= 0: the bake marks drawn texels by it), (N, 7)."""
    area = face_areas(vertices, faces)
    six = stress[:, [0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]] * area[:, None]
    sums = _node_sums(np.ascontiguousarray(faces, np.int64),
                      np.ascontiguousarray(np.column_stack([six, area])), len(vertices))
    out = np.empty((len(vertices), 7))
    out[:, :6] = sums[:, :6] / np.where(sums[:, 6:] > 0, sums[:, 6:], 1.0)
    out[:, 6] = np.maximum(np.nan_to_num(sep), 0.0)  # >= 0 marks drawn texels (_render)
    return out


@njit(cache=True, nogil=True)
def _node_sums(faces: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
    # Each face's row added to its three nodes, in face order: a sparse product built 4.5M
    # entries at 1.5M faces (1.4 s a call); this is one pass.
    out = np.zeros((n, rows.shape[1]))
    for f in range(len(faces)):
        for c in range(3):
            for k in range(rows.shape[1]):
                out[faces[f, c], k] += rows[f, k]
    return out


def draw_data(uvmesh, tangents: np.ndarray, vertices, faces, asset_face, nodal) -> np.ndarray:
    """Vertex buffer (3M, 9 + C) float32 of sim triangles in UV space, three rows per triangle
    in face order (draw it unindexed): uv, T, w, N interpolated from the triangle's asset face
    at the node, then the node's ``nodal`` (N, C) row.

    Each corner interpolates in its own triangle's asset face, so a node on a UV seam gets each
    side's UV and the same world values.  Rows are not shared between triangles: at a
    1.5M-face asset every sim triangle has its own asset face and sharing saved nothing, while
    finding the shared rows cost 1 s.
    """
    uv_faces = np.asarray(uvmesh.faces, np.int64)
    n_asset = len(uv_faces)
    asset_face = np.asarray(asset_face, np.int64)
    if len(asset_face) != len(faces) or (len(faces) and (asset_face.min() < 0 or
                                                         asset_face.max() >= n_asset)):
        raise CrackbakeError(
            "the simulation mesh's asset faces do not index the output mesh; bake stress with "
            "the UV mesh of the asset the simulation was built from")
    data = np.empty((3 * len(faces), 9 + nodal.shape[1]), np.float32)
    # One pass per triangle (numba): the asset face is read once for its three corners.
    outside = _corner_rows(
        np.ascontiguousarray(faces, np.int64), asset_face,
        np.ascontiguousarray(vertices, np.float64),
        np.ascontiguousarray(uvmesh.vertices, np.float64), uv_faces,
        np.ascontiguousarray(uvmesh.uv, np.float64), np.ascontiguousarray(tangents, np.float64),
        np.ascontiguousarray(uvmesh.normals, np.float64), np.ascontiguousarray(nodal, np.float64),
        _BARY_TOL, data,
    )
    if outside:
        raise CrackbakeError(
            f"{outside} simulation nodes lie outside the asset face their triangle "
            "belongs to; bake stress with the simulation mesh built from this asset")
    return data


@njit(cache=True, nogil=True)
def _corner_rows(faces, asset_face, points, verts, tris, uv, tangents, normals, nodal, tol, out):
    """Fill ``out`` (uv, T, w, N interpolated at each corner's node in its triangle's asset
    face, then the node's ``nodal`` row); return how many distinct nodes lie outside their
    face (barycentric below -tol, or off its plane by more than tol x the face's size).  The
    same arithmetic as :func:`crackbake.geometry.barycentric` followed by a clip to [0, 1] and
    renormalisation."""
    bad = np.zeros(len(points), np.bool_)
    for f in range(len(faces)):
        i0, i1, i2 = tris[asset_face[f], 0], tris[asset_face[f], 1], tris[asset_face[f], 2]
        d11 = d12 = d22 = size2 = 0.0
        for a in range(3):
            e1 = verts[i1, a] - verts[i0, a]
            e2 = verts[i2, a] - verts[i0, a]
            d11 += e1 * e1
            d12 += e1 * e2
            d22 += e2 * e2
            lo = min(verts[i0, a], verts[i1, a], verts[i2, a])
            hi = max(verts[i0, a], verts[i1, a], verts[i2, a])
            size2 += (hi - lo) ** 2
        det = d11 * d22 - d12 * d12
        if det == 0.0:
            det = 1.0
        for c in range(3):
            node, k = faces[f, c], 3 * f + c
            p1 = p2 = 0.0
            for a in range(3):
                d = points[node, a] - verts[i0, a]
                p1 += d * (verts[i1, a] - verts[i0, a])
                p2 += d * (verts[i2, a] - verts[i0, a])
            b1 = (d22 * p1 - d12 * p2) / det
            b2 = (d11 * p2 - d12 * p1) / det
            b0 = 1.0 - b1 - b2
            off2 = 0.0
            for a in range(3):
                back = b0 * verts[i0, a] + b1 * verts[i1, a] + b2 * verts[i2, a]
                off2 += (back - points[node, a]) ** 2
            if min(b0, b1, b2) < -tol or off2 > (tol * max(np.sqrt(size2), 1e-300)) ** 2:
                bad[node] = True
            b0, b1, b2 = min(max(b0, 0.0), 1.0), min(max(b1, 0.0), 1.0), min(max(b2, 0.0), 1.0)
            total = b0 + b1 + b2
            b0, b1, b2 = b0 / total, b1 / total, b2 / total
            for a in range(2):
                out[k, a] = b0 * uv[i0, a] + b1 * uv[i1, a] + b2 * uv[i2, a]
            for a in range(4):
                out[k, 2 + a] = (b0 * tangents[i0, a] + b1 * tangents[i1, a]
                                 + b2 * tangents[i2, a])
            for a in range(3):
                out[k, 6 + a] = b0 * normals[i0, a] + b1 * normals[i1, a] + b2 * normals[i2, a]
            for a in range(nodal.shape[1]):
                out[k, 9 + a] = nodal[node, a]
    # Counted here, not with np.count_nonzero: its implementation's module (numba.np.arraymath)
    # imports scipy.linalg when the cached kernel loads, 0.3 s of the stress bake.
    count = 0
    for i in range(len(bad)):
        count += bad[i]
    return count


def on_final_mesh(v0: np.ndarray, f0: np.ndarray, values0: np.ndarray,
                  v1: np.ndarray) -> np.ndarray:
    """The initial field's node values (N0, C) at the final mesh's nodes (N1, C).

    The solvers only refine: iben keeps every initial node (same index, same position) and
    appends the nodes its edge and node splits make, each inside an initial face.  Those are
    located among the initial faces (the few whose centroids lie nearest,
    :func:`crackbake.nearest.nearest_k`; the one that contains the point and lies closest to
    it) and interpolated there; a node split's copies sit
    where the node was, so they get its value.  Interpolating the piecewise-linear initial field
    at the final nodes reproduces it exactly on every final triangle (each lies inside one
    initial triangle), so one draw of the final mesh carries both fields.
    """
    n0 = len(v0)
    keep = len(v1) >= n0 and np.array_equal(v1[:n0], v0)
    start = n0 if keep else 0
    out = np.empty((len(v1), values0.shape[1]))
    if keep:
        out[:n0] = values0
    points = v1[start:]
    if len(points) == 0:
        return out
    from crackbake.nearest import nearest_k

    k = min(_CANDIDATES, len(f0))
    cand = nearest_k(v0[f0].mean(axis=1), points, k)[1]
    tri = v0[f0[cand]]  # (P, k, 3, 3)
    bary = barycentric(tri.reshape(-1, 3, 3), np.repeat(points, k, axis=0)).reshape(-1, k, 3)
    size = np.linalg.norm(tri[:, :, 1] - tri[:, :, 0], axis=-1)
    back = np.einsum("pkc,pkca->pka", bary, tri)
    # Outside distance (approximate) plus the gap to the face's plane: 0 for the holding face.
    miss = (np.maximum(-bary.min(axis=-1), 0.0) * size
            + np.linalg.norm(back - points[:, None], axis=-1))
    best = miss.argmin(axis=1)
    rows = np.arange(len(points))
    b = np.clip(bary[rows, best], 0.0, 1.0)
    b /= b.sum(axis=1, keepdims=True)
    out[start:] = np.einsum("pc,pcx->px", b, values0[f0[cand[rows, best]]])
    return out
