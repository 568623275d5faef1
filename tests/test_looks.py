"""Crack looks (:mod:`crackbake.looks`): the presets' ``[look]`` tables and ``--look``, the width
noise along each crack, chipped edges, curled rims and normal strength in the bake, the
composite modes of the base colour, and what each preset's look measures on real runs.

The runs build their meshes (a plate from :func:`crackbake.precompile.plate_obj`, or
``examples/spot.obj``) and read back the files the command wrote: ``cracks.json`` for the
network measures (:mod:`crackbake.metrics.looks`), the PNGs for the composited colours, the GLB's
JSON chunk for the material.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from crackbake.bake.raster import CURL_REACH, bake_cracks
from crackbake.cli import main
from crackbake.errors import CrackbakeError
from crackbake.exchange.materials import SURFACE_RGB, base_color
from crackbake.io.mesh import load_mesh
from crackbake.looks import (
    FEWEST_CELLS,
    KEYS,
    Look,
    open_to_cells,
    parse_look,
    resolve_look,
    vary_widths,
)
from crackbake.metrics.cells import network_stats
from crackbake.metrics.looks import crack_area_share, width_cell_ratio, width_cv
from crackbake.network import Crack, CrackNetwork, Segments, segments
from crackbake.params import RunParams, load_preset, preset_names
from crackbake.precompile import plate_obj

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"


# --- the table and its overrides ------------------------------------------------------------


def test_every_preset_has_a_complete_checked_look():
    for name in preset_names():
        table = load_preset(name)["look"]
        assert set(table) == set(KEYS), name
        look = RunParams(mesh=Path("x.obj"), preset=name).validate().crack_look()
        assert look.mode in ("darken", "lighten", "multiply")
    # Bright glass, dark stained hairlines for crackle and glaze, varied widths for concrete.
    glass = resolve_look(load_preset("glass"), {})
    assert glass.mode == "lighten" and min(glass.color) > max(SURFACE_RGB)
    assert glass.roughness < 0.5
    for name in ("crackle", "glaze"):
        look = resolve_look(load_preset(name), {})
        assert look.mode in ("darken", "multiply") and max(look.color) < 100
    assert resolve_look(load_preset("concrete"), {}).width_variation >= 0.4


def test_look_overrides_are_parsed_and_checked():
    over = parse_look(["mode=lighten", "color=250,240,230", "normal-strength=3", "chipping=0.1"])
    assert over == {"mode": "lighten", "color": (250.0, 240.0, 230.0), "normal_strength": 3.0,
                    "chipping": 0.1}
    look = resolve_look(load_preset("mud"), over)
    assert look.mode == "lighten" and look.normal_strength == 3.0
    assert look.curl == load_preset("mud")["look"]["curl"]  # the rest stays the preset's
    bad = {
        "mode=glow": "mode 'glow' is unknown",
        "colour=1,2,3": "unknown look key 'colour'",
        "color=1,2": "give three sRGB values",
        "roughness=2": "roughness 2.0 is out of range",
        "chipping=nan": "chipping nan is out of range",
        "width_variation=x": "width_variation 'x' is not a number",
        "roughness": "expected KEY=VALUE",
    }
    for text, message in bad.items():
        with pytest.raises(CrackbakeError, match=message):
            parse_look([text])
    with pytest.raises(CrackbakeError, match="roughness"):
        RunParams(mesh=Path("x.obj"), look={"roughness": -1}).validate()


def test_bad_look_on_the_command_line_is_one_line_exit_2(tmp_path):
    mesh = plate_obj(tmp_path / "plate.obj", 1)
    r = CliRunner().invoke(main, [str(mesh), "--look", "mode=glow", "-o", str(tmp_path / "o")])
    assert r.exit_code == 2
    assert r.output.strip().splitlines() == [
        "error: --look mode 'glow' is unknown; use one of darken, lighten, multiply"
    ]
    assert not (tmp_path / "o").exists()


# --- width noise along the cracks -----------------------------------------------------------


def _straight_network(n_cracks: int = 40, points: int = 60) -> CrackNetwork:
    cracks = []
    for i in range(n_cracks):
        x = np.linspace(0.0, 1.0, points)
        p = np.column_stack([x, np.full(points, 0.02 * i), np.zeros(points)])
        w = np.full(points, 0.004)
        cracks.append(Crack(id=i, points=p, faces=np.zeros(points, int), time=x, width=w,
                            depth=0.5 * w))
    return CrackNetwork(cracks=cracks, mesh={})


def test_width_variation_gives_the_asked_spread_seeded_and_order_free():
    net = vary_widths(_straight_network(), 0.5, seed=7, scale=0.02)
    cv = width_cv([c.points for c in net.cracks], [c.width for c in net.cracks])
    assert 0.35 < cv < 0.65
    widths = np.concatenate([c.width for c in net.cracks])
    assert widths.min() > 0
    assert np.mean(widths) == pytest.approx(0.004, rel=0.1)  # the mean opening stays
    for c in net.cracks:  # depth follows the width: the profile keeps its shape
        np.testing.assert_allclose(c.depth, 0.5 * c.width)
    again = vary_widths(_straight_network(), 0.5, seed=7, scale=0.02)
    reordered = _straight_network()
    reordered.cracks.reverse()
    vary_widths(reordered, 0.5, seed=7, scale=0.02)
    by_id = {c.id: c.width for c in reordered.cracks}
    for a, b in zip(net.cracks, again.cracks, strict=True):
        np.testing.assert_array_equal(a.width, b.width)
        np.testing.assert_array_equal(a.width, by_id[a.id])
    other = vary_widths(_straight_network(), 0.5, seed=8, scale=0.02)
    assert not np.array_equal(other.cracks[0].width, net.cracks[0].width)
    untouched = vary_widths(_straight_network(), 0.0, seed=7, scale=0.02)
    assert all((c.width == 0.004).all() for c in untouched.cracks)


def _grid_network(lines: int, seed: int = 0) -> CrackNetwork:
    """Cracks along x = k / lines and y = k / lines (k = 1 .. lines - 1) across the unit plate:
    lines^2 square cells of side 1 / lines, with widths that vary along and between cracks."""
    rng = np.random.default_rng(seed)
    cracks = []
    t = np.linspace(0.0, 1.0, 41)
    for k in range(1, lines):
        for axis in (0, 1):
            p = np.zeros((len(t), 3))
            p[:, axis] = k / lines
            p[:, 1 - axis] = t
            w = 0.002 * (1.0 + rng.random(len(t)))
            cracks.append(Crack(id=len(cracks), points=p, faces=np.zeros(len(t), int), time=t,
                                width=w, depth=0.8 * w))
    return CrackNetwork(cracks=cracks, mesh={})


def test_open_to_cells_sizes_the_mean_width_by_the_cells():
    v, f, *_ = _plane()
    net = _grid_network(4)  # 16 cells of side 0.25: the cell size is 0.25
    before = [c.width.copy() for c in net.cracks]
    factor, cells = open_to_cells(net, 0.04, v, f)
    assert cells == 16
    pts = [c.points for c in net.cracks]
    wid = [c.width for c in net.cracks]
    st = network_stats(pts, wid, v, f)
    assert st.mean_width == pytest.approx(0.04 * 0.25, rel=1e-9)
    assert width_cell_ratio(st.mean_width, st.mean_cell_area) == pytest.approx(0.04, rel=0.01)
    for c, w in zip(net.cracks, before, strict=True):  # one factor: the shape of the widths stays
        np.testing.assert_allclose(c.width, factor * w, rtol=1e-12)
        np.testing.assert_allclose(c.depth, 0.8 * c.width, rtol=1e-12)
    # Twice as many cells a side: half the cell size, half the gap.
    finer = _grid_network(8)
    open_to_cells(finer, 0.04, v, f)
    st8 = network_stats([c.points for c in finer.cracks], [c.width for c in finer.cracks], v, f)
    assert st8.mean_width == pytest.approx(0.5 * st.mean_width, rel=1e-9)
    # Too few cells to size anything by: untouched.
    assert FEWEST_CELLS > 2
    one = CrackNetwork(cracks=_grid_network(2).cracks[:1], mesh={})  # one crack across: 2 cells
    kept = one.cracks[0].width.copy()
    assert open_to_cells(one, 0.04, v, f) == (1.0, 2)
    np.testing.assert_array_equal(one.cracks[0].width, kept)


# --- the bake: chipping, curl, normal strength ----------------------------------------------


def _plane(n: int = 8):
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    idx = np.arange(v.shape[0]).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(v), 1))
    return v, f, v[:, :2].copy(), normals, tangents


def _one_crack(width: float = 0.03) -> Segments:
    p = np.column_stack([np.linspace(0.1, 0.9, 9), np.full(9, 0.5), np.zeros(9)])
    w = np.full(9, width)
    crack = Crack(id=0, points=p, faces=np.zeros(9, int), time=np.linspace(0, 1, 9), width=w,
                  depth=0.5 * w)
    return segments(CrackNetwork(cracks=[crack], mesh={}))


def _bake(look, seed=0, res=256):
    v, f, uv, n, t = _plane()
    return bake_cracks(v, f, uv, _one_crack(), res, normals=n, tangents=t, look=look, seed=seed)


@pytest.mark.usefixtures("gl_ctx")
def test_default_look_bakes_exactly_as_no_look():
    plain, looked = _bake(None), _bake(Look())
    for name, image in plain.channels().items():
        np.testing.assert_array_equal(image, looked.channels()[name], err_msg=name)


@pytest.mark.usefixtures("gl_ctx")
def test_chipping_ragged_edges_seeded_width_channel_physical():
    plain = _bake(Look())
    chipped = _bake(Look(chipping=0.5), seed=3)
    # Columns across the crack: the drawn width varies along it only when chipped.
    cols = slice(64, 192)
    across_plain = plain.mask[:, cols].astype(np.float64).sum(axis=0)
    across = chipped.mask[:, cols].astype(np.float64).sum(axis=0)
    assert across_plain.std() / across_plain.mean() < 0.02
    assert across.std() / across.mean() > 0.1
    assert across.max() / across.min() > 1.4
    np.testing.assert_array_equal(plain.width, chipped.width)  # crack.width stays physical
    np.testing.assert_array_equal(chipped.mask, _bake(Look(chipping=0.5), seed=3).mask)
    assert not np.array_equal(chipped.mask, _bake(Look(chipping=0.5), seed=4).mask)
    # The normal map follows the drawn edge: tilted texels and covered texels coincide.
    tilted = chipped.normal[..., 2] < 0.999
    covered = chipped.mask > 0.5
    assert (tilted & covered).sum() / covered.sum() > 0.9


@pytest.mark.usefixtures("gl_ctx")
def test_curl_raises_the_rims_and_normal_strength_steepens_the_walls():
    plain, curled = _bake(Look()), _bake(Look(curl=0.4))
    np.testing.assert_array_equal(plain.mask, curled.mask)
    inside = plain.depth > 0
    np.testing.assert_array_equal(plain.depth[inside], curled.depth[inside])
    rim = (curled.mask == 0) & (curled.normal[..., 2] < 0.999)
    assert rim.sum() > 0 and (plain.normal[..., 2][rim] == 1).all()
    # The depth map holds the same rim as the normal map: raised (negative depth) off the
    # crack only, wherever the normal leans there, at most curl x D high (D = 0.015 here).
    raised = curled.depth < 0
    off = plain.depth == 0
    assert (plain.depth >= 0).all() and off[raised].all()
    assert raised[off & (curled.normal[..., 2] < 0.999)].all()
    # The rim's slope at height h is 2 sqrt(curl D h) / (CURL_REACH hw): the least height
    # whose lean shows in float precision grows with the reach squared.
    least = 1e-5 * (CURL_REACH / 1.5) ** 2
    assert (curled.normal[..., 2][curled.depth < -least] < 0.9999).all()
    assert -curled.depth.min() <= 0.4 * 0.015 * (1 + 1e-6)
    assert -curled.depth.min() > 0.8 * 0.4 * 0.015
    # ... and its slope: in the middle of the crack (columns 96..160), down the rows, the
    # central difference of the height -depth is the normal's slope ny / nz (texel 1/256; image
    # row 0 is v = 1, so a row down is -y).
    h = -curled.depth[:, 96:160].astype(np.float64)
    n = curled.normal[:, 96:160].astype(np.float64)
    dh_dy = (h[:-2] - h[2:]) / (2.0 / 256)
    both = rim[:-2, 96:160] & rim[1:-1, 96:160] & rim[2:, 96:160]  # the smooth part of the rim
    assert both.sum() > 64
    np.testing.assert_allclose(dh_dy[both], -(n[1:-1, :, 1] / n[1:-1, :, 2])[both],
                               rtol=0.02, atol=1e-3)
    # A raised rim leans away from the crack (the crack runs along y = 0.5, row res / 2).
    rows = np.nonzero(rim)[0]
    ny = curled.normal[..., 1][rim]
    above = rows < 128  # image row 0 is v = 1: above the crack in the image is +y
    assert (ny[above] > 0).all() and (ny[~above] < 0).all()
    steep = _bake(Look(normal_strength=2.0))
    walls = (plain.mask > 0.99) & (plain.normal[..., 2] < 0.999)

    def slope(n):
        return np.hypot(n[..., 0], n[..., 1])[walls] / n[..., 2][walls]

    np.testing.assert_allclose(slope(steep.normal), 2.0 * slope(plain.normal), rtol=1e-3)


# --- composite modes --------------------------------------------------------------------------


def test_composite_modes_on_grey_and_on_a_texture():
    mask = np.array([[0.0, 1.0]], np.float16)
    occ = np.array([[1.0, 0.5]], np.float16)
    default = base_color(mask, occlusion=occ)
    np.testing.assert_array_equal(base_color(mask, occlusion=occ, look=Look()), default)
    dark = base_color(mask, occlusion=np.ones_like(occ), look=Look(color=(20, 30, 40)))
    np.testing.assert_array_equal(dark[0, 1], [20, 30, 40])
    bright = base_color(mask, occlusion=occ, look=Look(color=(250, 250, 255), mode="lighten"))
    np.testing.assert_array_equal(bright[0, 0], np.round(SURFACE_RGB))
    np.testing.assert_array_equal(bright[0, 1], [250, 250, 255])  # no occlusion: a bright line
    mult = base_color(mask, occlusion=np.ones_like(occ),
                      look=Look(color=(128, 255, 255), mode="multiply"))
    np.testing.assert_allclose(mult[0, 1], SURFACE_RGB * [128 / 255, 1, 1], atol=1)
    tex = np.array([[[100, 150, 200], [100, 150, 200]]], np.uint8)
    lit = base_color(mask, occlusion=occ, texture=tex,
                     look=Look(color=(250, 250, 255), mode="lighten"))
    np.testing.assert_array_equal(lit[0, 0], tex[0, 0])
    assert (lit[0, 1] > tex[0, 1]).all() and lit.max() <= 255


# --- real runs ------------------------------------------------------------------------------


def _run(tmp_path: Path, mesh: Path, name: str, *args: str, res: int = 1024) -> Path:
    out = tmp_path / name
    argv = [str(mesh), "--res", str(res), "--formats", "png,glb", "-o", str(out), "-q", *args]
    result = CliRunner().invoke(main, argv, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out


def _network(out: Path):
    cracks = json.loads((out / "cracks.json").read_text())["cracks"]
    return [np.asarray(c["points"]) for c in cracks], [np.asarray(c["width"]) for c in cracks]


def _glb_material(path: Path) -> dict:
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    return json.loads(data[20 : 20 + length])["materials"][0]


@pytest.fixture(scope="module")
def plate(tmp_path_factory) -> Path:
    return plate_obj(tmp_path_factory.mktemp("plate") / "plate.obj", 12, uv_margin=0.0)


@pytest.mark.parametrize("kind", ["plate", pytest.param("spot", marks=pytest.mark.slow)])
def test_mud_opens_gaps_of_its_cell_size(tmp_path, plate, kind):
    mesh = plate if kind == "plate" else SPOT
    out = _run(tmp_path, mesh, "mud", "--preset", "mud", "--sim-faces", "40000")
    pts, wid = _network(out)
    surf = load_mesh(mesh)
    st = network_stats(pts, wid, surf.vertices, surf.faces)
    ratio = width_cell_ratio(st.mean_width, st.mean_cell_area)
    area = crack_area_share(pts, wid, surf.vertices, surf.faces)
    # Mud's widths are sized by its cells (crack_width_cell, measured at a coarser sampling
    # than network_stats' default: within 2 %), so the gap is the preset's share on any mesh.
    assert 0.03 <= ratio <= 0.08, ratio
    assert ratio == pytest.approx(load_preset("mud")["crack_width_cell"], rel=0.03)
    # Issue 18 asks for a crack area of 4-8 %: gaps of g of the cell size cover about 1.9 g of
    # this plate (1.90-1.94 over seeds 0-3) and 2.1 g of spot.  Over seeds 0-3 (this plate,
    # 40k sim faces) width / cell 0.0343-0.0348, area 0.066-0.067 (the widest point at 0.015 of
    # the diagonal gave 0.044-0.061 and 0.083-0.118).
    assert 0.04 <= area <= 0.08, area
    if kind == "plate":  # every texel of the plate has the same area: the mask's mean is a share
        mask = np.asarray(Image.open(out / "plate_mask.png"), np.float64) / 255
        # The share of texels the mask covers (at least half): 0.067-0.069 over the same runs,
        # 0.066-0.068 re-baked at 2048^2 (seeds 0-2; the curled rims are relief only, not in
        # the mask).
        assert 0.04 <= (mask >= 0.5).mean() <= 0.08, (mask >= 0.5).mean()
        # Dark interiors: the deepest quarter of the gaps (the occlusion darkens them) is about
        # half as bright as the open surface, while the walls keep the clay's colour.  (Grooves
        # under four texels wide show the depth and occlusion averaged over a texel: their
        # centres are a little less deep and less dark than point samples at the apex.)
        base = np.asarray(Image.open(out / "plate_basecolor.png"), np.float64).mean(axis=2)
        depth = np.asarray(Image.open(out / "plate_depth.png"), np.float64)
        on = mask > 0.99
        deep = on & (depth >= np.percentile(depth[on], 75))
        assert base[deep].mean() < 0.52 * base[mask == 0].mean()
        assert base[on].mean() < 0.8 * base[mask == 0].mean()


def test_mud_crack_width_overrides_the_cells_and_too_few_cells_warn(tmp_path, plate):
    quick = ["--preset", "mud", "--sim-faces", "3000", "--look", "width_variation=0"]
    out = _run(tmp_path, plate, "given", *quick, "--crack-width", "0.004", res=64)
    _, wid = _network(out)
    assert max(w.max() for w in wid) == pytest.approx(0.004)  # the solver's widest opening
    argv = [str(plate), *quick, "--max-cracks", "1", "--res", "64", "--formats", "png",
            "-o", str(tmp_path / "few")]
    r = CliRunner().invoke(main, argv, catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert "fewer than 4" in r.output and "crack_width_rel" in r.output, r.output
    _, wid = _network(tmp_path / "few")
    diagonal = load_mesh(plate).diagonal
    widest = load_preset("mud")["crack_width_rel"] * diagonal
    assert max(w.max() for w in wid) == pytest.approx(widest)


@pytest.mark.parametrize("impact", [False, True])
def test_concrete_width_varies_along_each_crack(tmp_path, plate, impact):
    args = ["--preset", "concrete", "--sim-faces", "30000"]
    args += ["--impact", "0.5,0.5,0"] if impact else []
    out = _run(tmp_path, plate, "concrete", *args, res=256)
    pts, wid = _network(out)
    assert width_cv(pts, wid) >= 0.4


def test_glass_cracks_are_bright_glossy_lines_and_the_glb_says_so(tmp_path, plate):
    out = _run(tmp_path, plate, "glass", "--preset", "glass", "--impact", "0.5,0.5,0",
               "--sim-faces", "30000")
    mask = np.asarray(Image.open(out / "plate_mask.png"), np.float64) / 255
    base = np.asarray(Image.open(out / "plate_basecolor.png"), np.float64).mean(axis=2)
    orm = np.asarray(Image.open(out / "plate_orm.png"), np.float64) / 255
    on, off = mask > 0.9, mask == 0
    assert on.sum() > 100
    assert base[on].mean() > base[off].mean() + 20
    assert orm[..., 1][on].mean() < orm[..., 1][off].mean() - 0.4  # glossier at the crack
    look = _glb_material(out / "plate.glb")["extras"]["crackbake_look"]
    assert look["mode"] == "lighten" and look["roughness"] == pytest.approx(0.15)


def test_look_overrides_reach_the_outputs_and_runs_repeat(tmp_path, plate):
    args = ["--preset", "mud", "--sim-faces", "20000", "--seed", "4"]
    over = ["--look", "mode=lighten", "--look", "color=250,250,250", "--look", "roughness=0.1",
            "--look", "width_variation=0"]
    a = _run(tmp_path, plate, "a", *args, *over, res=256)
    b = _run(tmp_path, plate, "b", *args, *over, res=256)
    plain = _run(tmp_path, plate, "plain", *args, res=256)
    mask = np.asarray(Image.open(a / "plate_mask.png"), np.float64) / 255
    base = np.asarray(Image.open(a / "plate_basecolor.png"), np.float64)
    orm = np.asarray(Image.open(a / "plate_orm.png"))
    on = mask > 0.99
    assert (base[on] >= 249).all()
    assert np.abs(orm[..., 1][on].astype(int) - round(0.1 * 255)).max() <= 1
    manifest = json.loads((a / "manifest.json").read_text())
    assert manifest["params"]["look"]["mode"] == "lighten"
    assert _glb_material(a / "plate.glb")["extras"]["crackbake_look"]["roughness"] == 0.1
    # width_variation=0: the solver's widths as they were; the preset's own noise changes them.
    pa, wa = _network(a)
    pp, wp = _network(plain)
    assert all(np.array_equal(x, y) for x, y in zip(pa, pp, strict=True))
    assert width_cv(pa, wa) < width_cv(pp, wp)
    for name in ("cracks.json", "plate_basecolor.png", "plate_normal.png", "plate_mask.png"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
