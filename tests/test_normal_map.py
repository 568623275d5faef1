"""Depth-normal and occlusion maps on a real EGL context, checked against the analytic V groove.

The scene is a tilted plane whose UV islands are rotated, stretched and mirrored; its tangent
frames are computed analytically here (not with crackbake's tangent code).  The baked normal map
is written as 16- and 8-bit PNGs, read back by readers independent of the writer (a small zlib
decoder for 16 bit, as Pillow reads 16-bit RGB only as 8 bit; Pillow for 8 bit) and decoded as an
engine does, ``normalize(x T + y B + z N)``, ``B = w cross(N, T)``.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from conftest import grid_faces
from PIL import Image
from test_bake import make_segments

from crackbake.bake import normal_map, raster
from crackbake.bake.raster import bake_cracks
from crackbake.errors import CrackbakeError
from crackbake.exchange.packing import normal_q
from crackbake.exchange.pngenc import png_bytes

RES = 256
# Tilted plane: world point = ORIGIN + x E1 + y E2, plane coordinates (x, y) in [0, 1]^2.
N0 = np.array([0.3, -0.45, 0.84]) / np.linalg.norm([0.3, -0.45, 0.84])
E1 = np.cross(N0, [0.0, 0.0, 1.0])
E1 /= np.linalg.norm(E1)
E2 = np.cross(N0, E1)
ORIGIN = np.array([0.2, -0.1, 0.5])
# The V groove: axis from A to B (plane coordinates), constant width and depth.
A_XY, B_XY = np.array([0.18, 0.32]), np.array([0.82, 0.61])
WIDTH, DEPTH = 0.09, 0.03
HW = WIDTH / 2
SLOPE = DEPTH / HW


def rotation(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s], [s, c]])


def world(xy: np.ndarray) -> np.ndarray:
    return ORIGIN + xy[..., :1] * E1 + xy[..., 1:2] * E2


class Island:
    """The part ``x0 <= x <= x1`` of the plane, mapped to UV by ``uv = offset + M (x, y)``."""

    def __init__(self, x0: float, x1: float, m: np.ndarray, uv_box: tuple[float, float]):
        self.x0, self.x1, self.m = x0, x1, m
        corners = np.array([[x0, 0], [x1, 0], [x1, 1], [x0, 1]], float) @ m.T
        lo, hi = corners.min(0), corners.max(0)
        assert (hi - lo).max() <= uv_box[1] - uv_box[0]
        self.offset = uv_box[0] - lo
        # Analytic tangent frame: dp/du and dp/dv are the columns of [E1 E2] M^-1.
        jac = np.column_stack([E1, E2]) @ np.linalg.inv(m)
        self.t = jac[:, 0] / np.linalg.norm(jac[:, 0])
        self.w = float(np.sign(np.dot(np.cross(N0, self.t), jac[:, 1])))

    def xy_of_uv(self, uv: np.ndarray) -> np.ndarray:
        return (uv - self.offset) @ np.linalg.inv(self.m).T

    def contains(self, xy: np.ndarray) -> np.ndarray:
        eps = 1e-9
        return (xy[..., 0] >= self.x0 - eps) & (xy[..., 0] <= self.x1 + eps) & (
            xy[..., 1] >= -eps) & (xy[..., 1] <= 1 + eps)  # fmt: skip


def scene(islands: list[Island], cells: int = 6):
    """Mesh (vertices, faces, uv, normals, tangents) of the islands, seams split."""
    verts, faces, uvs, tans = [], [], [], []
    base = 0
    for isl in islands:
        nx = max(1, round(cells * (isl.x1 - isl.x0)))
        x, y = np.meshgrid(np.linspace(isl.x0, isl.x1, nx + 1), np.linspace(0, 1, cells + 1),
                           indexing="ij")  # fmt: skip
        xy = np.stack([x.ravel(), y.ravel()], 1)
        f = grid_faces(nx, cells)
        uv = isl.offset + xy @ isl.m.T
        # Keep the faces front-facing in UV (counter-clockwise) on mirrored islands too.
        if np.linalg.det(isl.m) < 0:
            f = f[:, ::-1]
        verts.append(world(xy))
        faces.append(f + base)
        uvs.append(uv)
        tans.append(np.tile(np.r_[isl.t, isl.w], (len(xy), 1)))
        base += len(xy)
    v = np.concatenate(verts)
    return v, np.concatenate(faces), np.concatenate(uvs), np.tile(N0, (len(v), 1)), np.concatenate(
        tans)  # fmt: skip


def texel_points(islands: list[Island]):
    """Per texel: world point of its centre, its island index (-1: none)."""
    c, r = np.meshgrid(np.arange(RES), np.arange(RES))
    uv = np.stack([(c + 0.5) / RES, 1.0 - (r + 0.5) / RES], -1)
    which = np.full((RES, RES), -1)
    xy = np.zeros((RES, RES, 2))
    for k, isl in enumerate(islands):
        q = isl.xy_of_uv(uv)
        hit = isl.contains(q) & (which < 0)
        which[hit] = k
        xy[hit] = q[hit]
    return world(xy), xy, which


def groove(xy: np.ndarray):
    """Analytic V groove at plane points: distance to the axis, world normal, sky visibility."""
    ab = B_XY - A_XY
    t = np.clip(((xy - A_XY) @ ab) / (ab @ ab), 0, 1)
    g2 = xy - (A_XY + t[..., None] * ab)
    d = np.linalg.norm(g2, axis=-1)
    g = g2[..., :1] * E1 + g2[..., 1:2] * E2
    gn = g / np.maximum(d, 1e-300)[..., None]
    inside = d < HW
    # Height h = -DEPTH (1 - d / HW): surface normal normalize(N - grad h).
    n = np.where(inside[..., None], N0 - SLOPE * gn, N0)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    # 2D view factor to the sky of a point on the wall (the far rim is the horizon).
    h = DEPTH * (1 - d / HW)
    lv = np.hypot(HW + d, h)
    vis = 0.5 * (1 + ((HW + d) * HW - h * DEPTH) / (lv * np.hypot(HW, DEPTH)))
    return d, n, np.where(inside, vis, 1.0)


def read_png16(path) -> np.ndarray:
    """Minimal PNG reader (16-bit truecolour, non-interlaced): zlib + scanline unfiltering."""
    data = open(path, "rb").read()
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos : pos + 8])
        body = data[pos + 8 : pos + 8 + n]
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, bits, colour, _, _, interlace = ihdr
    assert (bits, colour, interlace) == (16, 2, 0)
    bpp, stride = 6, 6 * w
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, stride + 1)
    out = np.zeros((h, stride), np.int64)
    prev = np.zeros(stride, np.int64)
    for y in range(h):
        ftype, line = raw[y, 0], raw[y, 1:].astype(np.int64)
        if ftype == 0:
            cur = line
        elif ftype == 1:
            cur = np.cumsum(line.reshape(w, bpp), axis=0).reshape(-1) % 256
        elif ftype == 2:
            cur = (line + prev) % 256
        else:
            cur = np.zeros(stride, np.int64)
            for i in range(stride):
                left = cur[i - bpp] if i >= bpp else 0
                up, ul = prev[i], (prev[i - bpp] if i >= bpp else 0)
                if ftype == 3:
                    pred = (left + up) // 2
                else:
                    p = left + up - ul
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - ul)
                    pred = left if pa <= pb and pa <= pc else (up if pb <= pc else ul)
                cur[i] = (line[i] + pred) % 256
        out[y] = cur
        prev = cur
    b = out.reshape(h, w, 3, 2)
    return (b[..., 0] << 8 | b[..., 1]).astype(np.uint16)


def decode(img: np.ndarray, islands: list[Island], which: np.ndarray) -> np.ndarray:
    """World normals from a tangent-space map as an engine decodes them (per-island frames)."""
    out = np.zeros(img.shape)
    for k, isl in enumerate(islands):
        b = isl.w * np.cross(N0, isl.t)
        n = img[..., :1] * isl.t + img[..., 1:2] * b + img[..., 2:3] * N0
        out[which == k] = n[which == k]
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    return out / np.where(norm > 0, norm, 1.0)


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def bake(islands, ctx, **kw):
    v, f, uv, n, tan = scene(islands)
    segs = make_segments([world(A_XY)], [world(B_XY)], width=WIDTH, depth=DEPTH)
    return bake_cracks(v, f, uv, segs, RES, max_distance=0.15, normals=n, tangents=tan,
                       ctx=ctx, **kw)  # fmt: skip


MIRRORED = Island(0.0, 1.0, rotation(35.0) @ np.diag([-0.5, 0.68]), (0.04, 0.96))


def test_v_groove_normals_through_png_match_the_analytic_surface(gl_ctx, tmp_path):
    islands = [MIRRORED]
    assert MIRRORED.w == -1  # the island really is mirrored
    maps = bake(islands, gl_ctx)
    assert maps.normal.shape == (RES, RES, 3) and maps.normal.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(maps.normal, axis=-1), 1, atol=1e-5)
    _, xy, which = texel_points(islands)
    which[~maps.inside] = -1
    d, n_true, _ = groove(xy)
    # The texel size in world units along the worst direction.
    texel = np.linalg.norm(np.linalg.inv(MIRRORED.m), 2) / RES
    crack = (which >= 0) & (d < HW)
    assert crack.sum() > 500
    # Excluded: texel centres within 1e-3 texel of the axis or of the rim.  The map is point
    # sampled at texel centres, where the V's normal is exact except on the axis (its two
    # walls meet: the bake gives the average, N) and at the rim (crease to the flat ground);
    # there float32 rounding decides the side.  Every other crack texel is checked, including
    # the anti-aliased edge texels (whose centres lie on one side of the rim).
    checked = crack & (d > 1e-3 * texel) & (np.abs(d - HW) > 1e-3 * texel)
    assert (crack & ~checked).sum() <= 4
    png16, png8 = tmp_path / "normal16.png", tmp_path / "normal8.png"
    # the path a run's normal PNGs take: quantise to n * 0.5 + 0.5, then the encoder
    png16.write_bytes(png_bytes(normal_q(maps.normal, 16, flip_y=False)))
    png8.write_bytes(png_bytes(normal_q(maps.normal, 8, flip_y=False)))
    q16 = read_png16(png16)
    with Image.open(png8) as im:
        assert im.mode == "RGB"
        q8 = np.asarray(im)
    errors = {}
    for name, img in (("float", maps.normal), ("png16", q16 / 65535.0 * 2 - 1),
                      ("png8", q8 / 255.0 * 2 - 1)):  # fmt: skip
        world_n = decode(img, islands, which)
        err = angle_deg(world_n, n_true)
        errors[name] = float(err[checked].max())
        assert errors[name] < 2.0, name
        # Flat texels (no crack within a texel) decode to the surface normal.
        flat = (which >= 0) & (d > HW + 1.5 * texel)
        assert float(err[flat].max()) < (0.5 if name == "png8" else 0.01), name
    # Measured: 0.010 degree on llvmpipe, 0.080 on an NVIDIA H100 (its varyings interpolate with
    # coarser float rounding); an 8-bit PNG's quantisation alone is ~0.45 degree.
    assert errors["float"] < 0.1 and errors["png16"] < 0.1
    # Flat texels hold exactly (0, 0, 1) in the float map.
    flat = maps.inside & (maps.depth == 0)
    assert (maps.normal[flat] == [0, 0, 1]).all()


def grid_barycentrics(xy: np.ndarray, cells: int):
    """Corner vertex indices (..., 3) and barycentrics (..., 3) of plane points in the one-island
    grid of :func:`scene` (vertex ``i * (cells + 1) + j`` at (i, j) / cells)."""
    g = np.clip(xy * cells, 0, cells - 1e-9)
    i, j = np.floor(g[..., 0]).astype(int), np.floor(g[..., 1]).astype(int)
    fx, fy = g[..., 0] - i, g[..., 1] - j
    a = i * (cells + 1) + j
    b, c, d = a + cells + 1, a + cells + 2, a + 1
    lower = fy <= fx  # triangle (a, b, c); else (a, c, d)
    idx = np.where(lower[..., None], np.stack([a, b, c], -1), np.stack([a, c, d], -1))
    bary = np.where(lower[..., None], np.stack([1 - fx, fx - fy, fy], -1),
                    np.stack([1 - fy, fx, fy - fx], -1))  # fmt: skip
    return idx, bary


def test_varying_vertex_frames_decode_as_the_engine_interpolates_them(gl_ctx):
    """Smooth-shaded normals and tangents that vary per vertex (not orthogonal to each other):
    the engine's per-pixel interpolation of N and T, not the face plane, decodes the map."""
    cells = 6
    v, f, uv, _, _ = scene([MIRRORED], cells)
    rng = np.random.default_rng(7)
    normals = N0 + 0.25 * rng.normal(size=(len(v), 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    tangents = np.tile(np.r_[MIRRORED.t, MIRRORED.w], (len(v), 1))
    tangents[:, :3] += 0.2 * rng.normal(size=(len(v), 3))
    tangents[:, :3] /= np.linalg.norm(tangents[:, :3], axis=1, keepdims=True)
    segs = make_segments([world(A_XY)], [world(B_XY)], width=WIDTH, depth=DEPTH)
    maps = bake_cracks(v, f, uv, segs, RES, max_distance=0.15, normals=normals,
                       tangents=tangents, ctx=gl_ctx)  # fmt: skip
    _, xy, which = texel_points([MIRRORED])
    sel = (which == 0) & maps.inside
    idx, bary = grid_barycentrics(xy, cells)
    n_px = (bary[..., None] * normals[idx]).sum(-2)
    t_px = (bary[..., None] * tangents[idx, :3]).sum(-2)
    b_px = MIRRORED.w * np.cross(n_px, t_px)
    m = maps.normal.astype(np.float64)
    decoded = m[..., :1] * t_px + m[..., 1:2] * b_px + m[..., 2:3] * n_px
    decoded /= np.linalg.norm(decoded, axis=-1, keepdims=True)
    # Expected: the groove's height field over the interpolated shading normal.
    d, _, _ = groove(xy)
    texel = np.linalg.norm(np.linalg.inv(MIRRORED.m), 2) / RES
    nn = n_px / np.linalg.norm(n_px, axis=-1, keepdims=True)
    ab = B_XY - A_XY
    t = np.clip(((xy - A_XY) @ ab) / (ab @ ab), 0, 1)
    g2 = xy - (A_XY + t[..., None] * ab)
    g = g2[..., :1] * E1 + g2[..., 1:2] * E2
    grad = -SLOPE * g / np.maximum(d, 1e-300)[..., None]  # gradient of the depth
    grad -= (grad * nn).sum(-1, keepdims=True) * nn
    expected = np.where((d < HW)[..., None], nn + grad, nn)
    expected /= np.linalg.norm(expected, axis=-1, keepdims=True)
    checked = sel & (d > 1e-3 * texel) & (np.abs(d - HW) > 1e-3 * texel)
    err = angle_deg(decoded, expected)
    assert (checked & (d < HW)).sum() > 500
    assert float(err[checked].max()) < 0.1
    # The frames really vary: the face plane's normal would be off by degrees.
    assert float(angle_deg(nn[sel], N0).max()) > 5


def test_uv_seam_gives_the_same_world_normal_on_both_islands(gl_ctx):
    # The plane cut at x = 0.5 into two islands with different rotations (one mirrored).
    left = Island(0.0, 0.5, rotation(-20.0) @ np.diag([0.5, 0.38]), (0.02, 0.48))
    right = Island(0.5, 1.0, rotation(110.0) @ np.diag([-0.5, 0.38]), (0.52, 0.98))
    islands = [left, right]
    assert left.w == 1 and right.w == -1
    maps = bake(islands, gl_ctx)
    _, xy, which = texel_points(islands)
    which[~maps.inside] = -1
    d, n_true, _ = groove(xy)
    world_n = decode(maps.normal, islands, which)
    ab = B_XY - A_XY
    side = np.sign((xy - A_XY) @ np.array([-ab[1], ab[0]]))
    # Along the straight part (past the ends the groove is a cone), off the axis and the rim.
    t = ((xy - A_XY) @ ab) / (ab @ ab)
    wall = (d > 0.1 * HW) & (d < 0.9 * HW) & (t > 0.02) & (t < 0.98)
    means = {}
    for k in (0, 1):
        for s in (-1, 1):
            sel = (which == k) & wall & (side == s)
            assert sel.sum() > 50
            assert float(angle_deg(world_n[sel], n_true[sel]).max()) < 0.1
            m = world_n[sel].mean(0)
            means[k, s] = m / np.linalg.norm(m)
    for s in (-1, 1):
        assert float(angle_deg(means[0, s], means[1, s])) < 0.05
    # The two walls differ by twice the slope angle: the test would see a wrong side.
    assert float(angle_deg(means[0, -1], means[0, 1])) == pytest.approx(
        2 * np.degrees(np.arctan(SLOPE)), abs=0.1)


def test_occlusion_is_open_away_from_cracks_and_darkest_on_the_axis(gl_ctx):
    islands = [MIRRORED]
    maps = bake(islands, gl_ctx)
    assert maps.occlusion.dtype == np.float16 and maps.occlusion.shape == (RES, RES)
    _, xy, which = texel_points(islands)
    on = (which >= 0) & maps.inside
    d, _, vis = groove(xy)
    occ = maps.occlusion.astype(np.float64)
    assert (occ[maps.depth == 0] == 1).all()
    assert (occ >= 0).all() and (occ <= 1).all()
    crack = on & (d < HW)
    # The analytic view factor of a point on a V wall, within half precision.
    np.testing.assert_allclose(occ[crack], vis[crack], atol=2e-3)
    # Darkest on the axis: cos^2 of the slope angle; texels nearest the axis are the darkest.
    assert float(occ[on].min()) == pytest.approx(1 / (1 + SLOPE**2), abs=0.01)
    darkest = np.unravel_index(np.argmin(np.where(on, occ, 2)), occ.shape)
    texel = np.linalg.norm(np.linalg.inv(MIRRORED.m), 2) / RES
    assert d[darkest] < texel


def _thin_crack(res: int):
    """A unit quad (UVs = xy, tangent +x) and a straight crack 0.4 texel wide along x, 0.2
    texel off a texel row: ``v, f, tan, w, depth, y, segs``."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    tan = np.tile([1.0, 0, 0, 1], (4, 1))
    w, depth, y = 0.4 / res, 0.3 / res, 0.5 + 0.2 / res
    segs = make_segments([[0.05, y, 0]], [[0.95, y, 0]], width=w, depth=depth)
    return v, f, tan, w, depth, y, segs


def _box_tent(s, fw):
    """The coverage ramp max(1 - |s| / fw, 0) averaged over [s - fw/2, s + fw/2], by quadrature."""
    u = ((np.arange(200_000) + 0.5) / 200_000 - 0.5) * fw  # midpoint rule
    return float(np.clip(1 - np.abs(s + u) / fw, 0, None).mean())


def test_sub_texel_crack_normal_is_the_slope_of_its_area_average(gl_ctx):
    """A crack 0.4 texel wide: the bake stores the area-averaged depth, a tent one footprint
    wide, averaged over one more footprint across (point-sampled, the tent's slope flips sign
    where the axis crosses a texel centre: dashes); its normal is that average's slope and its
    occlusion the averaged covered fraction of cos(alpha)."""
    res, shape = 128, 1.0
    v, f, tan, w, depth, y, segs = _thin_crack(res)
    maps = bake_cracks(v, f, v[:, :2], segs, res, max_distance=0.05, tangents=tan, ctx=gl_ctx,
                       min_px=0.0)  # the physical width only
    col = res // 2
    fw = 1.0 / res
    for row in range(res // 2 - 3, res // 2 + 3):
        yc = 1 - (row + 0.5) / res
        ramp = _box_tent(yc - y, fw)
        # Height rises away from the axis: the normal leans towards it (-y above, +y below).
        e = 1e-3 * fw
        slope = depth * w / ((shape + 1) * fw) * (_box_tent(yc - y + e, fw)
                                                  - _box_tent(yc - y - e, fw)) / (2 * e)
        expected = np.array([0.0, slope, 1.0])
        expected /= np.linalg.norm(expected)
        np.testing.assert_allclose(maps.normal[row, col], expected, atol=1e-4)
        cos_a = (w / 2) / np.hypot(w / 2, depth)
        occ = 1 - ramp * (w / fw) * (1 - cos_a)
        assert float(maps.occlusion[row, col]) == pytest.approx(occ, abs=2e-3)
        assert float(maps.depth[row, col]) == pytest.approx(depth * w * ramp / (2 * fw), rel=1e-4,
                                                            abs=1e-9)  # fmt: skip


def test_min_px_crack_normal_is_the_filtered_one_texel_crack(gl_ctx):
    """The same 0.4-texel crack drawn at min_px = 1: baked as a crack exactly one footprint fw
    wide in the filtered form (no one-texel V to alias): the tent D fw / ((shape + 1) fw) *
    (1 - d / fw) averaged over a footprint, its slope in the normal, the occlusion that ramp times
    the one-texel groove's wall shade; the width channel keeps the physical width."""
    res, shape = 128, 1.0
    v, f, tan, w, depth, y, segs = _thin_crack(res)
    maps = bake_cracks(v, f, v[:, :2], segs, res, max_distance=0.05, tangents=tan, ctx=gl_ctx,
                       min_px=1.0)
    col, fw = res // 2, 1.0 / res
    cos_a = (fw / 2) / np.hypot(fw / 2, depth)
    for row in range(res // 2 - 3, res // 2 + 3):
        yc = 1 - (row + 0.5) / res
        ramp = _box_tent(yc - y, fw)
        e = 1e-3 * fw
        slope = depth / ((shape + 1) * fw) * (_box_tent(yc - y + e, fw)
                                              - _box_tent(yc - y - e, fw)) / (2 * e) * fw
        expected = np.array([0.0, slope, 1.0])
        np.testing.assert_allclose(maps.normal[row, col], expected / np.linalg.norm(expected),
                                   atol=1e-4)
        cover = max(1 - abs(yc - y) / fw, 0.0)  # the mask keeps the one-footprint ramp
        assert float(maps.mask[row, col]) == pytest.approx(cover, abs=2e-3)
        assert float(maps.depth[row, col]) == pytest.approx(depth * ramp / 2, rel=1e-4, abs=1e-9)
        occ = 1 - ramp * (1 - cos_a)
        assert float(maps.occlusion[row, col]) == pytest.approx(occ, abs=2e-3)
    assert float(maps.width[res // 2, col]) == pytest.approx(w, rel=2e-3)


def test_normals_leave_the_other_channels_bit_identical_and_tile(gl_ctx, monkeypatch):
    v, f, uv, n, tan = scene([MIRRORED])
    rng = np.random.default_rng(4)
    a = rng.random((30, 2))
    b = np.clip(a + (rng.random((30, 2)) - 0.5) * 0.4, 0, 1)
    segs = make_segments(world(a), world(b), width=rng.random((30, 2)) * 0.03,
                         depth=rng.random((30, 2)) * 0.01)  # fmt: skip
    plain = bake_cracks(v, f, uv, segs, RES, max_distance=0.1, ctx=gl_ctx)
    assert plain.normal is None and plain.occlusion is None
    full = bake_cracks(v, f, uv, segs, RES, max_distance=0.1, normals=n, tangents=tan,
                       ctx=gl_ctx)  # fmt: skip
    for name, arr in plain.channels().items():
        assert np.array_equal(arr, full.channels()[name]), name
    # Bands (tile 128 -> 64-row bands) give the same normal map, up to float32 rounding of the
    # interpolated positions (as for the mask: tie-breaks may move).  Grooves drawn under four
    # texels wide are box-averaged, so their slope varies along the distance (a point-sampled V's
    # is constant on each wall): a rounding of 1e-4 texel turns them by a few hundredths of a
    # degree (99th percentile measured: 0.012 on llvmpipe, 0.033 on an NVIDIA H100).
    tiled = bake_cracks(v, f, uv, segs, RES, max_distance=0.1, normals=n, tangents=tan,
                        tile=128, ctx=gl_ctx)  # fmt: skip
    diff = angle_deg(tiled.normal.astype(float), full.normal.astype(float))
    assert float(np.percentile(diff, 99)) < 0.05 and float(diff.max()) < 0.5
    np.testing.assert_allclose(tiled.occlusion.astype(float), full.occlusion.astype(float),
                               atol=1e-3)  # fmt: skip
    # Compute dispatches split in parts (as beyond 65535 groups) give the same result.
    monkeypatch.setattr(normal_map, "_DISPATCH", 100)
    split = bake_cracks(v, f, uv, segs, RES, max_distance=0.1, normals=n, tangents=tan,
                        ctx=gl_ctx)  # fmt: skip
    assert np.array_equal(split.normal, full.normal)
    assert np.array_equal(split.occlusion, full.occlusion)
    # Room for one crack texel record: the band is drawn again with room for all, same maps.
    monkeypatch.setattr(raster, "RECORDS_SHARE", 1 << 30)
    monkeypatch.setattr(raster, "RECORDS_LEAST", 1)
    again = bake_cracks(v, f, uv, segs, RES, max_distance=0.1, normals=n, tangents=tan,
                        ctx=gl_ctx)  # fmt: skip
    for name, arr in full.channels().items():
        assert np.array_equal(arr, again.channels()[name]), name
    # The gutters are filled from the islands like the other channels.
    assert not full.inside.all()
    np.testing.assert_allclose(np.linalg.norm(full.normal, axis=-1), 1, atol=1e-5)


def test_bad_tangents_are_refused_in_one_line(gl_ctx):
    v, f, uv, n, tan = scene([MIRRORED])
    segs = make_segments([world(A_XY)], [world(B_XY)], width=WIDTH)
    with pytest.raises(CrackbakeError, match=r"tangents have shape \(.*\), expected") as e:
        bake_cracks(v, f, uv, segs, 64, max_distance=0.1, tangents=tan[:, :3], ctx=gl_ctx)
    assert "\n" not in str(e.value)
    with pytest.raises(CrackbakeError, match="normals have shape"):
        bake_cracks(v, f, uv, segs, 64, max_distance=0.1, normals=n[:-1], tangents=tan,
                    ctx=gl_ctx)


@pytest.mark.parametrize("w_px", [1.5, 0.6])
def test_thin_groove_near_a_texel_row_shades_smoothly_along_the_crack(gl_ctx, w_px):
    """A groove 1.5 texels wide (a V), or 0.6 (drawn one texel wide: the sub-texel tent), at 3
    degrees to the texel rows (issue 18: dashes).  Point sampled, a texel just off the axis takes
    a full wall's tilt and its neighbour none, so the tilt flips in runs along the crack.
    Box-averaged over a footprint, each texel's tilt moves by a small step per column as the
    axis drifts 0.05 texel, and the tilt summed across the crack (the height's rise from one
    side to the other: zero) stays zero along it."""
    res = 128
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    tan = np.tile([1.0, 0, 0, 1], (4, 1))
    w, depth, fw = w_px / res, 0.5 / res, 1.0 / res
    if w_px > 1:  # the V, and a wall's slope
        hw, peak = w / 2, depth
    else:  # drawn fw wide (min_px 1): the tent D fw / (2 fw) (1 - d / fw)
        hw, peak = fw, depth / 2
    slope = peak / hw
    a, b = np.array([0.02, 0.47, 0]), np.array([0.98, 0.47 + 0.96 * np.tan(np.radians(3)), 0])
    segs = make_segments([a], [b], width=w, depth=depth)
    maps = bake_cracks(v, f, v[:, :2], segs, res, max_distance=0.05, tangents=tan, ctx=gl_ctx)
    tilt = (maps.normal[..., 1] / maps.normal[..., 2]).astype(np.float64)  # d(depth)/dy
    cols = np.arange(10, res - 10)
    rows = slice(res // 2 - 12, res // 2 + 8)  # the crack's rows, and a few more either side
    band = tilt[rows][:, cols]
    assert np.abs(band).max() > 0.3 * slope  # the walls do lean
    # Texel to texel along the crack: a V's box average changes by at most 2 slope x 0.05 texel
    # per texel, i.e. 0.1 slope (point sampled: up to 2 slopes, as the axis crosses a centre).
    step = np.abs(np.diff(band, axis=1))
    assert step.max() < 0.2 * slope, step.max() / slope
    # Summed across the crack, the slopes telescope to the height's rise, which is zero.
    assert np.abs(band.sum(0)).max() < 0.05 * slope, np.abs(band.sum(0)).max() / slope
    # Both are the profile (V or tent) averaged over one texel across the crack (fw = 1 / res
    # here), derived here by quadrature: depth A(s) = mean of the profile over
    # [s - fw/2, s + fw/2] (s the signed distance to the axis), the normal's slope A'(s).
    theta = np.radians(3)
    c, r = np.meshgrid(cols, np.arange(res)[rows])
    px, py = (c + 0.5) / res, 1 - (r + 0.5) / res
    sd = -(px - a[0]) * np.sin(theta) + (py - a[1]) * np.cos(theta)
    u = np.linspace(-0.5, 0.5, 2001) / res

    def mean_v(x):
        return (peak * np.clip(1 - np.abs(x[..., None] + u) / hw, 0, None)).mean(-1)

    e = 1e-3 / res
    np.testing.assert_allclose(maps.depth[rows][:, cols], mean_v(sd), rtol=0, atol=2e-3 * peak)
    expect = (mean_v(sd + e) - mean_v(sd - e)) / (2 * e) * np.cos(theta)
    np.testing.assert_allclose(band, expect, rtol=0, atol=0.01 * slope)


def test_crack_texels_are_numpys_nonzero_and_gather():
    # The compute pass's job list: the texels whose inside code is 2 + a record, row-major,
    # as np.nonzero and a truncating gather give them (NaN and codes below 2 left out).
    from crackbake.bake.normal_map import crack_texels

    rng = np.random.default_rng(3)
    code = np.zeros((64, 96), np.float32)
    code[rng.random(code.shape) < 0.3] = 1.0
    hit = rng.random(code.shape) < 0.05
    code[hit] = 2.0 + rng.integers(0, 1 << 22, hit.sum()).astype(np.float32)
    code[0, :4] = [np.nan, 2.0, np.nextafter(np.float32(2.0), np.float32(0.0)), 2.5]
    rows, cols = np.nonzero(code >= 2)
    want = (rows, cols, code[rows, cols].astype(np.int64) - 2)
    got = crack_texels(code)
    for a, b in zip(got, want, strict=True):
        assert a.dtype == np.int64
        np.testing.assert_array_equal(a, b)
    assert [len(a) for a in crack_texels(np.ones((3, 5), np.float32))] == [0, 0, 0]
