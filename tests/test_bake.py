"""GPU bake on a real EGL context (Mesa llvmpipe here): widths, seams, anti-aliasing, padding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import plate_mesh

from crackbake.bake.dilation import dilate, nearest_island
from crackbake.bake.grid import face_bins, face_reach
from crackbake.bake.raster import bake_cracks
from crackbake.errors import CrackbakeError
from crackbake.network import Segments


def make_segments(a, b, width, depth=None, time=(0.0, 1.0), ids=None) -> Segments:
    a = np.atleast_2d(np.asarray(a, float))
    b = np.atleast_2d(np.asarray(b, float))
    n = len(a)
    w = np.broadcast_to(np.asarray(width, float), (n, 2)).copy()
    d = w * 0.5 if depth is None else np.broadcast_to(np.asarray(depth, float), (n, 2)).copy()
    t = np.broadcast_to(np.asarray(time, float), (n, 2)).copy()
    ids = np.arange(n) if ids is None else np.asarray(ids)
    return Segments(a=a, b=b, width=w, depth=d, time=t, crack_id=ids.astype(np.int64))


def plate(uv_of_xy):
    """Unit square in z = 0 as two triangles (conftest's plate); UVs from a function of (x, y)."""
    m = plate_mesh(1)
    return m.vertices, m.faces, np.array([uv_of_xy(x, y) for x, y, _ in m.vertices], float)


def col_of(u, res):
    return int(np.floor(u * res))


def row_of(v, res):
    return int(np.floor((1.0 - v) * res))


def test_width_in_world_units_on_stretched_uvs(gl_ctx):
    res = 512
    # v is squashed 4x: one world unit spans res/4 texels along v but res texels along u.
    v, f, uv = plate(lambda x, y: (x, y / 4))
    w = 0.04
    segs = make_segments(
        [[0.1, 0.5, 0], [0.25, 0.6, 0]], [[0.9, 0.5, 0], [0.25, 0.95, 0]], width=w
    )
    m = bake_cracks(v, f, uv, segs, res, max_distance=0.05, ctx=gl_ctx)
    mask = m.mask.astype(np.float64)
    # Horizontal crack: its width runs along v -> w * res / 4 texels down a column.
    col = col_of(0.6, res)
    rows = slice(row_of(0.25, res), row_of(0.0, res))
    assert mask[rows, col].sum() == pytest.approx(w * res / 4, abs=0.05)
    # Vertical crack: its width runs along u -> w * res texels along a row.
    row = row_of(0.8 / 4, res)
    assert mask[row, :].sum() == pytest.approx(w * res, abs=0.05)
    # The width channel holds the world width, not a texel count.
    assert float(m.width[row, col_of(0.25, res)]) == pytest.approx(w, rel=2e-3)


def test_antialiased_coverage_is_exact_area_for_straight_edges(gl_ctx):
    """For a straight crack along a texel axis, the one-texel ramp equals the exact covered area."""
    res = 256
    v, f, uv = plate(lambda x, y: (x, y))
    w_tex = 3.3
    for shift in (0.0, 0.3, 0.65):
        y = 0.5 + shift / res
        segs = make_segments([[0.1, y, 0]], [[0.9, y, 0]], width=w_tex / res)
        m = bake_cracks(v, f, uv, segs, res, max_distance=0.05, ctx=gl_ctx)
        column = m.mask[:, res // 2].astype(np.float64)
        # A fractional value shows the edge is anti-aliased, not a hard step.
        assert ((column > 0.05) & (column < 0.95)).any()
        centre = (1.0 - y) * res  # in texel rows from the top
        lo, hi = centre - w_tex / 2, centre + w_tex / 2
        rows = np.arange(res)
        exact = np.clip(np.minimum(rows + 1, hi) - np.maximum(rows, lo), 0, 1)
        np.testing.assert_allclose(column, exact, atol=2e-3)


def test_thin_crack_keeps_its_area(gl_ctx):
    res = 256
    v, f, uv = plate(lambda x, y: (x, y))
    w = 0.3 / res
    segs = make_segments([[0.1, 0.5013, 0]], [[0.9, 0.5013, 0]], width=w)
    # min_px=0: the physical width only, so the sub-texel crack fades to its area average.
    m = bake_cracks(v, f, uv, segs, res, max_distance=0.05, ctx=gl_ctx, min_px=0.0)
    column = m.mask[:, res // 2].astype(np.float64)
    assert column.sum() == pytest.approx(0.3, abs=0.02)
    assert column.max() < 0.35


@pytest.mark.parametrize("offset", [0.0, 0.3])
def test_min_px_draws_a_thin_crack_one_texel_wide(gl_ctx, offset):
    """A crack 0.2 texel wide drawn at min_px = 1: the drawn half width is half a texel, so the
    one-texel anti-aliasing ramp gives coverage 1 - |d| / texel at a texel centre |d| texels from
    the axis: 1 on the axis, (1 - offset, offset) on the two rows it falls between, summing to
    one texel; the width channel keeps the physical 0.2 texel."""
    res = 256
    v, f, uv = plate(lambda x, y: (x, y))
    w = 0.2 / res
    y = 1.0 - (res // 2 + 0.5 + offset) / res  # `offset` texels below row res/2's centre
    segs = make_segments([[0.1, y, 0]], [[0.9, y, 0]], width=w)
    m = bake_cracks(v, f, uv, segs, res, max_distance=0.05, ctx=gl_ctx, min_px=1.0)
    column = m.mask[:, res // 2].astype(np.float64)
    assert column.sum() == pytest.approx(1.0, abs=0.01)
    assert column[res // 2] == pytest.approx(1.0 - offset, abs=2e-3)
    assert column[res // 2 + 1] == pytest.approx(offset, abs=2e-3)
    if offset == 0.0:
        assert np.round(255 * column.max()) == 255  # full in the 8-bit mask
    assert float(m.width[res // 2, res // 2]) == pytest.approx(w, rel=2e-3)
    assert m.min_px == 1.0
    # Depth: the area average of a V one texel wide, D / 2 on the axis (D = w / 2 here), as a
    # tent one texel in half width averaged over one more texel across (its normal is that
    # average's slope, so it has no sign flip at the axis): 3/4 of it on the axis.
    if offset == 0.0:
        assert float(m.depth[res // 2, res // 2]) == pytest.approx(0.75 * w / 4, rel=1e-3)
    # min_px below the physical width changes nothing: 3-texel cracks at min_px 0 and 2.
    wide = make_segments([[0.1, y, 0]], [[0.9, y, 0]], width=3.0 / res)
    a = bake_cracks(v, f, uv, wide, res, max_distance=0.05, ctx=gl_ctx, min_px=0.0)
    b = bake_cracks(v, f, uv, wide, res, max_distance=0.05, ctx=gl_ctx, min_px=2.0)
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_array_equal(a.depth, b.depth)


def test_min_px_must_not_be_negative(gl_ctx):
    v, f, uv = plate(lambda x, y: (x, y))
    segs = make_segments([[0.1, 0.5, 0]], [[0.9, 0.5, 0]], width=0.01)
    with pytest.raises(CrackbakeError, match="--min-px"):
        bake_cracks(v, f, uv, segs, 64, ctx=gl_ctx, min_px=-1.0)


def test_channels_values(gl_ctx):
    res = 256
    v, f, uv = plate(lambda x, y: (x, y))
    w, dmax = 0.04, 0.01
    segs = make_segments([[0.1, 0.5, 0]], [[0.9, 0.5, 0]], width=w, depth=dmax, ids=[7])
    m = bake_cracks(v, f, uv, segs, res, max_distance=0.1, ctx=gl_ctx)
    r, c = row_of(0.5, res), col_of(0.5, res)  # texel centre half a texel from the crack
    assert float(m.crack_id[r, c]) == 7
    assert float(m.time[r, c]) == pytest.approx((0.5 + 0.5 / res - 0.1) / 0.8, abs=2e-3)
    assert float(m.depth[r, c]) == pytest.approx(dmax * (1 - (0.5 / res) / (w / 2)), rel=1e-4)
    assert float(m.distance[r, c]) == pytest.approx(0.5 / res, rel=1e-3)
    # Far from the crack: no id, distance clamped.
    far_r = row_of(0.9, res)
    assert float(m.crack_id[far_r, c]) == -1
    assert float(m.distance[far_r, c]) == pytest.approx(0.1)
    assert float(m.mask[far_r, c]) == 0
    # Past the crack's end the distance is to the end point.
    r2, c2 = row_of(0.5, res), col_of(0.95, res)
    x2, y2 = (c2 + 0.5) / res, 1 - (r2 + 0.5) / res
    assert float(m.distance[r2, c2]) == pytest.approx(np.hypot(x2 - 0.9, y2 - 0.5), rel=1e-4)


def test_continuous_across_uv_seam(gl_ctx):
    """A crack crossing a UV seam continues on both islands with the same width and depth."""
    res = 512
    s = 0.4  # UV units per world unit on both islands
    vertices = np.array(
        [[0, 0, 0], [0.5, 0, 0], [0.5, 1, 0], [0, 1, 0],  # left half
         [0.5, 0, 0], [1, 0, 0], [1, 1, 0], [0.5, 1, 0]],  # right half, seam copies
        float,
    )
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    uv = np.empty((8, 2))
    uv[:4] = 0.05 + s * vertices[:4, :2]  # left island as is
    # Right island rotated 90 degrees: x runs along v, y along u.
    uv[4:, 0] = 0.55 + s * vertices[4:, 1]
    uv[4:, 1] = 0.55 + s * (vertices[4:, 0] - 0.5)
    w, dmax = 0.03, 0.01
    segs = make_segments([[0.2, 0.5, 0]], [[0.8, 0.5, 0]], width=w, depth=dmax)
    m = bake_cracks(vertices, faces, uv, segs, res, max_distance=0.05, dilate_px=0, ctx=gl_ctx)
    mask = m.mask.astype(np.float64)
    expected = w * s * res
    # Left island: the crack runs along u; the seam is at u = 0.25. Sum down the column next to it.
    left_col = col_of(0.25, res) - 1
    left = mask[row_of(0.45, res) : row_of(0.05, res), left_col]
    # Right island: the crack runs along v; the seam is at v = 0.55. Sum along the row next to it.
    right_row = row_of(0.55, res) - 1
    right = mask[right_row, col_of(0.55, res) : col_of(0.95, res)]
    assert left.sum() == pytest.approx(expected, abs=0.05)
    assert right.sum() == pytest.approx(expected, abs=0.05)
    dl = m.depth[row_of(0.45, res) : row_of(0.05, res), left_col].max()
    dr = m.depth[right_row, col_of(0.55, res) : col_of(0.95, res)].max()
    assert dl == pytest.approx(dr, rel=0.02)
    assert dl > 0.8 * dmax


def test_unbounded_and_limited_dilation(gl_ctx):
    res = 256
    v, f, uv = plate(lambda x, y: (0.25 + 0.5 * x, 0.25 + 0.5 * y))
    segs = make_segments([[0.0, 0.5, 0]], [[1.0, 0.5, 0]], width=0.05, ids=[3])
    full = bake_cracks(v, f, uv, segs, res, max_distance=0.1, ctx=gl_ctx)
    assert full.inside.mean() == pytest.approx(0.25, abs=0.01)
    r = row_of(0.5, res) - 1
    # Unbounded: the crack's row continues to the image border, and the far corner is filled.
    assert float(full.mask[r, 0]) == pytest.approx(float(full.mask[r, res // 2]), abs=1e-3)
    assert float(full.crack_id[r, 0]) == 3
    assert float(full.crack_id[0, 0]) == -1  # the island's corner is far from the crack
    assert float(full.distance[0, 0]) == pytest.approx(float(full.distance[res // 4, res // 4]))
    # Limited to 4 texels: 3 texels out is filled, 10 texels out is background.
    lim = bake_cracks(v, f, uv, segs, res, max_distance=0.1, dilate_px=4, ctx=gl_ctx)
    edge = col_of(0.25, res)
    assert float(lim.mask[r, edge - 3]) > 0.5
    assert float(lim.mask[r, edge - 10]) == 0
    assert float(lim.crack_id[r, edge - 10]) == -1
    assert float(lim.distance[r, edge - 10]) == pytest.approx(0.1)


def test_tiled_bake_matches_single_pass(gl_ctx):
    res = 512
    v, f, uv = plate(lambda x, y: (x, y))
    rng = np.random.default_rng(1)
    a = rng.random((40, 3)) * [1, 1, 0]
    b = a + (rng.random((40, 3)) - 0.5) * [0.3, 0.3, 0]
    segs = make_segments(a, b, width=rng.random((40, 2)) * 0.01)
    one = bake_cracks(v, f, uv, segs, res, max_distance=0.05, tile=512, ctx=gl_ctx)
    tiled = bake_cracks(v, f, uv, segs, res, max_distance=0.05, tile=256, ctx=gl_ctx)  # 4 bands
    for name, arr in one.channels().items():
        np.testing.assert_allclose(
            tiled.channels()[name].astype(np.float64), arr.astype(np.float64),
            atol=2e-3, err_msg=name,
        )


def _point_segment_distance(p, a, b):
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0, 1)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def test_face_geometry_kernel_gives_the_numpy_bits():
    # face_bins' one-pass kernel against face_reach and _face_boxes, the numpy it replaced: the
    # same float64 bits (reach, boxes, bin sizes), with faces of no UV area (footprint 0), a
    # mesh crossing 0 (-0.0 against 0.0 in the boxes) and UVs stretched along one axis.
    from crackbake.bake.grid import _SLACK, _face_boxes, _face_geometry

    rng = np.random.default_rng(3)
    m = plate_mesh(12)
    v = (m.vertices - 0.5) * [3.0, 1.0, 0.0] + rng.normal(0, 1e-3, m.vertices.shape)
    v[::7, 2] = 0.0
    v[::5, 2] = -0.0
    f = np.asarray(m.faces, np.int64)
    uv = m.vertices[:, :2] * [1.0, 0.3] + rng.normal(0, 1e-3, (len(v), 2))
    uv[f[:4].ravel()] = 0.5  # four faces of no UV area
    for res, clamp, half, min_px in ((256, 0.05, 0.002, 0.0), (4096, 0.0, 0.0, 3.0),
                                     (64, 0.001, 0.2, 1.5)):
        reach = face_reach(v, f, uv, res, clamp, half, min_px)
        lo, hi = _face_boxes(v, f)
        size = np.maximum((hi - lo).max(axis=1), reach / (1 + _SLACK) - max(clamp, half))
        got = _face_geometry(v, f, uv, float(res), clamp, half, 0.5 * min_px, 1.0 + _SLACK)
        for want, have in zip((reach, lo, hi, size), got, strict=True):
            assert want.view(np.int64).tolist() == have.view(np.int64).tolist()
        assert (got[0][:4] == max(clamp, half) * (1 + _SLACK)).all()  # footprint 0


def test_face_bins_list_every_segment_within_reach_with_valid_bounds():
    # A 20 x 20 plate of 800 faces, some stretched in UV, and 300 short segments on it.
    rng = np.random.default_rng(0)
    m = plate_mesh(20)
    v, f = m.vertices, m.faces
    uv = v[:, :2] * [1.0, 0.25]  # v squashed 4x: footprints differ along x and y
    a = rng.random((300, 3)) * [1, 1, 0]
    b = a + (rng.random((300, 3)) - 0.5) * 0.05 * [1, 1, 0]
    segs = make_segments(a, b, width=rng.random((300, 2)) * 0.004)
    bins = face_bins(v, f, uv, segs, 256, max_distance=0.05)
    reach = face_reach(v, f, uv, 256, 0.05, 0.5 * float(segs.width.max()))
    assert len(bins.face_bin) == len(f) and bins.bin_start[-1] == len(bins.candidates)
    n_bins = len(bins.bin_start) - 1
    assert 1 < n_bins < len(f)  # faces share lists
    # Sample points on every face: each segment within the face's reach of one is listed in the
    # face's bin, with a bound no larger than its distance; lists run in ascending bound.
    w = rng.dirichlet([1, 1, 1], size=(len(f), 8))
    pts = np.einsum("fkc,fcd->fkd", w, v[f])
    d = _point_segment_distance(pts[:, :, None, :], a[None, None], b[None, None])
    for face in range(len(f)):
        k0, k1 = bins.bin_start[bins.face_bin[face]], bins.bin_start[bins.face_bin[face] + 1]
        listed = bins.candidates[k0:k1].astype(int)
        bound = bins.bounds[k0:k1]
        assert np.all(np.diff(bound) >= 0)
        near = np.flatnonzero((d[face] < reach[face]).any(axis=0))
        assert set(near.tolist()) <= set(listed.tolist())
        closest = d[face][:, listed].min(axis=0)
        assert np.all(bound <= closest + 1e-7)


def test_bake_matches_a_cpu_reference_of_the_nearest_crack(gl_ctx):
    # Many segments on a finely tessellated plate: the shader's early stop in the bins' lists
    # must still find the nearest segment of every texel (distance and id channels).
    rng = np.random.default_rng(4)
    m = plate_mesh(16)
    v, f, uv = m.vertices, m.faces, m.vertices[:, :2].copy()
    a = rng.random((120, 3)) * [1, 1, 0]
    b = a + (rng.random((120, 3)) - 0.5) * 0.1 * [1, 1, 0]
    segs = make_segments(a, b, width=0.002)
    res = 128
    maps = bake_cracks(v, f, uv, segs, res, max_distance=0.08, ctx=gl_ctx)
    ys, xs = np.mgrid[0:res, 0:res]
    p = np.stack([(xs + 0.5) / res, 1 - (ys + 0.5) / res, np.zeros_like(xs, float)], -1)
    sample = (slice(3, None, 7), slice(5, None, 7))
    d = _point_segment_distance(p[sample][:, :, None, :], a, b)
    nearest = d.min(axis=-1)
    expect = np.minimum(nearest, 0.08)
    np.testing.assert_allclose(maps.distance[sample], expect, atol=2e-6)
    hit = nearest < 0.08 - 1e-5
    assert hit.sum() > 100
    assert np.array_equal(maps.crack_id[sample][hit], d.argmin(axis=-1)[hit])


def test_nearest_island_matches_brute_force_and_scipy():
    from scipy import ndimage

    rng = np.random.default_rng(3)
    inside = rng.random((61, 50)) < 0.03
    inside[40:45, 10:30] = True
    src, dist2 = nearest_island(inside)
    iy, ix = np.nonzero(inside)
    for e in range(0, inside.size, 7):
        ey, ex = divmod(e, 50)
        brute = ((iy - ey) ** 2 + (ix - ex) ** 2).min()
        assert dist2[e] == brute
        sy, sx = divmod(int(src[e]), 50)
        assert inside[sy, sx] and (sy - ey) ** 2 + (sx - ex) ** 2 == brute
    edt = ndimage.distance_transform_edt(~inside)
    assert np.allclose(np.sqrt(dist2.reshape(inside.shape)), edt)
    img = rng.random((61, 50)).astype(np.float32)
    half = img.astype(np.float16)
    before = img.copy()
    dilate([img, half], inside)
    assert np.array_equal(img[inside], before[inside])
    assert np.array_equal(img.reshape(-1), before.reshape(-1)[src])
    assert np.array_equal(half.reshape(-1), before.astype(np.float16).reshape(-1)[src])
    limited = before.copy()
    dilate([limited], inside, limit=2, background=[-7.0])
    far = dist2.reshape(inside.shape) > 4
    assert (limited[far] == -7.0).all()
    assert np.array_equal(limited[~far], before.reshape(-1)[src].reshape(inside.shape)[~far])


def test_nearest_island_across_column_chunks():
    # Wider than several of the column pass's chunks, not a multiple of one: exact EDT anyway.
    from scipy import ndimage

    from crackbake.bake.dilation import _COLUMN_CHUNK

    rng = np.random.default_rng(5)
    w = 2 * _COLUMN_CHUNK + 37
    inside = rng.random((40, w)) < 0.01
    inside[:, _COLUMN_CHUNK - 1] = False  # a column with no island texel, at a chunk's edge
    src, dist2 = nearest_island(inside)
    edt = ndimage.distance_transform_edt(~inside)
    assert np.array_equal(dist2.reshape(inside.shape), np.rint(edt**2).astype(np.int32))
    assert inside.reshape(-1)[src].all()


def test_fill_plan_ahead_equals_the_plan_in_place():
    """PlanAhead's serial, GIL-free kernels on a thread: the same plan as fill_plan's parallel
    ones; handed to dilate, the same pixels; for other islands or limit, no plan."""
    from crackbake.bake.dilation import PlanAhead, fill_plan

    rng = np.random.default_rng(11)
    inside = rng.random((97, 300)) < 0.02
    inside[30:50, 100:180] = True
    for limit in (None, 3):
        here = fill_plan(inside, limit)
        ahead = PlanAhead(inside, limit)
        plan = ahead.plan_for(inside.copy(), limit)
        for name in ("targets", "sources", "far"):
            assert np.array_equal(getattr(plan, name), getattr(here, name)), name
        assert ahead.plan_for(inside, 7) is None
        other = inside.copy()
        other[0, 0] = ~other[0, 0]
        assert ahead.plan_for(other, limit) is None
        ahead.close()
        img = rng.random(inside.shape).astype(np.float32)
        a, b = img.copy(), img.copy()
        dilate([a], inside, limit=limit, background=[-1.0])
        dilate([b], inside, limit=limit, background=[-1.0], plan=plan)
        assert np.array_equal(a, b) and (limit is None or (a == -1.0).any())


@pytest.mark.parametrize("tile", [200, 64])  # one band, and four with a short last one
def test_coverage_is_the_bakes_inside(gl_ctx, tile):
    """The faces' coverage drawn without the cracks is exactly the bake's ``inside``, and a bake
    given the gutter planned from it fills the same pixels."""
    from crackbake.bake.dilation import PlanAhead
    from crackbake.bake.raster import coverage

    res = 200
    m = plate_mesh(7, wobble=0.03, seed=2)
    v, f = np.asarray(m.vertices, float), np.asarray(m.faces)
    # Islands with gutters, a sliver and a face straying past the page's edge.
    uv = v[:, :2] * 0.8 + 0.1
    uv[0] = [-0.02, 0.05]
    rng = np.random.default_rng(4)
    a = rng.random((25, 3)) * [1, 1, 0]
    segs = make_segments(a, a + (rng.random((25, 3)) - 0.5) * [0.3, 0.3, 0], width=0.01)
    own = bake_cracks(v, f, uv, segs, res, max_distance=0.05, tile=tile, ctx=gl_ctx)
    inside = coverage(gl_ctx, uv, f, res, tile, with_normals=False)
    assert inside.dtype == bool and 0 < inside.sum() < inside.size
    assert np.array_equal(inside, own.inside)
    gutter = PlanAhead(inside, None)
    planned = bake_cracks(v, f, uv, segs, res, max_distance=0.05, tile=tile, ctx=gl_ctx,
                          gutter=gutter)  # fmt: skip
    for name, image in own.channels().items():
        assert planned.channels()[name].tobytes() == image.tobytes(), name


def test_dilation_with_no_island_fills_background():
    img = np.ones((8, 8), np.float32)
    dilate([img], np.zeros((8, 8), bool), background=[3.0])
    assert (img == 3.0).all()


def test_bad_arguments(gl_ctx):
    v, f, uv = plate(lambda x, y: (x, y))
    segs = make_segments([[0.1, 0.5, 0]], [[0.9, 0.5, 0]], width=0.01)
    with pytest.raises(ValueError, match="res must be a positive"):
        bake_cracks(v, f, uv, segs, 0, ctx=gl_ctx)
    with pytest.raises(CrackbakeError, match="profile"):
        bake_cracks(v, f, uv, segs, 64, profile_shape=0, ctx=gl_ctx)


def test_no_cracks_bakes_clean_maps(gl_ctx):
    v, f, uv = plate(lambda x, y: (x, y))
    segs = make_segments(np.zeros((0, 3)), np.zeros((0, 3)), width=0.0)
    m = bake_cracks(v, f, uv, segs, 64, max_distance=0.2, ctx=gl_ctx)
    assert float(m.mask.max()) == 0
    assert (m.crack_id == -1).all()
    assert np.allclose(m.distance, 0.2)


def _subdivided_spot(path, levels: int):
    """examples/spot.obj split ``levels`` times into four (edge midpoints, UVs interpolated)."""
    import trimesh

    from crackbake.io.mesh import load_mesh

    mesh = load_mesh(Path(__file__).resolve().parents[1] / "examples" / "spot.obj")
    v, f, t = mesh.vertices, mesh.faces, mesh.uv
    for _ in range(levels):
        v, f, attr = trimesh.remesh.subdivide(v, f, vertex_attributes={"uv": t})
        t = attr["uv"]
    with open(path, "w") as fh:
        np.savetxt(fh, v, fmt="v %.7f %.7f %.7f")
        np.savetxt(fh, t, fmt="vt %.7f %.7f")
        np.savetxt(fh, np.repeat(f + 1, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
    return len(f)


# Runs the crackbake command in this child process and reports the RSS when the bake starts and
# the peak while it runs (a sampling thread, switched by the pipeline's stage log lines).
_STAGE_RSS = """
import json, logging, os, sys, threading, time
from crackbake.cli import main

def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

state = {"stage": "", "start": 0, "peak": 0}
def sample():
    while True:
        if state["stage"] == "bake":
            state["peak"] = max(state["peak"], rss())
        time.sleep(0.01)

class Stage(logging.Handler):
    def emit(self, record):
        msg = record.getMessage()
        if msg.startswith("baking "):
            state["start"] = state["peak"] = rss()
            state["stage"] = "bake"
        elif msg.startswith("writing "):
            state["peak"] = max(state["peak"], rss())
            state["stage"] = "write"

logging.getLogger("crackbake.pipeline").addHandler(Stage())
threading.Thread(target=sample, daemon=True).start()
try:
    main(sys.argv[1:], standalone_mode=False)
finally:
    print(json.dumps(state))
"""


@pytest.mark.slow
def test_bake_memory_grows_with_faces_and_texels_not_their_product(tmp_path):
    # 375k faces under the crackle preset (about 15k crack segments).  Per-face candidate lists
    # (the earlier bake) grew by 2.5 GB here; the bins' lists keep the bake near its images.
    import json
    import os
    import subprocess
    import sys

    import OpenImageIO as oiio

    n_faces = _subdivided_spot(tmp_path / "spot375k.obj", 3)
    res = 1024
    out = tmp_path / "out"
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run(
        [sys.executable, "-c", _STAGE_RSS, str(tmp_path / "spot375k.obj"), "--preset", "crackle",
         "--res", str(res), "--formats", "exr,png", "-o", str(out), "--quiet"],
        capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    state = json.loads(r.stdout.strip().splitlines()[-1])
    growth = state["peak"] - state["start"]
    # Images: 19 bytes a texel in numpy, 67 in GL, about 30 in the gutter fill; faces: the
    # vertex/index buffers and per-face arrays.  Generous, still 4x under the old growth.
    bound = 256 * 2**20 + 200 * res * res + 600 * n_faces
    print(f"bake grew {growth / 2**30:.3f} GiB (bound {bound / 2**30:.2f})")
    assert state["start"] > 0  # the bake stage was seen
    assert growth < bound, f"bake grew {growth / 2**30:.2f} GiB (bound {bound / 2**30:.2f})"

    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["mesh"]["faces"] == n_faces and manifest["cracks"]["cracks"] > 50
    exr = next(out.glob("*.exr"))
    img = oiio.ImageBuf(str(exr))
    assert img.spec().width == res and img.spec().height == res
    names = list(img.spec().channelnames)
    pixels = img.get_pixels(oiio.FLOAT)
    mask = pixels[..., [i for i, n in enumerate(names) if "mask" in n.lower()][0]]
    assert np.isfinite(pixels).all()
    # Crackle cracks are thinner than a texel at 1024: coverage, not a solid line.
    assert 0.005 < float((mask > 0).mean()) < 0.5  # a crack network, neither empty nor flooded
    assert float(mask.max()) <= 1.0


@pytest.mark.parametrize("crack_last", [False, True])
def test_stacked_islands_take_the_face_drawn_last(gl_ctx, crack_last):
    # Two unit plates on the same UVs (a stacked island): one crossed by a crack, one far from
    # every crack (its faces' lists are empty).  Each texel takes the face drawn last there, as
    # if that plate were baked alone, whichever of the two lists segments.
    v, f, uv = plate(lambda x, y: (x, y))
    far = v + [0.0, 0.0, 10.0]
    segs = make_segments([[0.1, 0.3, 0.0]], [[0.9, 0.6, 0.0]], width=0.05)
    kw = {"max_distance": 0.2, "ctx": gl_ctx}
    first, last = (far, v) if crack_last else (v, far)
    stacked = bake_cracks(np.vstack([first, last]), np.vstack([f, f + len(first)]),
                          np.vstack([uv, uv]), segs, 64, **kw)  # fmt: skip
    alone = bake_cracks(last, f, uv, segs, 64, **kw)
    for name, arr in alone.channels().items():
        assert np.array_equal(arr, stacked.channels()[name]), name
    assert (float(alone.mask.max()) > 0.9) == crack_last


def test_each_crack_pass_slice_draws_the_faces_reaching_its_rows_in_order(monkeypatch):
    # Each slice of the crack pass draws only the listed faces whose rows reach it, in their
    # order; compared with the rows measured here, over bands that do not divide the image.
    import crackbake.bake.raster as raster

    monkeypatch.setattr(raster, "SLICE_TEXELS", 64 * 37)  # 37 rows a slice at 64 texels
    rng = np.random.default_rng(5)
    uv = rng.uniform(-0.05, 1.05, (400, 2))
    uv[7, 1] = np.nan  # goes everywhere
    faces = rng.integers(0, 400, (300, 3))
    faces[:40, 1:] = faces[:40, :1]  # thin ones: a single row
    listed = np.sort(rng.choice(300, 220, replace=False))
    for band in (64, 50, 17):
        drawn, slices = raster._slice_runs(uv, faces, listed, 64, band)
        rows = (1.0 - uv[:, 1][faces[listed]]) * 64
        reached = 0
        for (y0, r0), (first, count) in slices.items():
            top, bottom = y0 + r0, min(y0 + r0 + 37, y0 + band, 64)
            lo, hi = np.nanmin(rows, axis=1), np.nanmax(rows, axis=1)
            near = (np.ceil(hi) + 2 >= top) & (np.floor(lo) - 2 < bottom)
            want = listed[near | np.isnan(rows).any(axis=1)]
            assert np.array_equal(drawn[first:first + count], want), (band, y0, r0)
            reached += count
        assert reached == len(drawn)
        assert len(slices) == sum(-(-min(band, 64 - y0) // 37) for y0 in range(0, 64, band))
