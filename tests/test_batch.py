"""``crackbake batch`` (crackbake/batch/) on a real local Ray: each job's folder equals what the
plain bake command writes, failures are recorded, ``--resume`` reruns only what changed, a
killed worker is retried, and a bad batch file is refused before any work."""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

ray = pytest.importorskip("ray")

from test_docs import RUN_ELSEWHERE  # noqa: E402

from crackbake.batch.command import batch  # noqa: E402
from crackbake.cli.bake import bake  # noqa: E402

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
SMALL = 'res = 256\nsim-faces = 1500\nformats = "png,exr,preview"\n'


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray for the module (2 CPUs, no dashboard), shut down after it."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    # The workers import crackbake from this tree, installed or not (as the command's own
    # local Ray does).
    os.environ["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(SPOT.parents[1]), os.environ.get("PYTHONPATH")) if p)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             object_store_memory=80 * 2**20, logging_level="ERROR")
    yield ray
    ray.shutdown()


def _run(cmd, args):
    return CliRunner().invoke(cmd, [str(a) for a in args], catch_exceptions=False)


def _folder(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


def _manifest_core(data: bytes) -> dict:
    """A manifest without what differs between two equal runs (stage and solver timings, the
    output folder) and the batch's own key."""
    doc = json.loads(data)
    doc.pop("timings_s")
    doc.pop("batch", None)
    doc["params"].pop("out")
    for key in ("seconds", "loop_seconds"):
        doc["params"].get("solver", {}).pop(key, None)
    return doc


def test_batch_failed_job_recorded_and_resume(tmp_path, local_ray):
    """4 jobs, one broken mesh: 3 ok, each equal to the plain command's folder, the broken one
    failed with its one-line error; --resume after the fix runs only that job."""
    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    (tmp_path / "jobs.toml").write_text(
        f"[defaults]\n{SMALL}\n"
        '[[job]]\nmesh = "spot.obj"\npreset = "mud"\nname = "mud"\n\n'
        '[[job]]\nmesh = "spot.obj"\npreset = "glass"\nimpact = ["0.334,0.044,0.287"]\n'
        "seeds = [1, 2]\n\n"
        '[[job]]\nmesh = "broken.obj"\npreset = "crackle"\n'
    )
    out = tmp_path / "out"
    res = _run(batch, [tmp_path / "jobs.toml", "-o", out])
    assert res.exit_code == 1, res.output
    doc = json.loads((out / "batch.json").read_text())
    status = {j["name"]: j["status"] for j in doc["jobs"]}
    assert status == {"mud": "ok", "spot_glass_s1": "ok", "spot_glass_s2": "ok",
                      "broken": "failed"}
    broken = doc["jobs"][3]
    assert "\n" not in broken["error"] and "broken.obj" in broken["error"]
    assert broken["error"].startswith("error: ")
    assert not (out / "broken").exists()
    assert {j["node"] for j in doc["jobs"]} == {ray.get_runtime_context().get_node_id()}
    assert all(j["peak_rss_mb"] > 50 and j["files"] for j in doc["jobs"][:3])
    assert len({j["pid"] for j in doc["jobs"]}) == 4  # a fresh worker process per job
    assert "failed: broken: error: " in res.stderr
    assert (out / "batch.csv").read_text().count("\n") == 5

    # The plain command into another folder: every file equal, the manifest but its timings.
    plain = {
        "mud": ["--preset", "mud"],
        "spot_glass_s1": ["--preset", "glass", "--impact", "0.334,0.044,0.287", "--seed", "1"],
        "spot_glass_s2": ["--preset", "glass", "--impact", "0.334,0.044,0.287", "--seed", "2"],
    }
    for name, extra in plain.items():
        ref = tmp_path / f"plain_{name}"
        r = _run(bake, [tmp_path / "spot.obj", "--res", 256, "--sim-faces", 1500,
                        "--formats", "png,exr,preview", "-q", "-o", ref, *extra])
        assert r.exit_code == 0, r.output
        got, want = _folder(out / name), _folder(ref)
        assert sorted(got) == sorted(want)
        for f in want:
            if f == "manifest.json":
                assert _manifest_core(got[f]) == _manifest_core(want[f])
            else:
                assert got[f] == want[f], f"{name}/{f} differs from the plain command's"
        assert json.loads(got["manifest.json"])["batch"]["job"] == name

    # The sheet: one labelled tile per job.
    from PIL import Image

    with Image.open(out / "batch_sheet.png") as sheet:
        assert sheet.size == (2 * 256, 2 * (256 + 40))

    # Fixed mesh, --resume: only the broken job runs; the others' files are untouched.
    before = {n: (out / n / "manifest.json").stat().st_mtime_ns for n in plain}
    shutil.copy(SPOT, tmp_path / "broken.obj")
    res = _run(batch, [tmp_path / "jobs.toml", "-o", out, "--resume"])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "batch.json").read_text())
    assert [j["status"] for j in doc["jobs"]] == ["skipped", "skipped", "skipped", "ok"]
    assert before == {n: (out / n / "manifest.json").stat().st_mtime_ns for n in plain}
    assert (out / "broken" / "preview.png").is_file()
    # A changed option is a new job hash: that job runs again.
    text = (tmp_path / "jobs.toml").read_text().replace('name = "mud"', 'name = "mud"\nseed = 3')
    (tmp_path / "jobs.toml").write_text(text)
    res = _run(batch, [tmp_path / "jobs.toml", "-o", out, "--resume", "--dry-run"])
    assert res.exit_code == 0
    from crackbake.batch.jobs import load_jobs
    from crackbake.batch.run import resume_record

    jobs = load_jobs(tmp_path / "jobs.toml", out)
    assert [resume_record(j, j.job_hash()) is not None for j in jobs] == [False, True, True, True]


@pytest.mark.parametrize(
    "body, words",
    [
        ('[[job]]\nmesh = "spot.obj"\nress = 256\n', ["[[job]] 1 'spot'", "unknown key 'ress'"]),
        ('[[job]]\nmesh = "nope.obj"\n', ["[[job]] 1", "key 'mesh'", "nope.obj", "not found"]),
        ('[[job]]\nmesh = "spot.obj"\nres = 99999\n', ["key 'res'", "--res 99999 is out of"]),
        ('[defaults]\nres = 8\n[[job]]\nmesh = "spot.obj"\n', ["[defaults] key 'res'", "--res 8"]),
        ('[[job]]\nmesh = "spot.obj"\npreset = "lava"\n', ["key 'preset'", "lava"]),
        ('[[job]]\nmesh = "spot.obj"\n[[job]]\nmesh = "spot.obj"\nseed = 2\n',
         ["[[job]] 2 'spot'", "same folder", "[[job]] 1 'spot'"]),
        ('[[job]]\nmesh = "spot.obj"\nseeds = [1, 1]\n', ["[[job]] 1 'spot_s1'", "same folder"]),
        ('[[job]]\nmesh = "*.ply"\n', ["key 'mesh'", "matches no file"]),
        ('[[job]]\nmesh = "spot.obj"\nformats = "png,tiff"\n', ["key 'formats'", "subset"]),
        ('[[job]]\nmesh = "spot.obj"\nout = "x"\n', ["unknown key 'out'"]),
        ('[[job]]\nmesh = "spot.obj"\nname = "../up"\n', ["key 'name'", "not a folder name"]),
        ('[[job]]\nmesh = "spot.obj"\nimpact = "1,2"\n', ["key 'impact'"]),
        ("[[job]\n", ["not valid TOML"]),
        ("[defaults]\nres = 256\n", ["no [[job]] entries"]),
    ],
)
def test_bad_batch_files_refused(tmp_path, body, words):
    """Each refusal: one line naming the job and key, exit 2, nothing written (no Ray)."""
    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "jobs.toml").write_text(body)
    res = _run(batch, [tmp_path / "jobs.toml", "-o", tmp_path / "out"])
    assert res.exit_code == 2, res.output
    line = res.stderr.strip()
    assert "\n" not in line and line.startswith("error: jobs.toml: "), line
    for w in words:
        assert w in line, line
    assert not (tmp_path / "out").exists()


def test_batch_agrees_with_the_bake_command(tmp_path):
    """A value the bake command refuses is refused by batch with the same words."""
    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "jobs.toml").write_text('[[job]]\nmesh = "spot.obj"\ntoughness = -1\n')
    res = _run(batch, [tmp_path / "jobs.toml", "-o", tmp_path / "out"])
    cli = _run(bake, [tmp_path / "spot.obj", "--toughness", "-1", "-o", tmp_path / "o2"])
    assert res.exit_code == cli.exit_code == 2
    assert cli.stderr.strip().removeprefix("error: ") in res.stderr


@pytest.mark.slow
def test_killed_worker_is_retried(tmp_path, local_ray):
    """SIGKILL the worker mid-job (its pid is in the output folder's lock file): Ray retries the
    job in a new process and the folder ends complete, no staging left."""
    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "jobs.toml").write_text(
        f"[defaults]\n{SMALL}\n[[job]]\nmesh = \"spot.obj\"\npreset = \"mud\"\n")
    out = tmp_path / "out"
    lock = out / ".spot.crackbake-lock"
    result = {}
    runner = threading.Thread(target=lambda: result.update(
        res=_run(batch, [tmp_path / "jobs.toml", "-o", out, "--retries", 1])))
    runner.start()
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and time.monotonic() < deadline:
        try:
            text = lock.read_text().strip()
        except OSError:
            text = ""
        if text.isdigit():
            killed = int(text)
            time.sleep(1.0)  # well into the job (loading, solving)
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.05)
    runner.join(300)
    assert killed is not None
    res = result["res"]
    assert res.exit_code == 0, res.output
    job = json.loads((out / "batch.json").read_text())["jobs"][0]
    assert job["status"] == "ok" and job["pid"] != killed
    manifest = json.loads((out / "spot" / "manifest.json").read_text())
    assert sorted(p.name for p in (out / "spot").iterdir()) == sorted(
        [f["name"] for f in manifest["files"]] + ["manifest.json"])
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def _ray_processes(cwd: Path | None = None) -> set[int]:
    """Pids of Ray's own daemons on this machine (raylet, gcs_server); with ``cwd``, only those
    working there (a batch's daemons keep its current folder; other Rays may run beside it)."""
    pids = set()
    for d in Path("/proc").iterdir():
        try:
            name = (d / "comm").read_text().strip()
            if name in ("raylet", "gcs_server") and (
                    cwd is None or os.readlink(d / "cwd") == str(cwd)):
                pids.add(int(d.name))
        except OSError:
            continue
    return pids


#: The two commands docs/batch.md opens with: tests/test_docs.py leaves them to the test below,
#: which runs them as written and checks what they print and leave behind.
DOCUMENTED = tuple(cmd for cmd, test in RUN_ELSEWHERE.items() if test.startswith("test_batch.py"))


@pytest.mark.slow
def test_the_documented_batch_on_a_pipe_leaves_nothing_running(tmp_path):
    """docs/batch.md's two commands as written (examples/batch.toml, no --address): the command
    starts its own Ray sized to the machine, prints one line per finished job on a pipe and
    shuts Ray down (no raylet or gcs_server of its own left); the --resume run skips every
    job."""
    import shlex
    import subprocess
    import sys

    page = (SPOT.parents[1] / "docs" / "batch.md").read_text()
    assert all(cmd in page for cmd in DOCUMENTED)
    assert len(DOCUMENTED) == 2
    (tmp_path / "examples").mkdir()
    for name in ("batch.toml", "spot.obj"):
        shutil.copy(SPOT.parent / name, tmp_path / "examples" / name)
    env = {**os.environ, "PYTHONPATH": str(SPOT.parents[1])}

    def run(cmd: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "crackbake", *shlex.split(cmd)[1:]],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)

    first = run(DOCUMENTED[0])
    assert first.returncode == 0, first.stderr
    lines = first.stderr.splitlines()
    names = ["spot_crackle_ue", "spot_glass_s1", "spot_glass_s2", "spot_mud"]
    assert sorted(line.split()[2] for line in lines if line.startswith("[")) == names
    assert lines[-1].startswith("4 jobs: 4 ok")
    assert "\r" not in first.stderr  # a pipe: no progress bar
    assert not _ray_processes(cwd=tmp_path)
    out = tmp_path / "spot_batch"
    doc = json.loads((out / "batch.json").read_text())
    assert doc["ray"]["cpus"] >= 1 and doc["ray"]["start_s"] > 0
    # no --workers: one job per core, numba's threads the one CPU each job was given
    assert {j["numba_threads"] for j in doc["jobs"]} == {"1"}
    assert all(_committed(out / n) for n in names)
    again = run(DOCUMENTED[1])
    assert again.returncode == 0, again.stderr
    doc = json.loads((out / "batch.json").read_text())
    assert [j["status"] for j in doc["jobs"]] == ["skipped"] * 4


def _default_signals() -> None:
    # A shell's background job (``make test &``) ignores SIGINT and its children inherit that;
    # Ctrl-C must reach the batch as it does from a terminal.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _on_a_terminal() -> None:
    """In the child: a session of its own whose controlling terminal is its stdin (a pty), so a
    ^C typed into the pty is SIGINT to its whole foreground process group, Ray's too."""
    import fcntl
    import termios

    _default_signals()
    fcntl.ioctl(0, termios.TIOCSCTTY, 0)


def _wait_for(check, what: str, proc, timeout: float = 240.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got = check()
        if got:
            return got
        assert proc.poll() is None, f"the batch ended (exit {proc.returncode}) before {what}"
        time.sleep(0.1)
    raise AssertionError(f"waited {timeout:.0f} s for {what}")


def _descendants(pid: int) -> set[int]:
    """Pids of every process below ``pid`` (children, their children...)."""
    found, todo = set(), [pid]
    while todo:
        for task in Path(f"/proc/{todo.pop()}/task").glob("*"):
            try:
                kids = {int(k) for k in (task / "children").read_text().split()}
            except OSError:
                continue
            todo += kids - found
            found |= kids
    return found


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _interrupted_batch(tmp_path: Path, how: str):
    """Run a 3-job batch (--workers 1) as a real process, wait until the first job's folder is
    committed and the second job's staging folder exists, then interrupt it: ``how`` is
    ``ctrl-c`` (^C typed into its terminal, a pty) or ``sigterm`` (``kill PID``, on a pipe).
    Returns the exit code, what it printed, the first folder's files when committed."""
    import subprocess
    import sys

    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "jobs.toml").write_text(
        f"[defaults]\n{SMALL}\n"
        '[[job]]\nmesh = "spot.obj"\npreset = "mud"\nname = "first"\n\n'
        # slow enough to be caught mid-run: cancelled while its staging folder exists
        '[[job]]\nmesh = "spot.obj"\npreset = "crackle"\nname = "second"\nres = 2048\n'
        "sim-faces = 20000\n\n"
        '[[job]]\nmesh = "spot.obj"\npreset = "glaze"\nname = "third"\n')
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(SPOT.parents[1])}
    cmd = [sys.executable, "-m", "crackbake", "batch", "jobs.toml", "-o", "out", "--workers", "1"]
    chunks: list[bytes] = []
    if how == "ctrl-c":
        import pty

        master, slave = pty.openpty()
        proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdin=slave, stdout=slave,
                                stderr=slave, start_new_session=True, preexec_fn=_on_a_terminal)
        os.close(slave)

        def read() -> None:
            while True:
                try:
                    data = os.read(master, 4096)
                except OSError:  # the child closed its end
                    return
                if not data:
                    return
                chunks.append(data)
    else:
        proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                preexec_fn=_default_signals)

        def read() -> None:
            for data in iter(lambda: proc.stdout.read1(4096), b""):
                chunks.append(data)
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        _wait_for(lambda: (out / "first" / "manifest.json").is_file(), "the first job's folder",
                  proc)
        first = _folder(out / "first")  # committed: the folder appears whole, by one rename
        _wait_for(lambda: any(p.name.startswith(".second.crackbake-staging-")
                              for p in out.iterdir()), "the second job's staging folder", proc)
        started = _descendants(proc.pid)  # its Ray: raylet, gcs_server, workers, agents
        assert started & _ray_processes(), "no Ray daemon under the batch process"
        if how == "ctrl-c":
            os.write(master, b"\x03")
        else:
            proc.send_signal(signal.SIGTERM)
        rc = proc.wait(120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(10)
    if how == "ctrl-c":
        os.close(master)
    return rc, b"".join(chunks).decode(errors="replace"), first, started


@pytest.mark.slow
@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_interrupted_batch(tmp_path, how):
    """Ctrl-C (or SIGTERM) mid-batch: the running job is cancelled and its staging folder
    removed, the queued one never starts, the finished folder stays as it was, the summary is
    written with both marked cancelled, exit 130 (143); the local Ray is shut down."""
    rc, text, first, started = _interrupted_batch(tmp_path, how)
    out = tmp_path / "out"
    assert rc == (130 if how == "ctrl-c" else 143), text
    assert _folder(out / "first") == first
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
    assert not (out / "second").exists() and not (out / "third").exists()
    doc = json.loads((out / "batch.json").read_text())
    jobs = {j["name"]: j for j in doc["jobs"]}
    assert [jobs[n]["status"] for n in ("first", "second", "third")] == [
        "ok", "cancelled", "cancelled"]
    assert jobs["second"]["error"].startswith(
        "cancelled (Ctrl-C)" if how == "ctrl-c" else "cancelled (SIGTERM)")
    assert "before it started" in jobs["third"]["error"]
    assert doc["counts"] == {"ok": 1, "cancelled": 2}
    assert doc["ray"]["interrupted"] == (signal.SIGINT if how == "ctrl-c" else signal.SIGTERM)
    import csv

    with open(out / "batch.csv", newline="") as fh:
        assert [row["status"] for row in csv.DictReader(fh)] == ["ok", "cancelled", "cancelled"]
    assert (out / "batch_sheet.png").is_file()
    assert "interrupted (" in text
    if how == "ctrl-c":  # the terminal showed the live bar
        assert "batch  [" in text and "1 running" in text and "1/3" in text
    else:  # a pipe: one line per finished job, no bar
        assert "[1/1]" not in text and "[1/3] ok     first" in text
        assert "\r" not in text
    end = time.monotonic() + 30  # Ray's daemons exit a moment after the driver
    while any(_alive(p) for p in started) and time.monotonic() < end:
        time.sleep(0.2)
    assert not [p for p in started if _alive(p)], "processes of the batch's Ray outlived it"


def test_worker_imports_no_numba_before_its_job():
    """A worker unpickles crackbake.batch.run (the task) and the job's RunParams before the job
    sets NUMBA_NUM_THREADS and NUMBA_CACHE_DIR: neither may import numba."""
    import subprocess
    import sys

    code = ("import pickle, sys\n"
            "import crackbake.batch.run, crackbake.batch.progress, crackbake.params\n"
            "print('numba' in sys.modules)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(SPOT.parents[1])}, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"


def _committed(folder: Path) -> bool:
    """The folder holds exactly the files its manifest lists, plus the manifest."""
    manifest = json.loads((folder / "manifest.json").read_text())
    return sorted(p.name for p in folder.iterdir()) == sorted(
        [f["name"] for f in manifest["files"]] + ["manifest.json"])


@pytest.mark.slow
def test_two_node_cluster(tmp_path, monkeypatch):
    """Two Ray nodes of 1 CPU each on this machine (ray.cluster_utils.Cluster) and the batch
    command as a separate driver with --address: the 2 jobs land one on each node (node ids in
    batch.json), both folders complete, each worker's numba cache the node-local folder (or
    the one the environment names)."""
    import subprocess
    import sys

    from ray.cluster_utils import Cluster

    from crackbake.batch.numba_cache import node_cache_dir

    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "jobs.toml").write_text(
        f"[defaults]\n{SMALL}\n[[job]]\nmesh = \"spot.obj\"\npreset = \"mud\"\nseeds = [1, 2]\n")
    # The nodes' workers import crackbake from this tree; each node's raylet passes on this env.
    monkeypatch.setenv("PYTHONPATH", str(SPOT.parents[1]))
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")
    node = {"num_cpus": 1, "object_store_memory": 80 * 2**20}
    cluster = Cluster(initialize_head=True, head_node_args={**node, "include_dashboard": False})
    try:
        cluster.add_node(**node)
        cluster.wait_for_nodes()
        alive = {n.node_id for n in [cluster.head_node, *cluster.worker_nodes]}
        r = subprocess.run([sys.executable, "-m", "crackbake", "batch", "jobs.toml", "-o", "out",
                            "--address", cluster.address], cwd=tmp_path, capture_output=True,
                           text=True, timeout=600)
    finally:
        cluster.shutdown()
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "out" / "batch.json").read_text())
    assert doc["ray"]["nodes"] == 2 and doc["ray"]["cpus"] == 2
    jobs = doc["jobs"]
    assert [j["status"] for j in jobs] == ["ok", "ok"]
    assert {j["node"] for j in jobs} == alive and len(alive) == 2
    for j in jobs:  # in OUT: the workers' current folder is not the driver's
        assert Path(j["folder"]).parent == tmp_path / "out"
        assert _committed(Path(j["folder"]))
        # make test points every process at one prepared cache (NUMBA_CACHE_DIR), which a
        # batch keeps; without it each node's own folder is used.
        assert j["numba_cache"] == os.environ.get("NUMBA_CACHE_DIR", str(node_cache_dir()))
    assert any(Path(jobs[0]["numba_cache"]).rglob("*.nbi"))


def test_numba_cache_seeded_per_node(tmp_path):
    """A package's in-tree numba cache, seeded into a node cache folder, is what numba loads
    there (nothing recompiled or rewritten); seeding again copies nothing; the user's own
    NUMBA_CACHE_DIR is left alone."""
    import subprocess
    import sys

    from crackbake.batch.numba_cache import seed, use_node_cache

    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "sub" / "kern.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef twice(x):\n    return 2 * x\n")
    run = [sys.executable, "-c", "import sys; sys.path.insert(0, sys.argv[1]); "
           "from sub.kern import twice; print(twice(21))", str(pkg)]
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    first = subprocess.run(run, env={**env, "NUMBA_DEBUG_CACHE": "1"}, capture_output=True,
                           text=True, timeout=300)
    assert first.stdout.strip().endswith("42") and "data saved" in first.stdout, first.stderr
    node = tmp_path / "node"
    assert seed(node, pkg) == 2  # the index and one overload's object code
    assert seed(node, pkg) == 0
    again = subprocess.run(run, env={**env, "NUMBA_DEBUG_CACHE": "1",
                                     "NUMBA_CACHE_DIR": str(node)},
                           capture_output=True, text=True, timeout=300)
    assert again.stdout.strip().endswith("42")
    assert "data loaded" in again.stdout and "data saved" not in again.stdout, again.stdout
    assert str(node) in again.stdout
    mine = {"NUMBA_CACHE_DIR": str(tmp_path / "mine")}
    assert use_node_cache(mine) == str(tmp_path / "mine") and mine == {
        "NUMBA_CACHE_DIR": str(tmp_path / "mine")}


def test_contact_sheet_bounded_for_large_batches(tmp_path):
    """The sheet's size does not grow without bound with the job count (the driver's memory):
    1,000 jobs get smaller tiles, 5,000 as many tiles as fit, the failed ones first."""
    from crackbake.batch.summary import MAX_SHEET_PIXELS, contact_sheet

    def records(n, failed=()):
        return [{"name": f"job{k}", "folder": str(tmp_path / f"job{k}"),
                 "status": "failed" if k in failed else "ok"} for k in range(n)]

    small = contact_sheet(records(12))
    assert small.size == (4 * 256, 3 * (256 + 40))
    big = contact_sheet(records(1000))
    assert big.width * big.height <= MAX_SHEET_PIXELS * 1.05 and big.width >= 32 * 64
    huge = contact_sheet(records(5000, failed={4321}))
    assert huge.width * huge.height <= MAX_SHEET_PIXELS * 1.05
    # the failed job is the first tile: red label strip under it
    assert huge.getpixel((2, 64 + 2)) == (190, 40, 40)
    assert big.getpixel((2, big.height // 32 - 2)) == (40, 140, 60)


def test_egl_device_for_the_gpu_ray_assigned():
    """CUDA_VISIBLE_DEVICES (nvidia-smi's index, PCI bus order) -> the EGL device at the same
    PCI address, whatever EGL's own order (here software renderers first and the GPUs in
    reverse)."""
    from crackbake.batch.gpu import egl_device_for, normalise_pci

    gpus = ["00000000:1A:00.0", "00000000:3B:00.0", "00000000:D8:00.0"]  # nvidia-smi's spelling
    egl = [None, "0000:d8:00.0", "0000:3b:00.0", None, "0000:1a:00.0"]
    assert [egl_device_for(str(i), gpus, egl) for i in range(3)] == [4, 2, 1]
    assert egl_device_for("2,0", gpus, egl) == 1  # one context per job: the first GPU
    assert egl_device_for(" 1 ", gpus, egl) == 2
    for none in (None, "", "-1", "NoDevFiles", "GPU-8f2a3c1e-0000-1111-2222-333344445555"):
        assert egl_device_for(none, gpus, egl) is None
    assert egl_device_for("1", gpus, [None, "0000:1a:00.0"]) is None  # no EGL on that GPU
    with pytest.raises(ValueError, match="GPU 3 but the node has 3"):
        egl_device_for("3", gpus, egl)
    assert normalise_pci("3b:00.0") == "0000:3b:00.0"
    with pytest.raises(ValueError, match="not a PCI address"):
        normalise_pci("card1")


def _library_hashes(out: Path) -> dict[str, str]:
    return {f["name"]: f["sha256"]
            for f in json.loads((out / "manifest.json").read_text())["files"]}


@pytest.mark.slow
def test_decals_on_ray_equal_the_local_library(tmp_path, local_ray):
    """``crackbake decals --address`` (a separate driver on the running local Ray): the variants
    bake as tasks in fresh workers, one variant per task here, and every file equals the library
    baked in one process."""
    import subprocess
    import sys

    args = ["decals", "--preset", "glass", "-n", "3", "--size", "0.5", "--res", "64",
            "--sim-faces", "5000", "--seed", "5"]
    env = {**os.environ, "PYTHONPATH": str(SPOT.parents[1])}
    address = local_ray.get_runtime_context().gcs_address
    on_ray = subprocess.run([sys.executable, "-m", "crackbake", *args, "--address", address,
                             "-o", str(tmp_path / "ray")], capture_output=True, text=True,
                            env=env, timeout=600)
    assert on_ray.returncode == 0, on_ray.stderr
    assert "3 glass decals in a" in on_ray.stderr
    here = subprocess.run([sys.executable, "-m", "crackbake", *args, "-q", "-o",
                           str(tmp_path / "here")], capture_output=True, text=True, env=env,
                          timeout=600)
    assert here.returncode == 0, here.stderr
    want = _library_hashes(tmp_path / "here")
    assert _library_hashes(tmp_path / "ray") == want and len(want) >= 5



def test_an_unreachable_address_is_one_line_at_once(tmp_path):
    """``--address HOST:PORT`` where nothing listens: one line naming the address and the fix,
    exit 2, in seconds (Ray itself retries for minutes, printing a log line every few seconds),
    and nothing written; the same for ``crackbake decals --address ray://...``."""
    import socket
    import subprocess
    import sys

    with socket.socket() as s:  # a port nothing listens on once closed
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    shutil.copy(SPOT, tmp_path / "spot.obj")
    (tmp_path / "jobs.toml").write_text('[[job]]\nmesh = "spot.obj"\nres = 64\n')
    for args in (["batch", "jobs.toml", "-o", "out", "--address", f"127.0.0.1:{port}"],
                 ["decals", "--preset", "mud", "-n", "2", "--res", "64", "-o", "out",
                  "--address", f"ray://127.0.0.1:{port}"]):
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "crackbake", *args], cwd=tmp_path,
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 2, r.stderr
        assert time.perf_counter() - t < 60
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and f"127.0.0.1:{port}" in lines[0] and "ray start" in lines[0]
        assert not (tmp_path / "out").exists()


def test_local_slots():
    """A local Ray's job slots and CPUs per job: --workers (the cores shared among them), else
    the cores over --cpus-per-job."""
    from crackbake.batch.run import Plan, local_slots

    cores = len(os.sched_getaffinity(0))
    assert local_slots(Plan(workers=1)) == (1, cores)
    assert local_slots(Plan()) == (cores, 1)
    assert local_slots(Plan(workers=2, cpus_per_job=3)) == (2, 3)
    assert local_slots(Plan(cpus_per_job=cores)) == (1, cores)
