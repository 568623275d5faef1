"""The package's layering, checked in a fresh interpreter: what a module pulls in on import."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

# Imports every module under crackbake.simulate and prints the crackbake.metrics modules loaded.
_SIMULATE = """
import importlib, pkgutil, sys
import crackbake.simulate as sim
names = [m.name for m in pkgutil.walk_packages(sim.__path__, "crackbake.simulate.")]
for name in names:
    importlib.import_module(name)
print(len(names))
print(" ".join(sorted(m for m in sys.modules if m.startswith("crackbake.metrics"))))
"""


def test_simulate_does_not_import_metrics():
    """The simulation depends on no measure of its results (metrics/ reads networks)."""
    r = subprocess.run([sys.executable, "-c", _SIMULATE], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    count, loaded = (r.stdout.splitlines() + ["", ""])[:2]
    assert int(count) > 20  # the walk really reached the solver's modules
    assert loaded == "", f"crackbake.simulate imports {loaded}"


_CLI = """
import sys
import crackbake.cli
before = " ".join(sorted(m for m in sys.modules if m.startswith("crackbake.")))
try:
    crackbake.cli.main(sys.argv[1:], prog_name="crackbake")
except SystemExit:
    pass
print(before, file=sys.stderr)
print(" ".join(sorted(m for m in sys.modules if m.startswith("crackbake."))), file=sys.stderr)
"""


def _cli_loads(*args: str) -> tuple[set[str], set[str]]:
    """The crackbake modules loaded by ``import crackbake.cli``, then after running ``args``."""
    r = subprocess.run([sys.executable, "-c", _CLI, *args], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    before, after = r.stderr.splitlines()[-2:]  # after the command's own output
    return set(before.split()), set(after.split())


def test_the_command_group_loads_no_command_module_and_no_pipeline():
    """``crackbake MESH`` parses its options with only the bake command loaded: the other
    commands are imported when named, the pipeline (GL, numba) once the options are valid;
    the group itself loads no command until it routes."""
    before, loaded = _cli_loads("--help")
    assert "crackbake.cli.bake" not in before
    assert "crackbake.cli.bake" in loaded
    for heavy in ("crackbake.cli.inspect", "crackbake.decals", "crackbake.tile", "crackbake.batch",
                  "crackbake.pipeline", "crackbake.bake", "crackbake.simulate"):
        assert heavy not in loaded, heavy


def test_inspect_loads_no_bake_options():
    """``crackbake inspect`` routes without the bake's options (their presets and defaults,
    about 0.1 s of the 0.5 s inspect floor, issue 25)."""
    _, loaded = _cli_loads("inspect", "--help")
    assert "crackbake.cli.inspect" in loaded
    for heavy in ("crackbake.cli.bake", "crackbake.params", "crackbake.pipeline"):
        assert heavy not in loaded, heavy


def test_no_private_names_cross_into_or_out_of_the_commands():
    """The commands share public helpers (crackbake.cli.common): no module imports a ``_name``
    from crackbake.cli, and no command module imports one from elsewhere."""
    root = Path(__file__).resolve().parents[1] / "crackbake"
    commands = {root / "decals" / "command.py", root / "tile" / "command.py",
                root / "batch" / "command.py",
                *(root / "cli").glob("*.py")}
    found = []
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or not (node.module or "").startswith(
                    "crackbake"):
                continue
            private = [a.name for a in node.names
                       if a.name.startswith("_") and not a.name.startswith("__")]
            if private and (node.module.startswith("crackbake.cli") or path in commands):
                found.append(f"{path.relative_to(root)}: {node.module} {private}")
    assert not found, found


# Runs the bake command on a mesh path that does not exist, then prints the heavy libraries
# that were imported on the way to the refusal.
_REFUSED = """
import sys
from crackbake.cli import main
try:
    main(sys.argv[1:], prog_name="crackbake")
except SystemExit as exc:
    code = exc.code
heavy = ("numba", "scipy", "trimesh", "moderngl", "crackbake.bake", "crackbake.exchange")
print(code, " ".join(sorted(h for h in heavy if h in sys.modules)))
"""


def test_a_run_refused_before_its_stages_imports_none_of_them(tmp_path):
    """The pipeline imports each stage (GL, numba kernels, scipy, trimesh) where it runs, and
    the mesh reader imports trimesh after the path checks: a wrong path is refused at once,
    which a catalogue of bad inputs (and a user's typo) pays in every process."""
    r = subprocess.run([sys.executable, "-c", _REFUSED, str(tmp_path / "missing.obj"),
                        "--shrink", "1", "-o", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert "file not found" in r.stderr, r.stderr
    code, _, loaded = r.stdout.strip().partition(" ")
    assert code == "2" and loaded == "", r.stdout


# Runs the console entry with the arguments given and prints the libraries it imported.
_ENTRY = """
import atexit
import sys
heavy = ("click", "numpy", "numba", "scipy", "trimesh", "moderngl", "OpenEXR",
         "crackbake.cli.bake", "crackbake.io.mesh", "crackbake.pipeline")
# At the exit: the command ends the process itself (crackbake.entry.leave), atexit handlers run.
atexit.register(lambda: print(" ".join(sorted(h for h in heavy if h in sys.modules)),
                              file=sys.stderr))
from crackbake.entry import main
main()
"""


def _entry_loads(*args: str) -> tuple[str, set[str]]:
    r = subprocess.run([sys.executable, "-c", _ENTRY, *args], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout, set(r.stderr.split())


def test_help_loads_the_options_but_no_numpy():
    """``crackbake --help`` needs click and the options' defaults, not the arrays (numpy alone
    is about 0.1 s of a 0.15 s budget, issue 25)."""
    out, loaded = _entry_loads("--help")
    assert "--impact" in out and "--res" in out  # the bake's options really were listed
    assert loaded == {"click", "crackbake.cli.bake"}, loaded


def test_version_loads_nothing_but_the_package():
    """``crackbake --version`` (a script's or the add-on's check) prints what click's version
    option prints, without importing click or any command."""
    out, loaded = _entry_loads("--version")
    assert loaded == set(), loaded
    r = subprocess.run([sys.executable, "-c", "from crackbake.cli import main; "
                        "main(['-V'], prog_name='crackbake')"],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0 and r.stdout.startswith("crackbake, version "), r
    assert out == r.stdout


def test_inspect_loads_no_bake_modules(tmp_path):
    """``crackbake inspect`` reads the EXR and prints its table without the bake's libraries
    (numba alone is ~0.4 s of its 0.5 s budget at 4096², issue 25); the pictures (``--png``)
    load the packing kernels when asked for."""
    import numpy as np

    from crackbake.exchange.exr import write_exr

    exr = tmp_path / "a.exr"
    write_exr(exr, {"crack.mask.V": np.eye(8, dtype=np.float16)})
    code = _ENTRY.replace("main()", "sys.argv[1:1] = ['inspect']; main()")
    r = subprocess.run([sys.executable, "-c", code, str(exr)], capture_output=True, text=True,
                       timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "crack.mask" in r.stdout  # the table really was printed
    loaded = set(r.stderr.split())
    assert not loaded & {"numba", "scipy", "trimesh", "moderngl", "crackbake.pipeline"}, loaded


_LOAD = """
import sys
from crackbake.io.mesh import load_mesh
mesh = load_mesh(sys.argv[1])
print(len(mesh.faces), " ".join(sorted(m for m in ("trimesh", "numba", "PIL", "scipy")
                                       if m in sys.modules)))
"""


def test_loading_an_obj_imports_no_trimesh_numba_or_pillow(tmp_path):
    """The load of an OBJ (its texture bound by an MTL) reads it with numpy alone: importing
    trimesh (with scipy), numba and Pillow was nearly all of the load stage's time."""
    spot = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
    (tmp_path / "spot.mtl").write_text("newmtl skin\nmap_Kd skin.png\n")
    (tmp_path / "spot.obj").write_text("mtllib spot.mtl\nusemtl skin\n" + spot.read_text())
    r = subprocess.run([sys.executable, "-c", _LOAD, str(tmp_path / "spot.obj")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    faces, _, loaded = r.stdout.strip().partition(" ")
    assert int(faces) == 5856
    assert loaded == ""


# Runs the bake command on a mesh refused just after its load (too small for the float32 bake)
# and prints the exit code, then the heavy modules already loaded when the ``load`` stage began.
_FIRST_STAGE = """
import logging
import sys
from crackbake.cli import main

heavy = ("numba", "scipy", "trimesh", "moderngl", "crackbake.bake", "crackbake.exchange",
         "crackbake.simulate", "crackbake.io.sidecar", "crackbake.network", "crackbake.memory",
         "crackbake.io.ply_strips")
seen = []

class AtLoad(logging.Handler):
    def emit(self, record):
        if getattr(record, "stage", None) == "load" and not seen:
            seen.append(" ".join(sorted(h for h in heavy if h in sys.modules)))

logging.getLogger("crackbake.pipeline").addHandler(AtLoad())
try:
    main(sys.argv[1:], prog_name="crackbake")
except SystemExit as exc:
    code = exc.code
print(code, len(seen), *seen, sep="|")
"""


def test_the_first_stage_starts_before_the_later_stages_are_imported(tmp_path):
    """The launch-to-first-stage time (0.25 s floor, issue 25) is imports: the load stage
    begins before the solver's, the bake's and the writers' modules (scipy, numba, GL) and
    the run's later helpers (sidecar, memory estimate, network) are imported."""
    tiny = tmp_path / "tiny.obj"  # 1.7e-12 units across: refused by the scale check after load
    tiny.write_text("v 0 0 0\nv 1e-12 0 0\nv 0 1e-12 0\nv 0 0 1e-12\n"
                    "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", _FIRST_STAGE, str(tiny), "--preset", "glass",
                        "--impact", "0,0,0", "-o", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert "rescale the mesh" in r.stderr, r.stderr  # the load stage ran, then the scale check
    code, count, loaded = r.stdout.strip().split("|")
    assert code == "2" and count == "1", r.stdout  # the load stage really was logged
    assert loaded == "", loaded


# Runs the bake of spot up to the start of its UV stage (a handler stops it there) and prints
# whether scipy's sparse matrices and spatial trees were loaded by then.
_UV_STAGE = """
import logging
import sys
from crackbake.cli import main

seen = []

class AtUVs(logging.Handler):
    def emit(self, record):
        if getattr(record, "stage", None) == "unwrap":
            seen.append(" ".join(sorted(m for m in ("scipy.sparse", "scipy.spatial")
                                        if m in sys.modules)))
            raise SystemExit(0)

logging.getLogger("crackbake.pipeline").addHandler(AtUVs())
try:
    main(sys.argv[1:], prog_name="crackbake")
except SystemExit:
    pass
print(len(seen), *seen, sep="|")
"""


def test_the_uv_stage_starts_without_scipy(tmp_path):
    """The sources are checked before the UV stage without the stress fields' scipy imports
    (0.3-0.5 s of CPU), and the tangents import scipy.sparse only for zero-UV-area faces:
    the UV stage, and a ``--cracks`` re-bake, never wait for them (issue 25)."""
    spot = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
    r = subprocess.run([sys.executable, "-c", _UV_STAGE, str(spot),
                        "--preset", "glass", "--impact", "0.334,0.044,0.287", "--res", "64",
                        "-q", "-o", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    count, loaded = r.stdout.strip().split("|")
    assert count == "1", r.stdout + r.stderr  # the UV stage began
    assert loaded == "", loaded


_RUN = """
import sys
import crackbake.cli
try:
    crackbake.cli.main(sys.argv[1:], prog_name="crackbake")
except SystemExit as exc:
    assert not exc.code, exc.code
print(" ".join(sorted(m for m in sys.modules if m.startswith("scipy"))), file=sys.stderr)
"""


def test_runs_from_a_warm_cache_import_no_scipy_spatial_sparse_or_linalg(tmp_path):
    """scipy.spatial, scipy.sparse and scipy.linalg are 0.3-0.4 s of imports each on the main
    thread (much of it shared).  A solving run
    takes its KD-tree searches and graph pieces from crackbake.nearest; the preview's guessed
    up axis (a convex hull) is the mesh cache's once a run has stored it.  So the first run of
    an asset imports scipy.spatial (for the hull, to the check's eye), the next solving run and
    a ``--cracks`` re-bake neither."""
    import os

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, CRACKBAKE_CACHE_DIR=str(tmp_path / "cache"))
    spot = str(root / "examples" / "spot.obj")

    def scipy_loaded(*args: str) -> set[str]:
        r = subprocess.run([sys.executable, "-c", _RUN, spot, "--res", "64", *args],
                           capture_output=True, text=True, timeout=300, env=env)  # fmt: skip
        assert r.returncode == 0, r.stderr
        return set(r.stderr.splitlines()[-1].split())

    impact = ("--impact", "0.334,0.044,0.287")
    first = scipy_loaded(*impact, "-o", str(tmp_path / "a"))
    assert "scipy.spatial" in first  # the hull: the check sees what a run imports
    for args in ((*impact, "-o", str(tmp_path / "b")),
                 ("--cracks", str(tmp_path / "a" / "cracks.json"), "-o", str(tmp_path / "c"))):
        loaded = scipy_loaded(*args)
        # scipy.linalg: numba's numpy-function module imports it (its BLAS check) when a
        # cached kernel that uses one of those functions loads
        assert not {"scipy.spatial", "scipy.sparse", "scipy.linalg"} & loaded, (args,
                                                                                sorted(loaded))


def test_the_crack_targets_allocate_before_numba_is_imported():
    """A re-bake starts allocating the crack bake's targets before the bake's modules import
    numba (0.3-0.4 s the allocation waited): their layout and the prefetch import neither numba
    nor GL wrappers."""
    code = ("import sys, crackbake.bake.crack_targets, crackbake.bake.prefetch; "
            "print(' '.join(m for m in ('numba', 'moderngl', 'scipy') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == ""
