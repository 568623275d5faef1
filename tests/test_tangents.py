"""MikkTSpace tangents (crackbake.bake.tangents): analytic frames, MikkTSpace's rules, the vertex
split, and (with Blender's bpy) agreement with Blender's own MikkTSpace."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crackbake.bake.tangents import corner_tangents, with_tangents
from crackbake.bake.uv.uvmesh import UVMesh
from crackbake.errors import CrackbakeError
from crackbake.exchange.glb import write_glb
from crackbake.geometry import vertex_normals
from crackbake.io.mesh import load_mesh
from tests.blender_runner import run_blender

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


def tilted_plane(theta: float, mirror: bool = False, n: int = 4):
    """A plane through the origin spanned by orthonormal E1, E2 (tilted off every axis) and its
    UV island: (s, t) rotated by ``theta``, scaled, optionally mirrored in u."""
    e1 = np.array([2.0, 1.0, 2.0]) / 3.0
    e2 = np.cross([0.0, 0.0, 1.0], e1)
    e2 /= np.linalg.norm(e2)
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    st = np.column_stack([s.ravel(), t.ravel()])
    vertices = st[:, :1] * e1 + st[:, 1:] * e2
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    uv = 0.3 * st @ rot.T + 0.4
    if mirror:
        uv[:, 0] = 1.0 - uv[:, 0]
    normals = np.tile(np.cross(e1, e2), (len(vertices), 1))
    return vertices, faces, uv, normals, e1, e2


def uvmesh(vertices, faces, uv, normals) -> UVMesh:
    return UVMesh(
        vertices=np.asarray(vertices, dtype=np.float64), faces=np.asarray(faces, dtype=np.int64),
        uv=np.asarray(uv, dtype=np.float64), normals=np.asarray(normals, dtype=np.float64),
        vertex_map=np.arange(len(vertices)), method="kept", overlap_fraction=0.0, padding_px=0,
    )


def mirrored_dome(n: int = 16) -> UVMesh:
    """A curved sheet whose right half maps mirrored onto the left half's UVs: the middle
    column of vertices is shared (one welded mirror seam), plus one zero-UV-area triangle, one
    zero-area (collapsed) triangle and an isolated all-zero-UV triangle."""
    rng = np.random.default_rng(3)
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    inner = (s > 0) & (s < 1) & (t > 0) & (t < 1) & (np.abs(s - 0.5) > 1e-9)
    s = s + inner * rng.uniform(-0.25, 0.25, s.shape) / n
    t = t + inner * rng.uniform(-0.25, 0.25, t.shape) / n
    z = 0.3 * np.sin(np.pi * s) * np.sin(np.pi * t) + 0.05 * np.cos(5 * t)
    vertices = np.stack([s, t, z], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    uv = np.column_stack([0.5 - np.abs(s.ravel() - 0.5), t.ravel()]) * [1.6, 0.9] + 0.05
    uv[faces[40, 2]] = uv[faces[40, 1]]  # zero UV area (exactly, in any precision)
    # A collapsed triangle: a copy of vertex faces[7, 0] (same values, so welded to it).
    vertices = np.vstack([vertices, vertices[faces[7, 0]], [[2.0, 2.0, 0.0], [2.1, 2.0, 0.0],
                                                          [2.0, 2.1, 0.0]]])
    uv = np.vstack([uv, uv[faces[7, 0]], [[0.9, 0.9]] * 3])
    k = len(vertices)
    faces = np.vstack([faces, [[faces[7, 0], k - 4, faces[7, 1]], [k - 3, k - 2, k - 1]]])
    normals = vertex_normals(vertices, faces)
    normals[k - 4] = normals[faces[7, 0]]
    return uvmesh(vertices, faces, uv, normals)


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("theta", [0.0, 0.7, 2.5, -1.9])
def test_rotated_island_tangent_is_world_u(theta):
    v, f, uv, n, e1, e2 = tilted_plane(theta)
    tan = corner_tangents(v, f, uv, n)
    # u = 0.3 (cos s - sin t) + c, so u grows along cos E1 - sin E2 and v along sin E1 + cos E2.
    want_t = np.cos(theta) * e1 - np.sin(theta) * e2
    want_b = np.sin(theta) * e1 + np.cos(theta) * e2
    assert np.allclose(tan[..., :3], want_t, atol=1e-6)
    assert (tan[..., 3] == 1.0).all()
    b = tan[..., 3:] * np.cross(n[f], tan[..., :3])
    assert np.allclose(b, want_b, atol=1e-6)


def test_mirrored_island_has_negative_sign():
    theta = 0.7
    v, f, uv, n, e1, e2 = tilted_plane(theta, mirror=True)
    tan = corner_tangents(v, f, uv, n)
    assert (tan[..., 3] == -1.0).all()
    assert np.allclose(tan[..., :3], -(np.cos(theta) * e1 - np.sin(theta) * e2), atol=1e-6)
    b = tan[..., 3:] * np.cross(n[f], tan[..., :3])  # still towards +v
    assert np.allclose(b, np.sin(theta) * e1 + np.cos(theta) * e2, atol=1e-6)


def test_corner_angle_weighting():
    # Two flat triangles sharing the edge from the origin to (0, 1, 0), welded (same UVs):
    # A = (0,0) (1,0) (0,1) maps u along +x; B = (0,0) (0,1) (-1,1) has UVs giving
    # dP/du = (10, 10, 0), so its tangent is (1, 1, 0)/sqrt 2.  At the origin A's corner angle is
    # 90 deg and B's 45 deg, at (0, 1) the other way round: each shared corner gets the
    # angle-weighted mean of the two; the unshared corners keep their own triangle's tangent.
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.5, 0.5], [0.6, 0.5], [0.5, 0.6], [0.4, 0.7]])
    n = np.tile([0.0, 0.0, 1.0], (4, 1))
    tan = corner_tangents(v, f, uv, n)
    t_a, t_b = np.array([1.0, 0.0, 0.0]), unit(np.array([1.0, 1.0, 0.0]))
    at_origin = unit(np.pi / 2 * t_a + np.pi / 4 * t_b)
    at_top = unit(np.pi / 4 * t_a + np.pi / 2 * t_b)
    assert np.allclose(tan[0, 0, :3], at_origin, atol=1e-9)
    assert np.array_equal(tan[0, 0], tan[1, 0])
    assert np.allclose(tan[0, 2, :3], at_top, atol=1e-9)
    assert np.array_equal(tan[0, 2], tan[1, 1])
    assert np.allclose(tan[0, 1, :3], t_a, atol=1e-9)
    assert np.allclose(tan[1, 2, :3], t_b, atol=1e-9)
    assert (tan[..., 3] == 1).all()
    # Different UVs at (0, 1) break the weld: no shared edge, so no averaging at all.
    uv2 = np.vstack([uv, [0.5, 0.6001]])
    tan2 = corner_tangents(np.vstack([v, v[2]]), [[0, 1, 2], [0, 4, 3]], uv2,
                           np.vstack([n, n[2]]))
    assert np.allclose(tan2[0, :, :3], t_a, atol=1e-9)


def test_welding_is_by_value_not_index():
    mesh = mirrored_dome()
    split = np.arange(mesh.faces.size)
    flat = [a[mesh.faces.reshape(-1)] for a in (mesh.vertices, mesh.uv, mesh.normals)]
    welded = corner_tangents(mesh.vertices, mesh.faces, mesh.uv, mesh.normals)
    unwelded = corner_tangents(flat[0], split.reshape(-1, 3), flat[1], flat[2])
    assert np.array_equal(welded, unwelded)


def test_degenerate_triangles_get_valid_frames():
    mesh = mirrored_dome()
    tan = corner_tangents(mesh.vertices, mesh.faces, mesh.uv, mesh.normals)
    n = mesh.normals[mesh.faces]
    assert np.isfinite(tan).all()
    assert np.allclose(np.linalg.norm(tan[..., :3], axis=-1), 1.0)
    assert np.abs(np.einsum("fck,fck->fc", tan[..., :3], n)).max() < 1e-6
    assert set(np.unique(tan[..., 3])) <= {-1.0, 1.0}
    # The zero-UV-area face (40) takes its corners' frames from the neighbouring groups: each
    # equals the frame of another face's corner at the same vertex.
    for c in range(3):
        others = np.argwhere(mesh.faces == mesh.faces[40, c])
        others = others[others[:, 0] != 40]
        assert any(np.array_equal(tan[40, c], tan[g, k]) for g, k in others)
    # The collapsed face copies the frames of the welded corners of a kept face.
    collapsed = len(mesh.faces) - 2
    assert np.array_equal(tan[collapsed, 0], tan[7, 0])
    assert np.array_equal(tan[collapsed, 1], tan[7, 0])  # the copy welds to vertex faces[7,0]
    assert np.array_equal(tan[collapsed, 2], tan[7, 1])
    # The isolated all-zero-UV face: MikkTSpace's default +X (here in the plane), w = -1.
    assert np.allclose(tan[-1], [[1.0, 0.0, 0.0, -1.0]] * 3)


@pytest.mark.parametrize("a_first", [True, False])
def test_zero_uv_face_takes_orientation_of_first_group(a_first):
    # A fan around the origin (flat, normal +z), UVs mirrored at x = 0 (u = 0.5 + 0.3 |x|):
    # A on the left (mirrored, T = -x, w = -1), B on the right (T = +x, w = +1), and between
    # them g = (0, P2, P1) whose P1, P2 are mirror images, so g has zero UV area.  MikkTSpace
    # gives g the orientation of the first group reaching it (groups start in face order):
    # g then shares that side's frames, and its corner on the other side, which no group of
    # its orientation reaches, gets the default frame (1, 0, 0), w = -1.
    v = np.array([[0, 0, 0], [-1, -0.2, 0], [-0.5, 1, 0], [0.5, 1, 0], [1, -0.2, 0]], float)
    uv = np.column_stack([0.5 + 0.3 * np.abs(v[:, 0]), 0.3 + 0.3 * v[:, 1]])
    a, b, g = [0, 2, 1], [0, 4, 3], [0, 3, 2]
    f = np.array([a, b, g] if a_first else [b, a, g])
    tan = corner_tangents(v, f, uv, np.tile([0.0, 0.0, 1.0], (5, 1)))
    default = [1.0, 0.0, 0.0, -1.0]
    if a_first:  # g's corners at 0, P2 (right), P1 (left)
        want = [[-1.0, 0, 0, -1], default, [-1.0, 0, 0, -1]]
    else:
        want = [[1.0, 0, 0, 1], [1.0, 0, 0, 1], default]
    assert np.allclose(tan[2], want, atol=1e-6)  # float32 inputs


def test_default_frame_is_orthogonal_to_tilted_normal():
    v = np.array([[0, 0, 0], [1, 0, 1], [0, 1, 0]], float)
    n = np.tile(unit(np.cross(v[1], v[2])), (3, 1))
    tan = corner_tangents(v, [[0, 1, 2]], np.full((3, 2), 0.5), n)
    # n = (-1, 0, 1)/sqrt 2; +X minus its normal part is (1, 0, 1)/2.
    assert np.allclose(tan[0, :, :3], unit(np.array([1.0, 0.0, 1.0])), atol=1e-6)
    assert (tan[0, :, 3] == -1).all()


def test_with_tangents_splits_the_mirror_seam_and_keeps_geometry():
    mesh = mirrored_dome()
    out = with_tangents(mesh)
    n_seam = 17  # the shared middle column of the 17 x 17 grid
    assert len(out.vertices) == len(mesh.vertices) + n_seam
    assert out.faces.shape == mesh.faces.shape
    src = out.vertex_map
    assert np.array_equal(out.vertices, mesh.vertices[src])
    assert np.array_equal(out.uv, mesh.uv[src])
    assert np.array_equal(out.normals, mesh.normals[src])
    assert np.array_equal(src[out.faces], mesh.faces)  # same corners, same order
    assert np.array_equal(out.vertices[: len(mesh.vertices)], mesh.vertices)
    corner = corner_tangents(mesh.vertices, mesh.faces, mesh.uv, mesh.normals)
    assert np.array_equal(out.tangents[out.faces], corner)
    assert out.tangents.shape == (len(out.vertices), 4)
    # Idempotent: the split mesh needs no further split.
    again = with_tangents(out)
    assert np.array_equal(again.faces, out.faces)
    assert np.array_equal(again.tangents, out.tangents)


def test_with_tangents_keeps_other_fields():
    v, f, uv, n, *_ = tilted_plane(0.3)
    mesh = uvmesh(np.vstack([v, [[9.0, 9.0, 9.0]]]), f, np.vstack([uv, [[0, 0]]]),
                  np.vstack([n, [[1.0, 0.0, 0.0]]]))
    out = with_tangents(mesh)
    assert len(out.vertices) == len(mesh.vertices)  # nothing to split
    assert out.method == "kept" and out.padding_px == 0
    # The unused vertex gets a frame orthogonal to its normal (+X normal: +Y).
    assert np.allclose(out.tangents[-1], [0.0, 1.0, 0.0, -1.0])


def test_empty_and_all_degenerate_meshes():
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    assert corner_tangents(np.zeros((3, 3)), np.zeros((0, 3), int), np.zeros((3, 2)),
                           n).shape == (0, 3, 4)
    # One point-like triangle: no face to take a frame from, so the default for every corner.
    tan = corner_tangents(np.zeros((3, 3)), [[0, 1, 2]], np.zeros((3, 2)), n)
    assert np.array_equal(tan, np.tile([1.0, 0.0, 0.0, -1.0], (1, 3, 1)))
    out = with_tangents(uvmesh(np.zeros((2, 3)), np.zeros((0, 3), int), np.zeros((2, 2)), n[:2]))
    assert out.tangents.shape == (2, 4) and len(out.vertices) == 2


@pytest.mark.parametrize("bad", ["faces", "uv", "nan"])
def test_bad_inputs_raise(bad):
    v, f, uv, n, *_ = tilted_plane(0.0)
    if bad == "faces":
        f = f[:, :2]
    elif bad == "uv":
        uv = uv[:-1]
    else:
        v = v.copy()
        v[0, 0] = np.nan
    with pytest.raises(CrackbakeError, match="tangents"):
        corner_tangents(v, f, uv, n)


def blender_compare(tmp_path: Path, mesh: UVMesh) -> dict:
    """Write ``mesh`` with our tangents as a GLB and compare with Blender's MikkTSpace.

    Also runs :func:`corner_tangents` on exactly the corners Blender's MikkTSpace saw (its
    imported positions, corner normals and UVs, one vertex per corner so welding is by value
    alone) and adds ``same_input``: the max angle (deg) and sign agreement against Blender.
    """
    out = with_tangents(mesh)
    glb, expected = tmp_path / "mesh.glb", tmp_path / "expected.npz"
    write_glb(glb, out.vertices, out.faces, out.uv, out.normals,
              np.full((4, 4, 3), 128, np.uint8), tangents=out.tangents)
    np.savez(expected, positions=out.vertices[out.faces], normals=out.normals[out.faces],
             tangents=out.tangents[out.faces])
    res = run_blender("tangents.py", glb, expected, tmp_path / "blender.npz")
    b = np.load(tmp_path / "blender.npz")
    corners = np.arange(b["positions"].size // 3).reshape(-1, 3)
    ours = corner_tangents(b["positions"].reshape(-1, 3), corners, b["uv"].reshape(-1, 2),
                           b["normals"].reshape(-1, 3))
    # Blender leaves MikkTSpace's default +X as it is; ours is made orthogonal to the normal,
    # so compare with Blender's tangents made orthogonal to its normals (a no-op elsewhere).
    nb = unit(b["normals"].reshape(-1, 3))
    theirs = b["tangents"].reshape(-1, 3)
    theirs = theirs - nb * np.einsum("ij,ij->i", nb, theirs)[:, None]
    cos = np.einsum("ij,ij->i", ours[..., :3].reshape(-1, 3), unit(theirs))
    res["same_input"] = {
        "max_angle_deg": float(np.degrees(np.arccos(np.clip(cos, -1, 1))).max()),
        "sign_agreement": float(np.mean(ours[..., 3].reshape(-1) == b["signs"].reshape(-1))),
    }
    return res


@pytest.mark.reference
def test_blender_agrees_on_spot(tmp_path):
    m = load_mesh(SPOT)
    res = blender_compare(tmp_path, uvmesh(m.vertices, m.faces, m.uv, m.normals))
    assert res["faces_matched"] == res["faces"] == len(m.faces)
    assert res["explained_faces"] == []
    assert res["all"]["sign_agreement"] == 1.0
    assert res["all"]["max_angle_deg"] < 0.5, res
    # What is left is Blender's custom-normal storage (about 0.1 deg): on Blender's own input
    # the two implementations agree to float32 precision.
    assert res["same_input"]["sign_agreement"] == 1.0
    assert res["same_input"]["max_angle_deg"] < 0.01, res


@pytest.mark.reference
@pytest.mark.parametrize("seed", [0, 1])
def test_blender_agrees_on_zero_uv_faces_at_a_mirror_seam(tmp_path, seed):
    # Faces in random order and zero-UV-area faces along a welded mirror seam: MikkTSpace's
    # one order dependence (which group such a face joins) decides the frames here.
    rng = np.random.default_rng(seed)
    n = 24
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    vertices = np.stack([s, t, 0.2 * np.sin(3 * s) * np.cos(4 * t)], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    faces = faces[rng.permutation(len(faces))]
    uv = np.column_stack([np.abs(s.ravel() - 0.5) + 0.1, t.ravel() * 0.8])
    at_seam = np.flatnonzero(np.isclose(vertices[faces, 0], 0.5).any(axis=1))
    for k in rng.choice(at_seam, 12, replace=False):
        corner = rng.integers(3)
        uv[faces[k, corner]] = uv[faces[k, (corner + 1) % 3]]
    res = blender_compare(tmp_path, uvmesh(vertices, faces, uv, vertex_normals(vertices, faces)))
    assert res["faces_matched"] == res["faces"] == len(faces)
    # Blender's importer changes the normals at some zero-UV-area corners (explained); the
    # rest agree, and on Blender's own input everything does.
    assert res["unexplained"]["sign_agreement"] == 1.0
    assert res["unexplained"]["max_angle_deg"] < 0.5, res
    assert res["same_input"]["sign_agreement"] == 1.0
    assert res["same_input"]["max_angle_deg"] < 0.01, res


@pytest.mark.reference
def test_blender_agrees_on_mirrored_uvs(tmp_path):
    mesh = mirrored_dome()
    res = blender_compare(tmp_path, mesh)
    assert res["faces_matched"] == res["faces"] == len(mesh.faces)
    # Blender's custom normals cannot hold the written normals on the collapsed (zero-area)
    # face, so its corners do not weld to the kept face's there and get the default frame;
    # every other corner (mirror seam, zero-UV-area face included) matches.
    assert res["explained_faces"] == [len(mesh.faces) - 2]
    assert res["unexplained"]["corners"] == 3 * len(mesh.faces) - 3
    assert res["unexplained"]["sign_agreement"] == 1.0
    assert res["unexplained"]["max_angle_deg"] < 0.5, res
    # Given Blender's input, the collapsed face gets Blender's frames too.
    assert res["same_input"]["sign_agreement"] == 1.0
    assert res["same_input"]["max_angle_deg"] < 0.01, res
