"""UDIM tiles: detection, a page per tile continuous across tile edges, names, manifest, GLB.

The meshes are generated: a 2 x 2 plate whose unit squares each have their UVs on a tile of
their own (1001, 1002, 1011, 1012), islands inset by 0.05 of a tile.
"""

from __future__ import annotations

import json
import os
import subprocess
import warnings
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from crackbake.bake.raster import bake_cracks
from crackbake.bake.tangents import with_tangents
from crackbake.bake.udim import bake_udim, packed_uv, udim_name
from crackbake.bake.uv import check_uvs, prepare_uvs
from crackbake.bake.uv.uvmesh import bake_arrays
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import load_mesh
from crackbake.io.sidecar import write_sidecar
from crackbake.network import Crack, CrackNetwork, Segments, mesh_info
from crackbake.params import RunParams
from crackbake.pipeline import run
from tests.conftest import make_mesh, uv_grid

INSET = 0.05  # islands span 0.05..0.95 of their tile


def tiled_plate(n: int = 8, tiles=((0, 0), (1, 0), (0, 1), (1, 1)), shift=None):
    """The 2 x 2 plate: unit square (i, j) (x in [i, i+1], y in [j, j+1]) with an n x n grid,
    its UVs on tile ``tiles[2 j + i]``; vertices on square edges are separate per square (a UV
    seam).  ``shift`` moves the UVs of square 0's vertices by a (du, dv)."""
    pts, faces = uv_grid(n, n, 1.0, 1.0)
    verts, uvs, fs = [], [], []
    for k, (i, j) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        base = len(verts) * len(pts)
        verts.append(np.c_[pts + [i, j], np.zeros(len(pts))])
        uv = np.asarray(tiles[k], float) + INSET + (1 - 2 * INSET) * pts
        if k == 0 and shift is not None:
            uv = uv + np.asarray(shift, float)
        uvs.append(uv)
        fs.append(faces + base)
    return make_mesh(np.concatenate(verts), np.concatenate(fs), np.concatenate(uvs),
                     source="tiles.obj")  # fmt: skip


def _segments(lines, width: float = 0.03) -> Segments:
    a = np.array([p for p, _ in lines], float)
    b = np.array([q for _, q in lines], float)
    k = len(lines)
    return Segments(a=a, b=b, width=np.full((k, 2), width), depth=np.full((k, 2), width / 2),
                    time=np.tile([0.0, 1.0], (k, 1)), crack_id=np.arange(k))  # fmt: skip


# Cracks crossing the tile edges: 1001 -> 1002 along y = 0.5, 1002 -> 1012 along x = 1.5.
LINES = [((0.2, 0.5, 0.0), (1.8, 0.5, 0.0)), ((1.5, 0.2, 0.0), (1.5, 1.8, 0.0))]


def test_udim_layout_is_kept_with_its_tiles(gl_ctx):
    mesh = tiled_plate()
    check = check_uvs(mesh, ctx=gl_ctx)
    assert check.usable and check.udim and check.overlap_fraction == 0.0
    np.testing.assert_array_equal(check.tiles, [[0, 0], [1, 0], [0, 1], [1, 1]])
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        uvm = prepare_uvs(mesh, "auto", res=64, ctx=gl_ctx)
    assert uvm.method == "kept" and uvm.udim is not None and len(uvm.udim) == 4
    np.testing.assert_array_equal(uvm.uv, mesh.uv)  # the artist's layout, untouched


@pytest.mark.parametrize(
    ("shift", "why"),
    [((0.6, 0.0), "faces straddle two tiles"), ((0.5, 0.0), "islands run across a tile edge"),
     ((-1.0, 0.0), "on negative tiles")],
)
def test_bad_udim_layouts_warn_and_unwrap(gl_ctx, shift, why):
    mesh = tiled_plate(4, shift=shift)
    check = check_uvs(mesh, ctx=gl_ctx)
    assert not check.usable and why in check.reason
    with pytest.warns(CrackbakeWarning, match=f"{why}.*unwrapping with xatlas instead; move each"):
        uvm = prepare_uvs(mesh, "auto", res=64, cache=False, ctx=gl_ctx)
    assert uvm.method == "unwrapped" and uvm.udim is None
    with pytest.raises(CrackbakeError, match=f"cannot keep the UVs: .*{why}"):
        prepare_uvs(mesh, "keep", res=64, ctx=gl_ctx)


def test_tiles_bake_as_one_atlas_continuous_across_tile_edges(gl_ctx):
    res = 64
    uvm = with_tangents(prepare_uvs(tiled_plate(), "keep", res=res, ctx=gl_ctx))
    arrays = bake_arrays(uvm)
    segs = _segments(LINES)
    tiles = bake_udim(arrays, uvm.udim, segs, res, ctx=gl_ctx)
    assert tiles.numbers == [1001, 1002, 1011, 1012]
    # The same mesh on one page, its tiles side by side (uv / 2: tile (i, j) -> quadrant (i, j)),
    # baked at twice the resolution: every tile's texels are the page's quadrant's.
    page = bake_cracks(arrays["vertices"], arrays["faces"], arrays["uv"] / 2, segs, 2 * res,
                       max_distance=tiles.max_distance, normals=arrays["normals"],
                       tangents=arrays["tangents"], ctx=gl_ctx)  # fmt: skip
    for (i, j), maps in zip(uvm.udim, tiles.pages, strict=True):
        rows = slice((1 - j) * res, (2 - j) * res)  # image row 0 is v = 1
        cols = slice(i * res, (i + 1) * res)
        inside = page.inside[rows, cols]
        assert (maps.inside == inside).mean() > 0.995
        both = maps.inside & inside
        for name in ("mask", "width", "distance", "occlusion"):
            a = getattr(maps, name).astype(np.float32)[both]
            b = getattr(page, name)[rows, cols].astype(np.float32)[both]
            np.testing.assert_allclose(a, b, atol=2e-3, err_msg=name)
    # The crack along y = 0.5 reaches the inner edge of 1001's island and goes on in 1002's.
    row = res - 1 - int((INSET + 0.9 * 0.5) * res)  # v of y = 0.5, image rows from the top
    edge_in, edge_out = int(0.94 * res), int(0.06 * res)
    a, b = tiles.pages[0], tiles.pages[1]
    assert a.mask[row, edge_in] > 0.5 and b.mask[row, edge_out] > 0.5
    assert a.width[row, edge_in] == pytest.approx(b.width[row, edge_out], rel=1e-3)
    # ... and the one along x = 1.5 from 1002 into 1012, and tile 1011 has no crack.
    col = int((INSET + 0.9 * 0.5) * res)
    assert tiles.pages[1].mask[int(0.06 * res), col] > 0.5  # 1002's top edge
    assert tiles.pages[3].mask[int(0.94 * res), col] > 0.5  # 1012's bottom edge
    assert tiles.pages[2].mask.max() == 0
    # Shared data scales: the tiles' data maps read with one width and depth divisor.
    assert all(p.scales == tiles.scales for p in tiles.pages)


def _plate_run(tmp_path, formats=("exr", "png", "glb", "preview"), target="gltf", res=64,
               materials=None, extra=(), one_page=False):
    """Bake the plate written as ``tiles.obj`` with the crossing cracks (:data:`LINES`).
    ``materials``: one material name per square (``usemtl`` before its faces, ``mtllib
    tiles.mtl``: the caller writes it); ``extra``: more keywords for RunParams; ``one_page``:
    the same plate with its UVs halved onto one 0-1 page (tile (i, j) -> quadrant (i, j))."""
    mesh = tiled_plate()
    if one_page:
        mesh = make_mesh(mesh.vertices, mesh.faces, mesh.uv / 2, source="tiles.obj")
    obj = tmp_path / "tiles.obj"
    lines = [f"v {x} {y} {z}" for x, y, z in mesh.vertices]
    lines += [f"vt {u} {v}" for u, v in mesh.uv]
    per_square = len(mesh.faces) // 4
    if materials is not None:
        lines.insert(0, "mtllib tiles.mtl")
    for k, (a, b, c) in enumerate(mesh.faces + 1):
        if materials is not None and k % per_square == 0:
            lines.append(f"usemtl {materials[k // per_square]}")
        lines.append(f"f {a}/{a} {b}/{b} {c}/{c}")
    obj.write_text("\n".join(lines) + "\n")
    loaded = load_mesh(obj)
    cracks = []
    for k, (p, q) in enumerate(LINES):
        pts = np.linspace(p, q, 17)
        cen = loaded.vertices[loaded.faces].mean(axis=1)
        face = np.argmin(((pts[:, None] - cen[None]) ** 2).sum(-1), axis=1)
        cracks.append(Crack(id=k, points=pts, faces=face, time=np.linspace(0, 1, 17),
                            width=np.full(17, 0.03), depth=np.full(17, 0.015)))  # fmt: skip
    side = tmp_path / "net.json"
    write_sidecar(CrackNetwork(cracks=cracks, mesh=mesh_info(loaded)), side)
    out = tmp_path / f"out_{target}"
    result = run(RunParams(mesh=obj, cracks=side, res=res, out=out, formats=formats,
                           target=target, **dict(extra)))  # fmt: skip
    return result, out


def test_a_udim_run_writes_every_map_per_tile_and_lists_the_tiles(tmp_path):
    result, out = _plate_run(tmp_path, formats=("exr", "png", "glb", "preview"))
    names = sorted(p.name for p in out.iterdir())
    for number in (1001, 1002, 1011, 1012):
        assert f"tiles_cracks.{number}.exr" in names
        for m in ("mask", "depth", "basecolor", "normal", "orm", "data"):
            assert f"tiles_{m}.{number}.png" in names
    assert "tiles_cracks.exr" not in names and "tiles.glb" in names and "preview.png" in names
    udim = result.manifest["uv"]["udim"]
    assert [t["udim"] for t in udim["tiles"]] == [1001, 1002, 1011, 1012]
    assert udim["resolution_per_tile"] == 64 and udim["glb_grid"] == [2, 2]
    assert "tiles_mask.1002.png" in udim["tiles"][1]["files"]
    assert "tiles_mask.<UDIM>.png" in result.manifest["maps"]["textures"]["files"]
    # Each tile is a 64 x 64 EXR whose mask holds the cracks crossing it.
    for number, crossed in ((1001, True), (1002, True), (1011, False), (1012, True)):
        buf = oiio.ImageBuf(str(out / f"tiles_cracks.{number}.exr"))
        spec = buf.spec()
        assert (spec.width, spec.height) == (64, 64)
        mask = buf.get_pixels(oiio.FLOAT)[..., spec.channelnames.index("crack.mask.V")]
        assert (mask.max() > 0.5) == crossed


def test_the_glb_packs_the_tiles_with_remapped_uvs(tmp_path):
    from tests.test_pipeline import accessor, read_glb

    result, out = _plate_run(tmp_path, formats=("glb",))
    doc, binary = read_glb(out / "tiles.glb")
    prim = doc["meshes"][0]["primitives"][0]
    uv = accessor(doc, binary, prim["attributes"]["TEXCOORD_0"])
    assert uv.min() >= 0 and uv.max() <= 1
    # glTF stores (u, 1 - v); the square (i, j)'s UVs land in grid cell (i, j) of the 2 x 2 page.
    pos = accessor(doc, binary, prim["attributes"]["POSITION"])
    square = np.floor(np.clip(pos[:, :2], 0, 1.999)).astype(int)
    cell = np.floor(np.c_[uv[:, 0], 1 - uv[:, 1]] * 2).astype(int)
    inner = ((pos[:, :2] % 1 > 0.01) & (pos[:, :2] % 1 < 0.99)).all(axis=1)
    np.testing.assert_array_equal(cell[inner], square[inner])
    image = doc["images"][doc["textures"][doc["materials"][0]["pbrMetallicRoughness"][
        "baseColorTexture"]["index"]]["source"]]  # fmt: skip
    assert image["mimeType"] == "image/png"


def test_packed_uv_puts_each_tile_in_its_cell():
    mesh = tiled_plate(2, tiles=((0, 0), (3, 0), (0, 2), (9, 4)))
    tiles = np.array([[0, 0], [3, 0], [0, 2], [9, 4]])
    uv = packed_uv(mesh.uv, mesh.faces, tiles)
    cells = np.floor(uv * 2).astype(int)  # k = 2
    expect = np.repeat([[0, 0], [1, 0], [0, 1], [1, 1]], len(mesh.uv) // 4, axis=0)
    np.testing.assert_array_equal(cells, expect)
    assert udim_name("a_mask.png", 1012) == "a_mask.1012.png"


def test_the_packed_page_leaves_no_row_empty():
    from types import SimpleNamespace

    from crackbake.bake.udim import UdimMaps, grid_size, packed_maps

    assert [grid_size(n) for n in (1, 2, 3, 5, 10)] == [(1, 1), (2, 1), (2, 2), (3, 2), (4, 3)]
    res = 16

    def page(value):
        normal = np.zeros((res, res, 3), np.float32)
        normal[..., 0] = value  # unnormalised on purpose: a halving renormalises
        normal[..., 2] = 1.0
        return SimpleNamespace(res=res, mask=np.full((res, res), value, np.float16),
                               normal=normal, occlusion=np.full((res, res), 1 - value,
                                                                np.float16), look=None)

    two = packed_maps(UdimMaps(np.array([[0, 0], [1, 0]]), [page(0.25), page(0.75)]), 32)
    assert two.mask.shape == (16, 32) and two.res == 32
    assert two.mask[:, :16].max() == 0.25 and two.mask[:, 16:].min() == 0.75
    assert packed_maps(UdimMaps(np.array([[0, 0], [1, 0]]), [page(0.25), page(0.75)]),
                       16).mask.shape == (8, 16)  # at most 16 wide: 8-texel cells
    three = packed_maps(UdimMaps(np.array([[0, 0], [1, 0], [0, 1]]),
                                 [page(0.25), page(0.5), page(0.75)]), 16)  # fmt: skip
    # Halved into 8-texel cells; tile 3 in the top-left cell (v up), the top-right one empty.
    assert three.mask.shape == (16, 16)
    assert three.mask[8:, :8].max() == 0.25 and three.mask[8:, 8:].min() == 0.5
    assert three.mask[:8, :8].min() == 0.75 and three.mask[:8, 8:].max() == 0
    assert three.occlusion[:8, 8:].min() == 1 and (three.normal[:8, 8:] == [0, 0, 1]).all()
    np.testing.assert_allclose(np.linalg.norm(three.normal, axis=-1), 1, rtol=1e-6)


@pytest.mark.parametrize(("target", "warns"), [("unreal", False), ("unity", True)])
def test_engines_without_udim_get_one_warning(tmp_path, target, warns):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result, out = _plate_run(tmp_path, formats=("png",), target=target)
    said = [str(w.message) for w in caught if "read no UDIM sets" in str(w.message)]
    assert len(said) == (1 if warns else 0)
    assert result.manifest["maps"]["textures"]["engine_reads_udim"] is not warns
    if target == "unreal":
        assert (out / "T_tiles_BC.1012.png").is_file()


def _validator() -> Path | None:
    folder = os.environ.get("CRACKBAKE_GLTF_VALIDATOR")
    if folder:
        for cand in (Path(folder), Path(folder) / "node_modules" / "gltf-validator"):
            if (cand / "package.json").is_file() and cand.name == "gltf-validator":
                return cand
    return None


@pytest.mark.reference
@pytest.mark.skipif(_validator() is None, reason="CRACKBAKE_GLTF_VALIDATOR not set")
def test_the_packed_glb_is_validator_clean(tmp_path):
    from tests.test_bundle_glb import _JS

    _, out = _plate_run(tmp_path, formats=("glb",))
    r = subprocess.run(["node", "-e", _JS, str(_validator()), str(out / "tiles.glb")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    issues = json.loads(r.stdout)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def test_inspect_reads_a_udim_set_and_one_tile(tmp_path):
    from click.testing import CliRunner

    from crackbake.cli.inspect import inspect
    from crackbake.exchange.inspect import inspect_exr, inspect_udim

    _, out = _plate_run(tmp_path, formats=("exr",))
    info, per_tile = inspect_udim(out / "tiles_cracks.<UDIM>.exr")
    assert info.tiles == [1001, 1002, 1011, 1012] and set(per_tile) == set(info.tiles)
    mask = next(c for c in info.channels if c.name == "crack.mask.V")
    one = [next(c for c in inspect_exr(out / f"tiles_cracks.{n}.exr")[0].channels
                if c.name == "crack.mask.V") for n in info.tiles]  # fmt: skip
    assert mask.max == max(c.max for c in one) and mask.min == min(c.min for c in one)
    assert mask.nonzero == pytest.approx(np.mean([c.nonzero for c in one]))
    r = CliRunner().invoke(inspect, [str(out / "tiles_cracks.<UDIM>.exr"), "--png",
                                     str(tmp_path / "pics")])  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "UDIM set of 4 tiles (1001, 1002, 1011, 1012), each 64x64" in r.output
    assert (tmp_path / "pics" / "1012_crack_mask.png").is_file()
    r = CliRunner().invoke(inspect, [str(out / "tiles_cracks.1002.exr")])
    assert r.exit_code == 0 and "64x64" in r.output
    r = CliRunner().invoke(inspect, [str(out / "other.<UDIM>.exr")])
    assert r.exit_code == 2 and "no tile of the UDIM set" in r.output


def test_usd_references_the_tiles_with_the_udim_token(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom, UsdShade

    _, out = _plate_run(tmp_path, formats=("png", "usd"))
    stage = Usd.Stage.Open(str(out / "tiles.usda"))
    prim = stage.GetPrimAtPath("/tiles/mesh")
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    surface = material.ComputeSurfaceSource()[0]
    (src,) = surface.GetInput("diffuseColor").GetConnectedSources()[0]
    path = UsdShade.Shader(src.source.GetPrim()).GetInput("file").Get().path
    assert path == "./tiles_basecolor.<UDIM>.png"
    for n in (1001, 1002, 1011, 1012):
        assert (out / f"tiles_basecolor.{n}.png").is_file()
    # The UVs stay on their tiles.
    uv = np.asarray(UsdGeom.PrimvarsAPI(prim).GetPrimvar("st").ComputeFlattened())
    assert uv[:, 0].max() > 1.5 and uv[:, 1].max() > 1.5
    # USD's own UDIM resolver finds the four tiles of every texture the material reads.
    layer = stage.GetRootLayer()
    files = {UsdShade.Shader(p).GetInput("file").Get().path for p in stage.Traverse()
             if p.GetTypeName() == "Shader" and UsdShade.Shader(p).GetInput("file")}  # fmt: skip
    assert len(files) >= 4
    for f in files:
        assert UsdShade.UdimUtils.IsUdimIdentifier(f)
        tiles = UsdShade.UdimUtils.ResolveUdimTilePaths(f, layer)
        assert sorted(t for _, t in tiles) == ["1001", "1002", "1011", "1012"], f
    # The validators: only the MaterialX ids usd-core's registry lacks (as tests/test_usd.py),
    # and the normal-map check, which opens the file and does not expand <UDIM> (usd-core 0.26).
    from pxr import UsdValidation as V

    reg = V.ValidationRegistry()
    names = [m.name for m in reg.GetAllValidatorMetadata() if "UsdzValidators" not in
             list(m.GetKeywords())]  # fmt: skip
    left = [e for e in V.ValidationContext(reg.GetOrLoadValidatorsByName(names)).Validate(stage)
            if e.GetName() != "MissingShaderIdInRegistry"]  # fmt: skip
    assert all(e.GetName() == "InvalidFile" and "<UDIM>" in e.GetMessage() for e in left), [
        e.GetMessage() for e in left]  # fmt: skip


def test_a_solved_udim_run_writes_stress_per_tile(tmp_path):
    """The solver on the 2 x 2-tile plate: crack and stress masters per tile; the stress maps
    cover each tile's island (its faces moved onto the page), not another tile's."""
    from click.testing import CliRunner

    from crackbake.cli import main
    from crackbake.exchange.exr import read_exr

    mesh = tiled_plate(6)
    obj = tmp_path / "tiles.obj"
    lines = [f"v {x} {y} {z}" for x, y, z in mesh.vertices]
    lines += [f"vt {u} {v}" for u, v in mesh.uv]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in mesh.faces + 1]
    obj.write_text("\n".join(lines) + "\n")
    out = tmp_path / "o"
    r = CliRunner().invoke(main, [str(obj), "--preset", "glass", "--impact", "1,1,0:0.6",
                                  "--sim-faces", "1500", "--res", "64", "--formats",
                                  "exr,stress", "-o", str(out), "-q"])  # fmt: skip
    assert r.exit_code == 0, r.output
    stress = {}
    for n in (1001, 1002, 1011, 1012):
        cracks, _ = read_exr(out / f"tiles_cracks.{n}.exr")
        assert cracks["crack.mask.V"].max() > 0.5  # the impact at the corner all four share
        stress[n] = read_exr(out / f"tiles_stress.{n}.exr")[0]["stress0.p1.V"]
    # The initial stress is smooth in world space: the columns either side of the x = 1 edge
    # (1001's island ends at u = 0.95, 1002's starts at 0.05) agree, as on one page.
    rows = slice(8, 56)
    left, right = stress[1001][rows, 60], stress[1002][rows, 3]
    assert np.abs(left).max() > 0
    np.testing.assert_allclose(left, right, rtol=0.1, atol=0.05 * np.abs(left).max())


@pytest.mark.reference
def test_blender_reads_the_tiles_and_the_usd_udim_textures(tmp_path):
    from tests.blender_runner import run_blender

    pytest.importorskip("pxr")
    _, out = _plate_run(tmp_path, formats=("png", "usd"), target="blender")
    got = run_blender("udim_tiles.py", out / "tiles_base_color.1001.png", out / "tiles.usda")
    assert [t["number"] for t in got["tiles"]] == [1001, 1002, 1011, 1012]
    assert all(t["size"] == [64, 64] for t in got["tiles"])
    images = got["usd_images"]
    assert images and all(i["source"] == "TILED" for i in images.values()), images
    assert all(i["tiles"] == [1001, 1002, 1011, 1012] for i in images.values()), images
    assert "tiles_base_color.<UDIM>.png" in images
    assert got["uv_max"][0] > 1.5 and got["uv_max"][1] > 1.5  # the layout kept its tiles


def test_usdz_is_not_written_for_tiles_with_one_warning(tmp_path):
    pytest.importorskip("pxr")
    with pytest.warns(CrackbakeWarning, match="--formats usdz: AR Quick Look .* no UDIM"):
        result, out = _plate_run(tmp_path, formats=("usd", "usdz"))
    assert (out / "tiles.usda").is_file() and not (out / "tiles.usdz").exists()
    assert "tiles.usdz" not in [f["name"] for f in result.files]


def test_islands_overlapping_on_one_tile_warn_as_overlap(gl_ctx):
    # Squares 1 and 2 both on tile 1002: kept (UDIM), measured per tile, the overlap warned.
    mesh = tiled_plate(4, tiles=((0, 0), (1, 0), (1, 0), (1, 1)))
    with pytest.warns(CrackbakeWarning, match="overlaps .* cracks will show twice"):
        uvm = prepare_uvs(mesh, "auto", res=64, ctx=gl_ctx)
    np.testing.assert_array_equal(uvm.udim, [[0, 0], [1, 0], [1, 1]])
    # Three islands of one area on three tiles, the one on 1002 covered twice: 1/3 of the texels.
    assert uvm.overlap_fraction == pytest.approx(1 / 3, abs=0.02)


NUMBERS = (1001, 1002, 1011, 1012)


def _tile_textures(folder: Path, name: str = "albedo.{}.png", res: int = 64) -> dict:
    """A distinct 8-bit texture per tile (its own hue plus a fine checker, so a texel from the
    wrong tile or place shows), saved as ``name.format(number)``; number -> (res, res, 3)."""
    from PIL import Image

    y, x = np.mgrid[:res, :res]
    out = {}
    for k, number in enumerate(NUMBERS):
        img = np.empty((res, res, 3), np.uint8)
        img[...] = [60 + 40 * k, 200 - 35 * k, 90 + 20 * (k % 2)]
        img[(x // 4 + y // 4) % 2 == 1] += 25
        out[number] = img
        Image.fromarray(img).save(folder / name.format(number))
    return out


def _png(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"))


@pytest.mark.parametrize("map_kd", ["albedo.<UDIM>.png", "albedo.%(UDIM)d.png",
                                    "albedo.1001.png", "per-material"])  # fmt: skip
def test_each_tile_composites_the_cracks_over_its_own_texture(tmp_path, map_kd):
    from tests.test_pipeline import read_glb

    tex = _tile_textures(tmp_path)
    if map_kd == "per-material":  # Maya-style: one material per tile, each naming its file
        (tmp_path / "tiles.mtl").write_text("".join(
            f"newmtl m{n}\nmap_Kd albedo.{n}.png\n" for n in NUMBERS))
        materials = [f"m{n}" for n in NUMBERS]
    else:
        (tmp_path / "tiles.mtl").write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd -bm 1 {map_kd}\n")
        materials = ["skin"] * 4
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, out = _plate_run(tmp_path, formats=("exr", "png", "glb"), materials=materials)
    said = [str(w.message) for w in caught if issubclass(w.category, CrackbakeWarning)]
    assert not [m for m in said if "texture" in m or "base-colour" in m or "grey" in m], said
    from crackbake.exchange.exr import read_exr

    tiles = {}
    for number in NUMBERS:
        planes, _ = read_exr(out / f"tiles_cracks.{number}.exr")
        mask, occ = planes["crack.mask.V"], planes["crack.occlusion.V"]
        base = _png(out / f"tiles_basecolor.{number}.png")
        tiles[number] = base
        off = (mask == 0) & (occ == 1)
        assert off.mean() > 0.5
        np.testing.assert_array_equal(base[off], tex[number][off])  # the tile's own texture
        on = mask > 0.5
        assert on.any() == (number != 1011)  # 1011 has no crack
        # On the cracks: the texture darkened towards the crack colour (the same composite
        # as one page, by hand: texture x (1 + m (crack / surface - 1)) x occlusion^(1/2.2)).
        from crackbake.exchange.materials import CRACK_RGB, SURFACE_RGB

        m, o = mask.astype(float)[..., None], occ.astype(float)[..., None]
        want = tex[number] * (1 + m * (CRACK_RGB / SURFACE_RGB - 1)) * o ** (1 / 2.2)
        np.testing.assert_allclose(base, want, atol=1.5)
        assert (base[on] < tex[number][on]).all()
    # The GLB's packed page (2 x 2 cells of 64, tile i in cell (i % 2, i // 2) from the
    # bottom left) is made of the composited tiles.
    doc, binary = read_glb(out / "tiles.glb")
    ref = doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    view = doc["bufferViews"][doc["images"][doc["textures"][ref]["source"]]["bufferView"]]
    from io import BytesIO

    from PIL import Image

    start = view.get("byteOffset", 0)
    page = np.asarray(Image.open(BytesIO(binary[start:start + view["byteLength"]])).convert("RGB"))
    assert page.shape == (128, 128, 3)
    for i, number in enumerate(NUMBERS):
        r0, c0 = (1 - i // 2) * 64, (i % 2) * 64
        np.testing.assert_array_equal(page[r0:r0 + 64, c0:c0 + 64], tiles[number])


def test_one_image_on_a_udim_layout_lies_under_every_tile_with_one_line(tmp_path):
    tex = _tile_textures(tmp_path)[1002]
    from PIL import Image

    Image.fromarray(tex).save(tmp_path / "albedo.png")
    (tmp_path / "tiles.mtl").write_text("newmtl skin\nmap_Kd albedo.png\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _, out = _plate_run(tmp_path, formats=("exr", "png"), materials=["skin"] * 4)
    said = [str(w.message) for w in caught if issubclass(w.category, CrackbakeWarning)]
    one = [m for m in said if "is one image on a UDIM layout" in m]
    assert len(one) == 1 and "albedo.png" in one[0] and "<name>.<UDIM>.png" in one[0], said
    assert not any("not composited" in m for m in said)
    from crackbake.exchange.exr import read_exr

    for number in NUMBERS:
        planes, _ = read_exr(out / f"tiles_cracks.{number}.exr")
        off = (planes["crack.mask.V"] == 0) & (planes["crack.occlusion.V"] == 1)
        np.testing.assert_array_equal(_png(out / f"tiles_basecolor.{number}.png")[off], tex[off])


def test_a_numbered_image_that_is_no_tile_set_is_one_image(tmp_path):
    from PIL import Image

    from crackbake.io.texture import base_color_tiles

    tex = _tile_textures(tmp_path)[1012]
    Image.fromarray(tex).save(tmp_path / "photo_2048.png")  # a number, but no tile of it
    (tmp_path / "tiles.mtl").write_text("newmtl skin\nmap_Kd photo_2048.png\n")
    (tmp_path / "tiles.obj").write_text("mtllib tiles.mtl\nusemtl skin\nv 0 0 0\n")
    with pytest.warns(CrackbakeWarning, match="photo_2048.png is one image on a UDIM layout"):
        got = base_color_tiles(tmp_path / "tiles.obj", [1001, 1002], 64)
    assert len(got) == 2 and all((t == tex).all() for t in got)


def test_a_missing_tile_texture_is_grey_with_one_warning(tmp_path):
    tex = _tile_textures(tmp_path)
    (tmp_path / "albedo.1011.png").unlink()
    (tmp_path / "tiles.mtl").write_text("newmtl skin\nmap_Kd albedo.<UDIM>.png\n")
    with pytest.warns(CrackbakeWarning, match=r"albedo.<UDIM>.png has no file for tile 1011; "
                      r"grey there \(add albedo.1011.png"):  # fmt: skip
        _, out = _plate_run(tmp_path, formats=("png",), materials=["skin"] * 4)
    from crackbake.exchange.materials import SURFACE_RGB

    grey = _png(out / "tiles_basecolor.1011.png")  # no crack on 1011: the plain surface
    assert (grey == SURFACE_RGB.astype(np.uint8)).all(axis=-1).mean() > 0.9
    base = _png(out / "tiles_basecolor.1001.png")
    assert (base == tex[1001]).all(axis=-1).mean() > 0.5


def test_the_texture_sets_a_mtl_names(tmp_path):
    from crackbake.io.texture import _udim_template

    assert _udim_template(["a.<UDIM>.png"]) == "a.<UDIM>.png"
    assert _udim_template(["a.%(UDIM)d.exr"]) == "a.<UDIM>.exr"
    assert _udim_template(["tex/a_1001.tif"]) == "tex/a_<UDIM>.tif"
    assert _udim_template(["a.1001.png", "a.1002.png"]) == "a.<UDIM>.png"
    assert _udim_template(["a.png"]) is None
    assert _udim_template(["a.1001.png", "b.1002.png"]) is None  # two sets
    assert _udim_template(["a.0042.png"]) is None  # not a tile number
    assert _udim_template(["a.<UDIM>.png", "b.png"]) is None


def test_decals_on_udim_tiles_are_the_one_page_decals(tmp_path):
    """Decals are projector images: the same plate with its UVs on four tiles or halved onto
    one page gives the same decal files and projectors, here one decal across the 1001 | 1002
    edge (the y = 0.5 crack runs through it); the UDIM set is written beside them."""
    from crackbake.params.impacts import parse_impact

    extra = (("impacts", (parse_impact("1.0,0.5,0"),)), ("decal", 1.0), ("decal_res", 64))
    runs = {}
    for one_page in (False, True):
        folder = tmp_path / ("page" if one_page else "udim")
        folder.mkdir()
        result, out = _plate_run(folder, formats=("png",), extra=extra, one_page=one_page)
        runs[one_page] = (result, out)
    (tiled, out_t), (page, out_p) = runs[False], runs[True]
    assert tiled.manifest["uv"]["udim"] and not page.manifest["uv"].get("udim")
    assert (out_t / "tiles_mask.1002.png").is_file() and not (out_t / "tiles_mask.png").exists()
    doc_t = json.loads((out_t / "decals.json").read_text())
    doc_p = json.loads((out_p / "decals.json").read_text())
    (entry_t,), (entry_p,) = doc_t["decals"], doc_p["decals"]
    np.testing.assert_allclose(entry_t["matrix"], entry_p["matrix"], atol=1e-12)
    assert entry_t["files"] == entry_p["files"]
    for role, name in entry_t["files"].items():
        a, b = _png_any(out_t / name), _png_any(out_p / name)
        np.testing.assert_array_equal(a, b, err_msg=role)
    alpha = _png_any(out_t / entry_t["files"]["alpha"])
    # The crack along y = 0.5 crosses the decal's middle row on both sides of x = 1.
    assert alpha[30:34, 4:28].max() > 200 and alpha[30:34, 36:60].max() > 200
    assert alpha[:20, :56].max() == 0  # (the x = 1.5 crack runs along its right edge)
    names = {f["name"] for f in tiled.files}
    assert {"decals.json", entry_t["files"]["alpha"]} <= names


def _png_any(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im)


def test_a_tile_set_outside_the_mesh_folder_is_not_read(tmp_path):
    from crackbake.io.texture import base_color_tiles

    _tile_textures(tmp_path)  # the set one folder up from the mesh
    asset = tmp_path / "asset"
    asset.mkdir()
    (asset / "tiles.mtl").write_text("newmtl skin\nmap_Kd ../albedo.<UDIM>.png\n")
    (asset / "tiles.obj").write_text("mtllib tiles.mtl\nusemtl skin\nv 0 0 0\n")
    with pytest.warns(CrackbakeWarning, match=r"'../albedo.1001.png' .* lies outside the mesh's "
                      r"folder, so it was not read; using grey"):  # fmt: skip
        assert base_color_tiles(asset / "tiles.obj", list(NUMBERS), 64) is None
    got = base_color_tiles(asset / "tiles.obj", list(NUMBERS), 64, allow_outside=True)
    assert [t.shape for t in got] == [(64, 64, 3)] * 4
