"""The preview's relief and camera (crackbake.bake.preview): normal-mapped lighting as engines
decode it, the up axis from the mesh, the camera aimed at the cracks."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import make_mesh
from maps_factory import plate_uvmesh

from crackbake.bake.preview import preview_camera, render_preview, up_axis
from crackbake.io.mesh import load_mesh
from crackbake.network import Crack, CrackNetwork, mesh_info

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
# (x, y, z) -> (x, -z, y): a Y-up mesh turned into the same object standing Z-up.
TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])


def _lin(c):
    return (np.asarray(c, float) / 255.0) ** 2.2


def _shade(n, key, fill):
    """preview.frag's light for unit normal ``n``."""
    return 0.15 + 0.75 * max(n @ key, 0) + 0.25 * max(n @ fill, 0)


def test_normal_map_shades_through_the_vertex_tangents(gl_ctx):
    _, uvm = plate_uvmesh()
    a = np.array([0.5, 0.5, 0.7]) / np.linalg.norm([0.5, 0.5, 0.7])
    b = np.array([-0.5, -0.5, 0.7]) / np.linalg.norm([0.5, 0.5, 0.7])
    nmap = np.empty((64, 64, 3), np.float32)
    nmap[:, :32], nmap[:, 32:] = a, b  # left half (u < 0.5) tilted to +T+B, right to -T-B
    color = np.full((8, 8, 3), 180, np.uint8)
    view = dict(size=128, view_dir=(0, 0, 1), up=(0, 1, 0), ctx=gl_ctx)

    def halves(tangents):
        pic = render_preview(uvm.vertices, uvm.faces, uvm.uv, uvm.normals, color,
                             normal_map=nmap, tangents=tangents, **view)  # fmt: skip
        g = _lin(pic[40:88, :, 1])
        return g[:, 36:58].mean(), g[:, 70:92].mean()

    key = np.array([0.4, 0.6, 1.0]) / np.linalg.norm([0.4, 0.6, 1.0])  # render_preview's lights
    fill = np.array([-1.0, 0.0, 0.0])
    left, right = halves(uvm.tangents)  # T = +x, B = +y: the map's x, y are world x, y
    assert left / right == pytest.approx(_shade(a, key, fill) / _shade(b, key, fill), rel=0.03)
    flipped = uvm.tangents * [-1, -1, -1, 1]  # T = -x, B = -y: the same map reads mirrored
    left2, right2 = halves(flipped)
    mirrored = _shade(-a * [1, 1, -1], key, fill) / _shade(-b * [1, 1, -1], key, fill)
    assert left2 / right2 == pytest.approx(mirrored, rel=0.03)
    flat = render_preview(uvm.vertices, uvm.faces, uvm.uv, uvm.normals, color, **view)
    g = _lin(flat[40:88, :, 1])
    assert g[:, 36:58].mean() == pytest.approx(g[:, 70:92].mean(), rel=0.01)  # no map: flat


def test_up_axis_from_what_the_mesh_stands_on():
    spot = load_mesh(SPOT)
    assert tuple(up_axis(spot)) == (0, 1, 0)
    z_up = replace(spot, vertices=spot.vertices @ TO_Z_UP.T, source="spot_z.ply")
    assert tuple(up_axis(z_up)) == (0, 0, 1)
    assert tuple(up_axis(replace(z_up, source="spot.glb"))) == (0, 1, 0)  # glTF is Y-up


def _figure():
    """A Y-up figure standing on two small feet: a 0.4 x 2 x 0.1 slab body (its flat back, 0.8
    square units, faces -Z) on two 0.1 x 0.1 soles 0.3 apart."""
    import trimesh

    body = trimesh.creation.box((0.4, 2.0, 0.1))
    body.apply_translation((0, 1.1, 0))
    feet = [trimesh.creation.box((0.1, 0.1, 0.1)) for _ in range(2)]
    feet[0].apply_translation((-0.15, 0.05, 0))
    feet[1].apply_translation((0.15, 0.05, 0))
    m = trimesh.util.concatenate([body, *feet])
    return make_mesh(m.vertices, m.faces, source="figure.obj")


def _statue():
    """A round Y-up statue (a capsule of radius 0.2 along Y) on a 0.8 x 0.05 x 0.8 pedestal."""
    import trimesh

    body = trimesh.creation.capsule(height=1.6, radius=0.2, count=[16, 16])
    body.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    body.apply_translation((0, 1.15, 0))
    base = trimesh.creation.box((0.8, 0.05, 0.8))
    base.apply_translation((0, 0.025, 0))
    m = trimesh.util.concatenate([body, base])
    return make_mesh(m.vertices, m.faces, source="statue.obj")


def test_a_y_up_figure_with_a_flat_back_stays_upright():
    from crackbake.bake.preview import _frame, up_vector

    fig = _figure()
    # Its back's hull facet (0.8) dwarfs the feet's (0.04), but it stands on its feet (its
    # centre over them) as it would on its back: no strong evidence, so +Y.  (The old rule,
    # Z's support 1.5x Y's, laid it on its back.)
    assert tuple(up_axis(fig)) == (0, 1, 0)
    assert tuple(up_axis(replace(fig, vertices=fig.vertices @ TO_Z_UP.T))) == (0, 1, 0)
    # A statue on a pedestal, exported Z-up: it stands only on -Z (0.64 against 0.04).
    statue = _statue()
    assert tuple(up_axis(statue)) == (0, 1, 0)
    z_up = replace(statue, vertices=statue.vertices @ TO_Z_UP.T, source="statue_z.ply")
    assert tuple(up_axis(z_up)) == (0, 0, 1)
    # --up overrides the guess; every axis gets a rotation taking +Y onto it.
    assert tuple(up_vector("-x", fig)) == (-1, 0, 0)
    for name in ("x", "y", "z", "-x", "-y", "-z"):
        r = _frame(up_vector(name, fig))
        np.testing.assert_allclose(r @ [0, 1, 0], up_vector(name, fig), atol=1e-12)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)


def test_up_option_turns_the_preview_camera():
    fig = _figure()
    net = CrackNetwork(cracks=[], mesh={})
    assert preview_camera(fig, net)[1] == (0, 1, 0)
    assert preview_camera(fig, net, "z")[1] == (0, 0, 1)
    assert preview_camera(fig, net, "-y")[0][1] < 0  # the view is tilted towards -Y's "up"
    from crackbake.errors import CrackbakeError
    from crackbake.params import RunParams

    with pytest.raises(CrackbakeError, match="--up 'w' is unknown; use one of x, y, z"):
        RunParams(mesh=SPOT, shrink=1.0, up="w").validate()


def test_z_up_mesh_renders_the_same_upright_picture(gl_ctx):
    spot = load_mesh(SPOT)
    z_up = replace(spot, vertices=spot.vertices @ TO_Z_UP.T, normals=spot.normals @ TO_Z_UP.T)
    pics = []
    for m in (spot, z_up):
        none = CrackNetwork(cracks=[], mesh=mesh_info(m))
        d, up, target, dist = preview_camera(m, none)
        pics.append(render_preview(m.vertices, m.faces, m.uv, m.normals,
                                   np.full((8, 8, 3), 200, np.uint8), size=128, view_dir=d,
                                   up=up, target=target, distance=dist, ctx=gl_ctx))  # fmt: skip
    diff = np.abs(pics[0].astype(int) - pics[1].astype(int))
    assert diff.mean() < 1.0 and (diff > 8).mean() < 0.005
    rows = np.nonzero((pics[0].astype(int).sum(2) > 3 * 60).any(1))[0]
    cols = np.nonzero((pics[0].astype(int).sum(2) > 3 * 60).any(0))[0]
    assert rows.size and cols.size  # the cow is in the picture


def test_camera_aims_at_the_cracks():
    spot = load_mesh(SPOT)
    f = int(np.argmax(spot.vertices[spot.faces].mean(1)[:, 0]))  # a face on the +x flank
    p = spot.vertices[spot.faces[f]].mean(0)
    crack = Crack(id=0, points=[p, p + [0, 0.01, 0.01]], faces=[f, f], time=[0, 1],
                  width=[0.01, 0.01], depth=[0.0, 0.0])  # fmt: skip
    d, up, target, dist = preview_camera(spot, CrackNetwork(cracks=[crack],
                                                            mesh=mesh_info(spot)))  # fmt: skip
    assert np.linalg.norm(np.asarray(target) - (p + [0, 0.005, 0.005])) < 1e-9
    assert d[0] > 0.5 and tuple(up) == (0, 1, 0)
    diag = float(np.linalg.norm(spot.vertices.max(0) - spot.vertices.min(0)))
    whole = float(np.linalg.norm(spot.vertices - target, axis=1).max()) / np.sin(np.radians(17.5))
    assert 0.2 * diag / np.sin(np.radians(17.5)) <= dist + 1e-9 and dist < whole
