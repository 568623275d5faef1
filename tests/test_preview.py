"""The preview (crackbake.bake.preview): rendered the right way round, from a view of the cracks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from conftest import plate_mesh

from crackbake.bake import preview
from crackbake.bake.preview import hidden_side, preview_direction, render_preview
from crackbake.network import Crack, CrackNetwork, mesh_info


def test_dark_texture_corner_shows_in_the_matching_corner_of_the_picture(gl_ctx):
    # A square plate facing +z, UVs = xy; the camera looks from +z with y up.
    m = plate_mesh(1)
    color = np.full((64, 64, 3), 220, np.uint8)
    color[:16, :16] = 0  # image row 0 = v = 1: the top-left of the texture is UV (0, 1)
    pic = render_preview(
        m.vertices, m.faces, m.uv, m.normals, color, size=256, view_dir=(0, 0, 1), up=(0, 1, 0),
        ctx=gl_ctx,
    )  # fmt: skip
    gray = pic.mean(axis=2)
    quarter = 256 // 4
    # The plate fills most of the frame; its top-left (x = 0, y = 1) is the picture's top-left.
    top_left = gray[quarter : quarter + 20, quarter : quarter + 20].mean()
    bottom_right = gray[-quarter - 20 : -quarter, -quarter - 20 : -quarter].mean()
    assert top_left < 40 and bottom_right > 120


def test_standalone_call_makes_its_own_context():
    m = plate_mesh(1)
    pic = render_preview(m.vertices, m.faces, m.uv, m.normals, np.zeros((8, 8, 3), np.uint8),
                         size=32)  # fmt: skip
    assert pic.shape == (32, 32, 3) and pic.dtype == np.uint8


def _two_sided_box():
    """Plate facing +z (faces 0, 1) and the same plate flipped to face -z (faces 2, 3)."""
    m = plate_mesh(1)
    flipped = m.faces[:, ::-1] + len(m.vertices)
    return replace(
        m,
        vertices=np.vstack([m.vertices, m.vertices]),
        faces=np.vstack([m.faces, flipped]),
        uv=np.vstack([m.uv, m.uv]),
        normals=np.vstack([m.normals, -m.normals]),
    )


def test_preview_direction_faces_the_cracks():
    m = _two_sided_box()
    crack = Crack(id=0, points=[[0.6, 0.1, 0.0], [0.9, 0.2, 0.0]], faces=[2, 2], time=[0, 1],
                  width=[0.01, 0.01], depth=[0.0, 0.0])  # fmt: skip
    d = preview_direction(m, CrackNetwork(cracks=[crack], mesh=mesh_info(m)), up=(0, 1, 0))
    assert np.isclose(np.linalg.norm(d), 1.0) and d[2] < 0  # the cracked side faces -z
    crack.faces = np.array([0, 0])
    assert preview_direction(m, CrackNetwork(cracks=[crack], mesh=mesh_info(m)), (0, 1, 0))[2] > 0


def _sphere():
    import trimesh

    s = trimesh.creation.uv_sphere(radius=1.0, count=[48, 48])
    v = np.asarray(s.vertices)
    uv = 0.5 + 0.5 * v[:, :2]
    return v, np.asarray(s.faces, np.int64), uv, v / np.linalg.norm(v, axis=1, keepdims=True)


def test_hidden_side_only_for_a_closed_surface_seen_from_outside():
    v, f, _, _ = _sphere()
    eye = np.array([0.0, 0.0, 4.0])
    assert hidden_side(v, f, eye, 0.1) == "back"
    assert hidden_side(v, f[:, ::-1], eye, 0.1) == "front"  # wound clockwise outside
    assert hidden_side(v, f[2:], eye, 0.1) is None  # open: its inside shows through
    assert hidden_side(v, f, np.array([0.0, 0.1, 0.2]), 0.01) is None  # the eye inside
    assert hidden_side(v, f, eye, 1.6) is None  # the near plane would cut it


def test_closed_surface_worked_out_ahead_gives_the_same_side():
    # The pipeline works out closed_surface on a thread while it solves.
    from crackbake.bake.preview import closed_surface

    v, f, _, _ = _sphere()
    eye = np.array([0.0, 0.0, 4.0])
    assert closed_surface(v, f) and closed_surface(v, f[:, ::-1])
    assert not closed_surface(v, f[2:])
    for faces in (f, f[:, ::-1], f[2:]):
        for at, near in ((eye, 0.1), (np.array([0.0, 0.1, 0.2]), 0.01), (eye, 1.6)):
            assert (hidden_side(v, faces, at, near, closed_surface(v, faces))
                    == hidden_side(v, faces, at, near))
    assert hidden_side(v, f[2:], eye, 0.1, closed=True) == "back"  # it takes the answer given


def test_culled_preview_equals_the_full_draw_on_a_closed_surface(gl_ctx, monkeypatch):
    # The faces turned away are hidden behind the others: the pictures agree but for a few
    # silhouette samples where a face turned away won the depth test.
    v, f, uv, n = _sphere()
    rng = np.random.default_rng(0)
    color = (rng.random((64, 64, 3)) * 255).astype(np.uint8)
    args = (v, f, uv, n, color)
    monkeypatch.setattr(preview, "CULL_FACES", 10**9)
    full = render_preview(*args, size=256, ctx=gl_ctx)
    monkeypatch.setattr(preview, "CULL_FACES", 0)
    culled = render_preview(*args, size=256, ctx=gl_ctx)
    assert (full != culled).any(axis=2).sum() <= 0.001 * 256 * 256
    # Turned inside out, the side wound towards the camera is culled and nothing changes.
    turned = (v, f[:, ::-1], uv, -n, color)
    monkeypatch.setattr(preview, "CULL_FACES", 0)
    assert (render_preview(*turned, size=256, ctx=gl_ctx) != full).any(axis=2).sum() \
        <= 0.001 * 256 * 256


def _llvmpipe(ctx) -> bool:
    return "llvmpipe" in ctx.info.get("GL_RENDERER", "")


def test_mip_levels_are_llvmpipes_own(gl_ctx):
    """Levels made on the CPU equal glGenerateMipmap's on llvmpipe, every level, every byte
    (other drivers round their own way: the preview there may differ by a level's rounding)."""
    import pytest

    if not _llvmpipe(gl_ctx):
        pytest.skip("the levels are llvmpipe's rounding")
    img = np.random.default_rng(3).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    tex = gl_ctx.texture((64, 64), 3, img.tobytes())
    tex.build_mipmaps()
    levels = preview.mip_levels(img)
    assert [lv.shape[0] for lv in levels] == [32, 16, 8, 4, 2, 1]
    for k, level in enumerate(levels, 1):
        size = 64 >> k
        gl = np.frombuffer(tex.read(level=k), np.uint8).reshape(size, size, 3)
        np.testing.assert_array_equal(level, gl)
    tex.release()
    assert preview.mip_levels(img[:48, :48]) is None  # not a power of two: GL mip-maps it


def test_preview_with_levels_made_beforehand_is_the_same_picture(gl_ctx):
    import pytest

    if not _llvmpipe(gl_ctx):
        pytest.skip("the levels are llvmpipe's rounding")
    m = plate_mesh(4)
    rng = np.random.default_rng(4)
    color = rng.integers(0, 256, (256, 256, 3), dtype=np.uint8)
    normal = rng.integers(100, 156, (256, 256, 3), dtype=np.uint8)
    normal[..., 2] = 255
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(m.vertices), 1))
    args = (m.vertices, m.faces, m.uv, m.normals, color)
    kw = dict(size=128, view_dir=(0.3, 0.2, 1.0), normal_map=normal, tangents=tangents,
              ctx=gl_ctx)  # fmt: skip
    by_gl = render_preview(*args, **kw)
    levels = (preview.mip_levels(color), preview.mip_levels(normal))
    np.testing.assert_array_equal(render_preview(*args, levels=levels, **kw), by_gl)


def test_cracks_on_an_underside_are_seen_from_below_and_others_from_above():
    # A box: cracks on its bottom face (normal -y, up +y) face away from every view from above,
    # which showed them edge-on at the picture's rim (an impact under Suzanne's chin); they
    # choose a view from below, tilted (up keeps its direction in the picture).  Cracks on a
    # side face keep a view from above, as before the views from below came in.
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 1.0, 2.0))
    m = replace(plate_mesh(2), vertices=np.asarray(box.vertices, float),
                faces=np.asarray(box.faces, np.int64), uv=None)
    normals = np.asarray(box.face_normals)
    bottom, side = (int(np.flatnonzero(normals[:, 1] < -0.9)[0]),
                    int(np.flatnonzero(normals[:, 0] > 0.9)[0]))

    def direction(face, point):
        crack = Crack(id=0, points=[point, np.add(point, [0.2, 0.0, 0.2])], faces=[face, face],
                      time=[0, 1], width=[0.01, 0.01], depth=[0.0, 0.0])
        return np.asarray(preview_direction(m, CrackNetwork(cracks=[crack], mesh=mesh_info(m)),
                                            up=(0, 1, 0)))

    below = direction(bottom, [-0.1, -0.5, -0.1])
    assert below[1] < -0.5 and np.hypot(below[0], below[2]) > 0.3
    above = direction(side, [1.0, 0.0, -0.1])
    assert above[1] > 0 and above[0] > 0.5


def test_the_mesh_only_part_worked_out_ahead_gives_the_same_camera(tmp_path, monkeypatch):
    # A run works out the up axis, the cross products and the views' area scores on a thread
    # while it solves (preview_ahead); the camera is the one worked out at once, up included.
    from crackbake.bake.preview import CULL_FACES, preview_ahead, preview_camera

    monkeypatch.setenv("CRACKBAKE_CACHE_DIR", str(tmp_path))
    m = _two_sided_box()
    for faces, side in (([2, 2], -1), ([0, 0], 1)):
        crack = Crack(id=0, points=[[0.6, 0.1, 0.0], [0.9, 0.2, 0.0]], faces=faces, time=[0, 1],
                      width=[0.01, 0.01], depth=[0.0, 0.0])  # fmt: skip
        network = CrackNetwork(cracks=[crack], mesh=mesh_info(m))
        ahead = preview_ahead(m, m.vertices, m.faces, None, cache=True)
        assert ahead.closed is None and len(m.faces) < CULL_FACES  # culling only from there
        assert ahead.cross.shape == (len(m.faces), 3)
        now = preview_camera(m, network)
        assert _same(preview_camera(m, network, ahead=ahead), now)
        assert np.sign(now[0][2]) == side  # the cracked side is the one seen
        z_up = preview_ahead(m, m.vertices, m.faces, "z", cache=True)
        assert np.array_equal(z_up.up, [0.0, 0.0, 1.0])
        assert _same(preview_camera(m, network, ahead=z_up), preview_camera(m, network, "z"))


def _same(a: tuple, b: tuple) -> bool:
    """Two preview cameras (view, up, target, distance), bit for bit."""
    return all(np.array_equal(np.asarray(x, float), np.asarray(y, float))
               for x, y in zip(a, b, strict=True))
