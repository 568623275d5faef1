"""Engine profiles (crackbake.exchange.targets): each target's file set, channel packing read
back from the PNGs with OpenImageIO, normal conventions."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import tiny_network
from maps_factory import plate_uvmesh, synthetic_maps

from crackbake.errors import CrackbakeError
from crackbake.exchange.bundle import write_outputs
from crackbake.exchange.targets import TARGETS, describe
from crackbake.params import TARGETS as TARGET_NAMES
from crackbake.params import RunParams
from crackbake.transaction.stage import OutputStage


def _read(path) -> np.ndarray:
    """Pixels as stored (uint8/uint16), alpha not premultiplied, (H, W, C)."""
    import OpenImageIO as oiio

    cfg = oiio.ImageSpec()
    cfg.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), cfg)
    spec = inp.spec()
    fmt = "uint16" if spec.format == oiio.TypeDesc("uint16") else "uint8"
    px = inp.read_image(0, 0, 0, spec.nchannels, fmt)
    inp.close()
    return px.reshape(spec.height, spec.width, spec.nchannels)


def _write(tmp_path, target, normal_y=None, maps=None, formats=("png",)):
    mesh, uvm = plate_uvmesh()
    maps = synthetic_maps() if maps is None else maps
    params = RunParams(mesh=mesh.source, target=target, normal_y=normal_y, formats=formats)
    out = tmp_path / f"{target}-{normal_y}"
    with OutputStage(out) as stage:
        write_outputs(stage, "rock", params, mesh, uvm, tiny_network(), maps)
        stage.commit()
    return out, maps


def _q(x, bits=8):
    top = 255 if bits == 8 else 65535
    return np.floor(np.clip(np.asarray(x, np.float64), 0, 1) * top + 0.5)


def test_the_table_covers_every_target_option():
    assert tuple(TARGETS) == TARGET_NAMES
    for t in TARGETS.values():
        names = [f.name for f in t.files]
        assert len(set(names)) == len(names) and t.normal_y in ("gl", "dx")
        assert {"base_color", "normal", "data"} <= {f.content for f in t.files}


@pytest.mark.parametrize("target", TARGET_NAMES)
def test_each_target_writes_its_files_packed_as_documented(tmp_path, target):
    out, maps = _write(tmp_path, target)
    written = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    expected = {f.name.format(stem="rock") for f in TARGETS[target].files}
    assert written == expected | {"cracks.json", "cracks.obj"}
    mask = maps.mask.astype(np.float64)
    occ = maps.occlusion.astype(np.float64)
    width, depth = maps.width.astype(np.float64), maps.depth.astype(np.float64)
    rough = 0.8 + 0.2 * mask
    for f in TARGETS[target].files:
        px = _read(out / f.name.format(stem="rock")).astype(np.float64)
        assert px.shape[:2] == (32, 32)
        b = f.bits
        want = {
            "mask": [mask],
            "depth": [depth / depth.max()],
            "occlusion": [occ],
            "roughness": [rough],
            "orm": [occ, rough, 0 * mask],
            "mask_map": [0 * mask, occ, 1 + 0 * mask, 1 - rough],
            "metallic_smoothness": [0 * mask, 0 * mask, 0 * mask, 1 - rough],
            "data": [mask, width / width.max(), depth / depth.max(), maps.time],
        }.get(f.content)  # fmt: skip
        if want is None:
            continue
        assert px.shape[2] == len(want), f.name
        for c, plane in enumerate(want):
            # float16 sources round once more; allow one step.
            np.testing.assert_allclose(px[..., c], _q(plane, b), atol=1, err_msg=f"{f.name}[{c}]")


def _decoded_normal(path) -> np.ndarray:
    px = _read(path).astype(np.float64)
    top = 255.0 if px.max() <= 255 and _read(path).dtype == np.uint8 else 65535.0
    return px / top * 2 - 1


def test_unreal_normals_have_y_flipped_relative_to_gltf(tmp_path):
    gl_dir, maps = _write(tmp_path, "gltf")
    dx_dir, _ = _write(tmp_path, "unreal")
    gl = _decoded_normal(gl_dir / "rock_normal.png")
    dx = _decoded_normal(dx_dir / "T_rock_N.png")
    n = maps.normal.astype(np.float64)
    step = 1 / 255 + 1e-9
    assert np.abs(gl - n).max() <= step
    assert np.abs(dx[..., 1] + n[..., 1]).max() <= step  # DirectX: green down
    np.testing.assert_array_equal(dx[..., [0, 2]], gl[..., [0, 2]])
    assert np.abs(n[..., 1]).max() > 0.3  # the flip is visible


def test_normal_y_option_overrides_the_target(tmp_path):
    gl_dir, _ = _write(tmp_path, "gltf")
    ue_gl, _ = _write(tmp_path, "unreal", normal_y="gl")
    np.testing.assert_array_equal(_read(ue_gl / "T_rock_N.png"), _read(gl_dir / "rock_normal.png"))
    gd_dx, _ = _write(tmp_path, "godot", normal_y="dx")
    ue, _ = _write(tmp_path, "unreal")
    np.testing.assert_array_equal(_read(gd_dx / "rock_normal.png"), _read(ue / "T_rock_N.png"))


def test_blender_normals_are_16_bit_and_accurate(tmp_path):
    out, maps = _write(tmp_path, "blender")
    px = _read(out / "rock_normal.png")
    assert px.dtype == np.uint16
    assert np.abs(px / 65535.0 * 2 - 1 - maps.normal).max() <= 1 / 65535 + 1e-6


def test_without_baked_normals_the_maps_are_flat_and_open(tmp_path):
    out, _ = _write(tmp_path, "gltf", maps=synthetic_maps(surface=False))
    nrm = _read(out / "rock_normal.png")
    assert (nrm[..., 0] == 128).all() and (nrm[..., 1] == 128).all() and (nrm[..., 2] == 255).all()
    assert (_read(out / "rock_orm.png")[..., 0] == 255).all()


def test_data_maps_are_untagged_and_base_colour_is_srgb(tmp_path):
    out, _ = _write(tmp_path, "gltf")
    for name in ("rock_data.png", "rock_depth.png", "rock_mask.png", "rock_orm.png"):
        data = (out / name).read_bytes()
        assert b"sRGB" not in data and b"gAMA" not in data and b"iCCP" not in data, name
    assert b"sRGB" in (out / "rock_basecolor.png").read_bytes()


def test_manifest_entry_states_scales_and_channels():
    maps = synthetic_maps()
    d = describe("unreal", None, "rock", maps)
    assert d["normal_y"] == "dx" and d["normal_baked"] is True
    assert d["data_scales"] == pytest.approx({"width": float(maps.width.max()),
                                              "depth": float(maps.depth.max())})  # fmt: skip
    assert d["files"]["T_rock_ORM.png"]["channels"].startswith("R occlusion")
    assert describe("gltf", "dx", "rock", maps)["normal_y"] == "dx"


def test_unknown_target_is_one_clear_error():
    with pytest.raises(CrackbakeError, match="--target 'cryengine' is unknown; use one of gltf"):
        RunParams(mesh="x.obj", target="cryengine").validate()
    with pytest.raises(CrackbakeError, match="--normal-y 'up' is unknown"):
        RunParams(mesh="x.obj", normal_y="up").validate()


def test_cli_target_unreal_writes_its_set_and_the_manifest_says_so(tmp_path):
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    out = tmp_path / "ue"
    r = subprocess.run(
        [sys.executable, "-m", "crackbake", str(repo / "examples" / "spot.obj"), "--res", "128",
         "--sim-faces", "300", "--impact", "0.4,0,0.3", "--max-cracks", "3",
         "--target", "unreal", "--formats", "png,glb", "-o", str(out), "-q"],
        capture_output=True, text=True, timeout=300,
        env={**os.environ, "PYTHONPATH": str(repo)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    names = {p.name for p in out.iterdir()}
    want = {"T_spot_BC.png", "T_spot_N.png", "T_spot_ORM.png", "T_spot_Data.png", "spot.glb"}
    assert want <= names
    manifest = json.loads((out / "manifest.json").read_text())
    tex = manifest["maps"]["textures"]
    assert tex["target"] == "unreal" and tex["normal_y"] == "dx"
    assert manifest["params"]["target"] == "unreal" and tex["data_scales"]["width"] > 0
    assert _read(out / "T_spot_Data.png").dtype == np.uint16


def test_fused_data_map_equals_the_numpy_quantisation():
    # The fused 16-bit kernel against quantise() plane by plane, on values that exercise the
    # rounding, the clipping and NaN (-> 0) of every channel.
    from types import SimpleNamespace

    from crackbake.exchange.targets import data_scales, pack, quantise

    rng = np.random.default_rng(3)
    shape = (37, 53)
    mask = rng.uniform(-0.2, 1.2, shape).astype(np.float16)
    width = rng.uniform(0, 0.01, shape).astype(np.float16)
    time = rng.uniform(0, 1, shape).astype(np.float16)
    depth = rng.uniform(-1e-3, 5e-3, shape).astype(np.float32)
    mask[0, 0], width[1, 1], time[2, 2], depth[3, 3] = np.nan, np.nan, np.nan, np.nan
    depth[4, 4] = 1.0  # far above the scale: clipped to the top
    maps = SimpleNamespace(mask=mask, width=width, time=time, depth=depth, normal=None,
                           occlusion=None)
    s = data_scales(maps)
    want = np.stack([quantise(mask, 16), quantise(width, 16, s["width"]),
                     quantise(depth, 16, s["depth"]), quantise(time, 16)], axis=-1)
    got = pack("data", maps, 16)
    assert got.dtype == np.dtype(">u2") and got.shape == (*shape, 4)
    assert np.array_equal(got.astype(np.int64), want.astype(np.int64))
    assert got[4, 4, 2] == 65535 and got[3, 3, 2] == 0 and got[0, 0, 0] == 0
