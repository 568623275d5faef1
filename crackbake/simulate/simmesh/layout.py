"""Point layout of the simulation mesh inside each asset face: 2-D face frames, how many
points each asset edge gets, and the jittered triangular lattice inside each face."""

from __future__ import annotations

import numpy as np

# Interior lattice points keep this distance (in target lengths) from the face's edges, so the
# triangles between an edge and the first lattice row are not slivers.  At sqrt(3)/4 the band
# it empties on both sides of an edge holds, on average, as many lattice points as the edge
# gets (one per target length), so the point density is the same near edges as inside.
_MARGIN = np.sqrt(3.0) / 4.0
_DENSITY = 2.0 / np.sqrt(3.0)  # lattice points per unit area, in target lengths
_ROW = np.sqrt(3.0) / 2.0  # lattice row spacing, target lengths


def face_frames_2d(tri: np.ndarray, h) -> np.ndarray:
    """Corners of each face in its own plane, in target lengths: (R, 3, 2), counter-clockwise.

    ``h`` is the target edge length, mesh units: one for all faces, or (R,) per face.

    Corner 0 at the origin, corner 1 on the +x axis, corner 2 above it.
    """
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    len1 = np.linalg.norm(e1, axis=1)
    u = e1 / len1[:, None]
    cx = np.einsum("ij,ij->i", e2, u)
    perp = e2 - cx[:, None] * u
    cy = np.linalg.norm(perp, axis=1)
    out = np.zeros((len(tri), 3, 2))
    out[:, 1, 0] = len1 / h
    out[:, 2, 0] = cx / h
    out[:, 2, 1] = cy / h
    return out


def lattice_points(
    corners: np.ndarray, rng: np.random.Generator, jitter: float
) -> tuple[np.ndarray, np.ndarray]:
    """Jittered triangular-lattice points inside each face, at least ``_MARGIN`` from its edges.

    Parameters
    ----------
    corners : (R, 3, 2) float64
        Face corners in target lengths (:func:`face_frames_2d`).

    Returns
    -------
    owner : (P,) int64
        Row of ``corners`` each point lies in.
    xy : (P, 2) float64
        Point positions in that face's 2-D frame, target lengths.
    """
    n_faces = len(corners)
    # Shrink each face by the margin: the inset triangle is the face scaled about its incentre
    # by (r - m) / r, r the inradius.
    a = np.linalg.norm(corners[:, 2] - corners[:, 1], axis=1)
    b = np.linalg.norm(corners[:, 0] - corners[:, 2], axis=1)
    c = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    perim = a + b + c
    incentre = (a[:, None] * corners[:, 0] + b[:, None] * corners[:, 1]
                + c[:, None] * corners[:, 2]) / perim[:, None]
    twice_area = corners[:, 1, 0] * corners[:, 2, 1]  # corner 0 at origin, 1 on the x axis
    inradius = twice_area / perim
    scale = np.clip(1.0 - _MARGIN / np.maximum(inradius, 1e-300), 0.0, None)
    inset = incentre[:, None] + (corners - incentre[:, None]) * scale[:, None, None]

    # Random lattice orientation and offset per face: no preferred direction on the surface.
    theta = rng.uniform(0.0, np.pi / 3.0, n_faces)
    offset = rng.uniform(0.0, 1.0, (n_faces, 2)) * [1.0, 2.0 * _ROW]
    cos, sin = np.cos(theta), np.sin(theta)
    # Rotate the inset face by -theta so the lattice rows are horizontal.
    qx = cos[:, None] * inset[..., 0] + sin[:, None] * inset[..., 1]
    qy = -sin[:, None] * inset[..., 0] + cos[:, None] * inset[..., 1]

    has = scale > 0
    k_lo = np.ceil((qy.min(axis=1) - offset[:, 1]) / _ROW).astype(np.int64)
    k_hi = np.floor((qy.max(axis=1) - offset[:, 1]) / _ROW).astype(np.int64)
    n_rows = np.where(has, np.maximum(k_hi - k_lo + 1, 0), 0)
    row_face = np.repeat(np.arange(n_faces), n_rows)
    row_start = np.cumsum(n_rows) - n_rows
    k = k_lo[row_face] + np.arange(len(row_face)) - row_start[row_face]
    y = offset[row_face, 1] + k * _ROW

    # x-interval of the (convex) inset triangle on the scanline y.
    lo = np.full(len(y), np.inf)
    hi = np.full(len(y), -np.inf)
    for i in range(3):
        j = (i + 1) % 3
        x0, y0 = qx[row_face, i], qy[row_face, i]
        x1, y1 = qx[row_face, j], qy[row_face, j]
        dy = y1 - y0
        hit = ((y - y0) * (y - y1) <= 0) & (dy != 0)
        x = x0 + (y - y0) * (x1 - x0) / np.where(dy != 0, dy, 1.0)
        lo = np.where(hit, np.minimum(lo, x), lo)
        hi = np.where(hit, np.maximum(hi, x), hi)
    shift = offset[row_face, 0] + 0.5 * (k & 1)
    ok = np.isfinite(lo)
    i_lo = np.where(ok, np.ceil(lo - shift), 0).astype(np.int64)
    i_hi = np.where(ok, np.floor(hi - shift), -1).astype(np.int64)
    n_pts = np.maximum(i_hi - i_lo + 1, 0)
    pt_row = np.repeat(np.arange(len(y)), n_pts)
    pt_start = np.cumsum(n_pts) - n_pts
    px = shift[pt_row] + i_lo[pt_row] + np.arange(len(pt_row)) - pt_start[pt_row]
    py = y[pt_row]
    owner = row_face[pt_row]

    # Jitter inside a disc of radius `jitter` (< margin, so points stay inside the face).
    r = jitter * np.sqrt(rng.uniform(0.0, 1.0, len(px)))
    phi = rng.uniform(0.0, 2.0 * np.pi, len(px))
    px = px + r * np.cos(phi)
    py = py + r * np.sin(phi)
    cs, sn = cos[owner], sin[owner]
    xy = np.stack([cs * px - sn * py, sn * px + cs * py], axis=1)
    return owner, xy


def edge_point_counts(
    corners: np.ndarray, face_edge: np.ndarray, n_e: int, rng: np.random.Generator
) -> np.ndarray:
    """How many points each welded edge gets, (E,) int64.

    Each face should end up with the lattice's point density; what its inset lattice does not
    supply (all of it for small faces) goes on its edges, in proportion to their lengths, and
    an edge takes the mean of its faces' requests.  For big faces this is about one point per
    target length; for faces of a few target lengths it is fewer, so dense asset meshes do not
    get denser sim meshes (edge points alone would).

    Parameters
    ----------
    corners : (R, 3, 2) float64
        Face corners in target lengths (:func:`face_frames_2d`).
    face_edge : (R, 3) int64
        Welded edge of each face side.
    n_e : int
        Number of welded edges.
    rng : numpy.random.Generator
        Draws ``n_e`` uniforms for the stochastic rounding.
    """
    face_count = np.bincount(face_edge.ravel(), minlength=n_e)
    side_len = np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2)
    perim = side_len.sum(axis=1)
    f_area = 0.5 * corners[:, 1, 0] * corners[:, 2, 1]
    inset = f_area * np.clip(1.0 - _MARGIN * perim / (2.0 * f_area), 0.0, None) ** 2
    budget = np.clip(_DENSITY * (f_area - inset) - 0.5, 0.0, None)  # 0.5: corner share
    request = 2.0 * budget[:, None] * side_len / perim[:, None]
    want = np.bincount(face_edge.ravel(), request.ravel(), minlength=n_e) / face_count
    # Stochastic rounding keeps the expected count right whatever the asset's edge lengths;
    # below half a point an edge stays whole, so an asset finer than the target is kept as is.
    return np.where(want < 0.5, 0, np.floor(want + rng.uniform(0.0, 1.0, n_e))).astype(np.int64)


def min_angle_2d(p: np.ndarray) -> np.ndarray:
    """Smallest angle (degrees) of 2-D triangles (K, 3, 2)."""
    e = p[:, [1, 2, 0]] - p  # e[:, i] runs from corner i to corner i+1
    length = np.linalg.norm(e, axis=2)
    # Angle at corner i+1 between -e[i] and e[i+1].
    cos = -np.einsum("kij,kij->ki", e, e[:, [1, 2, 0]]) / np.maximum(
        length * length[:, [1, 2, 0]], 1e-300)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).min(axis=1)
