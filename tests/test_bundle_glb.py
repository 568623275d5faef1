"""The run's GLB (crackbake.exchange.bundle + glb): complete glTF material, the asset's own
base-colour texture composited, and the Khronos glTF validator's verdict."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import tiny_network
from maps_factory import plate_uvmesh, synthetic_maps
from PIL import Image
from test_glb import _accessor, _image, _parse_glb

from crackbake.exchange.bundle import write_outputs
from crackbake.exchange.glb import write_glb
from crackbake.exchange.materials import CRACK_RGB, SURFACE_RGB
from crackbake.io.texture import base_color_texture
from crackbake.params import RunParams
from crackbake.transaction.stage import OutputStage


def _run(tmp_path, mesh, uvm, maps, target="gltf", formats=("glb",), name="out"):
    params = RunParams(mesh=mesh.source, target=target, formats=formats)
    out = tmp_path / name
    with OutputStage(out) as stage:
        write_outputs(stage, "rock", params, mesh, uvm, tiny_network(), maps)
        stage.commit()
    return out


def _checker(n=16) -> np.ndarray:
    """A red/blue checker texture, (n, n, 3) uint8, with one green texel at the top-left."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    img = np.where(((i // 4 + j // 4) % 2)[..., None] == 0, [200, 40, 40], [40, 40, 200])
    img = img.astype(np.uint8)
    img[:4, :4] = [30, 220, 30]
    return img


def _obj_with_texture(tmp_path, mesh, texture) -> Path:
    """Write ``mesh`` as OBJ + MTL (map_Kd with an option) + PNG; return the OBJ path."""
    Image.fromarray(texture).save(tmp_path / "albedo map.png")
    (tmp_path / "rock.mtl").write_text("newmtl stone\nKd 1 1 1\nmap_Kd -bm 1.0 albedo map.png\n")
    lines = ["mtllib rock.mtl"] + [f"v {x} {y} {z}" for x, y, z in mesh.vertices]
    lines += [f"vt {u} {v}" for u, v in mesh.uv] + ["usemtl stone"]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in mesh.faces + 1]
    path = tmp_path / "rock.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_glb_binds_normal_orm_and_tangents(tmp_path):
    mesh, uvm = plate_uvmesh()
    maps = synthetic_maps()
    gltf, binary = _parse_glb(_run(tmp_path, mesh, uvm, maps) / "rock.glb")
    prim = gltf["meshes"][0]["primitives"][0]
    tan = _accessor(gltf, binary, prim["attributes"]["TANGENT"])
    np.testing.assert_array_equal(tan, np.tile([1, 0, 0, 1], (len(uvm.vertices), 1)))
    mat = gltf["materials"][0]
    pbr = mat["pbrMetallicRoughness"]
    # One ORM image shared by occlusion and metallic-roughness: three images in all.
    assert mat["occlusionTexture"]["index"] == pbr["metallicRoughnessTexture"]["index"]
    assert len(gltf["images"]) == 3 and pbr["metallicFactor"] == 1.0
    orm = _image(gltf, binary, mat["occlusionTexture"]["index"]).astype(float)
    np.testing.assert_allclose(orm[..., 0], np.round(maps.occlusion.astype(float) * 255), atol=1)
    nrm = _image(gltf, binary, mat["normalTexture"]["index"]).astype(float) / 255 * 2 - 1
    assert np.abs(nrm - maps.normal).max() <= 1 / 255 + 1e-6  # OpenGL +Y, as glTF wants
    base = _image(gltf, binary, pbr["baseColorTexture"]["index"]).astype(float)
    np.testing.assert_allclose(base, _expected(maps, SURFACE_RGB), atol=1.5)


def _expected(maps, under) -> np.ndarray:
    """Composite by hand: under * (1 + m (crack / surface - 1)) * occlusion^(1/2.2)."""
    m = maps.mask.astype(float)[..., None]
    occ = maps.occlusion.astype(float)[..., None]
    return under * (1 + m * (CRACK_RGB / SURFACE_RGB - 1)) * occ ** (1 / 2.2)


def test_glb_without_tangents_binds_no_normal_map(tmp_path):
    mesh, uvm = plate_uvmesh(tangents=False)
    gltf, _ = _parse_glb(_run(tmp_path, mesh, uvm, synthetic_maps(surface=False)) / "rock.glb")
    assert "TANGENT" not in gltf["meshes"][0]["primitives"][0]["attributes"]
    assert "normalTexture" not in gltf["materials"][0]
    assert "occlusionTexture" in gltf["materials"][0]  # all open, but bound: one ORM file


def test_obj_map_kd_is_the_base_colour_under_the_cracks(tmp_path):
    mesh, uvm = plate_uvmesh()
    tex = _checker()
    obj = _obj_with_texture(tmp_path, mesh, tex)
    mesh = type(mesh)(**{**mesh.__dict__, "source": str(obj)})
    maps = synthetic_maps(res=32)
    got = base_color_texture(obj, 32)
    want = np.asarray(Image.fromarray(tex).resize((32, 32), Image.Resampling.LANCZOS))
    np.testing.assert_array_equal(got, want)
    out = _run(tmp_path, mesh, uvm, maps, formats=("glb", "png"))
    png = np.asarray(Image.open(out / "rock_basecolor.png"))
    gltf, binary = _parse_glb(out / "rock.glb")
    embedded = _image(gltf, binary, gltf["materials"][0]["pbrMetallicRoughness"][
        "baseColorTexture"]["index"])  # fmt: skip
    np.testing.assert_array_equal(png, embedded)  # the GLB embeds the file's very bytes
    assert (png[:8, :2] == want[:8, :2]).all() and png[0, 0, 1] > 200  # green corner, top-left
    assert maps.mask.max() > 0.9
    np.testing.assert_allclose(png, _expected(maps, want.astype(float)), atol=1.5)


def test_gltf_base_colour_texture_is_found_in_a_glb(tmp_path):
    mesh, uvm = plate_uvmesh()
    tex = _checker(32)
    src = tmp_path / "src.glb"
    write_glb(src, uvm.vertices, uvm.faces, uvm.uv, uvm.normals, tex)
    np.testing.assert_array_equal(base_color_texture(src, 32), tex)
    # A separate .gltf whose image is a file beside it.
    gltf, binary = _parse_glb(src)
    view = gltf["bufferViews"][gltf["images"][0]["bufferView"]]
    (tmp_path / "c.png").write_bytes(binary[view["byteOffset"]:][: view["byteLength"]])
    gltf["images"][0] = {"uri": "c.png"}
    gltf["buffers"][0]["uri"] = "data:application/octet-stream;base64,"
    (tmp_path / "src.gltf").write_text(json.dumps(gltf))
    np.testing.assert_array_equal(base_color_texture(tmp_path / "src.gltf", 32), tex)


def test_no_texture_gives_none_and_missing_file_warns(tmp_path):
    mesh, _ = plate_uvmesh()
    plain = tmp_path / "plain.obj"
    plain.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert base_color_texture(plain, 16) is None
    obj = _obj_with_texture(tmp_path, mesh, _checker())
    (tmp_path / "albedo map.png").unlink()
    with pytest.warns(Warning, match="albedo map.png not found; using grey"):
        assert base_color_texture(obj, 16) is None


def _validator() -> Path | None:
    node = shutil.which("node")
    for folder in (os.environ.get("CRACKBAKE_GLTF_VALIDATOR"), "/tmp/gv"):
        if node and folder:
            p = Path(folder)
            for cand in (p, p / "node_modules" / "gltf-validator"):
                if (cand / "package.json").is_file() and cand.name == "gltf-validator":
                    return cand
    return None


_JS = """
const v = require(process.argv[1]); const fs = require('fs');
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))
 .then(r => console.log(JSON.stringify(r.issues)))
 .catch(e => { console.error(String(e)); process.exit(2); });
"""


@pytest.mark.reference
@pytest.mark.skipif(_validator() is None, reason="node + gltf-validator not found "
                    "(npm install gltf-validator; CRACKBAKE_GLTF_VALIDATOR=its folder)")
@pytest.mark.parametrize("surface", [True, False])
def test_khronos_validator_reports_no_errors_or_warnings(tmp_path, surface):
    mesh, uvm = plate_uvmesh(tangents=surface)
    tex = _checker()
    obj = _obj_with_texture(tmp_path, mesh, tex)
    mesh = type(mesh)(**{**mesh.__dict__, "source": str(obj)})
    glb = _run(tmp_path, mesh, uvm, synthetic_maps(surface=surface)) / "rock.glb"
    r = subprocess.run(["node", "-e", _JS, str(_validator()), str(glb)], capture_output=True,
                       text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    issues = json.loads(r.stdout)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
    assert io.BytesIO(glb.read_bytes()).read(4) == b"glTF"
