"""The command line's display, on a real pseudo-terminal and on pipes (real processes)."""

from __future__ import annotations

import fcntl
import json
import os
import pty
import re
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from tests.test_bad_inputs import PLATE

REPO = Path(__file__).resolve().parents[1]
SPOT = REPO / "examples" / "spot.obj"
QUICK = ["--res", "64", "--sim-faces", "300", "--formats", "exr"]


def _env(tmp_path: Path) -> dict:
    return {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / "c")}


def run_on_pty(args: list[str], cwd: Path) -> tuple[int, str, str]:
    """Run ``python -m crackbake ARGS`` with stderr on a pseudo-terminal (stdout a pipe).

    Returns the exit code, everything written to the terminal and stdout.
    """
    master, slave = pty.openpty()
    # 200 columns, so the live line is not shortened to fit.
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 200, 0, 0))
    proc = subprocess.Popen(
        [sys.executable, "-m", "crackbake", *args], cwd=cwd, env=_env(cwd),
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave,
    )
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:  # EIO: the child closed its end
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    stdout = proc.stdout.read().decode()
    proc.stdout.close()
    return proc.wait(timeout=300), b"".join(chunks).decode(), stdout


def run_on_pipes(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "crackbake", *args], cwd=cwd, env=_env(cwd),
                          capture_output=True, text=True, timeout=300)


@pytest.fixture
def plate(tmp_path) -> Path:
    path = tmp_path / "plate.obj"
    path.write_text(PLATE)
    return path


def test_live_progress_on_a_terminal(plate, tmp_path):
    rc, term, stdout = run_on_pty([str(plate), "--shrink", "1", *QUICK, "-o", "a"], tmp_path)
    assert rc == 0, term
    assert stdout == ""
    assert "\r\x1b[K" in term  # the status line is redrawn in place
    # Each stage ends as a kept line with its time; the solver's result joins its stage.
    for stage in ("loading ", "building the simulation mesh", "growing cracks \\(iben\\): \\d+ "
                  "cracks started", "preparing UVs", "baking 64x64", "writing a"):
        assert re.search(stage + r".*, done in \d+\.\d s\r?\n", term), (stage, term)
    kept = [ln.rsplit("\x1b[K", 1)[-1] for ln in term.replace("\r\n", "\n").split("\n")]
    assert any(ln.startswith("wrote 4 files to a/") for ln in kept), term
    assert (tmp_path / "a" / "plate_cracks.exr").is_file()


def test_warning_clears_the_live_line(tmp_path):
    args = [str(SPOT), "--impact", "0.334,0.044,0.287:0.001", *QUICK, "-o", "w"]
    rc, term, _ = run_on_pty(args, tmp_path)
    assert rc == 0, term
    # The line is cleared first, so the warning starts at column 0 of a line of its own.
    assert re.search(r"\r\x1b\[Kwarning: impact radius 0\.001 is below the simulation edge "
                     r"length [0-9.]+; using [0-9.]+", term), term


def test_no_progress_when_stderr_is_not_a_terminal(plate, tmp_path):
    r = run_on_pipes([str(plate), "--shrink", "1", *QUICK, "-o", "b"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "\r" not in r.stderr and "\x1b" not in r.stderr
    assert not re.search(r"^(loading|building|growing|preparing|baking|writing)", r.stderr, re.M)
    assert r.stderr.startswith("mesh: 25 vertices, 32 faces") and "wrote 4 files to b/" in r.stderr


def test_quiet_on_a_terminal_prints_nothing_and_json_goes_to_stdout(plate, tmp_path):
    rc, term, stdout = run_on_pty([str(plate), "--shrink", "1", *QUICK, "-o", "q", "-q", "--json"],
                                  tmp_path)
    assert rc == 0 and term == ""
    summary = json.loads(stdout)
    assert summary["out_dir"] == "q" and "manifest.json" in summary["files"]
    assert summary["cracks"]["cracks"] > 0


def test_verbose_shows_timestamped_lines_not_the_live_line(plate, tmp_path):
    rc, term, _ = run_on_pty([str(plate), "--shrink", "1", *QUICK, "-o", "v", "-v"], tmp_path)
    assert rc == 0, term
    assert "\x1b[K" not in term
    assert re.search(r"^\[ *\d+\.\ds\] loading ", term, re.M)
    assert re.search(r"^  solve +\d+\.\d{3} s", term.replace("\r", ""), re.M)


def test_usage_error_is_one_line_on_a_terminal_too(plate, tmp_path):
    rc, term, _ = run_on_pty([str(plate), "--res", "abc"], tmp_path)
    assert rc == 2
    assert term.strip() == ("error: invalid value for '--res': 'abc' is not a valid integer; "
                            "run crackbake --help")


def test_tiny_impact_radius_is_raised_to_the_sim_edge(tmp_path):
    """The issue's crash (exit 1, ValueError in the stress field): now cracks with a warning."""
    r = run_on_pipes([str(SPOT), "--impact", "0.334,0.044,0.287:0.001", *QUICK, "-o", "t",
                      "--json"], tmp_path)
    assert r.returncode == 0, r.stderr
    assert "warning: impact radius 0.001 is below the simulation edge length" in r.stderr
    side = json.loads((tmp_path / "t" / "cracks.json").read_text())
    assert side["stats"]["cracks"] > 0
    # The radius the field used is recorded, and it is the raised one.
    assert side["impacts"][0]["radius"] > 0.001


def test_error_on_a_terminal_clears_the_live_line(plate, tmp_path):
    rc, term, _ = run_on_pty([str(plate), "--impact", "1e308,1e308,1e308", *QUICK, "-o", "e"],
                             tmp_path)
    assert rc == 2
    assert re.search(r"loading .*, done in \d+\.\d s", term)
    # What stays on screen after the last clear: the error alone.
    assert term.rsplit("\x1b[K", 1)[-1].strip().startswith(
        "error: impact point (1e+308, 1e+308, 1e+308) is 7.06e+307 mesh diagonals")
    assert not (tmp_path / "e").exists()


def test_ctrl_c_after_the_commit_is_ignored(plate, tmp_path):
    """Once the output set is committed, SIGINT is ignored: a Ctrl-C during the closing summary
    or the interpreter's shutdown printed "Exception ignored ... KeyboardInterrupt"."""
    import signal

    from click.testing import CliRunner

    from crackbake.cli import main

    before = signal.getsignal(signal.SIGINT)
    try:
        result = CliRunner().invoke(main, [str(plate), "--shrink", "1", *QUICK, "-o",
                                           str(tmp_path / "out"), "-q"])
        assert result.exit_code == 0, result.output
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


@pytest.mark.parametrize("name", ["tile", "inspect", "decals"])
def test_a_mesh_named_like_a_command_bakes_given_as_a_path(plate, tmp_path, name):
    """``crackbake ./tile`` bakes the file ``tile``; ``crackbake tile`` runs the tile command
    even with a file ``tile`` in the working folder (the command name wins, docs/cli.md)."""
    mesh = tmp_path / name
    mesh.write_text(plate.read_text())
    # The bake's own check, naming the file: the path went to the bake, not to the command.
    for arg in (f"./{name}", str(mesh)):
        r = run_on_pipes([arg], tmp_path)
        assert (r.returncode, r.stderr.strip()) == (
            2, f"error: {Path(arg)}: unsupported format '(none)'; use one of OBJ, PLY, STL, OFF, "
               "GLB, GLTF"), r.stderr
    # A folder of that name is only a path: its mesh bakes (QUICK: a small real run).
    folder = tmp_path / f"{name}_dir"
    (tmp_path / name).unlink()
    (tmp_path / name).mkdir()
    (tmp_path / name / "plate.obj").write_text(plate.read_text())
    r = run_on_pipes([f"{name}/plate.obj", *QUICK, "--preset", "mud", "-q", "-o", str(folder)],
                     tmp_path)
    assert r.returncode == 0, r.stderr
    assert (folder / "manifest.json").is_file() and (folder / "plate_cracks.exr").is_file()


def test_a_command_name_wins_over_a_file_of_that_name(plate, tmp_path):
    (tmp_path / "tile").write_text(plate.read_text())
    r = run_on_pipes(["tile", "--res", "3"], tmp_path)
    # the tile command's range (64..8192 texels per side), not the bake's (64..16384)
    assert (r.returncode, r.stderr.strip()) == (
        2, "error: --res 3 is out of range; use 64 to 8192 texels"), r.stderr
    r = run_on_pipes(["inspect"], tmp_path)
    assert (r.returncode, r.stderr.strip()) == (
        2, "error: missing argument 'EXR'; run crackbake --help"), r.stderr


def test_spacing_help_reads_the_presets_only_when_shown():
    """``--spacing``'s help lists the presets' own spacings (read from their TOML files) when
    the help is shown or read, not when the command module is imported for a run."""
    code = ("from crackbake.params.presets import load_preset, preset_names\n"
            "import crackbake.cli.bake as cb\n"
            "before = load_preset.cache_info().currsize\n"
            "spacing = next(p for p in cb.bake.params if p.name == 'spacing')\n"
            "own = [f\"{n} {load_preset(n)['spacing']}\" for n in preset_names()\n"
            "       if 'spacing' in load_preset(n)]\n"
            "print(before, all(o in spacing.help for o in own), bool(own))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60, env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])})
    assert r.stdout.split() == ["0", "True", "True"], r.stdout + r.stderr
