"""End to end through the library and the CLI: real EGL, real files, re-read independently."""

from __future__ import annotations

import json
import logging
import re
import struct
import subprocess
import sys
import warnings
from io import BytesIO
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner
from PIL import Image

from crackbake import __version__
from crackbake.cli import main
from crackbake.io.mesh import load_mesh
from crackbake.io.sidecar import write_sidecar
from crackbake.network import Crack, CrackNetwork, mesh_info
from crackbake.params import RunParams
from crackbake.pipeline import run

ROOT = Path(__file__).resolve().parents[1]

# A 2x1 plate whose UV island is offset and non-uniformly placed, so any flip or transpose of
# the image or of the GLB's v shows up.  u = 0.1 + 0.4 x, v = 0.2 + 0.6 y.
PLATE_OBJ = """\
v 0 0 0
v 2 0 0
v 2 1 0
v 0 1 0
vt 0.1 0.2
vt 0.9 0.2
vt 0.9 0.8
vt 0.1 0.8
f 1/1 2/2 3/3
f 1/1 3/3 4/4
"""


def plate_uv(x: float, y: float) -> tuple[float, float]:
    return 0.1 + 0.4 * x, 0.2 + 0.6 * y


@pytest.fixture
def plate(tmp_path) -> tuple[Path, Path, tuple[float, float, float]]:
    """Plate OBJ and a sidecar with one short crack around the world point (1.5, 0.75, 0)."""
    obj = tmp_path / "plate.obj"
    obj.write_text(PLATE_OBJ)
    mesh = load_mesh(obj)
    centre = (1.5, 0.75, 0.0)
    pts = np.array([[1.49, 0.75, 0.0], [1.51, 0.75, 0.0]])
    # Which face holds the points: the plate's triangles split along the (0,0)-(2,1) diagonal.
    face = 1 if 0.75 > 0.5 * 1.5 else 0
    crack = Crack(
        id=0,
        points=pts,
        faces=np.array([face, face]),
        time=np.array([0.0, 1.0]),
        width=np.array([0.02, 0.02]),
        depth=np.array([0.01, 0.01]),
    )
    net = CrackNetwork(cracks=[crack], mesh=mesh_info(mesh))
    side = tmp_path / "marker.json"
    write_sidecar(net, side)
    return obj, side, centre


def read_glb(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data)
    jlen, jtype = struct.unpack_from("<I4s", data, 12)
    assert jtype == b"JSON"
    doc = json.loads(data[20 : 20 + jlen])
    blen, btype = struct.unpack_from("<I4s", data, 20 + jlen)
    assert btype == b"BIN\x00"
    return doc, data[28 + jlen : 28 + jlen + blen]


def accessor(doc: dict, binary: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}[
        acc["componentType"]
    ]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    arr = np.frombuffer(binary, dtype, acc["count"] * width, start)
    return arr.reshape(acc["count"], width) if width > 1 else arr


def test_marker_lands_on_the_right_texel_in_exr_png_and_glb(plate, tmp_path):
    obj, side, centre = plate
    res = 256
    out = tmp_path / "out"
    run(RunParams(mesh=obj, cracks=side, res=res, out=out))
    u, v = plate_uv(centre[0], centre[1])
    row, col = int((1 - v) * res), int(u * res)
    flipped_row = int(v * res)

    # EXR, re-read with OpenImageIO (independent of the writer's own reader).
    buf = oiio.ImageBuf(str(out / "plate_cracks.exr"))
    names = list(buf.spec().channelnames)
    px = buf.get_pixels(oiio.FLOAT)
    mask = px[..., names.index("crack.mask.V")]
    assert mask.shape == (res, res)
    assert mask[row, col] > 0.9
    assert mask[flipped_row, col] == 0
    assert mask.sum() == pytest.approx(0.02 * 0.4 * res * 0.02 * 0.6 * res + 2, rel=0.6)
    assert px[..., names.index("crack.id.V")][row, col] == 0
    assert buf.spec().get_string_attribute("crackbake:version") == __version__

    # PNG mask: same place.
    png = np.asarray(Image.open(out / "plate_mask.png"))
    assert png.shape == (res, res) and png.dtype == np.uint8
    assert png[row, col] > 230 and png[flipped_row, col] == 0
    depth_png = np.asarray(Image.open(out / "plate_depth.png"))
    assert depth_png.dtype == np.uint16 or depth_png.max() > 255
    assert np.unravel_index(np.argmax(depth_png), depth_png.shape)[0] in (row - 1, row, row + 1)

    # GLB: find the crack centre's UV through the GLB's own TEXCOORD_0 and sample its texture.
    doc, binary = read_glb(out / "plate.glb")
    prim = doc["meshes"][0]["primitives"][0]
    pos = accessor(doc, binary, prim["attributes"]["POSITION"]).astype(np.float64)
    tex = accessor(doc, binary, prim["attributes"]["TEXCOORD_0"]).astype(np.float64)
    idx = accessor(doc, binary, prim["indices"]).reshape(-1, 3)
    p = np.array(centre)
    for tri in idx:
        a, b, c = pos[tri]
        m = np.array([b - a, c - a]).T[:2]
        l1, l2 = np.linalg.solve(m, (p - a)[:2])
        if min(l1, l2, 1 - l1 - l2) >= -1e-9:
            t0, t1, t2 = tex[tri]
            uv_gltf = t0 + l1 * (t1 - t0) + l2 * (t2 - t0)
            break
    else:
        pytest.fail("crack centre not inside any GLB triangle")
    image_index = doc["textures"][
        doc["materials"][prim["material"]]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    ]["source"]
    view = doc["bufferViews"][doc["images"][image_index]["bufferView"]]
    start = view.get("byteOffset", 0)
    img = np.asarray(Image.open(BytesIO(binary[start : start + view["byteLength"]])).convert("L"))
    h, w = img.shape
    gx, gy = int(uv_gltf[0] * w), int(uv_gltf[1] * h)  # glTF: v = 0 is the image's top row
    assert img[gy, gx] < 80  # dark crack
    assert img[h - 1 - gy, gx] > 150  # the v-flipped place is intact surface


def test_outputs_manifest_and_determinism(plate, tmp_path):
    obj, side, _ = plate
    a = run(RunParams(mesh=obj, cracks=side, res=128, out=tmp_path / "a", seed=3))
    b = run(RunParams(mesh=obj, cracks=side, res=128, out=tmp_path / "b", seed=3))
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert names == sorted(
        [
            "plate_cracks.exr",
            "plate_mask.png",
            "plate_depth.png",
            "plate_basecolor.png",
            "plate_normal.png",
            "plate_orm.png",
            "plate_data.png",
            "plate.glb",
            "cracks.json",
            "cracks.obj",
            "manifest.json",
            "preview.png",
        ]
    )
    man = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert man["crackbake"] == __version__
    assert set(man["timings_s"]) >= {"load", "unwrap", "bake", "write", "total"}
    assert man["params"]["seed"] == 3 and man["params"]["res"] == 128
    recorded = {f["name"]: f for f in man["files"]}
    for f in (tmp_path / "a").iterdir():
        if f.name == "manifest.json":
            continue
        import hashlib

        assert recorded[f.name]["bytes"] == f.stat().st_size
        assert recorded[f.name]["sha256"] == hashlib.sha256(f.read_bytes()).hexdigest()
    # Same inputs, same bytes (the manifest differs only in timings).
    for name in ("cracks.json", "plate_mask.png", "plate_depth.png", "plate_cracks.exr",
                 "preview.png", "plate_data.png", "plate.glb"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    assert a.summary()["files"][-1] == "manifest.json" and b.manifest["cracks"]["cracks"] == 1
    # The preview looks at the plate: mostly surface colour, with the dark crack somewhere.
    pic = np.asarray(Image.open(tmp_path / "a" / "preview.png").convert("L"))
    assert pic.shape == (1024, 1024)
    assert (pic > 120).mean() > 0.05


def test_formats_subset_and_float(plate, tmp_path):
    obj, side, _ = plate
    run(RunParams(mesh=obj, cracks=side, res=64, out=tmp_path / "o", formats=("exr",),
                  float32=True))
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert names == {"plate_cracks.exr", "cracks.json", "cracks.obj", "manifest.json"}
    spec = oiio.ImageInput.open(str(tmp_path / "o" / "plate_cracks.exr")).spec()
    assert {str(spec.channelformat(i)) for i in range(spec.nchannels)} == {"float"}


# --- CLI -----------------------------------------------------------------------------------


def cli(*args: str):
    return CliRunner().invoke(main, list(args), catch_exceptions=False)


def test_cli_version_and_help():
    r = cli("--version")
    assert r.exit_code == 0 and __version__ in r.output
    r = cli("--help")
    assert r.exit_code == 0
    assert "Examples:" in r.output and "--cracks" in r.output and "--res" in r.output


def test_cli_shows_stage_progress_from_the_log(plate, tmp_path):
    obj, side, _ = plate
    args = [str(obj), "--cracks", str(side), "--res", "64", "--formats", "exr"]
    # Not a terminal: no progress (tests/test_cli.py shows the live display on a real pty).
    r = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "a")])
    assert r.exit_code == 0, r.output
    assert not any(ln.startswith(("loading", "baking")) for ln in r.stderr.splitlines())
    assert r.stdout == ""
    r = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "b"), "-v"])
    assert r.exit_code == 0, r.output
    lines = [re.sub(r"^\[ *\d+\.\ds\] ", "", ln) for ln in r.stderr.splitlines()]
    assert lines[:5] == [
        f"loading {obj}",
        f"reading crack network {side}",
        "preparing UVs",
        "baking 64x64",
        f"writing {tmp_path / 'b'}",
    ]
    assert re.match(r"\[ *\d+\.\ds\] loading ", r.stderr.splitlines()[0])
    r = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "c"), "-q"])
    assert r.exit_code == 0 and r.stderr == ""
    # The display is the CLI's: after it, the library logs nothing on its own.
    assert not logging.getLogger("crackbake").handlers


def test_cli_bakes_with_json_summary(plate, tmp_path):
    obj, side, _ = plate
    out = tmp_path / "cli_out"
    r = CliRunner().invoke(
        main, [str(obj), "--cracks", str(side), "--res", "64", "-o", str(out), "--json", "-q"]
    )
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["out_dir"] == str(out)
    assert "manifest.json" in summary["files"]
    assert (out / "manifest.json").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.obj", "--cracks", "x.json"], "file not found"),
        (["{obj}", "--cracks", "{side}", "--res", "10"], "--res 10 is out of range"),
        (["{obj}", "--cracks", "{side}", "--res", "20000"], "--res 20000 is out of range"),
        (["{obj}", "--preset", "glass"], "needs an impact point"),
        (["{obj}", "--impact", "1,0.5,0", "--toughness", "-1"], "--toughness -1 is out of range"),
        (["{obj}", "--direction", "0,0,0"], "must not be zero"),
        (["{obj}", "--preset", "granite"], "invalid value for '--preset'"),
        (["{obj}", "--impact", "1,2", "--cracks", "{side}"], "--impact '1,2'"),
        (["{obj}", "--cracks", "{bad}"], "not valid JSON"),
        (["{obj}"], "nothing to crack"),
        (["{txt}", "--cracks", "{side}"], "unsupported format"),
    ],
)
def test_cli_errors_are_one_line_and_write_nothing(plate, tmp_path, args, message):
    obj, side, _ = plate
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    txt = tmp_path / "mesh.txt"
    txt.write_text("hello")
    out = tmp_path / "never"
    fill = {"obj": str(obj), "side": str(side), "bad": str(bad), "txt": str(txt)}
    argv = [a.format(**fill) for a in args] + ["-o", str(out)]
    r = CliRunner().invoke(main, argv)
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith(("error:", "Error:"))]
    assert len(lines) == 1 and message in lines[0], r.stderr
    assert not out.exists() or not any(out.iterdir())


def test_cli_runs_as_installed_command(plate, tmp_path):
    """The console script starts and fails cleanly (exit 2, one line) from a real process."""
    exe = Path(sys.executable).with_name("crackbake")
    argv = [str(exe), str(tmp_path / "none.obj"), "--cracks", "x.json", "--quiet"]
    r = subprocess.run(argv, capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and r.stderr.startswith("error:")


# --- solving --------------------------------------------------------------------------------


def test_impact_solves_bakes_and_rebakes_identically(plate, tmp_path):
    obj, _, _ = plate
    common = ["--res", "128", "--sim-faces", "6000", "--formats", "exr,png", "-q"]
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for out, seed in ((a, "1"), (b, "1"), (c, "2")):
        r = CliRunner().invoke(
            main, [str(obj), "--preset", "glass", "--impact", "1,0.5,0", "--seed", seed,
                   "-o", str(out), *common]
        )
        assert r.exit_code == 0, r.output
    side = json.loads((a / "cracks.json").read_text())
    assert side["stats"]["cracks"] > 0 and side["stats"]["solver_steps"] > 0
    assert side["params"]["preset"] == "glass" and side["params"]["method"] == "iben"
    assert side["params"]["seed"] == 1
    assert side["impacts"][0]["point"] == pytest.approx([1.0, 0.5, 0.0], abs=1e-9)
    # Same seed: byte-identical network and maps; another seed: another network.
    assert (a / "cracks.json").read_bytes() == (b / "cracks.json").read_bytes()
    assert (a / "plate_cracks.exr").read_bytes() == (b / "plate_cracks.exr").read_bytes()
    assert (a / "cracks.json").read_bytes() != (c / "cracks.json").read_bytes()
    man = json.loads((a / "manifest.json").read_text())
    assert {"simmesh", "stress", "solve"} <= set(man["timings_s"])
    # Re-baking the sidecar gives the same pixels as the solving run.
    d = tmp_path / "d"
    r = CliRunner().invoke(main, [str(obj), "--cracks", str(a / "cracks.json"), "-o", str(d),
                                  "--res", "128", "--formats", "exr,png", "-q"])
    assert r.exit_code == 0, r.output
    assert (d / "plate_mask.png").read_bytes() == (a / "plate_mask.png").read_bytes()


def test_thesis_method_and_shrinkage(plate, tmp_path):
    obj, _, _ = plate
    out = tmp_path / "t"
    r = CliRunner().invoke(
        main, [str(obj), "--method", "thesis", "--shrink", "1", "--sim-faces", "4000",
               "--res", "64", "--formats", "exr", "-o", str(out), "-q"]
    )
    assert r.exit_code == 0, r.output
    side = json.loads((out / "cracks.json").read_text())
    assert side["params"]["method"] == "thesis" and side["stats"]["cracks"] > 0
    mesh = load_mesh(obj)
    for crack in side["cracks"]:
        pts = np.array(crack["points"])
        assert (pts[:, 2] == 0).all()  # on the plate
        assert (np.array(crack["faces"]) < len(mesh.faces)).all()


def test_library_run_keeps_the_stress_field_and_solver_result(plate, tmp_path):
    obj, _, _ = plate
    from crackbake.params import Impact

    result = run(RunParams(mesh=obj, out=tmp_path / "lib", res=64, formats=("exr",),
                           impacts=(Impact((1.0, 0.5, 0.0)),), preset="glass", sim_faces=3000))
    solved = result.solved
    assert solved is not None
    m = len(solved.sim.faces)
    assert solved.field.stress.shape == (m, 3, 3)
    assert solved.result.stress_initial.shape == (m, 3, 3)
    assert len(solved.result.stress_final) == len(solved.result.faces) >= m  # splits add faces
    assert len(solved.result.separation) == len(solved.result.vertices)
    assert result.network is not None and len(result.network.cracks) > 0
    # The sim mesh's memoised edges, shells and fast-marching patch do not outlive the run.
    from crackbake import geometry

    assert not geometry._memo


def test_a_run_cut_short_by_max_steps_warns(plate, tmp_path):
    from crackbake.errors import CrackbakeWarning
    from crackbake.params import Impact

    obj, _, _ = plate
    base = dict(mesh=obj, res=64, formats=("exr",), impacts=(Impact((1.0, 0.5, 0.0)),),
                preset="glass", sim_faces=3000)
    with pytest.warns(CrackbakeWarning, match="--max-steps 5 with cracks still growing"):
        short = run(RunParams(out=tmp_path / "short", max_steps=5, **base))
    assert short.solved.result.stats["stopped"] == "max steps"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", CrackbakeWarning)
        full = run(RunParams(out=tmp_path / "full", **base))
    assert full.solved.result.stats["stopped"] in ("at rest", "max cracks", "saturated")
    # (a 3000-face sim mesh may also say its star is thin: only the step limit is under test)
    assert not [w for w in caught if "--max-steps" in str(w.message)]


def test_warnings_of_a_rebuilt_sim_mesh_are_said_once():
    from crackbake.errors import CrackbakeWarning
    from crackbake.pipeline import _warn_once

    def record(*texts):
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            for t in texts:
                warnings.warn(t, CrackbakeWarning, stacklevel=1)
        return got

    first = record("the mesh is not manifold (1 edge)", "impact lies 0.1 off; snapped to (0, 1.1)")
    second = record("impact lies 0.1 off; snapped to (0, 1.0999)",
                    "the mesh is not manifold (1 edge)", "a new one")  # fmt: skip
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        _warn_once(first, second)
    # Each kind once, in the first mesh's order, as the rebuilt mesh says it; new ones after.
    assert [str(w.message) for w in said] == [
        "the mesh is not manifold (1 edge)", "impact lies 0.1 off; snapped to (0, 1.0999)",
        "a new one"]  # fmt: skip


@pytest.mark.slow
def test_a_sim_mesh_rebuilt_for_a_thin_feature_warns_once(tmp_path):
    """A glass impact just off a thin capsule's tip (the default sim mesh is rebuilt finer for
    its shadow) on a mesh with a non-manifold fin: the snapped-impact and non-manifold
    warnings each show once on stderr, as the rebuilt mesh states them."""
    import trimesh

    t = trimesh.creation.capsule(height=2.0, radius=0.1, count=[24, 24])
    v, f = trimesh.remesh.subdivide_to_size(t.vertices, t.faces, max_edge=0.05)
    # A 3 x 3 square below it, with a fin on its diagonal: three faces on one edge.
    sq = np.array([[-1.5, -1.5, -2], [1.5, -1.5, -2], [1.5, 1.5, -2], [-1.5, 1.5, -2],
                   [0, 0, -1.0]])  # fmt: skip
    k = len(v)
    faces = np.r_[f, k + np.array([[0, 1, 2], [0, 2, 3], [0, 2, 4]])]
    path = tmp_path / "capsule.obj"
    trimesh.Trimesh(np.r_[v, sq], faces, process=False).export(path)
    tip = v[np.argmax(v[:, 2])] + [0, 0, 0.1]  # 0.1 above the pole: snapped, with a warning
    r = CliRunner().invoke(main, [
        str(path), "--preset", "glass", "--impact", ",".join(f"{x:g}" for x in tip) + ":0.6",
        "--max-steps", "30", "--res", "64", "--formats", "png", "-o", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    snapped = [ln for ln in lines if "snapped to" in ln]
    fins = [ln for ln in lines if "not manifold" in ln]
    assert len(snapped) == 1 and len(fins) == 1, lines
    assert len(lines) == len(set(lines))


def test_the_later_kernels_and_the_field_kernels_name_real_kernels():
    """The warm-up thread skips a name that does not resolve (a renamed kernel would only lose
    its head start, silently): every name the pipeline hands it is a module's numba kernel,
    or a module; the field's kernels are dispatchers the field calls."""
    import importlib
    from types import SimpleNamespace

    from numba.core.dispatcher import Dispatcher

    from crackbake.pipeline import _later_kernels
    from crackbake.simulate.stress.fields import field_kernels

    params = SimpleNamespace(decal=None, formats=("exr", "png", "glb", "preview", "stress"))
    names = _later_kernels(params, SimpleNamespace(udim=None))
    assert len(names) > 20
    for name in names:
        module, _, kernel = name.partition(":")
        mod = importlib.import_module(module)
        if kernel:
            assert isinstance(getattr(mod, kernel), Dispatcher), name
    assert _later_kernels(params, SimpleNamespace(udim=[1001, 1002])) == ()
    # a re-bake's: no solve's end, no stress bake, the bake's and the encoders' kept
    rebake = _later_kernels(params, SimpleNamespace(udim=None), solving=False)
    assert set(rebake) < set(names)
    assert not any(n.startswith(("crackbake.simulate.", "crackbake.nearest:",
                                 "crackbake.bake.stress")) for n in rebake)
    assert "crackbake.bake.grid:_bin_candidates" in rebake
    assert "crackbake.exchange.exrzip:_to_half" in rebake
    kernels = field_kernels()
    assert kernels and all(isinstance(k, Dispatcher) for k in kernels)
