"""The vectorised OBJ reader: the same mesh arrays, names and messages as trimesh's reader.

Each generated file is loaded twice through :func:`crackbake.io.mesh.load_mesh`: once as a run
loads it (the reader first) and once with the reader switched off, so that trimesh's loader
(the reference, and still the fallback) reads it; the arrays must be equal bit for bit and the
warnings and errors word for word.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from crackbake.errors import CrackbakeError
from crackbake.io import mesh as mesh_module
from crackbake.io import obj_checks, obj_reader
from crackbake.io.mesh import load_mesh

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


def _load(path: Path, monkeypatch, fast: bool, **kw):
    """(Mesh or the CrackbakeError, warnings, whether the reader read it)."""
    used = []
    real = obj_reader.read_obj

    def reader(*args, **kwargs):
        parts = real(*args, **kwargs) if fast else None
        used.append(parts is not None)
        return parts

    with monkeypatch.context() as m:
        m.setattr(mesh_module.obj_reader, "read_obj", reader)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                result = load_mesh(path, **kw)
            except CrackbakeError as exc:
                result = exc
    return result, [str(w.message) for w in caught], any(used)


def _same_as_trimesh(path: Path, monkeypatch, **kw) -> bool:
    """Assert the reader's load equals trimesh's; return whether the reader read the file."""
    ours, our_warnings, used = _load(path, monkeypatch, True, **kw)
    theirs, their_warnings, _ = _load(path, monkeypatch, False, **kw)
    assert our_warnings == their_warnings
    if isinstance(theirs, CrackbakeError):
        assert isinstance(ours, CrackbakeError) and str(ours) == str(theirs)
        return used
    assert not isinstance(ours, CrackbakeError), ours
    for key in ("vertices", "faces", "uv", "normals"):
        a, b = getattr(ours, key), getattr(theirs, key)
        assert (a is None) == (b is None), key
        if a is not None:
            assert a.dtype == b.dtype and a.shape == b.shape, key
            assert a.tobytes() == b.tobytes(), key
    assert (ours.name, ours.objects, set(ours.attributes)) == (
        theirs.name, theirs.objects, set(theirs.attributes)
    )  # fmt: skip
    return used


def _grid(n: int = 6, seams: bool = True, rng=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An (n x n)-quad bumpy sheet: vertices (V, 3), quads (Q, 4) 0-based, UVs per corner
    (Q, 4, 2) that jump at a seam down the middle (so vertices there split)."""
    rng = rng or np.random.default_rng(0)
    xs, ys = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    v = np.c_[xs.ravel(), ys.ravel(), 0.1 * rng.random(xs.size)]
    idx = np.arange(v.shape[0]).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    uv = v[quads][..., :2] * 0.5
    if seams:
        right = v[quads][..., 0].mean(axis=1) > 0.5
        uv[right] += 0.5  # the right half is its own UV island
    return v, quads, uv


def _write(path: Path, v, polys, uv=None, normals=None, head: str = "", groups=None) -> Path:
    """An OBJ of ``polys`` (lists of 0-based corners), with per-corner ``uv`` (list of (k, 2)
    arrays) and ``normals`` (one per vertex) when given; ``groups``: line -> text before it."""
    lines = [head] if head else []
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(v).tolist()]
    vt_of = {}
    if uv is not None:
        uv = [np.asarray(u).tolist() for u in uv]
        for poly_uv in uv:
            for t in map(tuple, poly_uv):
                vt_of.setdefault(t, len(vt_of) + 1)
        lines += [f"vt {s!r} {t!r}" for s, t in vt_of]
    if normals is not None:
        lines += [f"vn {x!r} {y!r} {z!r}" for x, y, z in np.asarray(normals).tolist()]
    for i, poly in enumerate(polys):
        if groups and i in groups:
            lines.append(groups[i])
        corners = []
        for k, c in enumerate(np.asarray(poly).tolist()):
            t = vt_of[tuple(uv[i][k])] if uv is not None else ""
            n = c + 1 if normals is not None else ""
            corners.append(f"{c + 1}/{t}/{n}" if n != "" else f"{c + 1}/{t}" if t else f"{c + 1}")
        lines.append("f " + " ".join(corners))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_example_and_seams(tmp_path, monkeypatch):
    assert _same_as_trimesh(EXAMPLE, monkeypatch)
    v, quads, uv = _grid()
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    tri_uv = np.concatenate([uv[:, [0, 1, 2]], uv[:, [0, 2, 3]]])
    path = _write(tmp_path / "seams.obj", v, tris, tri_uv)
    assert _same_as_trimesh(path, monkeypatch)
    m = load_mesh(path)
    assert len(m.vertices) > len(v)  # split along the seam
    assert np.array_equal(m.vertices[m.faces], v[tris])  # every corner keeps its position
    assert np.array_equal(m.uv[m.faces], tri_uv)  # ... and its own UV


def test_quads_mixed_polygons_and_normals(tmp_path, monkeypatch):
    v, quads, uv = _grid(seams=False)
    assert _same_as_trimesh(_write(tmp_path / "quads.obj", v, quads, uv), monkeypatch)
    # triangles, quads and a pentagon in one file: trimesh's fans, quads as (0,1,2),(2,3,0)
    polys = [list(q) for q in quads[:-2]] + [[0, 1, 2], [3, 4, 5, 6, 7]]
    mixed = _write(tmp_path / "mixed.obj", v, polys)
    assert _same_as_trimesh(mixed, monkeypatch)
    assert len(load_mesh(mixed).faces) == 2 * (len(quads) - 2) + 1 + 3
    rng = np.random.default_rng(1)
    n = rng.normal(size=v.shape)
    normals = _write(tmp_path / "normals.obj", v, quads, normals=n)  # v//vn
    assert _same_as_trimesh(normals, monkeypatch)
    m = load_mesh(normals)
    assert np.allclose(m.normals, (n / np.linalg.norm(n, axis=1, keepdims=True))[
        np.unique(quads)])  # the file's own, in file order  # fmt: skip
    full = _write(tmp_path / "full.obj", v, quads, uv=uv, normals=n)  # v/vt/vn
    assert _same_as_trimesh(full, monkeypatch)


def test_negative_indices_crlf_and_unreferenced_vertices(tmp_path, monkeypatch):
    text = ("v 0 0 0\nv 9 9 9\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n"
            "f -4/-4 -3/-3 -2/-2\nf 3/2 5/4 4/3\n")  # fmt: skip
    path = tmp_path / "neg.obj"
    path.write_text(text)
    assert _same_as_trimesh(path, monkeypatch)
    plain = tmp_path / "plain.obj"
    plain.write_text("v 0 0 0\nv 9 9 9\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n")
    assert _same_as_trimesh(plain, monkeypatch)
    assert len(load_mesh(plain).vertices) == 3  # the unused vertex is left out
    crlf = tmp_path / "crlf.obj"
    crlf.write_bytes(text.replace("\n", "\r\n").encode())
    assert _same_as_trimesh(crlf, monkeypatch)


def test_materials_objects_and_object_pick(tmp_path, monkeypatch):
    v, quads, uv = _grid(seams=False)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    tri_uv = np.concatenate([uv[:, [0, 1, 2]], uv[:, [0, 2, 3]]])
    half = len(tris) // 2
    groups = {0: "usemtl red", half: "o second\nusemtl blue", half + 3: "usemtl red"}
    (tmp_path / "two.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n")
    path = _write(tmp_path / "two.obj", v, tris, tri_uv, head="mtllib two.mtl\no first",
                  groups=groups)  # fmt: skip
    assert _same_as_trimesh(path, monkeypatch)
    for name in ("red", "blue", "first", "two.obj"):
        assert _same_as_trimesh(path, monkeypatch, object_name=name)
    assert len(load_mesh(path, object_name="blue").faces) == 3
    # without its material library, trimesh names the groups after the first object
    (tmp_path / "two.mtl").unlink()
    assert _same_as_trimesh(path, monkeypatch)
    assert _same_as_trimesh(path, monkeypatch, object_name="first_1")
    # a library outside the mesh's folder is not read (and names fall back the same way)
    inner = tmp_path / "inner"
    inner.mkdir()
    (tmp_path / "out.mtl").write_text("newmtl red\nnewmtl blue\n")
    far = _write(inner / "far.obj", v, tris, tri_uv, head="mtllib ../out.mtl", groups=groups)
    assert _same_as_trimesh(far, monkeypatch, object_name="far.obj_1")
    assert _same_as_trimesh(far, monkeypatch, object_name="red", allow_outside_textures=True)


def test_missing_texture_is_not_read_at_load(tmp_path, monkeypatch):
    (tmp_path / "m.mtl").write_text("newmtl skin\nmap_Kd missing.png\n")
    text = EXAMPLE.read_text()
    path = tmp_path / "spot.obj"
    path.write_text("mtllib m.mtl\nusemtl skin\n" + text)
    assert _same_as_trimesh(path, monkeypatch)
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)  # a texture that would block a read: the load reads no texture
    (tmp_path / "m.mtl").write_text("newmtl skin\nmap_Kd pipe.png\n")
    assert _same_as_trimesh(path, monkeypatch)


@pytest.mark.parametrize(
    "text, fast",
    [
        ("v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n", False),  # vertex colours
        ("v 0 0 0\nv 1 0 0 # corner\nv 0 1 0\nf 1 2 3\n", False),  # comment after data
        ("v\t0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n", False),  # tab: trimesh
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4\n", True),  # short face line
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", False),  # vertex 4 of 3: the error
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 3 2 0\n", None),  # index 0: obj_checks' error
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/7\n", False),  # bad vt: warned
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nf 1 2 3\n", False),  # unknown keyword
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nf 1 2 3 4\nf 1 2 3 4\n", True),  # non-planar quads
        ("v 0 0 0\nv 1 0 0\nv 1e-3 1 0\nf 1 2 3\n", True),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 1\nf 1 2 3\n", True),  # a zero-area face: warned
    ],
)
def test_bad_and_unusual_lines(tmp_path, monkeypatch, text, fast):
    path = tmp_path / "odd.obj"
    path.write_text(text)
    used = _same_as_trimesh(path, monkeypatch)
    if fast is not None:
        assert used is fast


def test_reader_declines_what_it_does_not_reproduce(tmp_path):
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"
    path = tmp_path / "x.obj"
    checked, scan = obj_checks.prepare_obj_scan(data, path)
    parts = obj_reader.read_obj(checked, scan, path)
    assert parts is not None and len(parts) == 1
    assert parts[0].faces.tolist() == [[0, 1, 2], [1, 3, 2]]
    for odd in (b"vp 0.5\n", b"f 1 2 3 # a comment\n", b"v 1 2 3\\\n4\n"):
        checked, scan = obj_checks.prepare_obj_scan(data + odd, path)
        assert obj_reader.read_obj(checked, scan, path) is None


@pytest.mark.parametrize("columns, high", [(2, 50), (3, 50), (2, 3_000_000_000), (3, 2_000_000)])
def test_vertex_order_matches_trimesh_unmerge(columns, high):
    """The tuple order behind the vertex order, against trimesh's own function, for packed
    keys (small indices) and for rows too wide to pack (compared as bytes)."""
    rng = np.random.default_rng(columns * 7 + high % 97)
    corners = rng.integers(-3, high, size=(3000, columns))
    corners[::5, 0] = corners[0, 0]  # many tuples share a vertex: argsort ties
    faces = [corners[:, i].reshape(-1, 3) for i in range(columns)]
    new_faces, *masks = trimesh.visual.texture.unmerge_faces(*faces)
    cols = [corners[:, i] for i in range(columns)]
    if columns == 2:
        cols.append(None)
    if high > 1e9:  # too many to allocate: only the order of the tuples
        rows, inverse = obj_reader._distinct_tuples([c for c in cols if c is not None])
        tuples = [c[rows] for c in cols if c is not None]
        order = tuples[0].argsort()
        assert np.array_equal(tuples[0][order], masks[0])
        assert np.array_equal(tuples[1][order], masks[1])
        rank = np.empty(len(order), dtype=np.int64)
        rank[order] = np.arange(len(order))
        assert np.array_equal(rank[inverse].reshape(-1, 3), new_faces)
        return
    size = int(np.abs(corners).max()) + 1
    v = np.arange(size, dtype=np.float64)[:, None].repeat(3, 1)
    vt = np.arange(size, dtype=np.float64)[:, None].repeat(2, 1)
    source, uv, normals, index = obj_reader._unmerge(len(v), vt, v if columns == 3 else None, *cols)
    vertices = v[source]
    assert np.array_equal(index.reshape(-1, 3), new_faces)
    assert np.array_equal(vertices, v[masks[0]])
    assert np.array_equal(uv, vt[masks[1]])
    if columns == 3:
        assert np.array_equal(normals, v[masks[2]])
