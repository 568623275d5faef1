"""Decal libraries (``crackbake decals``): real solves and bakes on the plate, real files read back.

Expected values come from the rules themselves: the mip-safe layout from the "variant 4 texels
wide" rule, UV scale/bias from texel-centre arithmetic, the normal map's sign from the written
height map's gradient, the contact sheet's flat shade from its lighting formula.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cli_forks
import numpy as np
import pytest
from conftest import wait_for_staging
from PIL import Image

from crackbake.decals.atlas import atlas_layout, contact_sheet, mip_chain
from crackbake.decals.library import (
    LibraryParams,
    Variant,
    bake_variant,
    build_library,
    plate_mesh,
    variants,
)
from crackbake.errors import CrackbakeError
from crackbake.params import Impact

REPO = Path(__file__).resolve().parents[1]
SIM = 5000  # small simulation meshes: the tests check plumbing and conventions, not patterns


def cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return cli_forks.run(list(args), env=env, timeout=timeout)


def read(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path))


@pytest.fixture(scope="module")
def lib3(tmp_path_factory):
    """Three glass variants of 64 texels: a 2x2 grid with one empty cell."""
    out = tmp_path_factory.mktemp("lib") / "lib3"
    params = LibraryParams(out=out, preset="glass", n=3, size=0.5, res=64, seed=5, sim_faces=SIM)
    doc = build_library(params)
    return params, doc, out


def test_layout_follows_the_four_texel_mip_rule():
    for res in (64, 100, 1000, 1024, 4096):
        lay = atlas_layout(4, res)
        b = lay.block
        assert 4 <= res / b < 8  # the deepest level where the variant is still >= 4 texels
        assert lay.cell % b == 0  # level-L texels average blocks inside one cell
        assert lay.pad >= b and lay.cell - res - lay.pad >= b  # one level-L texel of gutter
        assert lay.cell - res - 2 * b < b  # and no more cell than that needs
    lay = atlas_layout(16, 1024)
    assert (lay.level, lay.cell, lay.pad, lay.width) == (8, 1536, 256, 6144)
    with pytest.raises(CrackbakeError, match="atlas"):
        atlas_layout(16, 4096)


def test_files_and_document(lib3):
    params, doc, out = lib3
    on_disk = json.loads((out / "decals.json").read_text())
    assert on_disk["format"] == "crackbake-decals" and on_disk["version"] == 1
    assert {"generator", "units", "normal_y", "textures", "decals"} <= set(on_disk)
    assert [d["name"] for d in on_disk["decals"]] == ["glass_00", "glass_01", "glass_02"]
    for role, tex in on_disk["textures"].items():
        img = read(out / tex["file"])
        atlas = on_disk["atlas"]
        assert img.shape[:2] == (atlas["height"], atlas["width"]) == (192, 192)
        assert img.dtype == (np.uint16 if role == "height" else np.uint8)  # 16-bit height
    for d in on_disk["decals"]:
        assert d["size"] == [0.5, 0.5] and d["depth"] == pytest.approx(0.125)
        u, v = d["impact"]["uv"]
        assert abs(u - 0.5) <= 0.12 and abs(v - 0.5) <= 0.12  # jittered about the centre
        assert d["cracks"] > 0 and d["crack_depth_max"] > 0
    seeds = [d["seed"] for d in on_disk["decals"]]
    assert len(set(seeds)) == 3
    manifest = json.loads((out / "manifest.json").read_text())
    assert {f["name"] for f in manifest["files"]} == {
        "decals_alpha.png", "decals_normal.png", "decals_orm.png", "decals_height.png",
        "contact_sheet.png", "decals.json",
    }  # fmt: skip


def test_variants_depend_on_seed_and_index_only():
    a = variants(LibraryParams(out=Path("x"), n=3, seed=9))
    b = variants(LibraryParams(out=Path("x"), n=6, seed=9))
    assert a == b[:3]  # a bigger library keeps the first variants
    assert variants(LibraryParams(out=Path("x"), n=3, seed=10)) != a
    assert all(v.impact is None for v in variants(LibraryParams(out=Path("x"), preset="mud")))


def _owner_regions(doc: dict) -> np.ndarray:
    """Each texel's variant: within ``g`` texels (Chebyshev) of its rectangle, else -1."""
    h, w = doc["atlas"]["height"], doc["atlas"]["width"]
    g = min(doc["atlas"]["gutter"])
    owner = np.full((h, w), -1)
    for k, d in enumerate(doc["decals"]):
        x0, y0, r, _ = d["rect_px"]
        region = owner[max(0, y0 - g) : y0 + r + g, max(0, x0 - g) : x0 + r + g]
        assert (region == -1).all()  # regions of two variants never overlap
        region[...] = k
    return owner


def test_gutters_are_edge_extended_and_mips_never_mix_variants(lib3):
    _, doc, out = lib3
    owner = _owner_regions(doc)
    level = doc["atlas"]["mip_safe_level"]
    b = 1 << level
    assert doc["decals"][0]["rect_px"][2] >> level == 4
    for tex in doc["textures"].values():
        atlas = read(out / tex["file"]).astype(np.float64)
        for k, d in enumerate(doc["decals"]):
            x0, y0, r, _ = d["rect_px"]
            ys, xs = np.nonzero(owner == k)
            ext = atlas[np.clip(ys, y0, y0 + r - 1), np.clip(xs, x0, x0 + r - 1)]
            np.testing.assert_array_equal(atlas[ys, xs], ext)  # gutter = nearest edge texel
        # Each level-L texel a bilinear tap inside variant k reads averages a block that lies
        # wholly in k's region; so changing every other texel leaves those texels unchanged.
        mips = mip_chain(atlas, level)
        for k, d in enumerate(doc["decals"]):
            x0, y0, r, _ = d["rect_px"]
            lo_x, hi_x = int(np.floor(x0 / b - 0.5)), int(np.ceil((x0 + r) / b + 0.5))
            lo_y, hi_y = int(np.floor(y0 / b - 0.5)), int(np.ceil((y0 + r) / b + 0.5))
            blocks = owner[lo_y * b : hi_y * b, lo_x * b : hi_x * b]
            assert blocks.shape == ((hi_y - lo_y) * b, (hi_x - lo_x) * b)
            assert (blocks == k).all()
            other = atlas.copy()
            other[owner != k] = np.random.default_rng(k).uniform(0, 255, other[owner != k].shape)
            np.testing.assert_array_equal(
                mip_chain(other, level)[level][lo_y:hi_y, lo_x:hi_x],
                mips[level][lo_y:hi_y, lo_x:hi_x],
            )


def test_uv_scale_bias_find_each_variant(lib3):
    """A fresh bake of variant 1, sampled through decals.json's scale/bias in both v senses."""
    params, doc, out = lib3
    d = doc["decals"][1]
    v1 = variants(params)[1]
    mesh = plate_mesh(params.size)
    from crackbake.bake.context import create_context
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs
    from crackbake.exchange.targets import pack

    ctx = create_context()
    try:
        uvm = with_tangents(prepare_uvs(mesh, "keep", params.res, cache=False, ctx=ctx))
        own = pack("mask", bake_variant(ctx, mesh, uvm, params, v1).maps, 8)
    finally:
        ctx.release()
    atlas = read(out / "decals_alpha.png")
    h, w = atlas.shape
    r = params.res
    c = (np.arange(r) + 0.5) / r  # texel centres of the decal, image row 0 = its top
    sx, sy = d["uv_scale"]
    u = c[None, :] * sx + d["uv_bias_v_down"][0]
    v_down = c[:, None] * sy + d["uv_bias_v_down"][1]
    v_up = (1 - c[:, None]) * sy + d["uv_bias_v_up"][1]  # v up: the top row is v near 1
    cols = np.floor(u * w).astype(int).repeat(r, 0)
    rows_down = np.floor(v_down * h).astype(int).repeat(r, 1)
    rows_up = np.floor((1 - v_up) * h).astype(int).repeat(r, 1)
    np.testing.assert_array_equal(atlas[rows_down, cols], own)
    np.testing.assert_array_equal(atlas[rows_up, cols], own)
    assert d["unity"]["uvScale"] == d["uv_scale"] and d["unity"]["uvBias"] == d["uv_bias_v_up"]
    assert d["unreal"]["UVBias"] == d["uv_bias_v_down"] == d["godot"]["uv1_offset"][:2]
    assert own.max() > 0  # there are cracks to find


def test_plate_frame_image_right_is_x_and_up_is_y():
    """An impact placed at (0.8, 0.75) of the plate: its star lies right of and above centre."""
    params = LibraryParams(out=Path("x"), preset="glass", n=1, size=0.5, res=128, sim_faces=SIM)
    mesh = plate_mesh(params.size)
    from crackbake.bake.context import create_context
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs

    ctx = create_context()
    try:
        uvm = with_tangents(prepare_uvs(mesh, "keep", params.res, cache=False, ctx=ctx))
        v = Variant(0, "probe", 3, Impact((0.4, 0.375, 0.0), radius=0.08))
        mask = np.asarray(bake_variant(ctx, mesh, uvm, params, v).maps.mask, np.float64)
    finally:
        ctx.release()
    rows, cols = np.nonzero(mask > 0.05)
    assert cols.mean() / 128 > 0.6  # right of centre: +X
    assert 1 - rows.mean() / 128 > 0.55  # above centre (row 0 = top): +Y


def test_normals_follow_the_height_and_dx_flips_green(tmp_path):
    """Mud (wide cracks): the GL normal leans down the written height's slope in the plate
    frame (x right, y up); DirectX is the same map with green inverted."""
    docs = {}
    for y in ("gl", "dx"):
        p = LibraryParams(out=tmp_path / y, preset="mud", n=1, size=2.0, res=128, seed=1,
                          normal_y=y, sim_faces=SIM)  # fmt: skip
        docs[y] = build_library(p)
    x0, y0, r, _ = docs["gl"]["decals"][0]["rect_px"]
    sl = np.s_[y0 : y0 + r, x0 : x0 + r]
    gl = read(tmp_path / "gl" / "decals_normal.png")[sl].astype(np.int64)
    dx = read(tmp_path / "dx" / "decals_normal.png")[sl].astype(np.int64)
    np.testing.assert_array_equal(gl[..., [0, 2]], dx[..., [0, 2]])
    assert np.abs(gl[..., 1] + dx[..., 1] - 255).max() <= 1
    height = read(tmp_path / "gl" / "decals_height.png")[sl].astype(np.float64)
    dh_drow, dh_dx = np.gradient(height)
    dh_dy = -dh_drow  # rows run down, +Y runs up
    n = gl / 127.5 - 1
    slope = np.hypot(dh_dx, dh_dy) > 0
    assert slope.sum() > 100
    assert np.corrcoef(n[..., 0][slope], -dh_dx[slope])[0, 1] > 0.5
    assert np.corrcoef(n[..., 1][slope], -dh_dy[slope])[0, 1] > 0.5


def test_contact_sheet_flat_texels_have_the_formula_shade(lib3):
    params, doc, out = lib3
    sheet = read(out / "contact_sheet.png")
    lay = atlas_layout(params.n, params.res)
    t = params.res  # thumbs of 384 texels: a 64-texel variant is shown 1:1
    assert sheet.shape == (2 * (t + 8) + 8, 2 * (t + 8) + 8, 3)
    # A flat, open, uncracked texel: albedo * (0.25 + 0.75), then the 1/2.2 display curve.
    flat = (np.array([0.72, 0.78, 0.8]) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)
    thumb = sheet[8 : 8 + t, 8 : 8 + t].reshape(-1, 3)
    assert (thumb == flat).all(axis=1).mean() > 0.5
    x0, y0, r, _ = doc["decals"][0]["rect_px"]
    cracked = read(out / "decals_alpha.png")[y0 : y0 + r, x0 : x0 + r].reshape(-1) > 25
    assert cracked.any()
    assert (thumb[cracked].sum(axis=1) < thumb[~cracked].sum(axis=1).max()).all()  # darker
    atl = {r: read(out / doc["textures"][r]["file"]) for r in ("alpha", "normal", "orm")}
    np.testing.assert_array_equal(contact_sheet(lay, atl, "gl"), sheet)  # from the written maps


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["-n", "0"], "-n 0 is out of range"),
        (["--size", "-1"], "--size -1.0 is not a plate size"),
        (["--res", "10"], "--res 10 is out of range"),
        (["--preset", "lava"], "--preset 'lava' is unknown"),
        (["-n", "16", "--res", "4096"], "atlas"),
    ],
)
def test_bad_options_give_one_line(tmp_path, args, needle):
    proc = cli("decals", *args, "-o", str(tmp_path / "o"), timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0]
    assert not (tmp_path / "o").exists()


def test_cli_run_is_deterministic_and_replaces_its_folder(tmp_path):
    out = tmp_path / "lib"
    args = ["decals", "--preset", "crackle", "-n", "2", "--size", "1", "--res", "64",
            "--sim-faces", str(SIM), "-o", str(out)]  # fmt: skip
    first = cli(*args)
    assert first.returncode == 0, first.stderr
    assert "2 crackle decals in a 192x96 atlas" in first.stderr
    sums = _hashes(out)
    second = cli(*args, "--json", "-q")  # into the same folder: a library folder is replaceable
    assert second.returncode == 0, second.stderr
    assert _hashes(out) == sums
    assert json.loads(second.stdout)["format"] == "crackbake-decals"


def _hashes(out: Path) -> dict[str, str]:
    files = json.loads((out / "manifest.json").read_text())["files"]
    return {f["name"]: f["sha256"] for f in files}


def test_sigterm_leaves_no_folder(tmp_path):
    out = tmp_path / "lib"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "crackbake", "decals", "-n", "64", "--res", "256", "-o", str(out)],
        stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    wait_for_staging(proc, tmp_path)
    time.sleep(1.0)  # inside the variants' solves and bakes
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == "error: interrupted; no outputs were written"
    assert not out.exists() and not list(tmp_path.iterdir())


@pytest.mark.slow
def test_sixteen_variants_at_256(tmp_path):
    doc = build_library(LibraryParams(out=tmp_path / "l", n=16, res=256, seed=2, sim_faces=SIM))
    assert doc["atlas"]["width"] == doc["atlas"]["height"] == 4 * 384
    assert all(d["cracks"] > 0 for d in doc["decals"])
    assert len({d["seed"] for d in doc["decals"]}) == 16
