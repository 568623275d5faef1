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
    if len(segments.a) == 0 or len(faces) == 0:
        return _no_lists(len(faces), edge, nx)
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
        return _no_lists(len(faces), edge, nx)

    # float32 positions in the shader are off by about 1e-7 of their magnitude.
    slack = 1e-6 * float(np.abs(vertices).max()) + _SLACK * max_distance
    a = np.asarray(segments.a, np.float64) @ rot.T + shift
    b = np.asarray(segments.b, np.float64) @ rot.T + shift
    # Only segments within the largest reach of the drawn surface can matter.
    widest = max(max_distance, float(cell_cover[drawn].max())) * (1 + _SLACK) + slack
    all_lo, all_hi = lo[drawn].min(axis=0) - widest, hi[drawn].max(axis=0) + widest
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    near = np.flatnonzero(np.all((seg_hi >= all_lo) & (seg_lo <= all_hi), axis=1))
    a, b, seg_lo, seg_hi = a[near], b[near], seg_lo[near], seg_hi[near]
    if len(near) == 0:
        return _no_lists(len(faces), edge, nx)
    # A 2-D grid over the image plane (the decal's depth is thin), as fine as grid.py's.
    flat_lo, flat_hi = seg_lo.copy(), seg_hi.copy()
    flat_lo[:, 2] = flat_hi[:, 2] = 0.0
    grid_cell = max(0.25 * max(max_distance, half_width), edge * 2.0 / res / scale[0],
                    float(np.ptp(a[:, :2], axis=0).max()) / 2**11, 1e-30)  # fmt: skip
    grid = _segment_grid(flat_lo, flat_hi, grid_cell)
    nearest = _nearest_bounds(lo, hi, a, b, *grid, max_distance)
    reach = np.maximum(np.minimum(nearest, max_distance), cell_cover) * (1 + _SLACK) + slack
    bin_start, candidates, bounds = _cell_candidates(
        lo, hi, reach, a, b, seg_lo, seg_hi, near.astype(np.int64), *grid, slack
    )
    face_bin = np.zeros(len(faces), np.uint32)
    return FaceBins(face_bin, bin_start.astype(np.uint32), candidates, bounds, edge, nx)


def _no_lists(n_faces: int, edge: int, nx: int) -> FaceBins:
    """Cells with empty lists (no segments, or none near the drawn surface)."""
    return FaceBins(np.zeros(n_faces, np.uint32), np.zeros(nx * nx + 1, np.uint32),
                    np.zeros(1, np.uint32), np.zeros(1, np.float32), edge, nx)  # fmt: skip


@njit(cache=True, nogil=True)
def _nearest_bounds(lo, hi, a, b, origin, grid_cell, dims, cell_start, cell_items, limit):
    """Per box (lo, hi: (C, 3); empty where lo > hi), an upper bound of the distance from any of
    its points to the nearest segment (a, b: (S, 3)): the distance from its centre to the
    nearest segment plus its half diagonal; inf where the nearest is beyond ``limit``.

    The nearest is searched in squares of the 2-D segment grid of doubling half width R: once
    the nearest found is within R, no segment outside the square can be nearer."""
    n = lo.shape[0]
    out = np.full(n, np.inf)
    stamp = np.full(a.shape[0], -1, np.int64)
    c = np.empty(3)
    for ci in range(n):
        if not lo[ci, 0] <= hi[ci, 0]:
            continue
        half2 = 0.0
        for k in range(3):
            c[k] = 0.5 * (lo[ci, k] + hi[ci, k])
            half2 += (0.5 * (hi[ci, k] - lo[ci, k])) ** 2
        best2 = np.inf
        reach = grid_cell
        while True:
            x0 = max(int(np.floor((c[0] - reach - origin[0]) / grid_cell)), 0)
            y0 = max(int(np.floor((c[1] - reach - origin[1]) / grid_cell)), 0)
            x1 = min(int(np.floor((c[0] + reach - origin[0]) / grid_cell)), dims[0] - 1)
            y1 = min(int(np.floor((c[1] + reach - origin[1]) / grid_cell)), dims[1] - 1)
            for y in range(y0, y1 + 1):
                for x in range(x0, x1 + 1):
                    g = y * dims[0] + x
                    for j in range(cell_start[g], cell_start[g + 1]):
                        s = cell_items[j]
                        if stamp[s] == ci:
                            continue
                        stamp[s] = ci
                        ab2 = 0.0
                        t = 0.0
                        for k in range(3):
                            ab2 += (b[s, k] - a[s, k]) ** 2
                            t += (c[k] - a[s, k]) * (b[s, k] - a[s, k])
                        t = min(max(t / ab2, 0.0), 1.0) if ab2 > 0.0 else 0.0
                        d2 = 0.0
                        for k in range(3):
                            d2 += (c[k] - a[s, k] - t * (b[s, k] - a[s, k])) ** 2
                        best2 = min(best2, d2)
            if best2 <= reach * reach or reach > limit:
                break
            reach *= 2.0
        if best2 <= limit * limit:
            out[ci] = np.sqrt(best2) + np.sqrt(half2)
    return out


@njit(cache=True)
def _clip(src, n, dst, axis, value, keep_above):
    """Sutherland-Hodgman: the part of polygon ``src[:n]`` (rows col, row, z) on one side of
    ``[:, axis] = value``, written to ``dst``; returns its vertex count."""
    m = 0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        p_in = src[i, axis] >= value if keep_above else src[i, axis] <= value
        q_in = src[j, axis] >= value if keep_above else src[j, axis] <= value
        if p_in:
            dst[m] = src[i]
            m += 1
        if p_in != q_in:
            t = (value - src[i, axis]) / (src[j, axis] - src[i, axis])
            for k in range(3):
                dst[m, k] = src[i, k] + t * (src[j, k] - src[i, k])
            m += 1
    return m


@njit(cache=True, nogil=True)
def _cell_boxes(texel, faces, cover, edge, nx, res, to_local):
    """Per cell, the box (projector frame) of the faces clipped to its column, and the largest
    anti-aliasing reach of those faces; empty cells get lo > hi."""
    n_cells = nx * nx
    lo = np.full((n_cells, 3), np.inf)
    hi = np.full((n_cells, 3), -np.inf)
    cell_cover = np.zeros(n_cells)
    tri = np.empty((3, 3))
    ping = np.empty((8, 3))  # a triangle clipped by four lines has at most 7 corners
    pong = np.empty((8, 3))
    margin = _CLIP_MARGIN_PX
    for f in range(faces.shape[0]):
        for k in range(3):
            tri[k] = texel[faces[f, k]]
        c_lo = min(tri[0, 0], tri[1, 0], tri[2, 0])
        c_hi = max(tri[0, 0], tri[1, 0], tri[2, 0])
        r_lo = min(tri[0, 1], tri[1, 1], tri[2, 1])
        r_hi = max(tri[0, 1], tri[1, 1], tri[2, 1])
        if not (c_hi >= -margin and c_lo <= res + margin and r_hi >= -margin
                and r_lo <= res + margin):  # fmt: skip
            continue  # off the image (or not finite)
        x0 = max(int(np.floor((c_lo - margin) / edge)), 0)
        x1 = min(int(np.floor((c_hi + margin) / edge)), nx - 1)
        y0 = max(int(np.floor((r_lo - margin) / edge)), 0)
        y1 = min(int(np.floor((r_hi + margin) / edge)), nx - 1)
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                m = _clip(tri, 3, ping, 0, cx * edge - margin, True)
                m = _clip(ping, m, pong, 0, (cx + 1) * edge + margin, False)
                m = _clip(pong, m, ping, 1, cy * edge - margin, True)
                m = _clip(ping, m, pong, 1, (cy + 1) * edge + margin, False)
                if m == 0:
                    continue
                c = cy * nx + cx
                for i in range(m):
                    x = to_local[0] * pong[i, 0] + to_local[1]
                    y = to_local[2] * pong[i, 1] + to_local[3]
                    lo[c, 0] = min(lo[c, 0], x)
                    hi[c, 0] = max(hi[c, 0], x)
                    lo[c, 1] = min(lo[c, 1], y)
                    hi[c, 1] = max(hi[c, 1], y)
                    lo[c, 2] = min(lo[c, 2], pong[i, 2])
                    hi[c, 2] = max(hi[c, 2], pong[i, 2])
                cell_cover[c] = max(cell_cover[c], cover[f])
    return lo, hi, cell_cover


@njit(cache=True)
def _box_distance2(a, b, lo, hi, ts):
    """Squared distance between segment a-b and the box [lo, hi] (all (3,)): the minimum of a
    convex piecewise quadratic in the segment parameter, found on each of its pieces.  ``ts``:
    scratch space for 8 floats."""
    ts[0] = 0.0
    ts[1] = 1.0
    n = 2
    for k in range(3):
        dk = b[k] - a[k]
        if dk != 0.0:
            for v in (lo[k], hi[k]):
                t = (v - a[k]) / dk
                if 0.0 < t < 1.0:
                    # Insertion into the sorted breakpoints.
                    q = n - 1
                    while ts[q] > t:
                        ts[q + 1] = ts[q]
                        q -= 1
                    ts[q + 1] = t
                    n += 1
    best = np.inf
    for i in range(n):
        t_end = ts[i]
        if i + 1 < n:
            # The piece's quadratic: the axes outside the box at its middle; its minimum,
            # clamped to the piece (the piece's start is the previous piece's end).
            tm = 0.5 * (ts[i] + ts[i + 1])
            qa = 0.0
            qb = 0.0
            for k in range(3):
                dk = b[k] - a[k]
                x = a[k] + tm * dk
                if x < lo[k]:
                    qa += dk * dk
                    qb += (a[k] - lo[k]) * dk
                elif x > hi[k]:
                    qa += dk * dk
                    qb += (a[k] - hi[k]) * dk
            if qa > 0.0:
                t_end = min(max(-qb / qa, ts[i]), ts[i + 1])
        for t in (ts[i], t_end):
            s = 0.0
            for k in range(3):
                x = a[k] + t * (b[k] - a[k])
                g = max(lo[k] - x, 0.0, x - hi[k])
                s += g * g
            best = min(best, s)
    return best


@njit(cache=True, nogil=True)
def _cell_candidates(lo, hi, reach, a, b, seg_lo, seg_hi, ids, origin, grid_cell, dims,
                     cell_start, cell_items, slack):  # fmt: skip
    """Each cell's segments (``ids``: their indices in the bake) within its reach, ascending by
    distance to the cell's box, ties by index: (bin_start, candidates, bounds).

    The segment grid is two-dimensional (image x, y; ``dims[2]`` is 1): a decal's depth is thin.
    """
    n_cells = lo.shape[0]
    bin_start = np.zeros(n_cells + 1, np.int64)
    out = np.empty(max(4 * n_cells, 16), np.uint32)
    bound = np.empty(out.shape[0], np.float32)
    n_out = 0
    stamp = np.full(a.shape[0], -1, np.int64)
    found = np.empty(a.shape[0], np.int64)
    dist = np.empty(a.shape[0], np.float64)
    ts = np.empty(8)
    for ci in range(n_cells):
        bin_start[ci] = n_out
        if not lo[ci, 0] <= hi[ci, 0]:
            continue
        r = reach[ci]
        r2 = r * r
        gx0 = np.floor((lo[ci, 0] - r - origin[0]) / grid_cell)
        gy0 = np.floor((lo[ci, 1] - r - origin[1]) / grid_cell)
        gx1 = np.floor((hi[ci, 0] + r - origin[0]) / grid_cell)
        gy1 = np.floor((hi[ci, 1] + r - origin[1]) / grid_cell)
        if gx1 < 0 or gy1 < 0 or gx0 > dims[0] - 1 or gy0 > dims[1] - 1:
            continue
        x0, y0 = int(max(gx0, 0.0)), int(max(gy0, 0.0))
        x1, y1 = int(min(gx1, dims[0] - 1.0)), int(min(gy1, dims[1] - 1.0))
        m = 0
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                g = y * dims[0] + x
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
                    d2 = _box_distance2(a[s], b[s], lo[ci], hi[ci], ts)
                    if d2 <= r2:
                        found[m] = s
                        dist[m] = np.sqrt(d2)
                        m += 1
        if n_out + m > out.shape[0]:
            size = max(2 * out.shape[0], n_out + m)
            grown = np.empty(size, np.uint32)
            grown[:n_out] = out[:n_out]
            out = grown
            grown_bound = np.empty(size, np.float32)
            grown_bound[:n_out] = bound[:n_out]
            bound = grown_bound
        # Insertion sort by (distance, index): the lists are short.
        for j in range(1, m):
            fs, fd = found[j], dist[j]
            q = j - 1
            while q >= 0 and (dist[q] > fd or (dist[q] == fd and ids[found[q]] > ids[fs])):
                found[q + 1] = found[q]
                dist[q + 1] = dist[q]
                q -= 1
            found[q + 1] = fs
            dist[q + 1] = fd
        for j in range(m):
            out[n_out + j] = ids[found[j]]
            bound[n_out + j] = max(dist[j] - slack, 0.0)
        n_out += m
    bin_start[n_cells] = n_out
    if n_out == 0:  # GL refuses empty buffers
        return bin_start, np.zeros(1, np.uint32), np.zeros(1, np.float32)
    return bin_start, out[:n_out].copy(), bound[:n_out].copy()
