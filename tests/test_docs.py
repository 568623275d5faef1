"""Every ``crackbake ...`` command the README and ``docs/*.md`` show runs and exits 0.

Commands are taken from shell code blocks (lines starting ``crackbake`` or
``.venv/bin/crackbake``) and from inline code spans; ones with placeholders (``MESH``,
``FILE.exr``, ``X,Y,Z``, ``[...]``) and bare command names (``crackbake tile``) are syntax, not
commands, and are left out.  Each runs as ``crackbake`` (the entry point of ``python -m
crackbake``, forked from one process that imported it: tests/cli_forks.py; ``batch`` in a fresh
interpreter) in a scratch folder holding
``examples/`` (so the documented paths work), made small: ``--res`` lowered, a small
simulation mesh and few decal variants, since the check is that the command as written is
accepted and completes, not the picture.  An input a command names that the docs produced in
an earlier command (``--cracks mud/cracks.json``, ``inspect mud/spot_stress.exr``) is made
first by a small bake of spot into that folder.  The README's Python quick start runs too.

Marked slow: ``make test`` runs it, ``make check`` does not.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import cli_forks
import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PLACEHOLDER = re.compile(
    r"\b(MESH|FILE|OUT|DIR|IMG|NAME|SIZE|LIST|COMMAND|[A-Z])\b|\.\.\.|[\[<|]|X,Y,Z")
SMALL = {"bake": 128, "decals": 64, "tile": 128}
COMMANDS = ("inspect", "decals", "tile", "batch", "blender-addon")
SIM_FACES = "4000"
#: Commands the docs show that another test runs as written, with more checks than an exit
#: status (each starts a Ray of its own: running them here too cost half a minute).
RUN_ELSEWHERE = {
    "crackbake batch examples/batch.toml -o spot_batch/":
        "test_batch.py::test_the_documented_batch_on_a_pipe_leaves_nothing_running",
    "crackbake batch examples/batch.toml -o spot_batch/ --resume":
        "test_batch.py::test_the_documented_batch_on_a_pipe_leaves_nothing_running",
}
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _commands(text: str) -> list[str]:
    out, fence = [], None
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("```"):
            fence = None if fence is not None else s[3:]
            continue
        if fence is not None:
            if fence in ("", "sh", "bash") and re.match(r"(\.venv/bin/)?crackbake\s", s):
                out.append(s.split("  #")[0].strip())
            continue
        out += [m.group(1) for m in re.finditer(r"`((?:\.venv/bin/)?crackbake\s[^`]*)`", line)]
    return out


def documented() -> list[tuple[str, str]]:
    """(page, command) for every runnable command the docs show, each once."""
    seen, found = set(), []
    for page in PAGES:
        for cmd in _commands(page.read_text()):
            args = shlex.split(cmd)[1:]
            if PLACEHOLDER.search(cmd) or cmd in RUN_ELSEWHERE:
                continue
            key = tuple(small(args)) if args else ()
            if key in seen:
                continue
            if len(args) == 1 and args[0] in COMMANDS:
                continue  # the command's name in a sentence
            seen.add(key)
            found.append((page.name, cmd))
    return found


def _set(args: list[str], flag: str, value: str, only_lower: bool = False) -> list[str]:
    if flag in args:
        i = args.index(flag) + 1
        if not only_lower or int(args[i]) > int(value):
            args[i] = value
    else:
        args += [flag, value]
    return args


def small(args: list[str]) -> list[str]:
    """``args`` with a small resolution and simulation (and few decal variants)."""
    args = list(args)
    if any(a in ("--help", "-h", "--version", "-V") for a in args):
        return args
    kind = args[0] if args[0] in COMMANDS else "bake"
    # a batch's sizes are in its file (examples/batch.toml); blender-addon bakes nothing
    if kind in ("inspect", "batch", "blender-addon"):
        return args
    args = _set(args, "--res", str(SMALL[kind]), only_lower=True)
    if kind == "decals":
        args = _set(args, "-n", "2", only_lower=True)
    if "--detail" not in args and "--cracks" not in args:
        args = _set(args, "--sim-faces", SIM_FACES)
    return args


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    if args[:1] == ["batch"]:  # a batch starts Ray's own processes: a fresh interpreter
        return subprocess.run([sys.executable, "-m", "crackbake", *args], cwd=cwd, env=ENV,
                              capture_output=True, text=True, timeout=600)
    return cli_forks.run(args, cwd=cwd, env=ENV, timeout=600)


def _inputs(args: list[str], cwd: Path) -> None:
    """Bake spot into the folder of each named input (.json, .exr) that does not exist yet."""
    for i, a in enumerate(args):
        if a.endswith((".json", ".exr")) and args[i - 1] not in ("-o", "--out"):
            path = cwd / a
            if not path.exists():
                r = _run(["examples/spot.obj", "--preset", "mud", "-q", "-o", str(path.parent),
                          *small(["examples/spot.obj"])[1:]], cwd)
                assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("docs")
    (folder / "examples").symlink_to(ROOT / "examples")
    return folder


def test_the_docs_show_commands():
    cmds = [c for _, c in documented()]
    assert len(cmds) >= 8, cmds
    assert any(" inspect " in c for c in cmds) and any(" decals " in c for c in cmds)
    assert any(" tile " in c for c in cmds) and any("--cracks" in c for c in cmds)


@pytest.mark.slow
@pytest.mark.parametrize(("page", "cmd"), documented(),
                         ids=[f"{p}:{c[:60]}" for p, c in documented()])
def test_documented_command_runs(page, cmd, scratch):
    args = small(shlex.split(cmd)[1:])
    _inputs(args, scratch)
    r = _run(args, scratch)
    assert r.returncode == 0, f"{page}: `{cmd}` exited {r.returncode}:\n{r.stderr[-2000:]}"


@pytest.mark.slow
def test_readme_python_quick_start_runs(tmp_path):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks and "from crackbake" in blocks[0]
    code = re.sub(r"res=\d+", "res=128", blocks[0]).replace(
        'preset="glass",', f'preset="glass", sim_faces={SIM_FACES}, out="out",')
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=ENV,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "bake" in r.stdout  # the stage timings it prints


def _anchors(text: str) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    out = set()
    for h in re.findall(r"^#+ (.*)$", text, re.M):
        a = re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
        out.add(a)
    return out


def test_links_between_the_pages_resolve():
    bad = []
    for page in PAGES:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+://", target):
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                bad.append(f"{page.name}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest.read_text()):
                bad.append(f"{page.name}: {target} (no such heading)")
    assert not bad, bad


def test_readme_is_a_front_door():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    for page in sorted((ROOT / "docs").glob("*.md")):
        assert f"docs/{page.name}" in text, f"README does not link docs/{page.name}"
