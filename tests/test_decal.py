"""Decals from an impact (crackbake.decals.projector, crackbake.decals.files): real EGL bakes, real
PNG and JSON files, the decal applied back onto the mesh through its written transform, and each
engine's documented projection applied to the block written for it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cli_forks
import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from crackbake.bake.raster import bake_cracks
from crackbake.decals.apply import apply_decal, bilinear, uv_surface
from crackbake.decals.files import engine_blocks, write_decal_set
from crackbake.decals.projector import bake_decal, make_projector
from crackbake.errors import CrackbakeError
from crackbake.network import Crack, CrackNetwork, segments
from crackbake.params import Impact, RunParams

REPO = Path(__file__).resolve().parents[1]
RADIUS = 1.0


def half_cylinder(n_theta: int = 96, n_z: int = 48):
    """Half a cylinder of radius 1 around +Y (x = sin t, z = cos t, t in [-pi/2, pi/2]),
    y in [0, 2]; uv = (t / pi + 0.5, y / 2), faces counter-clockwise seen from outside."""
    t = np.linspace(-np.pi / 2, np.pi / 2, n_theta + 1)
    y = np.linspace(0.0, 2.0, n_z + 1)
    tt, yy = np.meshgrid(t, y, indexing="ij")
    v = np.stack([RADIUS * np.sin(tt), yy, RADIUS * np.cos(tt)], -1).reshape(-1, 3)
    uv = np.stack([tt / np.pi + 0.5, yy / 2.0], -1).reshape(-1, 2)
    idx = np.arange(len(v)).reshape(n_theta + 1, n_z + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    # Outward normal of (a, b, c): (b - a) along +t, (c - a) along +t and +y; t x y points out?
    e1, e2 = v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]]
    out = np.einsum("ij,ij->i", np.cross(e1, e2), v[faces[:, 0]] * [1, 0, 1]) > 0
    faces[~out] = faces[~out][:, [0, 2, 1]]
    return v, faces.astype(np.int64), uv


def cylinder_network(vertices, faces) -> CrackNetwork:
    """Three cracks on the half cylinder (points on the surface, 2 mm steps), 0.02 wide."""
    cracks = []
    for k, (t0, t1, y0, y1) in enumerate(
        [(-0.5, 0.45, 0.7, 1.25), (-0.3, 0.2, 1.3, 0.75), (0.05, 0.5, 1.0, 1.05)]
    ):
        s = np.linspace(0.0, 1.0, 200)
        t = t0 + (t1 - t0) * s
        y = y0 + (y1 - y0) * s + 0.05 * np.sin(9 * s)
        pts = np.stack([RADIUS * np.sin(t), y, RADIUS * np.cos(t)], 1)
        cracks.append(Crack(id=k, points=pts, faces=np.zeros(len(s), np.int64), time=s,
                            width=np.full(len(s), 0.02), depth=np.full(len(s), 0.01)))
    return CrackNetwork(cracks=cracks, mesh={})


def test_decal_on_a_curved_mesh_matches_the_uv_bake(gl_ctx, tmp_path):
    """The decal PNG applied back through decals.json puts the cracks where the UV bake has
    them: every crack texel of one lies within one UV texel of a crack texel of the other."""
    v, f, uv = half_cylinder()
    seg = segments(cylinder_network(v, f))
    res = 512
    uvmaps = bake_cracks(v, f, uv, seg, res, max_distance=0.05, ctx=gl_ctx)
    # An impact off the surface, 30 degrees round: the projector snaps to the surface there.
    hit = np.array([1.3 * np.sin(0.1), 1.0, 1.3 * np.cos(0.1)])
    proj = make_projector(v, f, hit, 0.8)
    np.testing.assert_allclose(proj.centre, [np.sin(0.1), 1.0, np.cos(0.1)], atol=2e-3)
    np.testing.assert_allclose(proj.axes[2], [np.sin(0.1), 0, np.cos(0.1)], atol=2e-3)
    # Depth covers the curvature: the arc of half width 0.4 falls 1 - cos(0.4) = 0.079 behind.
    sag = RADIUS * (1 - np.cos(0.4 / RADIUS))
    assert 2 * sag < proj.depth < 2 * sag * 1.1 + 0.1
    dec = bake_decal(v, f, seg, proj, 320, uvmaps.max_distance, ctx=gl_ctx)
    write_decal_set(lambda name: tmp_path / name, [(proj, dec, {"point": list(hit)})], "gl")
    doc = json.loads((tmp_path / "decals.json").read_text())
    entry = doc["decals"][0]
    alpha = np.asarray(Image.open(tmp_path / entry["files"]["alpha"]), np.float64) / 255
    pts, face = uv_surface(v, f, uv, res, ctx=gl_ctx)
    val, cov = apply_decal(pts, face, v, f, entry, alpha)
    core = ndimage.binary_erosion(cov, iterations=2)
    mask = np.asarray(uvmaps.mask, np.float64)
    a, b = (mask > 0.5) & core, (val > 0.5) & core
    near_a = ndimage.distance_transform_edt(~(mask > 0.05))
    near_b = ndimage.distance_transform_edt(~(val > 0.05))
    assert a.sum() > 1000 and b.sum() > 0.8 * a.sum()
    # Figures for the report: distances in UV texels and the mean difference.
    print(f"\ncovered {int(core.sum())} texels, cracks {int(a.sum())} / {int(b.sum())}; "
          f"decal->uv max {near_a[b].max():.2f}, uv->decal max {near_b[a].max():.2f} texels; "
          f"mean |diff| {np.abs(val - mask)[core].mean():.4f}")
    assert near_a[b].max() <= 1.0 and near_b[a].max() <= 1.0
    assert np.abs(val - mask)[core].mean() < 0.02


def letter_f(n: int = 32) -> np.ndarray:
    """An asymmetric test image, row 0 = top: an upright "F" (1) on 0."""
    img = np.zeros((n, n), np.uint8)
    img[4:28, 8:12] = 1  # the stem, on the left
    img[4:8, 8:24] = 1  # the top bar
    img[14:18, 8:20] = 1  # the middle bar
    return img


def quat_matrix(q) -> np.ndarray:
    """Rotation matrix (columns = rotated axes) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def unreal_axes(pitch, yaw, roll) -> np.ndarray:
    """Columns X, Y, Z of Unreal's FRotationMatrix(FRotator(pitch, yaw, roll)) (its rows)."""
    p, y, r = np.radians([pitch, yaw, roll])
    sp, cp, sy, cy, sr, cr = np.sin(p), np.cos(p), np.sin(y), np.cos(y), np.sin(r), np.cos(r)
    rows = np.array([
        [cp * cy, cp * sy, sp],
        [sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, -sr * cp],
        [-(cr * sp * cy + sr * sy), cy * sr - cr * sp * sy, cr * cp],
    ])  # fmt: skip
    return rows.T


def unity_uv(block, p):
    """URP/HDRP: decalToWorld = TRS(position, rotation * Euler(-90, 0, 0), 1) * T(offset) *
    S(size), offset = (pivot.x, -pivot.z, pivot.y), size = (x, z, y); positionDS *= (1, -1, 1);
    uv = positionDS.xz + 0.5 (Unity's v = 0 is the image bottom).  Returns (u, v_top), inside."""
    rx = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Euler(-90, 0, 0): -Y -> +Z
    rot = quat_matrix(block["rotation_xyzw"]) @ rx
    size = np.array(block["size"])[[0, 2, 1]]
    piv = np.array(block["pivot"])
    offset = np.array([piv[0], -piv[2], piv[1]])
    ds = ((p - block["position"]) @ rot - offset) / size
    ds[:, 1] *= -1
    inside = np.all(np.abs(ds) <= 0.5 + 1e-9, axis=1)
    return np.stack([ds[:, 0] + 0.5, 1 - (ds[:, 2] + 0.5)], 1), inside


def unreal_uv(block, p):
    """Unreal deferred decal: OS = local / DecalSize in [-1, 1]; DecalVector = OS * 0.5 + 0.5;
    DecalUVs = DecalVector.zy (v = 0 is the image top).  Rotation from the written rotator."""
    rot = unreal_axes(*block["rotator_pyr_deg"])
    os_ = (p - block["location_cm"]) @ rot / np.array(block["decal_size_cm"])
    inside = np.all(np.abs(os_) <= 1 + 1e-9, axis=1)
    dv = os_ * 0.5 + 0.5
    return np.stack([dv[:, 2], dv[:, 1]], 1), inside


def godot_uv(block, p):
    """Godot 4: uv_local = inverse(xform * scale(extents) * uv_xform) * p with uv_xform
    scale (2, 1, 2), origin (-1, 0, -1); samples uv_local.xz (v = 0 is the image top)."""
    basis = np.array(block["basis_columns"]).T
    ext = np.array(block["size"]) / 2
    local = (p - block["origin"]) @ basis / ext
    inside = np.all(np.abs(local) <= 1 + 1e-9, axis=1)
    return np.stack([(local[:, 0] + 1) / 2, (local[:, 2] + 1) / 2], 1), inside


def lookup(img, uv_top):
    n = img.shape[0]
    rows = np.clip(np.floor(uv_top[:, 1] * n).astype(int), 0, n - 1)
    cols = np.clip(np.floor(uv_top[:, 0] * n).astype(int), 0, n - 1)
    return img[rows, cols]


@pytest.mark.parametrize("normal", [(0.3, 0.5, 0.81), (0.0, 1.0, 0.0), (-0.7, -0.2, -0.1)])
def test_engine_blocks_place_an_f_as_the_projector_does(normal):
    """Each engine's documented projection, applied to the block written for it, reads the same
    texel of an "F" as the projector frame does at every texel centre of the decal (a mirrored
    or rotated placement would change the F)."""
    n = np.asarray(normal) / np.linalg.norm(normal)
    # A plate through c with that normal: two triangles, counter-clockwise seen from +n.
    c = np.array([0.3, -1.2, 2.0])
    a = np.cross(n, [0.31, 0.17, 0.93])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    quad = c + 2 * np.array([-a - b, a - b, a + b, -a + b])
    proj = make_projector(quad, np.array([[0, 1, 2], [0, 2, 3]]), c + 0.2 * n, 0.5)
    np.testing.assert_allclose(proj.axes[2], n, atol=1e-12)
    img = letter_f()
    k = (np.arange(32) + 0.5) / 32
    uu, vv = np.meshgrid(k, k)
    local = np.stack([(uu.ravel() - 0.5) * proj.width, (vv.ravel() - 0.5) * proj.height,
                      np.zeros(uu.size), np.ones(uu.size)], 1)
    p_mesh = (local @ proj.matrix.T)[:, :3]
    ours = lookup(img, np.stack([uu.ravel(), 1 - vv.ravel()], 1))
    blocks = engine_blocks(proj)
    for engine, project in (("unity", unity_uv), ("unreal", unreal_uv), ("godot", godot_uv)):
        conv = np.array(blocks[engine]["mesh_to_engine"]["matrix"])
        scale = blocks[engine]["mesh_to_engine"]["scale"]
        uv_top, inside = project(blocks[engine], scale * p_mesh @ conv.T)
        assert inside.all(), engine
        np.testing.assert_array_equal(lookup(img, uv_top), ours, err_msg=engine)
    # Projection directions: into the surface for each engine.
    unity_fwd = quat_matrix(blocks["unity"]["rotation_xyzw"])[:, 2]
    unreal_fwd = unreal_axes(*blocks["unreal"]["rotator_pyr_deg"])[:, 0]
    godot_up = np.array(blocks["godot"]["basis_columns"])[1]
    np.testing.assert_allclose(unity_fwd, np.diag([-1, 1, 1]) @ -n, atol=1e-9)
    np.testing.assert_allclose(unreal_fwd, np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0]]) @ -n,
                               atol=1e-9)
    np.testing.assert_allclose(godot_up, n, atol=1e-9)


def _cli(*args, cwd=None):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return cli_forks.run(list(args), env=env, cwd=cwd, timeout=300)


def test_decal_needs_an_impact():
    with pytest.raises(CrackbakeError, match="--decal needs --impact"):
        RunParams(mesh=Path("x.obj"), decal=0.3).validate()
    with pytest.raises(CrackbakeError, match="--decal 0 is out of range"):
        RunParams(mesh=Path("x.obj"), decal=0.0, impacts=(Impact((0, 0, 0)),)).validate()
    with pytest.raises(CrackbakeError, match="--decal-res needs --decal"):
        RunParams(mesh=Path("x.obj"), decal_res=256, impacts=(Impact((0, 0, 0)),)).validate()
    r = _cli(str(REPO / "examples" / "spot.obj"), "--decal", "0.3")
    assert r.returncode != 0
    assert r.stderr.strip().splitlines()[-1].startswith("error: --decal needs --impact")


@pytest.mark.slow
def test_cli_writes_the_decal_set(tmp_path):
    out = tmp_path / "out"
    r = _cli(str(REPO / "examples" / "spot.obj"), "--preset", "glass", "--impact",
             "0.334,0.044,0.287", "--res", "512", "--decal", "0.4", "--decal-res", "256",
             "--formats", "png", "-o", str(out))
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "decals.json").read_text())
    assert doc["format"] == "crackbake-decals" and doc["version"] == 1
    (entry,) = doc["decals"]
    m = np.array(entry["matrix"])
    np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(m[:3, :3]) > 0 and entry["width"] == entry["height"] == 0.4
    assert np.linalg.norm(m[:3, 3] - [0.334, 0.044, 0.287]) < 0.05
    with Image.open(out / entry["files"]["height"]) as im:
        assert im.mode.startswith("I;16") and im.size == (256, 256)
    for role in ("alpha", "normal", "orm"):
        with Image.open(out / entry["files"][role]) as im:
            assert im.size == (256, 256) and "srgb" not in im.info
    alpha = np.asarray(Image.open(out / entry["files"]["alpha"]))
    assert alpha.max() == 255 and (alpha > 127).mean() > 0.005
    manifest = json.loads((out / "manifest.json").read_text())
    assert "decals.json" in [f["name"] for f in manifest["files"]]


def test_bilinear_matches_texel_centres():
    img = np.arange(16.0).reshape(4, 4)
    u = (np.array([0, 3]) + 0.5) / 4
    v = 1 - (np.array([1, 2]) + 0.5) / 4
    np.testing.assert_allclose(bilinear(img, u, v), [img[1, 0], img[2, 3]])


def test_decal_of_a_plate_seen_square_on_is_its_uv_bake(gl_ctx):
    """A plate in z = 0 with uv = xy, decal centred over it, as wide as the plate: the projector
    frame is the UV frame (X right, Y up, N = +z), so every map equals the UV bake bit for bit."""
    from conftest import plate_mesh, tiny_network

    m = plate_mesh(8)
    seg = segments(tiny_network())
    n_v = len(m.vertices)
    frame = {
        "normals": np.tile([0.0, 0, 1], (n_v, 1)), "tangents": np.tile([1.0, 0, 0, 1], (n_v, 1))
    }
    uvm = bake_cracks(m.vertices, m.faces, m.uv, seg, 128, max_distance=0.05, ctx=gl_ctx, **frame)
    proj = make_projector(m.vertices, m.faces, [0.5, 0.5, 0.3], 1.0)
    np.testing.assert_allclose(proj.matrix[:3], [[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 0]])
    assert proj.depth == pytest.approx(0.05)  # flat: only the margins
    dec = bake_decal(m.vertices, m.faces, seg, proj, 128, uvm.max_distance, ctx=gl_ctx)
    for name in ("mask", "width", "depth", "distance", "crack_id", "normal", "occlusion"):
        np.testing.assert_array_equal(getattr(dec, name), getattr(uvm, name), err_msg=name)


def test_decal_normal_is_in_the_projector_frame(gl_ctx):
    """UVs turned 90 degrees on the plate (u = y, v = 1 - x: T = +y, B = -x) and the projector
    square on (X = +x, Y = +y): the decal is the UV bake turned back, and its normals are the
    same world normals written in the projector's frame, (x, y) -> (-y, x)."""
    from conftest import plate_mesh, tiny_network

    m = plate_mesh(8)
    uv = np.stack([m.vertices[:, 1], 1.0 - m.vertices[:, 0]], 1)
    seg = segments(tiny_network())
    n_v = len(m.vertices)
    res = 512
    uvm = bake_cracks(m.vertices, m.faces, uv, seg, res, max_distance=0.05, ctx=gl_ctx,
                      normals=np.tile([0.0, 0, 1], (n_v, 1)),
                      tangents=np.tile([0.0, 1, 0, 1], (n_v, 1)))  # fmt: skip
    proj = make_projector(m.vertices, m.faces, [0.5, 0.5, 0.0], 1.0)
    dec = bake_decal(m.vertices, m.faces, seg, proj, res, uvm.max_distance, ctx=gl_ctx)
    # Decal texel (r, c) is world (x, y) = ((c + .5) / R, 1 - (r + .5) / R): UV texel (c, R-1-r).
    turned = lambda a: np.rot90(a, 1)  # noqa: E731  (b[r, c] = a[c, R - 1 - r])
    mask_uv = turned(np.asarray(uvm.mask, np.float64))
    np.testing.assert_allclose(np.asarray(dec.mask, np.float64), mask_uv, atol=2e-3)
    assert (mask_uv > 0.5).sum() > 50
    n_uv = np.stack([turned(uvm.normal[..., k]) for k in range(3)], -1)
    expected = np.stack([-n_uv[..., 1], n_uv[..., 0], n_uv[..., 2]], -1)
    tilted = np.linalg.norm(expected[..., :2], axis=-1) > 0.05
    assert tilted.sum() > 50
    np.testing.assert_allclose(dec.normal, expected, atol=2e-3)


def _slab(gap: float = 0.01):
    """A unit square facing +z at z = 0 over a second facing -z at z = -gap (a thin ear or a
    sheet: two faces ``gap`` apart), 8 x 8 quads each."""
    n = 8
    g = np.linspace(0.0, 1.0, n + 1)
    xx, yy = np.meshgrid(g, g)
    top = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    idx = np.arange(xx.size).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    f_top = np.r_[np.c_[a, b, c], np.c_[a, c, d]]  # counter-clockwise from +z
    v = np.r_[top, top - [0, 0, gap]]
    f = np.r_[f_top, f_top[:, [0, 2, 1]] + len(top)]  # the back faces -z
    return v, f.astype(np.int64)


def test_a_decal_on_a_thin_slab_reaches_only_the_front(gl_ctx, tmp_path):
    v, f = _slab(0.01)
    size = 0.8  # the old box: 2.5 % of 0.8 = 0.02 each side, the back face inside it
    proj = make_projector(v, f, np.array([0.5, 0.5, 0.05]), size)
    np.testing.assert_allclose(proj.axes[2], [0, 0, 1], atol=1e-9)
    local = proj.to_local(v)
    front, back = local[: len(v) // 2], local[len(v) // 2 :]
    # The box holds the front (flat: z = 0) and stops halfway to the back, 0.01 behind.
    assert proj.depth / 2 == pytest.approx(0.005, rel=1e-6)
    assert (np.abs(front[:, 2]) <= proj.depth / 2).all()
    assert (np.abs(back[:, 2]) > proj.depth / 2).all()
    # Each engine's box too: the back face's points, inside the footprint, lie outside it
    # (the Godot block: local +Y towards the projector, size (w, d, h)).
    block = engine_blocks(proj)["godot"]
    basis = np.array(block["basis_columns"]).T
    inner = np.abs(back[:, :2]).max(axis=1) < size / 2
    pts = v[len(v) // 2 :][inner]
    y = (pts - np.array(block["origin"])) @ basis[:, 1] / np.linalg.norm(basis[:, 1])
    assert (np.abs(y) > block["size"][1] / 2).all()
    # The bake itself keeps the first surface: the decal shows the front's crack.
    crack = Crack(id=0, points=np.array([[0.2, 0.5, 0.0], [0.8, 0.5, 0.0]]),
                  faces=np.zeros(2, int), time=np.zeros(2), width=np.full(2, 0.02),
                  depth=np.full(2, 0.01))  # fmt: skip
    dec = bake_decal(v, f, segments(CrackNetwork(cracks=[crack], mesh={})), proj, 128, 0.05,
                     ctx=gl_ctx)  # fmt: skip
    assert dec.mask.max() > 0.9 and dec.inside.all()


def _tilted_plane(angle_deg: float):
    """A 1 x 1 plane through the origin, its normal tilted ``angle_deg`` from +z about x, and
    a crack across it along x (two triangles, subdivided for the bake's footprints)."""
    n = 16
    g = np.linspace(-0.5, 0.5, n + 1)
    xx, yy = np.meshgrid(g, g)
    a = np.radians(angle_deg)
    v = np.c_[xx.ravel(), yy.ravel() * np.cos(a), yy.ravel() * np.sin(a)]
    idx = np.arange(xx.size).reshape(n + 1, n + 1)
    p, q = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    r, s = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    f = np.r_[np.c_[p, q, r], np.c_[p, r, s]].astype(np.int64)
    crack = Crack(id=0, points=np.array([[-0.4, 0.0, 0.0], [0.4, 0.0, 0.0]]),
                  faces=np.zeros(2, int), time=np.zeros(2), width=np.full(2, 0.01),
                  depth=np.full(2, 0.005))  # fmt: skip
    return v, f, segments(CrackNetwork(cracks=[crack], mesh={}))


def test_decals_fade_with_the_angle_to_the_projector(gl_ctx):
    from crackbake.decals.projector import ANGLE_FADE_DEG, Projector, angle_fade_image

    lo, hi = (np.cos(np.radians(a)) for a in ANGLE_FADE_DEG[::-1])
    peak = {}
    for angle in (0.0, 40.0, 70.0, 85.0):
        v, f, seg = _tilted_plane(angle)
        proj = Projector(matrix=np.eye(4), width=1.0, height=1.0, depth=1.2)  # looks along -z
        fade = angle_fade_image(v, f, proj, 64, ctx=gl_ctx)
        t = np.clip((np.cos(np.radians(angle)) - lo) / (hi - lo), 0, 1)
        want = t * t * (3 - 2 * t)  # smoothstep, as engines' angle fade
        rows = np.abs(np.linspace(0.5, -0.5, 64) + 0.5 / 64) < 0.45 * np.cos(np.radians(angle))
        np.testing.assert_allclose(fade[rows], want, atol=2e-3)
        dec = bake_decal(v, f, seg, proj, 128, 0.05, ctx=gl_ctx)
        raw = bake_decal(v, f, seg, proj, 128, 0.05, ctx=gl_ctx, angle_fade=None)
        peak[angle] = (float(dec.mask.max()), float(raw.mask.max()))
        assert peak[angle][0] == pytest.approx(want * peak[angle][1], abs=0.01)
    # Face on and at 40 degrees: untouched; at 85 degrees (the dashed streaks): gone.
    assert peak[0.0][0] == peak[0.0][1] > 0.5 and peak[40.0][0] == peak[40.0][1]
    assert peak[85.0][0] == 0.0 and peak[85.0][1] >= 0.3


def test_sigterm_stops_a_decal_bake_between_two_gl_calls(gl_ctx, monkeypatch):
    """The crack pass runs in scissored slices (one GL call each, SLICE_TEXELS texels at most):
    SIGTERM sent while the first slice reports stops the bake before the second is drawn, the
    context stays clean, and the slices draw exactly what one call draws."""
    import signal

    from crackbake.bake import raster
    from crackbake.transaction.interrupt import Interrupt, interruptible

    v, f, _ = half_cylinder()
    seg = segments(cylinder_network(v, f))
    proj = make_projector(v, f, np.array([0.0, 1.0, 1.2]), 0.8)
    whole = bake_decal(v, f, seg, proj, 256, 0.05, ctx=gl_ctx)

    monkeypatch.setattr(raster, "SLICE_TEXELS", 256 * 32)  # 8 slices of 32 rows
    calls: list[int] = []

    def stop_at_first(done: int, total: int) -> None:
        calls.append(done)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGTERM)

    with pytest.raises(Interrupt) as caught, interruptible():
        bake_decal(v, f, seg, proj, 256, 0.05, ctx=gl_ctx, progress=stop_at_first)
    assert caught.value.signum == signal.SIGTERM
    assert calls == [32]

    rows: list[int] = []
    sliced = bake_decal(v, f, seg, proj, 256, 0.05, ctx=gl_ctx,
                        progress=lambda done, total: rows.append(done))  # fmt: skip
    assert rows == list(range(32, 257, 32))
    assert (whole.mask > 0.5).sum() > 500
    for name, img in whole.channels().items():
        np.testing.assert_array_equal(sliced.channels()[name], img, err_msg=name)


def _four_pieces(thin_back: bool = False):
    """Four unit squares as separate shells (no shared vertices) meeting at (1, 1, 0), z up;
    ``thin_back`` adds a back-facing copy of the first square in the same plane."""
    g = np.linspace(0.0, 1.0, 5)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    pts = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    i = np.arange(4)[:, None] * 5 + np.arange(4)[None, :]
    quads = np.stack([i, i + 5, i + 6, i + 1], -1).reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    verts, faces = [], []
    for k, (dx, dy) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        verts.append(pts + [dx, dy, 0])
        faces.append(tris + k * len(pts))
    if thin_back:
        verts.append(pts)
        faces.append(tris[:, ::-1] + 4 * len(pts))
    return np.concatenate(verts), np.concatenate(faces)


def test_touching_coplanar_pieces_take_one_decal_box():
    # Separate shells meeting in one plane under the impact (a tiled floor, panels) are one
    # surface for the decal: no "another surface" warning, and a box of real depth (it was 0,
    # and the projection matrix divided by it).
    import warnings

    v, f = _four_pieces()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        proj = make_projector(v, f, np.array([1.0, 1.0, 0.0]), 0.5)
    assert proj.depth > 0.01 * 0.5
    # A coincident back-facing sheet is another surface (an engine paints it too): said, and
    # the box still has a depth.
    v, f = _four_pieces(thin_back=True)
    with pytest.warns(UserWarning, match=r"the decal at \(1, 1, 0\) cannot hold"):
        proj = make_projector(v, f, np.array([1.0, 1.0, 0.0]), 0.5)
    assert proj.depth > 0 and np.isfinite(proj.matrix).all()
