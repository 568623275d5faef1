"""The output folder as a transaction, with real processes and real signals.

A ``crackbake`` process is started on a job slow enough to interrupt, stopped at a known stage
(its progress lines on stderr say which stage it is in) with SIGINT, SIGTERM or SIGKILL, and the
folder is checked: the previous set intact or the new one complete, never mixed; nothing left
beside it after the next run; no xatlas worker outliving its parent; one run per folder.

Only the signals sent while cracks grow need the solver; the bake and write stages are reached
by re-baking the earlier run's network at 2048 texels (``--cracks``), which skips the solve and
the stress bake that a whole run would pay before them.
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
from crackbake.transaction.interrupt import Interrupt, deferred, interruptible

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
CLI = [sys.executable, "-c", "from crackbake.cli import main; main()"]
# A few seconds per stage: solve ~3 s, bake ~1.6 s, write ~1.7 s on 2 busy cores.
SLOW = [str(SPOT), "--preset", "mud", "--sim-faces", "20000", "--res", "2048"]
QUICK = [str(SPOT), "--preset", "mud", "--sim-faces", "2000", "--res", "256", "--formats", "exr"]


def rebake(previous: Path, res: int = 2048, *extra: str) -> list[str]:
    """The arguments re-baking ``previous``'s network: no solve, the bake and write stages of
    a whole run (at 2048 texels: seconds each, long enough to signal inside them)."""
    return [str(SPOT), "--cracks", str(previous / "cracks.json"), "--res", str(res), *extra]


def _default_signals() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


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
            # A shell's background job (``make test &``) ignores SIGINT and its children inherit
            # that; the signals under test must reach crackbake as a terminal's Ctrl-C would.
            preexec_fn=_default_signals,
        )
        self.lines: list[str] = []
        self._new = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            with self._new:
                self.lines.append(line.rstrip("\n"))
                self._new.notify_all()

    def wait_for(self, text: str, timeout: float = 300.0) -> None:
        """Block until a stderr line contains ``text``."""
        end = time.monotonic() + timeout
        with self._new:
            while not any(text in ln for ln in self.lines):
                exited = self.proc.poll() is not None
                if time.monotonic() > end or (exited and not self._new.wait(1.0)):
                    raise AssertionError(f"never saw {text!r}; stderr: {self.lines}")
                self._new.wait(0.5)

    def finish(self, timeout: float = 300.0) -> int:
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
def test_interrupt_keeps_the_previous_set(previous, old_set, tmp_path, sig, stage):
    before = snapshot(old_set)
    r = Run(SLOW if stage == "growing cracks" else rebake(previous), old_set, tmp_path)
    r.wait_for(stage)
    r.proc.send_signal(sig)
    assert r.finish() == 128 + sig, r.lines
    assert r.lines[-1] == f"error: interrupted; the previous outputs in {old_set} are unchanged"
    assert snapshot(old_set) == before
    assert beside(old_set) == []


@pytest.mark.slow
def test_interrupt_without_previous_outputs_leaves_nothing(previous, tmp_path):
    out = tmp_path / "new" / "spot_cracks"
    r = Run(rebake(previous), out, tmp_path)
    r.wait_for("writing")
    r.proc.send_signal(signal.SIGTERM)
    assert r.finish() == 143, r.lines
    assert r.lines[-1] == "error: interrupted; no outputs were written"
    assert sorted(tmp_path.iterdir()) == []  # not even the parent folder it created


def star_on_a_square(folder: Path, n_cracks: int = 150) -> tuple[Path, Path]:
    """A unit square of two faces (plate_obj) and a sidecar of a dense glass-like star on it:
    ``n_cracks`` radial cracks of 12 points from near (0.5, 0.5) out to 0.1-0.2."""
    from crackbake.io.mesh import load_mesh
    from crackbake.io.sidecar import write_sidecar
    from crackbake.network import Crack, CrackNetwork, mesh_info
    from crackbake.precompile import plate_obj

    mesh_path = plate_obj(folder / "square.obj", 1, uv_margin=0.0)
    rng = np.random.default_rng(3)
    cracks = []
    for k in range(n_cracks):
        ang = 2 * np.pi * k / n_cracks
        r = np.linspace(0.001 + 0.002 * rng.random(), rng.uniform(0.1, 0.2), 12)
        p = np.c_[0.5 + r * np.cos(ang), 0.5 + r * np.sin(ang), np.zeros(12)]
        w = np.linspace(0.003, 0.001, 12)
        # plate_obj(n=1): face 0 holds x >= y, face 1 the rest.
        cracks.append(Crack(id=k, points=p, faces=(p[:, 0] < p[:, 1]).astype(np.int64),
                            time=np.linspace(0, 1, 12), width=w, depth=0.5 * w))  # fmt: skip
    sidecar = folder / "star.json"
    write_sidecar(CrackNetwork(cracks=cracks, mesh=mesh_info(load_mesh(mesh_path))), sidecar)
    return mesh_path, sidecar


def test_sigterm_during_a_decal_bake_stops_it_promptly(tmp_path):
    """A 4096-texel decal over a dense star on two faces (each texel near hundreds of segments):
    SIGTERM once the decal stage has started ends the run within seconds, exit 143, nothing
    written, nothing staged.  (The crack pass runs in short GL calls; before, one call over the
    whole decal walked every segment of the face at every texel and ignored signals for minutes.)"""
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    mesh, sidecar = star_on_a_square(inputs)
    out = tmp_path / "new" / "square_cracks"
    args = [str(mesh), "--cracks", str(sidecar), "--impact", "0.5,0.5,0", "--decal", "0.4",
            "--decal-res", "4096", "--res", "64", "--formats", "exr"]
    r = Run(args, out, tmp_path)
    r.wait_for("decal(s)")
    sent = time.monotonic()
    r.proc.send_signal(signal.SIGTERM)
    assert r.finish() == 143, r.lines
    took = time.monotonic() - sent
    assert r.lines[-1] == "error: interrupted; no outputs were written"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["inputs"]
    assert took < 10.0, f"{took:.1f} s from SIGTERM to exit"


@pytest.mark.slow
def test_sigkill_while_writing_then_the_next_run_cleans_up(previous, old_set, tmp_path):
    before = snapshot(old_set)
    r = Run(rebake(previous), old_set, tmp_path)
    r.wait_for("writing")
    time.sleep(0.3)  # some files staged
    r.proc.send_signal(signal.SIGKILL)
    assert r.finish() == -signal.SIGKILL
    assert snapshot(old_set) == before  # the old set, whole
    left = beside(old_set)
    assert ".spot_cracks.crackbake-lock" in left
    assert any(n.startswith(".spot_cracks.crackbake-staging-") for n in left), left
    # The next run is not blocked by the dead run's lock and removes its staging folder.
    again = Run(rebake(previous, 256, "--formats", "exr"), old_set, tmp_path)
    assert again.finish() == 0, again.lines
    assert beside(old_set) == []
    manifest = json.loads((old_set / "manifest.json").read_text())
    listed = {f["name"] for f in manifest["files"]} | {"manifest.json"}
    assert set(snapshot(old_set)) == listed


@pytest.mark.slow
def test_fewer_formats_leave_no_stale_files(previous, old_set, tmp_path):
    r = Run(rebake(previous, 256), old_set, tmp_path)
    assert r.finish() == 0, r.lines
    assert "spot.glb" in snapshot(old_set)
    r = Run(QUICK, old_set, tmp_path)
    assert r.finish() == 0, r.lines
    assert sorted(snapshot(old_set)) == [
        "cracks.json", "cracks.obj", "manifest.json", "spot_cracks.exr"
    ]


@pytest.mark.slow
def test_second_run_into_the_same_folder_fails_at_once(previous, old_set, tmp_path):
    first = Run(rebake(previous, 256), old_set, tmp_path)
    first.wait_for("loading")  # the folder is locked before the mesh is read
    # Held still while the second run tries the folder: however long that one takes to start
    # on a busy machine, the first still holds the lock (no race with its end).
    first.proc.send_signal(signal.SIGSTOP)
    try:
        t = time.monotonic()
        second = Run(QUICK, old_set, tmp_path)
        assert second.finish(timeout=120) == 2, second.lines
        assert time.monotonic() - t < 30
    finally:
        first.proc.send_signal(signal.SIGCONT)
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


def test_a_signal_during_an_import_is_raised_after_it(tmp_path):
    """SIGTERM arriving while the main thread imports a module is raised once the import is
    done: an exception inside the import machinery can leave Python's import lock held, and a
    re-bake stopped so hung (its encoder threads waiting on their imports for ever)."""
    code = (
        "import os, signal, sys, threading, time\n"
        "sys.path.insert(0, sys.argv[1])\n"
        "from crackbake.transaction.interrupt import Interrupt, interruptible\n"
        "def slow():\n"
        "    time.sleep(0.3)\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "threading.Thread(target=slow).start()\n"
        "try:\n"
        "    with interruptible():\n"
        "        import slowmod\n"
        "        time.sleep(5)\n"
        "except Interrupt as exc:\n"
        "    print('interrupted', exc.signum, slowmod.DONE)\n"
        "t = threading.Thread(target=lambda: __import__('json'))\n"
        "t.start(); t.join(10)\n"
        "print('imports work', not t.is_alive())\n"
    )
    # the module's body spins in Python (the signal's handler runs in it) for about a second
    (tmp_path / "slowmod.py").write_text(
        "import time\nend = time.monotonic() + 1.0\nwhile time.monotonic() < end:\n"
        "    pass\nDONE = True\n")  # fmt: skip
    repo = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True,
                         text=True, timeout=60, cwd=repo)  # fmt: skip
    assert out.stdout.split("\n")[:2] == [f"interrupted {int(signal.SIGTERM)} True",
                                           "imports work True"], out.stderr


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


# ------------------------------------------------------- files crackbake writes (issue 19 §1)

def _lock_of(out: Path) -> Path:
    return out.parent / f".{out.name}.crackbake-lock"


@pytest.mark.parametrize("dangling", [False, True], ids=["to a file", "dangling"])
def test_lock_never_writes_through_a_symlink(nouv_obj, tmp_path, dangling):
    """A symlink named like the lock: refused, its target neither written nor created."""
    target = tmp_path / "precious.txt"
    if not dangling:
        target.write_text("the user's own words\n")
    out = tmp_path / "o"
    _lock_of(out).symlink_to(target)
    before = sorted(p.name for p in tmp_path.iterdir())
    r = CliRunner().invoke(main, [str(nouv_obj), "--preset", "mud", "-o", str(out)])
    assert r.exit_code == 2, r.output
    assert r.stderr == (
        f"error: cannot lock output folder '{out}': '{_lock_of(out)}' is a symbolic link, not a "
        "lock file crackbake made, and crackbake will not write to it; remove it or choose "
        "another folder with -o\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    if dangling:
        assert not os.path.lexists(target)
    else:
        assert target.read_text() == "the user's own words\n"
    assert _lock_of(out).is_symlink()


@pytest.mark.parametrize(
    ("content", "links", "what"),
    [(b"my notes\n", 1, "a file that holds something other than a pid"),
     (b"123\n", 2, "a file with 2 hard links")],
    ids=["foreign text", "hard link"],
)
def test_lock_refuses_a_file_it_did_not_make(nouv_obj, tmp_path, content, links, what):
    lock = _lock_of(tmp_path / "o")
    lock.write_bytes(content)
    if links == 2:
        os.link(lock, tmp_path / "elsewhere.txt")
    r = CliRunner().invoke(main, [str(nouv_obj), "--preset", "mud", "-o", str(tmp_path / "o")])
    assert r.exit_code == 2 and f"'{lock}' is {what}, not a lock file" in r.stderr, r.output
    assert lock.read_bytes() == content and not (tmp_path / "o").exists()


def _exr(path: Path) -> Path:
    from crackbake.exchange.exr import write_exr

    ramp = np.linspace(0, 1, 16 * 24, dtype=np.float32).reshape(16, 24)
    write_exr(path, {"R": ramp, "G": 1 - ramp})
    return path


def _no_dac_override() -> None:
    """In the child, as root: drop the capabilities that bypass permission bits, so a
    read-only folder is read-only for it as for any user (they come back for no exec)."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (1, 2, 3):  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER
        if libc.prctl(24, cap, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
            raise OSError(ctypes.get_errno(), "PR_CAPBSET_DROP")


def inspect_cli(*args: str, cwd: Path, permissions: bool = False):
    """``crackbake inspect ARGS`` as a process; ``permissions``: file modes bind it even as root."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "crackbake", "inspect", *args], cwd=cwd, env=env, text=True,
        capture_output=True, timeout=120,
        preexec_fn=_no_dac_override if permissions and os.geteuid() == 0 else None,
    )  # fmt: skip


def test_inspect_png_is_a_transaction(tmp_path):
    """`inspect --png` writes a set with a manifest; it replaces its own set, never a user's
    files, and never writes through a symlink."""
    exr = _exr(tmp_path / "a.exr")
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    r = inspect_cli(str(exr), "--png", "pics", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    pics = tmp_path / "pics"
    assert sorted(p.name for p in pics.iterdir()) == ["G.png", "R.png", "manifest.json"]
    listed = json.loads((pics / "manifest.json").read_text())
    assert [f["name"] for f in listed["files"]] == ["G.png", "R.png"]
    # A picture replaced by a symlink to the user's file: the set is replaced as a whole, the
    # link removed, its target untouched.
    (pics / "R.png").unlink()
    (pics / "R.png").symlink_to(victim)
    r = inspect_cli(str(exr), "--png", "pics", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert not (pics / "R.png").is_symlink() and victim.read_text() == "keep me\n"
    assert beside(pics) == []
    # A folder of the user's own (here a link named like a picture): refused, untouched.
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "R.png").symlink_to(victim)
    r = inspect_cli(str(exr), "--png", "mine", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr == (
        "error: output folder 'mine' is not empty and has no crackbake manifest.json; crackbake "
        "replaces its output folder as a whole, so choose a new or empty folder with --png\n"
    )
    assert victim.read_text() == "keep me\n" and os.listdir(mine) == ["R.png"]


def test_inspect_png_into_a_read_only_folder(tmp_path):
    exr = _exr(tmp_path / "a.exr")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        r = inspect_cli(str(exr), "--png", str(ro / "pics"), cwd=tmp_path, permissions=True)
    finally:
        ro.chmod(0o755)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == (
        f"error: cannot lock output folder '{ro / 'pics'}': Permission denied creating "
        f"'{ro / '.pics.crackbake-lock'}'; the folder holding it must be writable, or choose "
        "another --png\n"
    )
    assert list(ro.iterdir()) == []


def test_read_only_previous_folder_leaves_no_copy(tmp_path):
    """A previous set made read-only is swapped out and deleted (with a warning), not kept in a
    hidden folder; a read-only leftover of an older version is removed by the next run."""
    exr = _exr(tmp_path / "a.exr")
    pics = tmp_path / "pics"
    assert inspect_cli(str(exr), "--png", "pics", cwd=tmp_path).returncode == 0
    pics.chmod(0o555)
    r = inspect_cli(str(exr), "--png", "pics", cwd=tmp_path, permissions=True)
    assert r.returncode == 0, r.stderr
    assert r.stderr.startswith("warning: output folder 'pics' was read-only; crackbake replaces")
    assert r.stderr.count("\n") == 1
    assert beside(pics) == []
    assert pics.stat().st_mode & 0o200  # the new set is writable
    # What crackbake before this fix left: the old set, read-only, under a staging name.
    left = tmp_path / ".pics.crackbake-staging-0123abcd"
    shutil.copytree(pics, left)
    (left / "R.png").chmod(0o444)
    left.chmod(0o555)
    r = inspect_cli(str(exr), "--png", "pics", cwd=tmp_path, permissions=True)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert beside(pics) == []


def test_user_folder_named_like_an_output_is_kept(old_set, tmp_path):
    """`out/cracks.json/mine.txt`: the folder would be deleted with the previous set: refused."""
    before = snapshot(old_set)
    (old_set / "cracks.json").unlink()
    (old_set / "cracks.json").mkdir()
    (old_set / "cracks.json" / "mine.txt").write_text("mine\n")
    r = CliRunner().invoke(main, [*QUICK, "-o", str(old_set)])
    assert r.exit_code == 2, r.output
    assert r.stderr == (
        f"error: output folder '{old_set}' holds a folder 'cracks.json' where crackbake wrote a "
        "file, and the folder is replaced as a whole; move it out or choose another folder "
        "with -o\n"
    )
    assert (old_set / "cracks.json" / "mine.txt").read_text() == "mine\n"
    (old_set / "cracks.json" / "mine.txt").unlink()
    (old_set / "cracks.json").rmdir()
    assert snapshot(old_set) == {k: v for k, v in before.items() if k != "cracks.json"}
    assert beside(old_set) == []
