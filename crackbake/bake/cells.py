"""Candidate segments per cell of the image plane, for a bake through an orthographic camera.

The decal bake (:mod:`crackbake.decals.projector`) draws the faces through the projector's
camera.  Face bins (:mod:`crackbake.bake.grid`) suit the UV bake, where a face's texels cover the
face; in a decal a few coarse faces can fill the whole image, and a bin as large as such a face
lists every segment of a dense star's centre with a distance bound of 0, so every texel walked
the whole list (104 s for a 4096-texel decal on spot, against 5.6 s for a UV bake of that size).

Here the lists belong to square cells of a few texels in the image instead.  The projection is
orthographic, so the surface drawn in a cell lies in the cell's column; each cell's box is the
bounding box (projector frame) of every face clipped to that column, and its list holds the
segments whose exact distance to the box is within the cell's reach, in ascending distance: the
walk in ``shaders/crack_bake.frag`` stops after the few segments near its texel.  The reach is
the anti-aliasing reach of the faces drawn there (what can add coverage or depth) or, where
larger, the distance within which the nearest segment surely lies (what the distance, id, width
and time channels need; at most the distance clamp): a point of the cell is at most the cell's
half diagonal from its centre, and the centre at most its distance to the nearest sample of the
segments from a segment, so lists stay short in dense and sparse parts alike.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.bake.grid import _SLACK, FaceBins, _segment_grid, face_footprint
from crackbake.network import Segments

#: Edge of an image cell in texels: small next to the spacing of a dense star's cracks, so the
#: distance bounds separate them, yet each cell's list is shared by this many texels squared.
CELL_PX = 8
#: Most cells of an image: the edge doubles past CELL_PX for images above 8192 texels.
CELLS_MAX = 1 << 20
#: Most sample points along the segments for the nearest-distance bound.
_SAMPLES_MAX = 1 << 21
#: A face is clipped to its cells widened by this many texels, so a texel centre the GPU's
#: float32 placement puts just inside a face that float64 puts just outside still finds it.
_CLIP_MARGIN_PX = 0.25


def cell_px(res: int) -> int:
    """Edge of the image cells of a ``res`` x ``res`` image, texels."""
    edge = CELL_PX
    while (res / edge) ** 2 > CELLS_MAX:
        edge *= 2
    return edge


def image_bins(
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    segments: Segments,
    res: int,
    max_distance: float,
    projection: np.ndarray,
    min_px: float = 0.0,
) -> FaceBins:
    """Candidate lists per image cell of a bake through an orthographic ``projection``.

    Parameters
    ----------
    vertices : (V, 3) float, faces : (F, 3) int
        The triangles drawn, mesh units.
    uv : (V, 2) float
        Their placement in the image, ``0.5 + 0.5 * clip.xy`` (v up, [0, 1] across the image).
    segments : Segments
        Crack segments, mesh units (widths widened by the look's reach, as for ``face_bins``).
    res : int
        Image edge, texels.
    max_distance : float
        Distance clamp of the bake, mesh units.
    projection : (4, 4) float
        The mesh -> clip matrix (column vectors) of an orthographic camera: rows 0-2 of its
        3 x 3 part are orthogonal.
    min_px : float
        Least drawn crack width, texels.

    Returns
    -------
    FaceBins
        ``cell`` (texels per cell edge) and ``cells_x`` set; bin ``r * cells_x + c`` is the cell
        of image rows ``r * cell ..`` (row 0 = top) and columns ``c * cell ..``; ``face_bin`` is
        zero (the texel's cell picks its list).
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    edge = cell_px(res)
    nx = -(-res // edge)
    n_cells = nx * nx
    face_bin = np.zeros(len(faces), np.uint32)
    if len(segments.a) == 0 or len(faces) == 0:
        return FaceBins(face_bin, np.zeros(n_cells + 1, np.uint32), np.zeros(1, np.uint32),
                        np.zeros(1, np.float32), edge, nx)  # fmt: skip
    # The camera's orthonormal frame (clip = S R p + t, S diagonal): distances there are the
    # mesh's; x follows image columns, y image rows upwards.
    m = np.asarray(projection, np.float64)
    scale = np.linalg.norm(m[:3, :3], axis=1)
    rot, shift = m[:3, :3] / scale[:, None], m[:3, 3] / scale
    local = vertices @ rot.T + shift
    texel = np.column_stack([uv[:, 0] * res, (1.0 - uv[:, 1]) * res, local[:, 2]])
    # Texel (col, row) -> local (x, y): x = (2 col / res - 1) / sx, y = (1 - 2 row / res) / sy.
    to_local = np.array([2.0 / res / scale[0], -1.0 / scale[0], -2.0 / res / scale[1],
                         1.0 / scale[1]])  # fmt: skip

    half_width = 0.5 * float(segments.width.max())
    foot = face_footprint(vertices, faces, uv, res)
    cover = np.maximum(half_width, 0.5 * min_px * foot) + foot  # crack_bake.frag's cover_reach
    lo, hi, cell_cover = _cell_boxes(texel, faces, cover, edge, nx, res, to_local)
    drawn = np.flatnonzero(lo[:, 0] <= hi[:, 0])
    if len(drawn) == 0:
        return FaceBins(face_bin, np.zeros(n_cells + 1, np.uint32), np.zeros(1, np.uint32),
                        np.zeros(1, np.float32), edge, nx)  # fmt: skip

    # float32 positions in the shader are off by about 1e-7 of their magnitude.
    slack = 1e-6 * float(np.abs(vertices).max()) + _SLACK * max_distance
    a = np.asarray(segments.a, np.float64) @ rot.T + shift
    b = np.asarray(segments.b, np.float64) @ rot.T + shift
    # Only segments within the largest reach of the drawn surface can matter.
    widest = max(max_distance, float(cell_cover[drawn].max())) * (1 + _SLACK) + slack
    all_lo, all_hi = lo[drawn].min(axis=0) - widest, hi[drawn].max(axis=0) + widest
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    near = np.flatnonzero(np.all((seg_hi >= all_lo) & (seg_lo <= all_hi), axis=1))
    reach = np.zeros(n_cells)
    if len(near):
        nearest = _nearest_bound(a[near], b[near], lo[drawn], hi[drawn], edge * 2.0 / res /
                                 scale[0])  # fmt: skip
        reach[drawn] = np.maximum(np.minimum(nearest, max_distance), cell_cover[drawn])
        reach[drawn] = reach[drawn] * (1 + _SLACK) + slack
    a, b, seg_lo, seg_hi = a[near], b[near], seg_lo[near], seg_hi[near]
    if len(near) == 0:
        return FaceBins(face_bin, np.zeros(n_cells + 1, np.uint32), np.zeros(1, np.uint32),
                        np.zeros(1, np.float32), edge, nx)  # fmt: skip
    grid_cell = max(0.25 * max(max_distance, half_width), float(np.ptp(a, axis=0).max()) / 2**16,
                    1e-30)  # fmt: skip
    grid = _segment_grid(seg_lo, seg_hi, grid_cell)
    ids = near.astype(np.int64)
    args = (lo, hi, reach, a, b, seg_lo, seg_hi, ids, *grid)
    counts = _cell_candidates(*args, np.zeros(1, np.int64), np.zeros(0, np.uint32),
                              np.zeros(0, np.float32), slack, False)  # fmt: skip
    bin_start = np.zeros(n_cells + 1, np.int64)
    np.cumsum(counts, out=bin_start[1:])
    candidates = np.zeros(max(int(bin_start[-1]), 1), np.uint32)
    bounds = np.zeros(len(candidates), np.float32)
    _cell_candidates(*args, bin_start, candidates, bounds, slack, True)
    return FaceBins(face_bin, bin_start.astype(np.uint32), candidates, bounds, edge, nx)


def _nearest_bound(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                   spacing: float) -> np.ndarray:  # fmt: skip
    """Per box (lo, hi: (C, 3)), an upper bound of the distance from any of its points to the
    nearest segment (a, b: (S, 3)): the distance from its centre to the nearest of points
    sampled along the segments, plus its half diagonal."""
    from scipy.spatial import cKDTree

    length = np.linalg.norm(b - a, axis=1)
    spacing = max(spacing, float(length.sum()) / _SAMPLES_MAX, 1e-300)
    n = np.ceil(length / spacing).astype(np.int64) + 1
    seg = np.repeat(np.arange(len(a)), n)
    t = (np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n).clip(1)
    points = a[seg] + t[:, None] * (b - a)[seg]
    dist, _ = cKDTree(points).query(0.5 * (lo + hi))
    return dist + 0.5 * np.linalg.norm(hi - lo, axis=1)


@njit(cache=True)
def _clip(poly, n, axis, value, keep_above):
    """Sutherland-Hodgman: the part of polygon ``poly[:n]`` (rows col, row, z) on one side of
    ``poly[:, axis] = value``; returns the new polygon and its vertex count."""
    out = np.empty((n + 2, 3))
    m = 0
    for i in range(n):
        p = poly[i]
        q = poly[(i + 1) % n]
        p_in = p[axis] >= value if keep_above else p[axis] <= value
        q_in = q[axis] >= value if keep_above else q[axis] <= value
        if p_in:
            out[m] = p
            m += 1
        if p_in != q_in:
            t = (value - p[axis]) / (q[axis] - p[axis])
            out[m] = p + t * (q - p)
            m += 1
    return out, m


@njit(cache=True)
def _cell_boxes(texel, faces, cover, edge, nx, res, to_local):
    """Per cell, the box (projector frame) of the faces clipped to its column, and the largest
    anti-aliasing reach of those faces; empty cells get lo > hi."""
    n_cells = nx * nx
    lo = np.full((n_cells, 3), np.inf)
    hi = np.full((n_cells, 3), -np.inf)
    cell_cover = np.zeros(n_cells)
    poly = np.empty((3, 3))
    for f in range(faces.shape[0]):
        for k in range(3):
            poly[k] = texel[faces[f, k]]
        c_lo = min(poly[0, 0], poly[1, 0], poly[2, 0])
        c_hi = max(poly[0, 0], poly[1, 0], poly[2, 0])
        r_lo = min(poly[0, 1], poly[1, 1], poly[2, 1])
        r_hi = max(poly[0, 1], poly[1, 1], poly[2, 1])
        if not (c_hi >= -_CLIP_MARGIN_PX and c_lo <= res + _CLIP_MARGIN_PX
                and r_hi >= -_CLIP_MARGIN_PX and r_lo <= res + _CLIP_MARGIN_PX):
            continue  # off the image (or not finite)
        x0 = max(int(np.floor((c_lo - _CLIP_MARGIN_PX) / edge)), 0)
        x1 = min(int(np.floor((c_hi + _CLIP_MARGIN_PX) / edge)), nx - 1)
        y0 = max(int(np.floor((r_lo - _CLIP_MARGIN_PX) / edge)), 0)
        y1 = min(int(np.floor((r_hi + _CLIP_MARGIN_PX) / edge)), nx - 1)
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                p, m = _clip(poly, 3, 0, cx * edge - _CLIP_MARGIN_PX, True)
                if m:
                    p, m = _clip(p, m, 0, (cx + 1) * edge + _CLIP_MARGIN_PX, False)
                if m:
                    p, m = _clip(p, m, 1, cy * edge - _CLIP_MARGIN_PX, True)
                if m:
                    p, m = _clip(p, m, 1, (cy + 1) * edge + _CLIP_MARGIN_PX, False)
                if m == 0:
                    continue
                c = cy * nx + cx
                for i in range(m):
                    x = to_local[0] * p[i, 0] + to_local[1]
                    y = to_local[2] * p[i, 1] + to_local[3]
                    lo[c, 0] = min(lo[c, 0], x)
                    hi[c, 0] = max(hi[c, 0], x)
                    lo[c, 1] = min(lo[c, 1], y)
                    hi[c, 1] = max(hi[c, 1], y)
                    lo[c, 2] = min(lo[c, 2], p[i, 2])
                    hi[c, 2] = max(hi[c, 2], p[i, 2])
                cell_cover[c] = max(cell_cover[c], cover[f])
    return lo, hi, cell_cover


@njit(cache=True)
def _box_distance2(a, b, lo, hi):
    """Squared distance between segment a-b and the box [lo, hi] (all (3,)): the minimum of a
    convex piecewise quadratic in the segment parameter, found on each of its pieces."""
    d = b - a
    ts = np.empty(8)
    ts[0] = 0.0
    ts[1] = 1.0
    n = 2
    for k in range(3):
        if d[k] != 0.0:
            for v in (lo[k], hi[k]):
                t = (v - a[k]) / d[k]
                if 0.0 < t < 1.0:
                    ts[n] = t
                    n += 1
    ts = np.sort(ts[:n])
    best = np.inf
    for i in range(n):
        cands = (ts[i], ts[i])
        if i + 1 < n:
            # The piece's quadratic: the axes outside the box at its middle.
            tm = 0.5 * (ts[i] + ts[i + 1])
            qa = 0.0
            qb = 0.0
            for k in range(3):
                x = a[k] + tm * d[k]
                if x < lo[k]:
                    qa += d[k] * d[k]
                    qb += (a[k] - lo[k]) * d[k]
                elif x > hi[k]:
                    qa += d[k] * d[k]
                    qb += (a[k] - hi[k]) * d[k]
            if qa > 0.0:
                cands = (ts[i], min(max(-qb / qa, ts[i]), ts[i + 1]))
        for t in cands:
            s = 0.0
            for k in range(3):
                x = a[k] + t * d[k]
                g = max(lo[k] - x, 0.0, x - hi[k])
                s += g * g
            best = min(best, s)
    return best


@njit(cache=True)
def _cell_candidates(
    lo, hi, reach, a, b, seg_lo, seg_hi, ids, origin, grid_cell, dims, cell_start, cell_items,
    bin_start, out, bound, slack, fill,
):  # fmt: skip
    """Count (``fill`` False) or write (True) each cell's segments (``ids``: their indices in
    the bake) within its reach, ascending by distance to the cell's box, ties by index."""
    n_cells = lo.shape[0]
    counts = np.zeros(n_cells, np.int64)
    stamp = np.full(a.shape[0], -1, np.int64)
    found = np.empty(a.shape[0], np.int64)
    dist = np.empty(a.shape[0], np.float64)
    for ci in range(n_cells):
        if not lo[ci, 0] <= hi[ci, 0]:
            continue
        r = reach[ci]
        r2 = r * r
        c0 = np.empty(3, np.int64)
        c1 = np.empty(3, np.int64)
        empty = False
        for k in range(3):
            g0 = np.floor((lo[ci, k] - r - origin[k]) / grid_cell)
            g1 = np.floor((hi[ci, k] + r - origin[k]) / grid_cell)
            if g1 < 0 or g0 > dims[k] - 1:
                empty = True
            c0[k] = int(max(g0, 0.0))
            c1[k] = int(min(g1, dims[k] - 1.0))
        if empty:
            continue
        m = 0
        for z in range(c0[2], c1[2] + 1):
            for y in range(c0[1], c1[1] + 1):
                for x in range(c0[0], c1[0] + 1):
                    g = (z * dims[1] + y) * dims[0] + x
                    for j in range(cell_start[g], cell_start[g + 1]):
                        s = cell_items[j]
                        if stamp[s] == ci:
                            continue
                        stamp[s] = ci
                        gap2 = 0.0
                        for k in range(3):
                            e = max(seg_lo[s, k] - hi[ci, k], lo[ci, k] - seg_hi[s, k], 0.0)
                            gap2 += e * e
                        if gap2 > r2:
                            continue
                        d2 = _box_distance2(a[s], b[s], lo[ci], hi[ci])
                        if d2 <= r2:
                            found[m] = s
                            dist[m] = np.sqrt(d2)
                            m += 1
        counts[ci] = m
        if fill:
            idx = ids[found[:m]]
            by_index = np.argsort(idx)
            # mergesort is stable: equal distances keep ascending segment order.
            order = by_index[np.argsort(dist[:m][by_index], kind="mergesort")]
            for j in range(m):
                e = order[j]
                out[bin_start[ci] + j] = idx[e]
                bound[bin_start[ci] + j] = max(dist[e] - slack, 0.0)
    return counts
