"""Round trips of the writers in crackbake.exchange, checked with independent readers.

EXR files are written with the OpenEXR bindings and re-read with OpenImageIO; PNGs are read with
Pillow; GLBs are parsed here by hand (header, JSON chunk, BIN chunk) and loaded with trimesh.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import struct
import warnings

import numpy as np
import OpenImageIO as oiio
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.exchange import (
    OutputStage,
    read_exr,
    sha256_file,
    write_exr,
    write_glb,
    write_png,
)

H, W = 24, 40  # not square, so a transposed image cannot pass
MARK_ROW, MARK_COL = 3, 29


def _half_values(rng: np.random.Generator, shape) -> np.ndarray:
    """Every kind of half: random bit patterns (NaN excluded: NaN != NaN), +-0, inf, subnormal."""
    bits = rng.integers(0, 2**16, size=shape, dtype=np.uint16)
    a = bits.view(np.float16)
    a[np.isnan(a)] = 0
    a.flat[:4] = [-0.0, np.inf, -np.inf, np.float16(6e-8)]
    return a


def _channels() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    mask = np.zeros((H, W), np.float16)
    mask[MARK_ROW, MARK_COL] = 1.0
    stress = (rng.standard_normal((H, W)) * 1e7).astype(np.float32)
    stress.flat[0] = np.float32(1e-40)  # subnormal float survives too
    return {
        "crack.mask": mask,
        "crack.width": _half_values(rng, (H, W)),
        "normal.X": rng.uniform(-1, 1, (H, W)).astype(np.float16),
        "stress.xx": stress,
        "crack.depth": rng.uniform(0, 1e-2, (H, W)).astype(np.float32),
        "crack.id": rng.integers(0, 2**32, (H, W), dtype=np.uint32),
    }


ATTRS = {
    "crackbake:version": "0.1.0",
    "crackbake:units": "mesh",
    "crackbake:uvConvention": "texel (0,0) = uv (0,1)",
    "crackbake:seed": 12345,
    "crackbake:scale": 0.25,
}


def _oiio_read(path) -> tuple[dict[str, np.ndarray], oiio.ImageSpec]:
    """Each channel in its stored type (a mixed-type read in one call crashes OIIO 3.2)."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    out = {}
    for i, name in enumerate(spec.channelnames):
        fmt = spec.channelformat(i)
        out[name] = inp.read_image(0, 0, i, i + 1, fmt)[:, :, 0]
    inp.close()
    return out, spec


def test_exr_round_trip_read_by_openimageio(tmp_path):
    chans = _channels()
    path = tmp_path / "master.exr"
    write_exr(path, chans, ATTRS)
    got, spec = _oiio_read(path)

    assert set(got) == set(chans)
    assert (spec.width, spec.height) == (W, H)
    kinds = {n: str(spec.channelformat(i)) for i, n in enumerate(spec.channelnames)}
    want = {
        np.dtype(np.float16): "half",
        np.dtype(np.float32): "float",
        np.dtype(np.uint32): "uint",
    }
    assert kinds == {n: want[a.dtype] for n, a in chans.items()}
    for name, a in chans.items():
        b = got[name]
        assert b.dtype == a.dtype, name
        # Bit-identical, -0.0 / inf / subnormals included.
        assert np.array_equal(b.view(f"u{a.itemsize}"), a.view(f"u{a.itemsize}")), name

    assert spec.get_string_attribute("compression") == "zip"
    assert spec.getattribute("crackbake:version") == "0.1.0"
    assert spec.getattribute("crackbake:units") == "mesh"
    assert spec.getattribute("crackbake:uvConvention") == ATTRS["crackbake:uvConvention"]
    assert spec.getattribute("crackbake:seed") == 12345
    assert spec.getattribute("crackbake:scale") == pytest.approx(0.25)


def test_exr_row_zero_is_top(tmp_path):
    path = tmp_path / "marker.exr"
    write_exr(path, {"crack.mask": _channels()["crack.mask"]})
    buf = oiio.ImageBuf(str(path))
    # OIIO's y axis points down from the first scanline; the marker must be where we put it.
    assert buf.getpixel(MARK_COL, MARK_ROW)[0] == 1.0
    px = buf.get_pixels(oiio.FLOAT)[:, :, 0]
    assert np.argwhere(px == 1.0).tolist() == [[MARK_ROW, MARK_COL]]
    assert buf.spec().get_string_attribute("openexr:lineOrder") == "increasingY"


def test_exr_own_reader_and_input_left_alone(tmp_path):
    chans = _channels()
    before = {k: v.copy() for k, v in chans.items()}
    path = tmp_path / "own.exr"
    write_exr(path, chans, ATTRS, compression="zstd")
    # The bindings rewrite the dict they are given; ours must be untouched.
    assert set(chans) == set(before)
    assert all(isinstance(v, np.ndarray) and np.array_equal(v, before[k]) for k, v in chans.items())
    got, header = read_exr(path)
    assert header["compression"] == "zstd"
    assert header["crackbake:units"] == "mesh"
    for name, a in before.items():
        assert got[name].dtype == a.dtype
        assert np.array_equal(got[name].view(f"u{a.itemsize}"), a.view(f"u{a.itemsize}"))


@pytest.mark.parametrize("compression", ["none", "zips", "piz", "zstd"])
def test_exr_other_lossless_compressions_recorded(tmp_path, compression):
    chans = _channels()
    path = tmp_path / f"{compression}.exr"
    write_exr(path, chans, compression=compression)
    got, spec = _oiio_read(path)
    assert spec.get_string_attribute("compression") == compression
    for name, a in chans.items():
        assert np.array_equal(got[name].view(f"u{a.itemsize}"), a.view(f"u{a.itemsize}"))


@pytest.mark.parametrize("compression", ["dwaa", "dwab", "b44", "pxr24", "DWAA"])
def test_exr_lossy_compression_refused(tmp_path, compression):
    path = tmp_path / "lossy.exr"
    with pytest.raises(CrackbakeError, match="lossy") as info:
        write_exr(path, _channels(), compression=compression)
    assert "\n" not in str(info.value)
    assert not path.exists()


def test_exr_bad_inputs(tmp_path):
    path = tmp_path / "bad.exr"
    a = np.zeros((4, 4), np.float16)
    cases = [
        ({}, None, "zip"),
        ({"a": np.zeros((4, 4))}, None, "zip"),  # float64: refused, not silently converted
        ({"a": a, "b": np.zeros((4, 5), np.float32)}, None, "zip"),
        ({"a": np.zeros((4, 4, 3), np.float16)}, None, "zip"),
        ({"a": a}, {"crackbake:big": 2**40}, "zip"),
        ({"a": a}, {"compression": "zip"}, "zip"),
        ({"a": a}, {"crackbake:list": [1, 2]}, "zip"),
        ({"a": a}, None, "lzma"),
    ]
    for chans, attrs, comp in cases:
        with pytest.raises(CrackbakeError) as info:
            write_exr(path, chans, attrs, compression=comp)
        assert "\n" not in str(info.value)
    with pytest.raises(CrackbakeError, match="cannot write"):
        write_exr(tmp_path / "missing" / "x.exr", {"a": a})
    # Strided views are fine (copied to C order).
    write_exr(path, {"a": np.zeros((4, 8), np.float16)[:, ::2]})
    assert read_exr(path)[0]["a"].shape == (4, 4)


# ---------------------------------------------------------------------------------------------
# PNG


def _no_warnings():
    ctx = warnings.catch_warnings()
    ctx.__enter__()
    warnings.simplefilter("error")
    return ctx


def test_png_8bit_gray_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 1, (H, W)).astype(np.float32)
    img[MARK_ROW, MARK_COL] = 1.0
    img[0, 0] = 1.0005  # within tolerance: clipped quietly
    path = tmp_path / "mask.png"
    ctx = _no_warnings()
    try:
        write_png(path, img)
    finally:
        ctx.__exit__(None, None, None)
    with Image.open(path) as im:
        assert im.mode == "L"
        got = np.asarray(im)
    assert got.shape == (H, W)
    assert np.all(np.abs(got / 255.0 - np.clip(img, 0, 1)) <= 0.5 / 255 + 1e-6)
    assert got[MARK_ROW, MARK_COL] == 255 and got[0, 0] == 255


def test_png_16bit_gray_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    img = rng.uniform(0, 1, (H, W))  # float64 accepted
    path = tmp_path / "height.png"
    write_png(path, img, bits=16, compression_level=1)
    with Image.open(path) as im:
        assert im.mode == "I;16"
        got = np.asarray(im).astype(np.float64)
    # OIIO scales in float32, so rounding is to nearest within ~0.005 of a step.
    assert np.all(np.abs(got / 65535.0 - img) <= 0.505 / 65535)


def _png_ihdr(path) -> tuple[int, int, int, int]:
    data = open(path, "rb").read(33)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    w, h, depth, colour = struct.unpack(">IIBB", data[16:26])
    return w, h, depth, colour


def test_png_16bit_rgb_and_8bit_rgba(tmp_path):
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    path = tmp_path / "normal16.png"
    write_png(path, rgb, bits=16)
    assert _png_ihdr(path) == (W, H, 16, 2)  # 16-bit truecolour
    with Image.open(path) as im:
        # Pillow reads 16-bit RGB only as 8-bit: the high byte of each 16-bit sample.
        got8 = np.asarray(im.convert("RGB")).astype(int)
    q16 = np.round(rgb.astype(np.float64) * 65535).astype(int)
    assert np.all(np.abs(got8 - (q16 >> 8)) <= 1)

    rgba = rng.uniform(0, 1, (H, W, 4)).astype(np.float32)
    path = tmp_path / "rgba.png"
    write_png(path, rgba)
    assert _png_ihdr(path) == (W, H, 8, 6)
    with Image.open(path) as im:
        got = np.asarray(im)
    assert np.all(np.abs(got / 255.0 - rgba) <= 0.5 / 255 + 1e-6)

    u8 = (rng.uniform(0, 1, (H, W, 3)) * 255).astype(np.uint8)
    path = tmp_path / "u8.png"
    write_png(path, u8)
    with Image.open(path) as im:
        assert np.array_equal(np.asarray(im), u8)


def test_png_out_of_range_warns_and_clips(tmp_path):
    img = np.full((H, W), 0.5, np.float32)
    img[1, 2] = 1.2
    img[2, 3] = -0.3
    img[4, 5] = np.nan
    path = tmp_path / "clipped.png"
    with pytest.warns(CrackbakeWarning, match="outside"):
        write_png(path, img)
    with Image.open(path) as im:
        got = np.asarray(im)
    assert got[1, 2] == 255 and got[2, 3] == 0 and got[4, 5] == 0 and got[0, 0] == 128


def test_png_compression_level_and_bad_inputs(tmp_path):
    y, x = np.mgrid[0:256, 0:256] / 255.0
    img = np.stack([x, y, x * y], -1)
    write_png(tmp_path / "l0.png", img, compression_level=0)
    write_png(tmp_path / "l9.png", img, compression_level=9)
    assert os.path.getsize(tmp_path / "l0.png") > 2 * os.path.getsize(tmp_path / "l9.png")
    for kwargs in (
        {"image": img, "bits": 12},
        {"image": np.zeros((4, 4, 5))},
        {"image": img, "compression_level": 11},
        {"image": np.zeros((4, 4), np.int32)},
    ):
        with pytest.raises(CrackbakeError):
            write_png(tmp_path / "bad.png", **kwargs)


# ---------------------------------------------------------------------------------------------
# GLB


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


# ---------------------------------------------------------------------------------------------
# Hashes and OutputStage


def test_sha256_file(tmp_path):
    p = tmp_path / "x.bin"
    data = os.urandom(3_000_000)
    p.write_bytes(data)
    assert sha256_file(p) == hashlib.sha256(data).hexdigest()


def test_output_stage_commit(tmp_path):
    out = tmp_path / "rock_cracks"
    out.mkdir()
    (out / "mask.png").write_bytes(b"old")
    with OutputStage(out) as stage:
        stage.path("mask.png").write_bytes(b"new mask")
        stage.path("master.exr").write_bytes(b"exr" * 1000)
        staging = stage.staging_dir
        assert staging.parent == out and staging.name.startswith(".")
        # Nothing visible under final names before commit.
        assert (out / "mask.png").read_bytes() == b"old" and not (out / "master.exr").exists()
        records = stage.records()
        assert [r["name"] for r in records] == ["mask.png", "master.exr"]
        for r in records:
            data = (staging / r["name"]).read_bytes()
            assert r["bytes"] == len(data)
            assert r["sha256"] == hashlib.sha256(data).hexdigest()
        assert stage.records() == records  # cached, same answer
        stage.path("manifest.json").write_text(json.dumps({"files": records}))
        moved = stage.commit(last=("manifest.json",))
    assert [p.name for p in moved][-1] == "manifest.json"
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "mask.png", "master.exr"]
    assert (out / "mask.png").read_bytes() == b"new mask"
    assert not staging.exists()


def test_output_stage_exception_touches_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mask.png").write_bytes(b"old")
    with pytest.raises(RuntimeError, match="bake failed"):
        with OutputStage(out) as stage:
            stage.path("mask.png").write_bytes(b"new")
            stage.path("manifest.json").write_text("{}")
            staging = stage.staging_dir
            raise RuntimeError("bake failed")
    assert not staging.exists()
    assert [p.name for p in out.iterdir()] == ["mask.png"]
    assert (out / "mask.png").read_bytes() == b"old"

    # Leaving without commit behaves the same; a new folder is created on demand.
    fresh = tmp_path / "new" / "dir"
    with OutputStage(fresh) as stage:
        stage.path("a.exr").write_bytes(b"x")
    assert list(fresh.iterdir()) == []


def test_output_stage_rejects_paths_outside(tmp_path):
    with OutputStage(tmp_path / "o") as stage:
        for name in ("../x.png", "a/b.png", "", ".."):
            with pytest.raises(CrackbakeError):
                stage.path(name)
        stage.commit()
        with pytest.raises(CrackbakeError):
            stage.path("late.png")
