"""Which crack segments each face's texels must measure, in memory linear in faces + segments.

Faces are grouped into *bins*: cubic cells of a size that grows with the face (so one big face
never widens the bin of many small ones).  Every bin gets one list of the segments that can
change any texel of its faces, and each face reads its bin's list.  Per-face lists, the earlier
design, grew with faces x segments (2.8 GB at 375k faces and 15k segments, killed for memory at
1.5M faces); bins keep the lists as long as a few per cell of surface.

A segment can change a texel only within the texel's *reach*: the distance clamp, or half the
widest crack plus one texel footprint (the anti-aliasing ramp).  The footprint of a face is the
Frobenius norm of its texel-to-world Jacobian, which bounds the footprint the shader measures along
any direction.  A bin lists every segment whose bounding box comes within the largest reach of its
faces of the bin's bounding box, so its list holds every segment that can matter to its texels,
with a lower bound of its distance to the bin.  Lists run in ascending bound, so the shader stops
as soon as the bound passes both the nearest crack found and the anti-aliasing reach; it keeps
the nearest segment with the lowest index on ties, so the maps do not depend on the list order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from crackbake.network import Segments

#: Bin edge (smallest level) as a fraction of the distance clamp.
BIN_PER_REACH = 0.25
#: Relative slack on reaches, covering float32 rounding in the shader.
_SLACK = 1e-3
#: Faces from which :func:`face_bins` measures them in one kernel pass (:func:`_face_geometry`,
#: the same bits): below it numpy takes milliseconds, less than loading the kernel.
KERNEL_FACES = 100_000


@dataclass(eq=False)
class FaceBins:
    """Faces grouped into bins, each bin with one candidate list (compressed rows).

    Attributes
    ----------
    face_bin : (F,) uint32
        Bin of each face.
    bin_start : (B + 1,) uint32
        Candidates of bin ``b`` are ``candidates[bin_start[b]:bin_start[b + 1]]``.
    candidates : (K,) uint32
        Segment indices (one entry at least: GL refuses empty buffers), each bin's in ascending
        ``bounds`` order, ties in ascending index.
    bounds : (K,) float32
        A lower bound, mesh units, on the distance from any point of the bin's faces to the
        segment: the shader stops its walk once the bound passes what can still matter.
    """

    face_bin: np.ndarray
    bin_start: np.ndarray
    candidates: np.ndarray
    bounds: np.ndarray
    #: Image cells instead of face bins (:func:`image_bins`): each cell's edge in texels (0:
    #: the bins are face bins, ``face_bin`` says which) and the cells per image row.
    cell: int = 0
    cells_x: int = 0


def face_reach(
    vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, res: int, max_distance: float,
    half_width: float, min_px: float = 0.0,
) -> np.ndarray:  # fmt: skip
    """Distance within which a segment can change a texel of each face, mesh units.

    Returns
    -------
    (F,) float64
        ``max(max_distance, max(half_width, min_px / 2 * footprint) + footprint)``, footprint the
        Frobenius norm of the face's texel-to-world Jacobian (0 for faces of no UV area: they
        draw no texels), plus a small slack; ``min_px`` is the bake's least drawn width in texels.
    """
    foot = face_footprint(vertices, faces, uv, res)
    drawn = np.maximum(half_width, 0.5 * min_px * foot)
    return np.maximum(max_distance, drawn + foot) * (1 + _SLACK)


def face_footprint(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, res: int) -> np.ndarray:
    """The Frobenius norm of each face's texel-to-world Jacobian, (F,) float64, mesh units per
    texel (0 for faces of no UV area: they draw no texels)."""
    # Corner columns, not (F, 3, 3) gathers: numpy reduces those slowly along the short axis.
    p0, p1, p2 = (vertices[faces[:, k]] for k in range(3))
    e1, e2 = p1 - p0, p2 - p0
    del p0, p1, p2
    t0, t1, t2 = (uv[faces[:, k]] * res for k in range(3))
    q1, q2 = t1 - t0, t2 - t0
    det = q1[:, 0] * q2[:, 1] - q1[:, 1] * q2[:, 0]
    # J = [e1 e2] [q1 q2]^-1, columns d(world)/d(texel x), d(world)/d(texel y).
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        dpx = (e1 * q2[:, 1:2] - e2 * q1[:, 1:2]) / det[:, None]
        dpy = (e2 * q1[:, 0:1] - e1 * q2[:, 0:1]) / det[:, None]
        foot = np.sqrt(np.einsum("ij,ij->i", dpx, dpx) + np.einsum("ij,ij->i", dpy, dpy))
    # A face with no UV area draws no texels: its reach never matters.
    return np.where(np.isfinite(foot), foot, 0.0)


def bin_faces(lo: np.ndarray, hi: np.ndarray, cell: float, size: np.ndarray) -> np.ndarray:
    """Bin of each face (bounding box ``lo``, ``hi``: (F, 3)): the cell holding its box centre,
    in a grid as coarse as ``size``.

    ``size`` (F,) is the face's extent, or its reach beyond the clamp where larger, so that
    neither a big face nor one stretched in UV widens the list of many small ones.

    Returns
    -------
    (F,) int64
        Bin indices ``0..B-1``, numbered in order of their (level, cell) key.
    """
    level = np.ceil(np.log2(np.maximum(size / cell, 1.0))).astype(np.int64)
    level = np.minimum(level, 40)
    origin = lo.min(axis=0)
    idx = np.floor((0.5 * (lo + hi) - origin) / (cell * 2.0**level)[:, None]).astype(np.int64)
    idx = np.clip(idx, 0, (1 << 18) - 1)  # the caller keeps cells >= extent / 2**16
    key = ((level << 18 | idx[:, 0]) << 18 | idx[:, 1]) << 18 | idx[:, 2]
    return np.unique(key, return_inverse=True)[1].reshape(-1)


def face_bins(
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    segments: Segments,
    res: int,
    max_distance: float,
    min_px: float = 0.0,
) -> FaceBins:
    """Bins of faces and the crack segments each bin's texels must measure.

    Parameters
    ----------
    vertices : (V, 3) float, faces : (F, 3) int, uv : (V, 2) float
        The triangles being baked, their world positions and UVs in [0, 1].
    segments : Segments
        Crack segments, world space.
    res : int
        Texels along the image edge.
    max_distance : float
        Distance clamp of the bake, mesh units.
    min_px : float
        Least drawn crack width of the bake, texels (widens the reach on coarse faces).

    Returns
    -------
    FaceBins
    """
    n_faces = len(faces)
    if len(segments.a) == 0 or n_faces == 0:
        return FaceBins(np.zeros(n_faces, np.uint32), np.zeros(2, np.uint32),
                        np.zeros(1, np.uint32), np.zeros(1, np.float32))  # fmt: skip
    half_width = 0.5 * float(segments.width.max())
    extent = float((vertices.max(axis=0) - vertices.min(axis=0)).max())
    cell = max(BIN_PER_REACH * max(max_distance, half_width), extent / 2**16, 1e-30)
    # A face's bin grows with its extent and with the part of its reach above the clamp (a face
    # stretched in UV has a wide texel footprint), never with the clamp itself.
    if n_faces >= KERNEL_FACES:
        # One pass: the numpy below makes a dozen (F, 3) temporaries (1.3 s at 1.5M faces);
        # the kernel does its arithmetic in its order, so the same bits.
        reach, lo, hi, size = _face_geometry(
            np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(faces, np.int64),
            np.ascontiguousarray(uv, np.float64), float(res), float(max_distance), half_width,
            0.5 * float(min_px), 1.0 + _SLACK)  # fmt: skip
    else:
        reach = face_reach(vertices, faces, uv, res, max_distance, half_width, min_px)
        excess = reach / (1 + _SLACK) - max(max_distance, half_width)
        lo, hi = _face_boxes(vertices, faces)
        size = np.maximum((hi - lo).max(axis=1), excess)
    face_bin = bin_faces(lo, hi, cell, size)

    order = np.argsort(face_bin, kind="stable")
    first = np.flatnonzero(np.r_[True, np.diff(face_bin[order]) != 0])
    bin_lo = np.minimum.reduceat(lo[order], first, axis=0)
    bin_hi = np.maximum.reduceat(hi[order], first, axis=0)
    # float32 positions in the shader are off by about 1e-7 of their magnitude.
    slack = 1e-6 * float(np.abs(vertices).max()) + _SLACK * max_distance
    bin_reach = np.maximum.reduceat(reach[order], first) + slack
    del lo, hi

    a, b = np.asarray(segments.a, np.float64), np.asarray(segments.b, np.float64)
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    grid = _segment_grid(seg_lo, seg_hi, cell)
    bin_start, candidates, bounds = _bin_candidates(bin_lo, bin_hi, bin_reach, seg_lo, seg_hi,
                                                    *grid, slack)  # fmt: skip
    return FaceBins(face_bin.astype(np.uint32), bin_start.astype(np.uint32), candidates, bounds)


def _face_boxes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box (lo, hi), each (F, 3), of every face."""
    p0, p1, p2 = (vertices[faces[:, k]] for k in range(3))
    return np.minimum(np.minimum(p0, p1), p2), np.maximum(np.maximum(p0, p1), p2)


@njit(cache=True, nogil=True, error_model="numpy")  # x / 0 is inf or nan, as in numpy
def _face_geometry(vertices, faces, uv, res, max_distance, half_width, half_px, grow):
    """:func:`face_reach` (F,), :func:`_face_boxes` (F, 3) twice and each face's bin size (F,):
    ``max(box extent, reach / grow - max(max_distance, half_width))``, in one pass.

    The arithmetic is the numpy's, operation for operation (``half_px`` is ``0.5 * min_px``,
    ``grow`` is ``1 + _SLACK``), so the results are the same bits."""
    n = faces.shape[0]
    reach = np.empty(n, np.float64)
    lo = np.empty((n, 3), np.float64)
    hi = np.empty((n, 3), np.float64)
    size = np.empty(n, np.float64)
    clamp = max(max_distance, half_width)
    dpx = np.empty(3, np.float64)
    dpy = np.empty(3, np.float64)
    for i in range(n):
        a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
        t0x, t0y = uv[a, 0] * res, uv[a, 1] * res
        q1x, q1y = uv[b, 0] * res - t0x, uv[b, 1] * res - t0y
        q2x, q2y = uv[c, 0] * res - t0x, uv[c, 1] * res - t0y
        det = q1x * q2y - q1y * q2x
        ext = 0.0
        for k in range(3):
            p0, p1, p2 = vertices[a, k], vertices[b, k], vertices[c, k]
            e1, e2 = p1 - p0, p2 - p0
            dpx[k] = (e1 * q2y - e2 * q1y) / det
            dpy[k] = (e2 * q1x - e1 * q2x) / det
            # np.minimum/np.maximum's rule (NaN wins, the second of two equals: -0.0 or 0.0)
            m0 = p0 if (p0 < p1 or np.isnan(p0)) else p1
            m1 = m0 if (m0 < p2 or np.isnan(m0)) else p2
            x0 = p0 if (p0 > p1 or np.isnan(p0)) else p1
            x1 = x0 if (x0 > p2 or np.isnan(x0)) else p2
            lo[i, k] = m1
            hi[i, k] = x1
            d = x1 - m1
            ext = d if k == 0 else (ext if (ext >= d or np.isnan(ext)) else d)
        # np.einsum("ij,ij->i") adds a row's three products as (x + z) + y
        foot = np.sqrt((dpx[0] * dpx[0] + dpx[2] * dpx[2] + dpx[1] * dpx[1])
                       + (dpy[0] * dpy[0] + dpy[2] * dpy[2] + dpy[1] * dpy[1]))
        if not np.isfinite(foot):  # no UV area: no texels, its reach never matters
            foot = 0.0
        drawn = max(half_width, half_px * foot)
        r = max(max_distance, drawn + foot) * grow
        reach[i] = r
        excess = r / grow - clamp
        size[i] = ext if (ext >= excess or np.isnan(ext)) else excess
    return reach, lo, hi, size


def _segment_grid(seg_lo: np.ndarray, seg_hi: np.ndarray, cell: float):
    """Segments binned by the cells their bounding boxes overlap (origin, cell, dims, CSR)."""
    origin = seg_lo.min(axis=0)
    extent = seg_hi.max(axis=0) - origin
    dims = np.floor(extent / cell).astype(np.int64) + 1
    while int(np.prod(dims)) > 1 << 22:
        cell *= 1.25
        dims = np.floor(extent / cell).astype(np.int64) + 1
    c0 = np.clip(np.floor((seg_lo - origin) / cell).astype(np.int64), 0, dims - 1)
    c1 = np.clip(np.floor((seg_hi - origin) / cell).astype(np.int64), 0, dims - 1)
    span = c1 - c0 + 1
    count = span.prod(axis=1)
    seg = np.repeat(np.arange(len(seg_lo), dtype=np.int64), count)
    local = np.arange(len(seg), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    sx, sy = span[seg, 0], span[seg, 1]
    flat = (
        ((c0[seg, 2] + local // (sx * sy)) * dims[1] + c0[seg, 1] + (local // sx) % sy) * dims[0]
        + c0[seg, 0]
        + local % sx
    )
    order = np.argsort(flat, kind="stable")
    n_cells = int(np.prod(dims))
    cell_start = np.zeros(n_cells + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=n_cells), out=cell_start[1:])
    return origin, float(cell), dims, cell_start, seg[order]


@njit(cache=True, nogil=True)
def _bin_candidates(
    bin_lo, bin_hi, bin_reach, seg_lo, seg_hi, origin, cell, dims, cell_start, cell_items, slack,
):  # fmt: skip
    """Each bin's segments and their distance bounds, in one pass: ``bin_start`` (B + 1,)
    int64, ``candidates`` (K,) uint32 and ``bounds`` (K,) float32 as :class:`FaceBins` holds
    them (one zero entry when no bin lists a segment: GL refuses empty buffers).  The lists
    grow by doubling: counting first and filling in a second search cost the search twice
    (0.8 s at 1.5M faces)."""
    n_bins = bin_lo.shape[0]
    bin_start = np.zeros(n_bins + 1, np.int64)
    capacity = max(8 * n_bins, 1024)
    out = np.zeros(capacity, np.uint32)
    bound = np.zeros(capacity, np.float32)
    total = 0
    for bi in range(n_bins):
        bin_start[bi] = total
        r = bin_reach[bi]
        c0 = np.empty(3, np.int64)
        c1 = np.empty(3, np.int64)
        empty = False
        for k in range(3):
            lo = np.floor((bin_lo[bi, k] - r - origin[k]) / cell)
            hi = np.floor((bin_hi[bi, k] + r - origin[k]) / cell)
            if hi < 0 or lo > dims[k] - 1:
                empty = True
            c0[k] = int(max(lo, 0.0))
            c1[k] = int(min(hi, dims[k] - 1.0))
        if empty:
            continue
        n = 0
        for z in range(c0[2], c1[2] + 1):
            for y in range(c0[1], c1[1] + 1):
                for x in range(c0[0], c1[0] + 1):
                    c = (z * dims[1] + y) * dims[0] + x
                    n += cell_start[c + 1] - cell_start[c]
        found = np.empty(n, np.int64)
        gaps = np.empty(n, np.float64)
        m = 0
        r2 = r * r
        for z in range(c0[2], c1[2] + 1):
            for y in range(c0[1], c1[1] + 1):
                for x in range(c0[0], c1[0] + 1):
                    c = (z * dims[1] + y) * dims[0] + x
                    for j in range(cell_start[c], cell_start[c + 1]):
                        s = cell_items[j]
                        gap2 = 0.0
                        for k in range(3):
                            g = max(seg_lo[s, k] - bin_hi[bi, k], bin_lo[bi, k] - seg_hi[s, k])
                            if g > 0:
                                gap2 += g * g
                        if gap2 <= r2:
                            found[m] = s
                            gaps[m] = gap2
                            m += 1
        by_index = np.argsort(found[:m])
        keep = np.empty(m, np.int64)
        u = 0
        for j in range(m):
            if j == 0 or found[by_index[j]] != found[by_index[j - 1]]:
                keep[u] = by_index[j]
                u += 1
        if total + u > capacity:
            while total + u > capacity:
                capacity *= 2
            grown = np.zeros(capacity, np.uint32)
            grown[:total] = out[:total]
            out = grown
            wider = np.zeros(capacity, np.float32)
            wider[:total] = bound[:total]
            bound = wider
        keep = keep[:u]
        # mergesort is stable: equal bounds keep ascending segment order.
        order = np.argsort(gaps[keep], kind="mergesort")
        for j in range(u):
            e = keep[order[j]]
            out[total + j] = found[e]
            bound[total + j] = max(np.sqrt(gaps[e]) - slack, 0.0)
        total += u
    bin_start[n_bins] = total
    size = max(total, 1)
    return bin_start, out[:size].copy(), bound[:size].copy()


@njit(cache=True, nogil=True, inline="always")
def _count_at_most(sorted_values, x):  # pragma: no cover - numba
    # How many of the ascending values are <= x (a bisection).
    lo, hi = 0, len(sorted_values)
    while lo < hi:
        mid = (lo + hi) // 2
        if sorted_values[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def slice_members(v, faces, listed, res, tops, bottoms):  # pragma: no cover - numba
    """For image slices of rows ``tops[s] <= row < bottoms[s]`` (sorted, disjoint): the
    ``listed`` faces whose rows ``(1 - v) res``, widened by two, reach each slice, in their
    order, slice after slice ((D,) int64), and each slice's first entry ((S + 1,) int64).  A
    face with a coordinate that is not finite reaches every slice."""
    # Plain loops only: a cached kernel calling numba's numpy functions (np.cumsum,
    # np.searchsorted) imports scipy.linalg when it loads (numba's BLAS check, 0.3 s).
    n_slices = len(tops)
    span = np.empty((len(listed), 2), np.int64)
    starts = np.zeros(n_slices + 1, np.int64)
    for k in range(len(listed)):
        f = listed[k]
        lo = np.inf
        hi = -np.inf
        finite = True
        for c in range(3):
            y = (1.0 - v[faces[f, c]]) * res
            if not np.isfinite(y):
                finite = False
            lo = min(lo, y)
            hi = max(hi, y)
        first, last = 0, n_slices - 1
        if finite:
            lo = np.floor(lo) - 2.0
            hi = np.ceil(hi) + 2.0
            first = _count_at_most(bottoms, lo)  # the first slice ending below lo
            last = _count_at_most(tops, hi) - 1  # the last slice starting by hi
        span[k, 0] = first
        span[k, 1] = last
        for s in range(first, last + 1):
            starts[s + 1] += 1
    for s in range(n_slices):
        starts[s + 1] += starts[s]
    fill = starts[:-1].copy()
    out = np.empty(starts[n_slices], np.int64)
    for k in range(len(listed)):
        for s in range(span[k, 0], span[k, 1] + 1):
            out[fill[s]] = listed[k]
            fill[s] += 1
    return out, starts


def warm() -> None:
    """Compile (or load from numba's cache) :func:`_face_geometry`, which only meshes of
    :data:`KERNEL_FACES` faces or more reach (:mod:`crackbake.precompile`'s plates are
    smaller): one triangle, with the argument types :func:`face_bins` passes."""
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    _face_geometry(v, np.array([[0, 1, 2]], np.int64), v[:, :2].copy(), 64.0, 0.1, 0.01, 0.5,
                   1.0 + _SLACK)
