"""The output folder as a transaction, with real processes and real signals.

A ``crackbake`` process is started on a job slow enough to interrupt, stopped at a known stage
(its progress lines on stderr say which stage it is in) with SIGINT, SIGTERM or SIGKILL, and the
folder is checked: the previous set intact or the new one complete, never mixed; nothing left
beside it after the next run; no xatlas worker outliving its parent; one run per folder.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import torus_mesh

from crackbake.cli import main
from crackbake.exchange.interrupt import Interrupt, deferred, interruptible

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
CLI = [sys.executable, "-c", "from crackbake.cli import main; main()"]
# A few seconds per stage: solve ~3 s, bake ~1.6 s, write ~1.7 s on 2 busy cores.
SLOW = [str(SPOT), "--preset", "mud", "--sim-faces", "20000", "--res", "2048"]
QUICK = [str(SPOT), "--preset", "mud", "--sim-faces", "2000", "--res", "256", "--formats", "exr"]


class Run:
    """A crackbake process whose stderr lines are collected as they come."""

    def __init__(self, args: list[str], out: Path, cwd: Path) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.proc = subprocess.Popen(
            # -v: stage lines on stderr even though it is a pipe (the tests wait for them).
            [*CLI, *args, "-v", "-o", str(out)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=cwd,
        )
        self.lines: list[str] = []
        self._new = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            with self._new:
                self.lines.append(line.rstrip("\n"))
                self._new.notify_all()

    def wait_for(self, text: str, timeout: float = 120.0) -> None:
        """Block until a stderr line contains ``text``."""
        end = time.monotonic() + timeout
        with self._new:
            while not any(text in ln for ln in self.lines):
                exited = self.proc.poll() is not None
                if time.monotonic() > end or (exited and not self._new.wait(1.0)):
                    raise AssertionError(f"never saw {text!r}; stderr: {self.lines}")
                self._new.wait(0.5)

    def finish(self, timeout: float = 120.0) -> int:
        rc = self.proc.wait(timeout)
        time.sleep(0.2)  # let the reader thread take the last lines
        return rc


def snapshot(folder: Path) -> dict[str, str]:
    """SHA-256 of every file in ``folder`` (and the folder's absence as {})."""
    if not folder.exists():
        return {}
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def beside(out: Path) -> list[str]:
    """What crackbake made next to ``out`` (staging, trash, lock)."""
    return sorted(p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}."))


def children(pid: int) -> list[int]:
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(k) for k in (task / "children").read_text().split()]
        except OSError:
            pass
    return kids


def alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.fixture(scope="module")
def previous(tmp_path_factory) -> Path:
    """An output folder holding a complete earlier run (mud, 2000 sim faces, EXR only)."""
    base = tmp_path_factory.mktemp("previous")
    out = base / "spot_cracks"
    r = Run(QUICK, out, base)
    assert r.finish() == 0, r.lines
    return out


@pytest.fixture
def old_set(previous, tmp_path) -> Path:
    out = tmp_path / "spot_cracks"
    shutil.copytree(previous, out)
    return out


SIGNAL_STAGES = [
    (signal.SIGINT, "growing cracks"),
    (signal.SIGTERM, "growing cracks"),
    (signal.SIGINT, "baking"),
    (signal.SIGINT, "writing"),
    (signal.SIGTERM, "writing"),
]


@pytest.mark.slow
@pytest.mark.parametrize(("sig", "stage"), SIGNAL_STAGES)
def test_interrupt_keeps_the_previous_set(old_set, tmp_path, sig, stage):
    before = snapshot(old_set)
    r = Run(SLOW, old_set, tmp_path)
    r.wait_for(stage)
    r.proc.send_signal(sig)
    assert r.finish() == 128 + sig, r.lines
    assert r.lines[-1] == f"error: interrupted; the previous outputs in {old_set} are unchanged"
    assert snapshot(old_set) == before
    assert beside(old_set) == []


@pytest.mark.slow
def test_interrupt_without_previous_outputs_leaves_nothing(tmp_path):
    out = tmp_path / "new" / "spot_cracks"
    r = Run(SLOW, out, tmp_path)
    r.wait_for("writing")
    r.proc.send_signal(signal.SIGTERM)
    assert r.finish() == 143, r.lines
    assert r.lines[-1] == "error: interrupted; no outputs were written"
    assert sorted(tmp_path.iterdir()) == []  # not even the parent folder it created


@pytest.mark.slow
def test_sigkill_while_writing_then_the_next_run_cleans_up(old_set, tmp_path):
    before = snapshot(old_set)
    r = Run(SLOW, old_set, tmp_path)
    r.wait_for("writing")
    time.sleep(0.3)  # some files staged
    r.proc.send_signal(signal.SIGKILL)
    assert r.finish() == -signal.SIGKILL
    assert snapshot(old_set) == before  # the old set, whole
    left = beside(old_set)
    assert ".spot_cracks.crackbake-lock" in left
    assert any(n.startswith(".spot_cracks.crackbake-staging-") for n in left), left
    # The next run is not blocked by the dead run's lock and removes its staging folder.
    again = Run(QUICK, old_set, tmp_path)
    assert again.finish() == 0, again.lines
    assert beside(old_set) == []
    manifest = json.loads((old_set / "manifest.json").read_text())
    listed = {f["name"] for f in manifest["files"]} | {"manifest.json"}
    assert set(snapshot(old_set)) == listed


@pytest.mark.slow
def test_fewer_formats_leave_no_stale_files(old_set, tmp_path):
    r = Run([*SLOW[:-2], "--res", "256"], old_set, tmp_path)
    assert r.finish() == 0, r.lines
    assert "spot.glb" in snapshot(old_set)
    r = Run(QUICK, old_set, tmp_path)
    assert r.finish() == 0, r.lines
    assert sorted(snapshot(old_set)) == [
        "cracks.json", "cracks.obj", "manifest.json", "spot_cracks.exr"
    ]


@pytest.mark.slow
def test_second_run_into_the_same_folder_fails_at_once(old_set, tmp_path):
    first = Run(SLOW, old_set, tmp_path)
    first.wait_for("growing cracks")
    t = time.monotonic()
    second = Run(QUICK, old_set, tmp_path)
    assert second.finish() == 2, second.lines
    assert time.monotonic() - t < 30
    assert second.lines == [
        f"error: output folder '{old_set}' is in use by another crackbake run "
        f"(pid {first.proc.pid}); wait for it to finish or choose another folder with -o"
    ]
    assert first.finish() == 0, first.lines  # the first run is not disturbed
    assert beside(old_set) == []
    assert "spot.glb" in snapshot(old_set)


@pytest.fixture(scope="module")
def big_torus(tmp_path_factory) -> Path:
    """An 80k-face torus without UVs: xatlas needs well over ten seconds for it."""
    mesh = torus_mesh(400, 100)
    path = tmp_path_factory.mktemp("torus") / "torus.obj"
    with open(path, "w") as fh:
        np.savetxt(fh, mesh.vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(fh, mesh.faces + 1, fmt="f %d %d %d")
    return path


def _worker_of(r: Run, timeout: float = 60.0) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for kid in children(r.proc.pid):
            try:
                cmd = Path(f"/proc/{kid}/cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"crackbake.bake.xatlas_worker" in cmd:
                time.sleep(1.0)  # let it get into xatlas
                # stdin/stdout carry the arrays: no file arguments, no temp files.
                assert cmd[cmd.index(b"crackbake.bake.xatlas_worker") + 1:] == [b""]
                return kid
        time.sleep(0.05)
    raise AssertionError(f"no xatlas worker appeared; stderr: {r.lines}")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_xatlas_worker_dies_with_its_parent(big_torus, tmp_path, sig):
    out = tmp_path / "torus_cracks"
    r = Run([str(big_torus), "--preset", "mud", "--uv", "unwrap", "--no-cache"], out, tmp_path)
    worker = _worker_of(r)
    r.proc.send_signal(sig)
    rc = r.finish()
    assert rc == (-sig if sig == signal.SIGKILL else 128 + sig), r.lines
    end = time.monotonic() + 10
    while alive(worker) and time.monotonic() < end:
        time.sleep(0.05)
    assert not alive(worker), f"xatlas worker {worker} outlived its parent"
    assert not out.exists()
    if sig != signal.SIGKILL:
        assert r.lines[-1] == "error: interrupted; no outputs were written"
        assert beside(out) == []


def test_signals_wait_for_a_deferred_section():
    """SIGTERM sent inside deferred() is raised only when the section ends."""
    reached = []
    with pytest.raises(Interrupt) as caught:
        with interruptible():
            with deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.05)
                reached.append("end of section")
            reached.append("after")
    assert reached == ["end of section"] and caught.value.signum == signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # handler put back


@pytest.fixture
def nouv_obj(tmp_path) -> Path:
    mesh = torus_mesh(24, 12)
    path = tmp_path / "nouv.obj"
    with open(path, "w") as fh:
        np.savetxt(fh, mesh.vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(fh, mesh.faces + 1, fmt="f %d %d %d")
    return path


@pytest.mark.parametrize(
    ("extra", "out", "message"),
    [
        (["--uv", "keep"], "o", "cannot keep the UVs: the mesh has no UVs; use --uv unwrap"),
        ([], "/dev/null", "output '/dev/null' exists and is not a folder"),
        ([], "file.txt/o", "'{tmp}/file.txt' is not a folder"),
        ([], "mine", "output folder '{tmp}/mine' is not empty and has no crackbake manifest"),
        (["--weight-map", "nothere.png"], "o", "--weight-map nothere.png: file not found"),
    ],
)
def test_unusable_inputs_and_outputs_fail_before_the_solver(nouv_obj, tmp_path, extra, out,
                                                             message):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "photo.jpg").write_bytes(b"x")
    before = sorted(p.name for p in tmp_path.iterdir())
    target = out if out.startswith("/") else str(tmp_path / out)
    t = time.perf_counter()
    r = CliRunner().invoke(main, [str(nouv_obj), "--preset", "mud", *extra, "-v", "-o", target])
    assert r.exit_code == 2, r.output
    last = r.stderr.splitlines()[-1]
    assert last.startswith("error: ") and message.format(tmp=tmp_path) in last
    assert "growing cracks" not in r.stderr and "simulation mesh" not in r.stderr
    assert time.perf_counter() - t < 10
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_empty_output_path_is_refused(nouv_obj, tmp_path, monkeypatch):
    from crackbake.errors import CrackbakeError
    from crackbake.params import RunParams
    from crackbake.pipeline import run

    with pytest.raises(CrackbakeError, match="-o '' names no folder"):
        run(RunParams(mesh=nouv_obj, out=""))
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, [str(nouv_obj), "--preset", "mud", "-o", ""])
    assert r.exit_code == 2 and "current folder" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nouv.obj"]


@pytest.fixture
def mount(tmp_path):
    """``mount(name, options)``: a fresh tmpfs under tmp_path (root only; skips otherwise)."""
    mounted = []

    def do(name: str, options: str) -> Path:
        path = tmp_path / name
        path.mkdir()
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip()}); needs root")
        mounted.append(path)
        return path

    yield do
    for path in mounted:
        subprocess.run(["umount", str(path)], check=False)


def test_disk_full_while_writing_the_manifest(previous, tmp_path, mount):
    """A file system with room for every file but the manifest: exit 2, clear, nothing left."""
    args = [str(SPOT), "--cracks", str(previous / "cracks.json"), "--res", "256",
            "--formats", "exr", "-q"]
    ref = tmp_path / "ref"
    r = CliRunner().invoke(main, [*args, "-o", str(ref)])
    assert r.exit_code == 0, r.output
    page = os.sysconf("SC_PAGE_SIZE")
    pages = sum(-(-p.stat().st_size // page) for p in ref.iterdir() if p.name != "manifest.json")
    disk = mount("disk", f"size={(pages + 1) * page}")  # + the lock file's page
    r = CliRunner().invoke(main, [*args, "-o", str(disk / "spot_cracks")])
    assert r.exit_code == 2, r.output
    assert r.stderr.count("\n") == 1
    assert r.stderr.startswith("error: cannot write manifest '") and r.stderr.endswith(
        "': No space left on device; check that the folder exists, is writable and has space\n"
    )
    assert list(disk.iterdir()) == []


def test_read_only_parent_is_refused_before_any_work(nouv_obj, mount):
    ro = mount("ro", "size=64k,ro")
    r = CliRunner().invoke(main, [str(nouv_obj), "--preset", "mud", "-o", str(ro / "out")])
    assert r.exit_code == 2, r.output
    assert r.stderr == (
        f"error: cannot lock output folder '{ro / 'out'}': Read-only file system creating "
        f"'{ro / '.out.crackbake-lock'}'; the folder holding it must be writable, or choose "
        "another -o\n"
    )
