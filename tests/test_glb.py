"""GLB export (crackbake.exchange.glb): parsed here by hand (header, JSON chunk, BIN chunk) and
loaded with trimesh."""

from __future__ import annotations

import io
import json
import struct

import numpy as np
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError
from crackbake.exchange import (
    write_glb,
)


def _grid_mesh(n: int = 4):
    """An (n x n)-quad sheet bent in z, UVs = normalised xy; a UV seam duplicates column 0."""
    ij = np.stack(np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="xy"), -1).reshape(-1, 2)
    uv = ij / n
    verts = np.column_stack([uv[:, 0] * 2.0 - 1.0, uv[:, 1] * 3.0, 0.3 * np.sin(uv[:, 0] * 3)])
    faces = []
    for r in range(n):
        for c in range(n):
            a = r * (n + 1) + c
            faces += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    faces = np.array(faces, np.int64)
    normals = np.tile([0.0, 0.0, 2.0], (len(verts), 1))  # not unit on purpose
    return verts, faces, uv, normals


def _parse_glb(path):
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2 and length == len(data)
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A and jlen % 4 == 0
    gltf = json.loads(data[20 : 20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942 and blen % 4 == 0
    binary = data[28 + jlen : 28 + jlen + blen]
    assert 28 + jlen + blen == len(data)
    assert gltf["buffers"] == [{"byteLength": blen}]
    return gltf, binary


def _accessor(gltf, binary, index) -> np.ndarray:
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    start = view["byteOffset"] + acc.get("byteOffset", 0)
    assert start % 4 == 0
    arr = np.frombuffer(binary, dtype, acc["count"] * width, start)
    return arr.reshape(acc["count"], width) if width > 1 else arr


def _image(gltf, binary, texture_index) -> np.ndarray:
    img = gltf["images"][gltf["textures"][texture_index]["source"]]
    assert img["mimeType"] == "image/png"
    view = gltf["bufferViews"][img["bufferView"]]
    raw = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
    with Image.open(io.BytesIO(raw)) as im:
        return np.asarray(im)


def test_glb_structure_and_values(tmp_path):
    verts, faces, uv, normals = _grid_mesh()
    rng = np.random.default_rng(4)
    base = rng.integers(0, 256, (16, 32, 3), dtype=np.uint8)
    path = tmp_path / "asset.glb"
    write_glb(path, verts, faces, uv, normals, base, name="rock")
    gltf, binary = _parse_glb(path)

    assert gltf["asset"]["version"] == "2.0"
    prim = gltf["meshes"][0]["primitives"][0]
    attrs = prim["attributes"]
    assert set(attrs) == {"POSITION", "NORMAL", "TEXCOORD_0"}
    pos = _accessor(gltf, binary, attrs["POSITION"])
    acc = gltf["accessors"][attrs["POSITION"]]
    assert acc["count"] == len(verts)
    assert np.array_equal(pos, verts.astype(np.float32))
    assert acc["min"] == verts.astype(np.float32).min(0).tolist()
    assert acc["max"] == verts.astype(np.float32).max(0).tolist()
    nrm = _accessor(gltf, binary, attrs["NORMAL"])
    assert np.allclose(nrm, [0, 0, 1])
    tex = _accessor(gltf, binary, attrs["TEXCOORD_0"])
    assert np.array_equal(tex, np.column_stack([uv[:, 0], 1 - uv[:, 1]]).astype(np.float32))
    idx = _accessor(gltf, binary, prim["indices"])
    assert gltf["accessors"][prim["indices"]]["count"] == faces.size
    assert np.array_equal(idx, faces.reshape(-1))
    assert prim.get("mode", 4) == 4

    mat = gltf["materials"][prim["material"]]
    pbr = mat["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 0 and pbr["roughnessFactor"] == pytest.approx(0.8)
    assert np.array_equal(_image(gltf, binary, pbr["baseColorTexture"]["index"]), base)
    sampler = gltf["samplers"][gltf["textures"][pbr["baseColorTexture"]["index"]]["sampler"]]
    assert sampler["magFilter"] == 9729 and sampler["minFilter"] == 9987
    assert sampler.get("wrapS", 10497) == 10497 and sampler.get("wrapT", 10497) == 10497
    assert gltf["nodes"][0]["name"] == "rock"


def test_glb_marker_texel_lands_at_its_uv(tmp_path):
    """A marker painted at image row r (row 0 = top = v 1) is what glTF samples at that vertex."""
    verts, faces, uv, normals = _grid_mesh(4)
    hh, ww = 20, 20
    base = np.zeros((hh, ww, 3), np.uint8)
    k = 7  # vertex at grid (col 2, row 1) -> uv (0.5, 0.25)
    u, v = uv[k]
    row, col = int((1 - v) * hh), int(u * ww)
    assert (row, col) == (15, 10)
    base[row, col] = [255, 0, 0]
    path = tmp_path / "marker.glb"
    write_glb(path, verts, faces, uv, normals, base)
    gltf, binary = _parse_glb(path)
    tex = _accessor(gltf, binary, gltf["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"])
    img = _image(gltf, binary, 0)
    # glTF: (0, 0) is the first (top-left) pixel of the image, no flip.
    s, t = tex[k]
    assert img[int(t * hh), int(s * ww)].tolist() == [255, 0, 0]


def test_glb_tangents_and_normal_texture(tmp_path):
    verts, faces, uv, normals = _grid_mesh()
    base = np.full((8, 8, 4), 200, np.uint8)
    nmap = np.zeros((8, 8, 3), np.uint8)
    nmap[..., 2] = 255
    nmap[0, 0] = [10, 20, 30]
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(verts), 1))
    path = tmp_path / "t.glb"
    write_glb(path, verts, faces, uv, normals, base, extra_textures={"normal": nmap},
              tangents=tangents)  # fmt: skip
    gltf, binary = _parse_glb(path)
    attrs = gltf["meshes"][0]["primitives"][0]["attributes"]
    tan = _accessor(gltf, binary, attrs["TANGENT"])
    assert tan.shape == (len(verts), 4) and np.array_equal(tan, tangents.astype(np.float32))
    mat = gltf["materials"][0]
    assert np.array_equal(_image(gltf, binary, mat["normalTexture"]["index"]), nmap)
    assert np.array_equal(
        _image(gltf, binary, mat["pbrMetallicRoughness"]["baseColorTexture"]["index"]), base
    )


def test_glb_loads_in_trimesh(tmp_path):
    import trimesh

    verts, faces, uv, normals = _grid_mesh(5)
    base = np.zeros((8, 8, 3), np.uint8)
    path = tmp_path / "load.glb"
    write_glb(path, verts, faces, uv, normals, base)
    scene = trimesh.load(path, process=False)
    meshes = list(scene.geometry.values()) if isinstance(scene, trimesh.Scene) else [scene]
    assert len(meshes) == 1
    m = meshes[0]
    assert len(m.vertices) == len(verts) and len(m.faces) == len(faces)
    assert np.allclose(m.vertices, verts, atol=1e-6)
    # trimesh undoes glTF's v flip on load, so it must give back the UVs we passed.
    assert np.allclose(m.visual.uv, uv, atol=1e-6)


def test_glb_bad_inputs(tmp_path):
    verts, faces, uv, normals = _grid_mesh()
    base = np.zeros((4, 4, 3), np.uint8)
    path = tmp_path / "bad.glb"
    bad = [
        dict(faces=faces + 1000),
        dict(uv=uv[:-1]),
        dict(base_color=np.zeros((4, 4, 3), np.float32)),
        dict(extra_textures={"emissive": base}),
        dict(tangents=np.zeros((len(verts), 3))),
    ]
    for override in bad:
        args = dict(vertices=verts, faces=faces, uv=uv, normals=normals, base_color=base)
        args.update(override)
        with pytest.raises(CrackbakeError):
            write_glb(path, **args)
