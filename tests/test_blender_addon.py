"""The Blender extension (crackbake.blender): the zip ``crackbake blender-addon`` writes, its
subprocess runner against real runs, and (with Blender's bpy) the extension installed into a
clean user profile, baking spot, cancelling, reporting errors, and its ray-cast helper."""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

from crackbake import __version__
from crackbake.blender.addon import runner
from crackbake.blender.build import (
    FOLDER,
    build_extension,
    default_command,
    version_tuple,
    zip_name,
)
from crackbake.params import parse_impact
from tests.blender_runner import blender_python, run_blender
from tests.test_bad_inputs import PLATE

REPO = Path(__file__).resolve().parents[1]
SPOT = REPO / "examples" / "spot.obj"
ADDON = REPO / "crackbake" / "blender" / "addon"


def _env(tmp_path: Path) -> dict:
    return {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / "c")}


@pytest.fixture(scope="module")
def addon_zip(tmp_path_factory) -> Path:
    return build_extension(tmp_path_factory.mktemp("zip"))


def test_the_zip_is_a_blender_extension(addon_zip):
    assert addon_zip.name == f"crackbake_blender-{__version__}.zip" == zip_name()
    with zipfile.ZipFile(addon_zip) as zf:
        names = set(zf.namelist())
        manifest = tomllib.loads(zf.read(f"{FOLDER}/blender_manifest.toml").decode())
        defaults = zf.read(f"{FOLDER}/defaults.py").decode()
        init = zf.read(f"{FOLDER}/__init__.py").decode()
    # every source of addon/ in the archive's one folder, nothing else but the generated file
    assert names == {f"{FOLDER}/{n}" for n in [p.name for p in ADDON.glob("*.py")]
                     + ["blender_manifest.toml", "defaults.py"]}
    assert manifest["id"] == "crackbake" and manifest["type"] == "add-on"
    assert manifest["version"] == __version__
    assert manifest["blender_version_min"] == "4.2.0"
    assert set(manifest["permissions"]) == {"files"}
    assert "wheels" not in manifest  # pure Python
    space: dict = {}
    exec(compile(defaults, "defaults.py", "exec"), space)
    assert space["COMMAND"] == default_command() and space["VERSION"] == __version__
    assert "glass" in space["PRESETS"] and space["METHODS"] == ("iben", "thesis")
    assert space["HELP"]["seed"] == "Random seed."
    # the legacy add-on's bl_info (Blender < 4.2), read as Blender reads it (a literal)
    tree = ast.parse(init)
    node = next(n for n in tree.body if isinstance(n, ast.Assign)
                and getattr(n.targets[0], "id", "") == "bl_info")
    bl_info = ast.literal_eval(node.value)
    assert bl_info["version"] == tuple(int(p) for p in __version__.split(".")[:3])
    assert bl_info["blender"] == (3, 4, 0) and bl_info["name"] == "Crackbake"
    assert bl_info["location"] == "3D View > Sidebar > Crackbake"


def test_the_version_tuple():
    assert version_tuple("0.1.0") == (0, 1, 0)
    assert version_tuple("1.2") == (1, 2, 0)
    assert version_tuple("2.10.3rc1") == (2, 10, 3)
    assert version_tuple("1.0.0.dev4") == (1, 0, 0)


def test_the_zip_is_reproducible(addon_zip, tmp_path):
    again = build_extension(tmp_path)
    assert again.read_bytes() == addon_zip.read_bytes()
    assert build_extension(tmp_path, "other").read_bytes() != addon_zip.read_bytes()


def test_the_command_writes_the_zip_and_refuses_a_file(tmp_path):
    def cli(*args):
        return subprocess.run([sys.executable, "-m", "crackbake", "blender-addon", *args],
                              cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True,
                              timeout=120)

    r = cli("-o", "ext", "--command", "/opt/cb/bin/crackbake")
    assert r.returncode == 0, r.stderr
    path = Path(r.stdout.strip())
    assert path == tmp_path / "ext" / zip_name() and path.is_file()
    with zipfile.ZipFile(path) as zf:
        assert "COMMAND = '/opt/cb/bin/crackbake'" in zf.read(f"{FOLDER}/defaults.py").decode()
    (tmp_path / "afile").write_text("x")
    r = cli("-o", "afile")
    assert r.returncode == 2
    assert r.stderr.strip() == "error: -o afile: not a folder; give a folder for the zip"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "ext"]


def test_impact_arguments_survive_the_trip():
    point = (0.1 + 1e-9, -2.0 / 3.0, 1e-7)
    parsed = parse_impact(runner.impact_arg(point, 0.25, 1.5))
    assert parsed.point == point and parsed.radius == 0.25 and parsed.strength == 1.5
    parsed = parse_impact(runner.impact_arg(point, 0.0, 2.0))  # 0: crackbake's default
    assert parsed.radius is None and parsed.strength == 2.0


def test_a_wrong_command_is_named(tmp_path):
    version, problem = runner.check_command(f"{sys.executable} -m crackbake")
    assert version == __version__ and problem is None
    version, problem = runner.check_command(str(tmp_path / "nothing"))
    assert version is None and problem.startswith(f"cannot run the crackbake command '"
                                                   f"{tmp_path / 'nothing'}'")
    version, problem = runner.check_command("true")  # runs, but is not crackbake
    assert version is None and "did not answer as crackbake does" in problem


def test_the_runner_follows_a_real_run_without_blocking(tmp_path):
    mesh = tmp_path / "plate.obj"
    mesh.write_text(PLATE)
    workdir = tmp_path / "work"
    workdir.mkdir()
    argv = [sys.executable, "-m", "crackbake", str(mesh), "--shrink", "1", "--res", "64",
            "-o", str(tmp_path / "out"), "--progress", "jsonl"]
    job = runner.Job(argv, str(workdir), env=_env(tmp_path)).start()
    polls, slowest, fractions = 0, 0.0, []
    while True:
        t = time.perf_counter()
        ended = job.poll()
        slowest = max(slowest, time.perf_counter() - t)
        polls += 1
        fractions.append(job.fraction)
        if ended:
            break
        time.sleep(0.02)
    assert job.error is None and job.summary is not None, job.stderr_lines
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert polls > 3 and slowest < 0.05
    assert "cracks.json" in job.summary["files"]
    job.cleanup()
    assert not workdir.exists()

    bad = runner.Job([*argv[:3], str(tmp_path / "missing.obj"), "--progress", "jsonl"],
                     str(workdir), env=_env(tmp_path)).start()
    bad.wait(120)
    assert bad.summary is None and not bad.cancelled
    assert bad.error.startswith(f"{tmp_path / 'missing.obj'}")


# ---------------------------------------------------------------- in Blender (bpy 5.0)


def _in_blender(addon_zip, tmp_path, mode: str, res: int, sim_faces: int, timeout=600) -> dict:
    (tmp_path / "user").mkdir()
    (tmp_path / "tmp").mkdir()
    env = {"BLENDER_USER_RESOURCES": str(tmp_path / "user"), "TMPDIR": str(tmp_path / "tmp"),
           "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / "c"),
           "CRACKBAKE_TEST_SIM_FACES": str(sim_faces)}
    out = run_blender("addon_bake.py", addon_zip, SPOT, tmp_path / "out", res, mode,
                      timeout=timeout, env=env)
    assert out["installed"] == ["FINISHED"] and out["enabled"]
    assert out["command"] == default_command()
    assert out["tmp_left"] == []  # the exported mesh and its folder are gone
    # the zip's one folder is unpacked as the extension itself
    assert (tmp_path / "user" / "extensions" / "user_default" / "crackbake" /
            "blender_manifest.toml").is_file()
    return out


@pytest.mark.reference
def test_blender_validates_the_manifest(addon_zip):
    exe = blender_python()
    if exe is None:
        pytest.skip("Blender's bpy is not available (set CRACKBAKE_BLENDER_PYTHON)")
    tool = subprocess.run(
        [exe, "-c", "import bpy, os; print(os.path.join(bpy.utils.system_resource('SCRIPTS'), "
         "'addons_core', 'bl_pkg', 'cli', 'blender_ext.py'))"],
        capture_output=True, text=True, timeout=120)
    script = tool.stdout.strip().splitlines()[-1]
    r = subprocess.run([exe, script, "validate", str(addon_zip)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "Success" in r.stdout, r.stdout + r.stderr


@pytest.mark.reference
def test_the_ray_cast_helper_hits_misses_and_rejects_back_faces():
    out = run_blender("addon_raycast.py", ADDON / "raycast.py")
    assert out["scale"] == pytest.approx(0.5)
    hit = out["hit"]
    assert np.allclose(hit["world"], out["expected_world"], atol=1e-5)
    assert np.allclose(hit["local"], [1.0, 0.0, 0.0], atol=1e-6)
    assert np.allclose(hit["normal"], out["expected_normal"], atol=1e-5)
    assert out["miss"] is None and out["inside"] is None
    circle = out["circle"]
    assert circle["count"] == 17 and circle["closed"] < 1e-6
    assert np.allclose(circle["radii"], 0.3) and np.allclose(circle["along_normal"], 0.0,
                                                             atol=1e-6)


@pytest.mark.reference
def test_install_bake_and_rebake_in_blender(addon_zip, tmp_path):
    out = _in_blender(addon_zip, tmp_path, "bake", 256, 3000)
    # impacts clicked in world space are stored, and reach crackbake, in object space
    local = np.array(out["impacts_local"])
    assert np.allclose(out["stored"], local, atol=1e-5)
    assert np.allclose(out["stored_radius"], 0.12, rtol=1e-5)  # 0.24 world / scale 2
    # each impact drawn as a circle of its world radius around its world point
    for centre, circle in zip(out["impacts_world"], out["circles"], strict=True):
        radii = np.linalg.norm(np.array(circle) - centre, axis=1)
        assert np.allclose(radii, 0.24, rtol=2e-3)
    sidecar = np.array([i["point"] for i in out["sidecar_impacts"]])
    assert np.allclose(sidecar, local, atol=1e-5)
    assert out["params"]["weight_attribute"] == "weight" and out["params"]["uv"] == "keep"
    assert out["bake"] == ["FINISHED"]
    first = out["first"]
    # the artist's material, kept, with the group between its values and the BSDF
    assert first["material"] == "artist" and first["materials"] == ["artist"]
    assert first["group"] == "Crackbake Cracks"
    assert all(first["linked"].values())
    assert np.allclose(first["kept"]["Base Color"], [0.2, 0.4, 0.8], atol=1e-6)
    assert first["kept"]["Roughness"] == pytest.approx(0.35)
    # data maps are Non-Color, at the baked size
    spaces = {v["file"]: (v["space"], v["size"]) for v in first["images"].values()}
    assert spaces == {f"spot_{m}.png": ("Non-Color", [256, 256])
                      for m in ("data", "normal", "ao")}
    assert out["keyframed"]
    # Cycles renders the spliced material: glass cracks (the preset's lighten look) lighter
    # than the intact blue; at Growth 0 no crack shows
    grown, ungrown = out["albedo_grown"], out["albedo_ungrown"]
    assert grown["crack_texels"] > 10 and grown["intact_texels"] > 1000
    assert grown["crack"] > grown["intact"] + 0.1, grown
    assert np.allclose(grown["intact_rgb"], [0.2, 0.4, 0.8], atol=0.05)  # the artist's colour
    assert ungrown["crack"] == pytest.approx(ungrown["intact"], abs=0.02), ungrown
    # Blender's status bar: a blocking bake's line is gone when it returns; a background
    # bake's ("Crackbake: <stage> <percent> %", with a Cancel button) is drawn from its start,
    # follows crackbake's progress at every timer call, and is taken out of the header after
    assert out["status_bar_after_wait"] == [None, False]
    assert out["rebake_started"] == [["Crackbake: starting 0 %", 0.0], True]
    run = out["rebake_run"]
    assert run["status_bar"] and all(p["shown"] for p in run["status_bar"])
    for p in run["status_bar"]:
        assert p["line"][0] == f"Crackbake: {p['message']} {int(100 * p['fraction'])} %", p
    # crackbake said it was done, and the extension read it. Which stages a 0.1 s timer sees is
    # timing: at 256² the bake and the write may both pass between two calls (CI once drew 0.66
    # last), so the bar is held to following the job forward, through more than one stage
    assert run["final_fraction"] == 1.0 and run["summary_read"]
    drawn = [p["fraction"] for p in run["status_bar"]]
    assert drawn == sorted(drawn) and len(set(drawn)) >= 2, drawn
    assert run["status_bar_after"] == {"line": None, "shown": False, "in_header": False}
    assert out["rebake_status"].endswith("cracks") and not run["workdir_left"]
    # re-bake of the same network at 128: the same images, reloaded; no duplicates
    second = out["second"]
    assert out["rebake"] == ["FINISHED"] and out["rebake_params"]["cracks"].endswith(
        "cracks.json")
    assert out["rebake_params"]["look"] == out["params"]["look"]  # the preset's look again
    assert {v["size"][0] for v in second["images"].values()} == {128}
    assert second["all_images"] == first["all_images"] and second["groups"] == ["Crackbake Cracks"]
    assert second["materials"] == ["artist"]


@pytest.mark.reference
@pytest.mark.slow
def test_cancel_keeps_the_previous_result(addon_zip, tmp_path):
    out = _in_blender(addon_zip, tmp_path, "cancel", 256, 3000)
    run = out["run"]
    assert run["cancelled_at"] and run["cancelled_at"].startswith("growing cracks")
    assert run["status"] == "cancelled; the previous result is kept"
    assert out["manifest_kept"] and not run["workdir_left"]
    assert {v["size"][0] for v in out["state"]["images"].values()} == {256}


# The timer's floor during a 4096² background bake (each call under 0.05 s) is a wall-clock
# measurement: benchmarks/bench_blender_addon.py --timer.


@pytest.mark.reference
def test_a_new_unwrap_is_stored_as_the_crackbake_uv_map(addon_zip, tmp_path):
    out = _in_blender(addon_zip, tmp_path, "unwrap", 256, 3000)
    assert "a new unwrap is stored on the mesh itself, and its modifiers change it" in \
        out["modifier"]
    assert out["bake"] == ["FINISHED"] and out["uv_layers"] == ["crackbake"]
    assert out["uv_nodes"] == ["crackbake"]
    # the sidecar's crack points fall on the mask through the stored UVs, not with v flipped
    assert out["points"] >= 10, out
    assert out["on_crack"] > 0.8 * out["points"], out
    assert out["on_flipped"] < 0.3 * out["points"], out
    assert all(v["space"] == "Non-Color" for v in out["state"]["images"].values())


@pytest.mark.reference
def test_clear_reports_for_a_camera_and_a_wrong_command(addon_zip, tmp_path):
    out = _in_blender(addon_zip, tmp_path, "errors", 256, 3000)
    assert out["camera"].strip().endswith(
        "Crackbake: the active object 'Camera' is a camera; select a mesh object")
    assert "cannot run the crackbake command '/nonexistent/crackbake'" in out["wrong_command"]
    assert "Crackbake: impact point (100, 100, 100) is" in out["crackbake_error"]
    assert out["crackbake_error"].strip().endswith("give a point on or within 1 mesh diagonal "
                                                   "of the surface")
    assert out["groups_after_error"] == []
    # the panel's settings as crackbake parses them
    from crackbake.cli.bake import bake

    argv = out["argv"]
    assert argv[:2] == ["crackbake", "m.ply"]
    p = bake.make_context("crackbake", argv[1:]).params
    assert p["preset"] == "glass" and p["method"] == "thesis" and p["seed"] == 3
    assert p["res"] == 256 and p["target"] == "blender" and p["uv"] == "keep"
    assert p["weight_attribute"] == "weight" and p["invert_weights"]
    assert p["directions"] == ("0,1,0:1.5",) and p["curvature"] == "0.5"
    assert (p["shrink"], p["noise"], p["spacing"], p["sim_faces"]) == (0.25, 0.1, 0.05, 5000)
    assert len(p["impacts"]) == 2 and p["progress"] == "jsonl"


@pytest.mark.reference
def test_the_export_is_the_evaluated_mesh_crackbake_reads(tmp_path):
    from crackbake.io.mesh import load_mesh
    from crackbake.simulate.stress import vertex_weights

    ply = tmp_path / "cube.ply"
    out = run_blender("addon_export.py", ADDON / "export.py", ply)
    mesh = load_mesh(ply)
    # the subdivided cube (24 quads), in object space (not moved, not scaled), seams kept
    assert out["triangles"] == len(mesh.faces) == 48
    assert len(mesh.vertices) == out["written_vertices"] > out["vertices"]
    assert sorted({tuple(np.round(v, 5)) for v in mesh.vertices}) == [tuple(c) for c in
                                                                      out["co"]]
    assert 0.5 < np.abs(mesh.vertices).max() < 1.0  # smoothed by the modifier, not scaled by 3
    assert mesh.uv is not None and -1e-6 <= mesh.uv.min() and mesh.uv.max() <= 1.0 + 1e-6
    # the vertex group, interpolated by the modifier: 1 on the top, 0 on the bottom
    w = vertex_weights(mesh, "weight")
    z = mesh.vertices[:, 2]
    top, bottom = z > z.max() - 1e-6, z < z.min() + 1e-6
    assert top.any() and bottom.any() and np.allclose(w[top], 1.0) and np.allclose(w[bottom], 0.0)
    assert out["bad_uv"] == "'Cube' has no UV map 'no such map'; add one (UV > Unwrap) or pick " \
        "another"
    assert out["bad_group"] == "'Cube' has no vertex group 'no such group'"


# ---------------------------------------------------------------- as a legacy add-on (< 4.2)


def _legacy_blender() -> str | None:
    """A Blender executable older than 4.2 (``CRACKBAKE_LEGACY_BLENDER``, or ``blender`` on the
    PATH, such as Debian's 3.4), or None."""
    exe = os.environ.get("CRACKBAKE_LEGACY_BLENDER") or shutil.which("blender")
    if exe is None:
        return None
    try:
        said = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return None
    words = said.stdout.split()
    if said.returncode != 0 or len(words) < 2 or words[0] != "Blender":
        return None
    version = tuple(int(p) for p in words[1].split(".")[:2])
    return exe if version < (4, 2) else None


# Not a ``reference`` check: make test installs bpy 5.0, not an old Blender, and a skipped
# reference check fails it.  It runs where a Blender < 4.2 is on the PATH (Debian's 3.4).
@pytest.mark.slow
def test_the_zip_installs_as_a_legacy_addon_and_bakes(addon_zip, tmp_path):
    exe = _legacy_blender()
    if exe is None:
        pytest.skip("no Blender older than 4.2 (set CRACKBAKE_LEGACY_BLENDER; Debian: "
                    "apt install blender python3-numpy)")
    for d in ("scripts", "config", "tmp"):
        (tmp_path / d).mkdir()
    env = {**os.environ, "BLENDER_USER_SCRIPTS": str(tmp_path / "scripts"),
           "BLENDER_USER_CONFIG": str(tmp_path / "config"), "TMPDIR": str(tmp_path / "tmp"),
           "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / "c"),
           "CRACKBAKE_TEST_SIM_FACES": "3000"}
    proc = subprocess.run(
        [exe, "-b", "--factory-startup", "--python", str(REPO / "tests" / "blender" /
                                                        "addon_legacy.py"),
         "--", str(addon_zip), str(SPOT), str(tmp_path / "out"), "128"],
        capture_output=True, text=True, timeout=600, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    assert lines, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = json.loads(lines[-1])
    assert out["version"] < [4, 2]
    assert out["installed"] == out["enabled"] == ["FINISHED"]
    # unpacked as the module crackbake_blender, with its bl_info (crackbake's version)
    assert set(out["addon_dir"]) >= {"__init__.py", "ops.py", "blender_manifest.toml"}
    assert out["bl_info"]["version"] == list(version_tuple())
    assert out["add_impact"] == ["FINISHED"]
    assert np.allclose(out["sidecar_impacts"], out["impacts"], atol=1e-5)
    assert out["bake"] == ["FINISHED"] and out["status"].endswith("cracks"), out["status"]
    # the status bar's line while it ran, gone after
    assert out["status_bar"] and all(p["shown"] for p in out["status_bar"])
    for p in out["status_bar"]:
        assert p["line"][0] == f"Crackbake: {p['message']} {int(100 * p['fraction'])} %", p
    assert out["status_bar_after"] == [None, False]
    # the group (3.x's node-group sockets) between the material and its BSDF; Non-Color maps
    assert out["group"] == "Crackbake Cracks" and all(out["linked"].values())
    assert sorted(v[0] for v in out["images"].values()) == ["Non-Color"] * 3
    assert {tuple(v[1]) for v in out["images"].values()} == {(128, 128)}
    assert not list((tmp_path / "tmp").glob("crackbake-*"))  # the temporary folder is gone
