"""Candidate lists per image cell (crackbake.bake.cells), the decal bake's: the lists lose nothing
(a real EGL bake through them equals one walking every segment at every texel), stay short in a
dense star's centre, and the exact segment-box distance they sort by is a true distance."""

from __future__ import annotations

import numpy as np
import pytest

from crackbake.bake import raster
from crackbake.bake.cells import _box_distance2, cell_px, image_bins
from crackbake.bake.grid import FaceBins
from crackbake.decals.projector import decal_faces, make_projector
from crackbake.network import Crack, CrackNetwork, segments


def _sampled_box_distance(a, b, lo, hi, n=20001):
    t = np.linspace(0.0, 1.0, n)[:, None]
    p = a + t * (b - a)
    gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.sqrt((gap**2).sum(1)).min()


def test_box_distance_is_the_exact_segment_box_distance():
    rng = np.random.default_rng(5)
    ts = np.empty(8)
    for _ in range(300):
        lo = rng.uniform(-1, 1, 3)
        hi = lo + rng.uniform(0, 0.5, 3) * (rng.random(3) > 0.2)  # flat boxes too
        a, b = rng.uniform(-2, 2, 3), rng.uniform(-2, 2, 3)
        if rng.random() < 0.1:
            b = a.copy()  # a point
        exact = np.sqrt(_box_distance2(a, b, lo, hi, ts))
        sampled = _sampled_box_distance(a, b, lo, hi)
        # The minimum over the segment is at most any sample's, and samples 1e-4 apart along a
        # segment under 7 long come within 7e-4 / 2 of it.
        assert exact <= sampled + 1e-12
        assert exact >= sampled - 4e-4 * max(np.linalg.norm(b - a), 1e-9)


def dome(n: int = 6):
    """A coarse spherical cap of radius 1 around +z (its faces much larger than a decal texel),
    (V, 3) and counter-clockwise (F, 3) seen from outside."""
    t = np.linspace(-0.6, 0.6, n + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    v = np.c_[x.ravel(), y.ravel(), np.sqrt(1.0 - x.ravel() ** 2 - y.ravel() ** 2)]
    idx = np.arange(len(v)).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    return v, f.astype(np.int64)


def star(n_cracks: int = 120, steps: int = 12, seed: int = 1) -> CrackNetwork:
    """A glass-like star on the dome's top: ``n_cracks`` wavy radial cracks starting near (0, 0,
    1) (at slightly different radii, so no two share a point) and running 0.1 to 0.2 out."""
    rng = np.random.default_rng(seed)
    cracks = []
    for k in range(n_cracks):
        ang = 2 * np.pi * k / n_cracks + rng.uniform(-0.01, 0.01)
        r = np.linspace(0.001 + 0.002 * rng.random(), rng.uniform(0.1, 0.2), steps)
        wob = 0.02 * np.sin(np.linspace(0, 3, steps) + k)
        xy = np.c_[r * np.cos(ang + wob), r * np.sin(ang + wob)]
        pts = np.c_[xy, np.sqrt(1 - (xy**2).sum(1))]
        w = np.linspace(0.004, 0.001, steps)
        cracks.append(Crack(id=k, points=pts, faces=np.zeros(steps, np.int64),
                            time=np.linspace(0, 1, steps), width=w, depth=0.5 * w))  # fmt: skip
    return CrackNetwork(cracks=cracks, mesh={})


def every_segment(vertices, faces, uv, segs, res, max_distance, projection, min_px=0.0):
    """Reference lists: every segment in every cell, bound 0, so the shader walks them all."""
    edge = cell_px(res)
    nx = -(-res // edge)
    n = len(segs.a)
    return FaceBins(np.zeros(len(faces), np.uint32),
                    (np.arange(nx * nx + 1) * n).astype(np.uint32),
                    np.tile(np.arange(n, dtype=np.uint32), nx * nx),
                    np.zeros(nx * nx * n, np.float32), edge, nx)  # fmt: skip


def _decal(gl_ctx, v, f, segs, proj, res, max_distance):
    sub = f[decal_faces(v, f, proj)]
    clip = proj.clip_matrix()
    placement = 0.5 + 0.5 * (np.c_[v, np.ones(len(v))] @ clip.T)[:, :2]
    n = np.broadcast_to(proj.axes[2], v.shape)
    tan = np.c_[np.broadcast_to(proj.axes[0], v.shape), np.ones(len(v))]
    return raster.bake_cracks(v, sub, placement, segs, res, max_distance=max_distance,
                              ctx=gl_ctx, normals=n, tangents=tan, projection=clip,
                              min_px=1.0)  # fmt: skip


def test_cell_lists_bake_what_walking_every_segment_bakes(gl_ctx, monkeypatch):
    v, f = dome()
    segs = segments(star())
    proj = make_projector(v, f, np.array([0.0, 0.0, 1.05]), 0.3)
    res, max_distance = 256, 0.05
    maps = _decal(gl_ctx, v, f, segs, proj, res, max_distance)
    monkeypatch.setattr(raster, "image_bins", every_segment)
    ref = _decal(gl_ctx, v, f, segs, proj, res, max_distance)
    assert (maps.mask > 0.5).sum() > 400  # the star is drawn
    for name, img in ref.channels().items():
        np.testing.assert_array_equal(maps.channels()[name], img, err_msg=name)
    np.testing.assert_array_equal(maps.inside, ref.inside)


def test_cell_lists_stay_short_in_a_dense_star():
    """Every texel of this decal lies in the star's centre, where one coarse face's bin listed all
    1320 segments; a cell lists the few near it."""
    v, f = dome()
    segs = segments(star())
    proj = make_projector(v, f, np.array([0.0, 0.0, 1.05]), 0.3)
    sub = f[decal_faces(v, f, proj)]
    clip = proj.clip_matrix()
    placement = 0.5 + 0.5 * (np.c_[v, np.ones(len(v))] @ clip.T)[:, :2]
    res = 1024
    bins = image_bins(v, sub, placement, segs, res, 0.05, clip, 1.0)
    assert bins.cell == 8 and bins.cells_x == 128
    lengths = np.diff(bins.bin_start.astype(np.int64))
    assert len(segs.a) == 120 * 11
    assert lengths.max() < len(segs.a) / 4
    assert lengths.mean() < 40
    # Each list ascends by its distance bound, and its entries are distinct segments.
    for c in np.flatnonzero(lengths > 1)[::97]:
        s, e = bins.bin_start[c], bins.bin_start[c + 1]
        assert np.all(np.diff(bins.bounds[s:e]) >= 0)
        assert len(set(bins.candidates[s:e].tolist())) == e - s


@pytest.mark.parametrize("res", [8, 8192 * 2])
def test_cells_cover_the_image(res):
    edge = cell_px(res)
    assert edge * 1024 >= res and (res / edge) ** 2 <= 1 << 20
