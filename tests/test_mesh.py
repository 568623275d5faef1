"""Mesh loading: every format through real files, UV seams kept, clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.geometry import weld_by_position, welded_vertex_normals
from crackbake.io.mesh import load_mesh

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"

CUBE_OBJ = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0.0 0.0
vt 0.25 0.0
vt 0.25 0.25
vt 0.0 0.25
vt 0.5 0.5
vt 0.75 0.5
vt 0.75 0.75
vt 0.5 0.75
f 1/1 4/4 3/3 2/2
f 5/5 6/6 7/7 8/8
f 1/1 2/2 6/6 5/5
f 2/2 3/3 7/7 6/6
f 3/3 4/4 8/8 7/7
f 4/4 1/1 5/5 8/8
"""


def test_example_spot_keeps_uv_seams():
    m = load_mesh(EXAMPLE)
    assert len(m.faces) == 5856
    assert m.uv is not None and m.uv.shape == (len(m.vertices), 2)
    wv, wf, inverse = weld_by_position(m.vertices, m.faces)
    # spot has UV seams: welding by position merges the seam copies.
    assert len(wv) < len(m.vertices)
    assert np.array_equal(wv[inverse], m.vertices)
    assert np.array_equal(wv[wf], m.vertices[m.faces])
    d = m.describe()
    assert d["faces"] == 5856 and d["has_uv"] is True
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0)


def test_quads_are_triangulated_and_uvs_follow_corners(tmp_path):
    p = tmp_path / "cube.obj"
    p.write_text(CUBE_OBJ)
    m = load_mesh(p)
    assert len(m.faces) == 12
    # Each triangle's corner UVs are the ones the OBJ gave that position (the file's pairing
    # of v and vt), so no seam was dropped.
    text_v = np.array([[float(x) for x in ln.split()[1:]] for ln in CUBE_OBJ.splitlines()
                       if ln.startswith("v ")])
    text_vt = np.array([[float(x) for x in ln.split()[1:]] for ln in CUBE_OBJ.splitlines()
                        if ln.startswith("vt ")])
    pairs = {tuple(text_v[i]): set() for i in range(8)}
    for ln in CUBE_OBJ.splitlines():
        if ln.startswith("f "):
            for c in ln.split()[1:]:
                vi, ti = (int(x) - 1 for x in c.split("/"))
                pairs[tuple(text_v[vi])].add(tuple(text_vt[ti]))
    for pos, uv in zip(m.vertices, m.uv, strict=True):
        assert tuple(np.round(uv, 6)) in {tuple(np.round(t, 6)) for t in pairs[tuple(pos)]}


@pytest.mark.parametrize("ext", ["ply", "stl", "off", "glb"])
def test_formats_load(tmp_path, ext):
    src = trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.2, sections=24)
    p = tmp_path / f"ring.{ext}"
    src.export(p)
    m = load_mesh(p)
    assert m.faces.shape[1] == 3
    assert len(m.faces) == len(src.faces)
    assert np.allclose(m.bbox_min, src.bounds[0]) and np.allclose(m.bbox_max, src.bounds[1])


def test_gltf_with_uvs_and_scene_objects(tmp_path):
    a = trimesh.creation.box(extents=(1, 1, 1))
    b = trimesh.creation.box(extents=(1, 1, 1))
    b.apply_translation((3, 0, 0))
    for g in (a, b):
        g.visual = trimesh.visual.TextureVisuals(uv=np.random.default_rng(0).random((8, 2)))
    scene = trimesh.Scene()
    scene.add_geometry(a, geom_name="left", node_name="left")
    scene.add_geometry(b, geom_name="right", node_name="right")
    p = tmp_path / "two.gltf"
    scene.export(p)
    with pytest.warns(CrackbakeWarning, match="concatenating"):
        both = load_mesh(p)
    assert len(both.faces) == 24 and both.uv is not None
    right = load_mesh(p, object_name="right")
    assert len(right.faces) == 12
    assert right.bbox_min[0] == pytest.approx(2.5)  # node transform applied
    with pytest.raises(CrackbakeError, match="no object named 'middle'.*left.*right"):
        load_mesh(p, object_name="middle")


def test_vertex_normals_are_smooth_across_seams():
    m = load_mesh(EXAMPLE)
    n = welded_vertex_normals(m.vertices, m.faces)
    _, _, inverse = weld_by_position(m.vertices, m.faces)
    # Seam copies (same welded index) get the same normal.
    for idx in np.flatnonzero(np.bincount(inverse) > 1)[:50]:
        copies = np.flatnonzero(inverse == idx)
        assert np.allclose(n[copies], n[copies[0]])


def test_errors(tmp_path):
    with pytest.raises(CrackbakeError, match="file not found"):
        load_mesh(tmp_path / "nope.obj")
    bad = tmp_path / "mesh.xyz"
    bad.write_text("1 2 3\n")
    with pytest.raises(CrackbakeError, match="unsupported format '.xyz'"):
        load_mesh(bad)
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(CrackbakeError, match="no triangles"):
        load_mesh(empty)
    cloud = tmp_path / "cloud.ply"
    trimesh.PointCloud(np.random.default_rng(0).random((20, 3))).export(cloud)
    with pytest.raises(CrackbakeError, match=r"point cloud \(the elements 20 'vertex' \(x, y, z\); "
                       "no faces or triangle strips"):  # fmt: skip
        load_mesh(cloud)
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    with pytest.raises(CrackbakeError, match="NaN"):
        load_mesh(nan)
    flat = tmp_path / "flat.obj"
    flat.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    with pytest.raises(CrackbakeError, match="zero area"):
        load_mesh(flat)
    garbage = tmp_path / "garbage.glb"
    garbage.write_bytes(b"not a glb at all")
    with pytest.raises(CrackbakeError, match="could not read"):
        load_mesh(garbage)


def test_vertex_attributes_are_read_with_the_mesh(tmp_path):
    """A PLY with a per-vertex scalar and colours: the weights come from the loaded Mesh, with
    no second read of the file (it is gone by then)."""
    from crackbake.io.mesh import VERTEX_COLOURS
    from crackbake.simulate.stress import vertex_weights

    box = trimesh.creation.box()
    n = len(box.vertices)
    wt = np.arange(n) / n
    header = [
        "ply", "format ascii 1.0", f"element vertex {n}",
        *[f"property float {c}" for c in ("x", "y", "z", "wt")],
        *[f"property uchar {c}" for c in ("red", "green", "blue")],
        f"element face {len(box.faces)}", "property list uchar int vertex_indices", "end_header",
    ]
    rows = [f"{x} {y} {z} {w} 255 0 0" for (x, y, z), w in zip(box.vertices, wt, strict=True)]
    rows += [f"3 {a} {b} {c}" for a, b, c in box.faces]
    path = tmp_path / "painted.ply"
    path.write_text("\n".join(header + rows) + "\n")
    mesh = load_mesh(path)
    path.unlink()
    assert {"wt", "red", VERTEX_COLOURS} <= set(mesh.attributes)
    assert all(len(a) == len(mesh.vertices) for a in mesh.attributes.values())
    assert np.allclose(vertex_weights(mesh, "wt"), wt)
    assert np.allclose(vertex_weights(mesh, None), 0.2126)  # luminance of pure red
    with pytest.raises(CrackbakeError, match=r"no vertex attribute 'paint'; available: .*wt"):
        vertex_weights(mesh, "paint")


# --- text encodings and damaged OBJ files (issue 9) -----------------------------------------


def _same_mesh(a, b) -> None:
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.uv, b.uv)


def test_utf8_bom_obj_loads_like_the_plain_file(tmp_path, recwarn):
    """trimesh read the BOM into the first vertex line: "index 2929 is out of bounds"."""
    bom = tmp_path / "bom.obj"
    bom.write_bytes(b"\xef\xbb\xbf" + EXAMPLE.read_bytes())
    _same_mesh(load_mesh(bom), load_mesh(EXAMPLE))
    assert not [w for w in recwarn if issubclass(w.category, CrackbakeWarning)]


def test_bom_on_other_text_formats(tmp_path):
    plain = tmp_path / "cube.off"
    trimesh.creation.box().export(plain)
    bom = tmp_path / "bom.off"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    a, b = load_mesh(plain), load_mesh(bom)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


def test_non_utf8_obj_loads(tmp_path):
    """One Latin-1 byte in a comment or material name needs trimesh's charset_normalizer."""
    latin = tmp_path / "latin1.obj"
    latin.write_bytes("# modèle exporté, café\no Kuh_Größe\n".encode("latin-1")
                      + EXAMPLE.read_bytes())
    _same_mesh(load_mesh(latin), load_mesh(EXAMPLE))


def test_truncated_obj_warns_with_the_cut_line(tmp_path):
    data = EXAMPLE.read_bytes()
    cut = tmp_path / "cut.obj"
    cut.write_bytes(data[: len(data) * 2 // 3])  # ends mid-way through a face line
    with pytest.warns(CrackbakeWarning, match=r"the last line \(line \d+\) is cut off mid-way; "
                      "dropped it. The file looks truncated"):
        m = load_mesh(cut)
    # spot's faces are triangles: every complete face line before the cut is kept.
    complete = data[: len(data) * 2 // 3].rsplit(b"\n", 1)[0].count(b"\nf ")
    assert len(m.faces) == complete and 0 < complete < 5856


def test_short_face_lines_are_counted_in_a_warning(tmp_path):
    obj = tmp_path / "short.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4\nf 3\nf 2 4 3\n")
    with pytest.warns(CrackbakeWarning, match=r"short.obj: 2 face lines with fewer than three "
                      r"corners dropped \(2 triangles loaded\)"):
        m = load_mesh(obj)
    assert len(m.faces) == 2


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
         "line 4 uses vertex index 0, but OBJ indices start at 1"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/2 3/3\nf 0/1 1/2 2/3\n", "OBJ indices start at 1"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 2 3 7\nf 1 2 -5\n",
         r"2 face lines use vertices the file does not have \(line 5: vertex 7, but only 3 "
         r"vertices\); the file is truncated or corrupt"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n",
         "line 2 is a vertex with fewer than three coordinates"),
    ],
    ids=["index 0", "index 0 with uv", "missing vertices", "short vertex"],
)
def test_damaged_obj_is_refused_clearly(tmp_path, text, message):
    obj = tmp_path / "bad.obj"
    obj.write_text(text)
    with pytest.raises(CrackbakeError, match=message) as info:
        load_mesh(obj)
    assert "\n" not in str(info.value)


def test_indices_like_10_are_not_index_0(tmp_path):
    verts = "".join(f"v {i} {i * i % 7} {i % 3}\n" for i in range(12))
    obj = tmp_path / "ten.obj"
    obj.write_text(verts + "f 10 1 2\nf 1 10 11\nf 2 11 10\n")
    assert len(load_mesh(obj).faces) == 3


def test_coordinates_beyond_float32_are_refused(tmp_path):
    """Found by tests/test_fuzz.py: one vertex at 1e308 crashed the sim mesh build."""
    obj = tmp_path / "huge.obj"
    obj.write_text("v 1e308 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    with pytest.raises(CrackbakeError, match="vertex coordinates reach 1e\\+308, beyond the "
                       "1e\\+38 the GPU bake's 32-bit floats hold; scale the mesh down"):
        load_mesh(obj)


def test_weight_map_folder_is_named_a_folder(tmp_path):
    from crackbake.io.images import load_weight_map

    with pytest.raises(CrackbakeError, match="the weight map is a folder; pass an image file"):
        load_weight_map(tmp_path)


def test_obj_checks_span_the_scan_chunks(tmp_path):
    """The numpy scan reads big files in 4 MiB chunks: line numbers and counts stay exact."""
    n = 700_000  # 8 bytes a line: 5.6 MB, two chunks
    body = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n" + b"v 1 2 3\n" * n
    short = tmp_path / "short.obj"
    short.write_bytes(body + b"f 1 2 3\nf 1 2\nf 2 3 4\nf 4\n")
    with pytest.warns(CrackbakeWarning, match="2 face lines with fewer than three corners"):
        load_mesh(short)
    zero = tmp_path / "zero.obj"
    zero.write_bytes(body + b"f 1 2 3\nf 3 2 0\n")
    with pytest.raises(CrackbakeError, match=f"line {n + 6} uses vertex index 0"):
        load_mesh(zero)


def _strip_ply(path: Path, binary: bool, nx: int = 5, ny: int = 4) -> np.ndarray:
    """A (nx x ny)-quad grid in z = 0 written as one PLY ``tristrips`` element: one strip per
    row (the row's vertices zig-zag, the next row's first), rows parted by ``-1`` and split
    over two list entries of different lengths.  Returns its vertices."""
    xs, ys = np.meshgrid(np.arange(nx + 1, dtype=float), np.arange(ny + 1, dtype=float))
    v = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    idx = np.arange(v.shape[0]).reshape(ny + 1, nx + 1)
    # Upper row first then lower: triangle (up0, lo0, up1) winds counter-clockwise (+z).
    rows = [np.stack([idx[j + 1], idx[j]], axis=1).ravel() for j in range(ny)]
    strips = [np.concatenate([rows[0], [-1], rows[1]]), np.concatenate([rows[2], [-1], rows[3]])]
    strips[1] = np.r_[strips[1], -1]  # a trailing restart, as some writers leave
    head = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\n"
            f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element tristrips {len(strips)}\nproperty list int int vertex_indices\n"
            "end_header\n")
    if binary:
        body = v.astype("<f4").tobytes() + b"".join(
            np.int32(len(s)).tobytes() + s.astype("<i4").tobytes() for s in strips)
        path.write_bytes(head.encode() + body)
    else:
        lines = [" ".join(f"{x:g}" for x in p) for p in v]
        lines += [" ".join(str(int(i)) for i in [len(s), *s]) for s in strips]
        path.write_text(head + "\n".join(lines) + "\n")
    return v


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_triangle_strip_ply_loads_as_triangles(tmp_path, binary):
    path = tmp_path / "strips.ply"
    v = _strip_ply(path, binary)
    mesh = load_mesh(path)
    np.testing.assert_allclose(mesh.vertices, v)
    # Every quad of the 5 x 4 grid becomes two triangles, each once, all facing +z (the
    # alternating winding kept), covering the grid's area exactly.
    assert mesh.faces.shape == (2 * 5 * 4, 3)
    assert len({tuple(sorted(f)) for f in mesh.faces.tolist()}) == 40
    e1 = v[mesh.faces[:, 1]] - v[mesh.faces[:, 0]]
    e2 = v[mesh.faces[:, 2]] - v[mesh.faces[:, 0]]
    z = np.cross(e1, e2)[:, 2]
    assert (z > 0).all() and 0.5 * z.sum() == pytest.approx(20.0)


def test_strip_triangles_alternate_winding_and_restart():
    from crackbake.io.ply_strips import strip_triangles

    tris = strip_triangles([np.array([0, 1, 2, 3, 4, -1, 5, 6, 7]), np.array([8, 9])])
    assert tris.tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4], [5, 6, 7]]
    # Degenerate joining triangles (a repeated index) are dropped and the parity runs on, as
    # GL draws a strip: windows 3 (odd) and 4 (even) give (3, 2, 4) and (3, 4, 5).
    tris = strip_triangles([np.array([0, 1, 2, 2, 3, 4, 5])])
    assert tris.tolist() == [[0, 1, 2], [3, 2, 4], [3, 4, 5]]
