"""Kept UVs (crackbake.bake.uv check, overlap, prepare): usable or not, the GL overlap measure,
the keep/auto/unwrap choice (real EGL, real xatlas, no mocks)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import make_mesh, torus_mesh, uv_grid

from crackbake.bake import uv as U
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    # Never touch the user's ~/.cache from tests.
    monkeypatch.setenv("CRACKBAKE_CACHE_DIR", str(tmp_path / "cache"))


# ------------------------------------------------------------------------------ overlap


def test_overlap_stacked_triangles_is_one(gl_ctx):
    uv = np.array([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]])
    # The second copy has the opposite winding (a mirrored island): it must count as well.
    faces = np.array([[0, 1, 2], [0, 2, 1]])
    assert U.uv_overlap_fraction(uv, faces, res=256, ctx=gl_ctx) == pytest.approx(1.0)


def test_overlap_two_triangle_square_is_zero(gl_ctx):
    uv = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    assert U.uv_overlap_fraction(uv, faces, res=256, ctx=gl_ctx) == 0.0


def test_overlap_shared_edges_never_double_count(gl_ctx):
    # 8000 irregular triangles sharing edges in every direction: any double counting on shared
    # edges would show up as overlap.
    pts, faces = uv_grid(40, 100, 0.8, 0.9, jitter=0.3)
    assert U.uv_overlap_fraction(pts + 0.05, faces, res=1024, ctx=gl_ctx) == 0.0


def test_overlap_half_overlapping_squares(gl_ctx):
    # A = [0.25, 0.75]^2 and B = A shifted right by 0.25 (both texel-aligned at 1024):
    # |A and B| = 0.25 * 0.5 = 0.125, |A or B| = 0.25 + 0.25 - 0.125 = 0.375, so 1/3.
    sq = np.array([[0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75]])
    uv = np.concatenate([sq, sq + [0.25, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    frac = U.uv_overlap_fraction(uv, faces, res=1024, ctx=gl_ctx)
    assert frac == pytest.approx(1.0 / 3.0, abs=1e-9)


def test_overlap_empty_is_zero():
    assert U.uv_overlap_fraction(np.zeros((0, 2)), np.zeros((0, 3), dtype=np.int64)) == 0.0


# ------------------------------------------------------------------------------ check_uvs


def _square_mesh(uv):
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    return make_mesh(v, [[0, 1, 2], [0, 2, 3]], uv)


def test_check_uvs_cases(gl_ctx):
    none = U.check_uvs(_square_mesh(None))
    assert not none.usable and "no UVs" in none.reason and none.overlap_fraction is None

    good = U.check_uvs(_square_mesh([[0, 0], [1, 0], [1, 1], [0, 1]]), ctx=gl_ctx)
    assert good.usable and good.reason == "" and not good.udim
    assert good.overlap_fraction == 0.0

    outside = U.check_uvs(_square_mesh([[-0.5, 0], [1.5, 0], [1.5, 1], [-0.5, 1]]))
    assert not outside.usable and not outside.udim and "outside [0, 1]" in outside.reason

    flat = U.check_uvs(_square_mesh([[0.2, 0.2]] * 4))
    assert not flat.usable and "zero UV area" in flat.reason

    nan = U.check_uvs(_square_mesh([[0, 0], [np.nan, 0], [1, 1], [0, 1]]))
    assert not nan.usable and "NaN" in nan.reason

    # Exporter round-off just outside the page is tolerated.
    eps = U.check_uvs(_square_mesh([[-1e-7, 0], [1 + 1e-7, 0], [1, 1], [0, 1]]))
    assert eps.usable


def _udim_mesh() -> Mesh:
    # Two quads: one in tile 1001 (u 0..1), one in tile 1002 (u 1..2).
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    vertices = np.concatenate([v, v + [2, 0, 0]])
    uv = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])
    uvs = np.concatenate([uv, uv + [1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return make_mesh(vertices, faces, uvs, source="udim.obj")


def test_udim_detected_and_kept_in_keep_mode():
    check = U.check_uvs(_udim_mesh())
    assert check.udim and check.usable and check.reason == ""
    np.testing.assert_array_equal(check.tiles, [[0, 0], [1, 0]])
    out = U.prepare_uvs(_udim_mesh(), mode="keep")  # tests/test_udim.py bakes such layouts
    np.testing.assert_array_equal(out.udim, [[0, 0], [1, 0]])


# ------------------------------------------------------------------------------ prepare_uvs


def test_keep_mode_keeps_uvs():
    pts, faces = uv_grid(4, 4, 1.0, 1.0)
    mesh = make_mesh(np.c_[pts, np.zeros(len(pts))], faces, uv=pts)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        out = U.prepare_uvs(mesh, mode="keep")
    assert out.method == "kept" and out.padding_px == 0 and out.overlap_fraction == 0.0
    np.testing.assert_array_equal(out.vertex_map, np.arange(len(pts)))
    np.testing.assert_array_equal(out.faces, mesh.faces)
    np.testing.assert_array_equal(out.uv, pts)
    # auto keeps usable UVs too, without unwrapping
    assert U.prepare_uvs(mesh, mode="auto").method == "kept"


def test_keep_mode_warns_on_overlapping_uvs(gl_ctx):
    # Two quads mirrored onto the same UV island (a common game-asset trick).
    mesh = _udim_mesh()
    uv = mesh.uv.copy()
    uv[4:] = uv[:4][:, ::-1]
    mirrored = make_mesh(mesh.vertices, mesh.faces, uv)
    with pytest.warns(CrackbakeWarning, match="cracks will show twice"):
        out = U.prepare_uvs(mirrored, mode="keep", ctx=gl_ctx)
    assert out.overlap_fraction > 0.9


def test_keep_mode_warns_when_the_uvs_cover_a_sliver_of_the_page():
    """Kept UVs squeezed into a corner of the page (an atlas share, another tool's packing)
    leave the cracks few texels: one line says so, with the texels across and the fixes; a
    share of an atlas (9 % of the page) stays quiet."""
    pts, faces = uv_grid(4, 4, 1.0, 1.0)
    xyz = np.c_[pts, np.zeros(len(pts))]
    small = make_mesh(xyz, faces, uv=0.4 + 0.1 * pts)  # 1 % of the page
    with pytest.warns(CrackbakeWarning, match=r"cover only 1\.0% of the 2048px texture \(about "
                      r"205 px across\).*raise --res, or use --uv unwrap"):
        U.prepare_uvs(small, mode="keep", res=2048)
    fine = make_mesh(xyz, faces, uv=0.4 + 0.3 * pts)  # 9 %: an atlas share, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        U.prepare_uvs(fine, mode="keep", res=2048)


def test_keep_mode_refuses_out_of_range_uvs():
    mesh = torus_mesh(24, 12)
    tiled = make_mesh(mesh.vertices, mesh.faces, uv=mesh.vertices[:, :2] * 2.0)
    with pytest.raises(CrackbakeError, match=r"outside \[0, 1\].*--uv unwrap"):
        U.prepare_uvs(tiled, mode="keep")


def test_keep_mode_without_uvs_is_an_error():
    with pytest.raises(CrackbakeError, match="no UVs.*--uv unwrap"):
        U.prepare_uvs(torus_mesh(24, 12), mode="keep")


def test_auto_mode_unwraps_out_of_range_uvs_with_a_warning():
    mesh = torus_mesh(24, 12)
    tiled = make_mesh(mesh.vertices, mesh.faces, uv=mesh.vertices[:, :2] * 2.0)
    with pytest.warns(CrackbakeWarning, match=r"outside \[0, 1\].*unwrapping"):
        out = U.prepare_uvs(tiled, mode="auto", res=256, cache=False)
    assert out.method == "unwrapped"
    assert out.uv.min() >= 0.0 and out.uv.max() <= 1.0


def test_auto_mode_without_uvs_unwraps_quietly():
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        out = U.prepare_uvs(torus_mesh(24, 12), mode="auto", res=256, cache=False)
    assert out.method == "unwrapped"


def test_unknown_mode_is_an_error():
    with pytest.raises(CrackbakeError, match="unknown UV mode 'smart'"):
        U.prepare_uvs(_square_mesh(None), mode="smart")


def test_a_few_faces_straying_outside_are_kept_with_a_warning():
    """Like spot.obj (10 of 5,856 faces reach u = -0.05): keep the artist's layout, warn."""
    pts, f = uv_grid(12, 12, 1.0, 1.0)
    v = np.c_[pts, np.zeros(len(pts))]
    uv = 0.05 + 0.9 * pts
    uv[0] = (-0.03, 0.02)  # one corner vertex strays: 2 of 288 faces reach outside
    mesh = make_mesh(v, f, uv)
    check = U.check_uvs(mesh)
    assert check.usable and 0 < check.outside_fraction < 0.01
    with pytest.warns(CrackbakeWarning, match="2 faces reach slightly outside"):
        kept = U.prepare_uvs(mesh, "auto", 256)
    assert kept.method == "kept" and np.array_equal(kept.uv, uv)  # not clipped
    # Many faces out, or far out: not usable.
    far = uv.copy()
    far[0] = (-0.6, 0.02)
    assert not U.check_uvs(make_mesh(v, f, far)).usable


# ------------------------------------------------------------------------------ stray UVs


def _overhanging_plane(n: int = 20, island: bool = False):
    """A unit plane (z = 0) of n x n quads whose UVs run u 0.2..1.1, v 0.1..0.9: its faces
    beyond x = 8/9 reach past u = 1 (at n = 20, three columns, one straddling u = 1), where
    REPEAT shows them at u 0..0.1 (empty).  With ``island``, a separate quad
    (at z = 1, never cracked) holds UVs [0, 0.1] x [0.1, 0.18]: the place of two rows' wraps."""
    pts, f = uv_grid(n, n, 1.0, 1.0)
    v = np.c_[pts, np.zeros(len(pts))]
    uv = np.c_[0.2 + 0.9 * pts[:, 0], 0.1 + 0.8 * pts[:, 1]]
    if island:
        k = len(v)
        v = np.r_[v, [[0, 0, 1], [0.1, 0, 1], [0.1, 0.08, 1], [0, 0.08, 1]]]
        uv = np.r_[uv, [[0, 0.1], [0.1, 0.1], [0.1, 0.18], [0, 0.18]]]
        f = np.r_[f, [[k, k + 1, k + 2], [k, k + 2, k + 3]]]
    return make_mesh(v, f, uv)


def _crack_at(x: float, width: float = 0.02):
    """One straight crack across the plane at world x, y 0..1 (a Segments of one segment)."""
    from crackbake.network import Segments

    return Segments(
        a=np.array([[x, 0.0, 0.0]]), b=np.array([[x, 1.0, 0.0]]),
        width=np.full((1, 2), width), depth=np.full((1, 2), width / 2),
        time=np.zeros((1, 2)), crack_id=np.zeros(1, np.int64),
    )  # fmt: skip


def _mask(uvmesh, segs, res, ctx):
    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.uv.uvmesh import bake_arrays

    a = bake_arrays(uvmesh)
    return bake_cracks(a["vertices"], a["faces"], a["uv"], segs, res, ctx=ctx,
                       min_px=0.0).mask.astype(np.float64)  # fmt: skip


def _texel(u: float, v: float, res: int) -> tuple[int, int]:
    """(row, column) of the texel holding UV (u, v): row 0 is v = 1."""
    return int((1.0 - v) * res), int(u * res)


def test_straying_faces_are_baked_where_repeat_shows_them(gl_ctx):
    import dataclasses

    mesh = _overhanging_plane()
    check = U.check_uvs(mesh, ctx=gl_ctx)
    # 3 of 20 face columns stray (15 %, above the old 1 % limit): kept because all wrap.
    assert check.usable and check.outside_fraction == pytest.approx(3 / 20)
    stray = np.flatnonzero((mesh.uv[mesh.faces][..., 0] > 1 + 1e-9).any(axis=1))
    assert np.array_equal(np.unique(check.wraps[:, 0]), stray)
    assert (check.wraps[:, 1:] == [1, 0]).all() and check.lost_faces == 0
    res = 256
    with pytest.warns(CrackbakeWarning, match=r"120 faces reach slightly outside.*120 are also "
                      r"baked wrapped into the tile$"):  # fmt: skip
        kept = U.prepare_uvs(mesh, "auto", res, ctx=gl_ctx)
    assert kept.method == "kept" and np.array_equal(kept.uv, mesh.uv)  # the GLB keeps them
    # World x = 0.95 has u = 0.2 + 0.9 * 0.95 = 1.055, which REPEAT samples at u = 0.055.
    segs = _crack_at(0.95)
    after = _mask(kept, segs, res, gl_ctx)
    before = _mask(dataclasses.replace(kept, wraps=None), segs, res, gl_ctx)
    rows = slice(*sorted(_texel(0.0, v, res)[0] for v in (0.15, 0.85)))
    col = _texel(0.055, 0.5, res)[1]
    assert after[rows, col].min() > 0.9 and before[rows, col].max() == 0.0
    # Away from the crack the wrapped band is clean, and the tile itself is unchanged.
    assert after[rows, _texel(0.01, 0.5, res)[1]].max() == 0.0
    inside = slice(_texel(0.2, 0.5, res)[1] + 1, res)
    assert np.array_equal(after[:, inside], before[:, inside])


def test_a_wrap_onto_another_island_is_not_drawn_and_counted(gl_ctx):
    mesh = _overhanging_plane(island=True)
    check = U.check_uvs(mesh, ctx=gl_ctx)
    assert check.usable
    corners = mesh.uv[mesh.faces]
    stray = (corners[..., 0] > 1 + 1e-9).any(axis=1)
    low = stray & (corners[..., 1].min(axis=1) < 0.18 - 1e-9)  # their wraps meet the island
    assert np.array_equal(np.unique(check.wraps[:, 0]), np.flatnonzero(stray & ~low))
    assert check.lost_faces == int(low.sum()) == 12
    # The lost part: u 1..1.1 x v 0.1..0.18 of the page, 0.008 of its texels (under the 1 %
    # that keeps a layout whose strays are more than 1 % of the faces).
    assert check.lost_fraction == pytest.approx(0.1 * 0.08, rel=0.03)
    res = 256
    with pytest.warns(CrackbakeWarning, match=r"12 could not be .*about (\d+) texels at 256x256") \
            as rec:  # fmt: skip
        kept = U.prepare_uvs(mesh, "auto", res, ctx=gl_ctx)
    texels = int(__import__("re").search(r"about (\d+) texels", str(rec[-1].message)).group(1))
    assert texels == pytest.approx(0.008 * res * res, rel=0.03)
    after = _mask(kept, _crack_at(0.95), res, gl_ctx)
    col = _texel(0.055, 0.5, res)[1]
    assert after[_texel(0, 0.5, res)[0], col] > 0.9  # wrapped above the island
    assert after[_texel(0, 0.14, res)[0], col] == 0.0  # the island keeps its own (no crack)


def test_an_island_running_on_past_the_page_edge_is_not_udim(gl_ctx):
    # At n = 18 the page edge u = 1 is a grid line: every face lies inside one tile, as in a
    # UDIM layout, but the island runs on across it (shared UV vertices), so it strays.
    check = U.check_uvs(_overhanging_plane(18), ctx=gl_ctx)
    assert check.usable and not check.udim and check.lost_faces == 0
    assert len(check.wraps) == 2 * 2 * 18
