"""The solve in a forked child process (crackbake.solve_beside): real forks, real runs."""

from __future__ import annotations

import json
import logging
import os
import pickle
import threading
import warnings
from pathlib import Path

import cli_forks
import numpy as np
import pytest

from crackbake import solve_beside
from crackbake.errors import CrackbakeError
from crackbake.geometry import SurfaceIndex
from crackbake.params import Impact, RunParams
from crackbake.pipeline import run

REPO = Path(__file__).resolve().parents[1]
SPOT = REPO / "examples" / "spot.obj"
IMPACT = (0.334, 0.044, 0.287)


def _params(out: Path, **kw) -> RunParams:
    kw = {"mesh": SPOT, "out": out, "res": 64, "preset": "glass", "sim_faces": 6000,
          "impacts": (Impact(IMPACT),), **kw}
    return RunParams(**kw)


def _run(out: Path, beside: bool, caplog, monkeypatch,
         **kw) -> tuple[dict, list[str], list[str]]:  # fmt: skip
    """One library run: its files' bytes (the manifest aside), warnings and stage records."""
    caplog.clear()
    started = []
    start = solve_beside.start

    def spy(*args):  # the real start, its handle kept to check that the child solved
        started.append(start(*args))
        return started[-1]

    monkeypatch.setattr(solve_beside, "start", spy)
    with caplog.at_level(logging.INFO, logger="crackbake"), \
            warnings.catch_warnings(record=True) as said:  # fmt: skip
        warnings.simplefilter("always")
        run(_params(out, **kw), solve_beside=beside)
    if beside:
        assert len(started) == 1 and started[0] is not None and not started[0].fell_back
    else:
        assert not started
    files = {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.name != "manifest.json"}
    stages = [r.stage for r in caplog.records if hasattr(r, "stage")]
    return files, sorted(str(w.message) for w in said), stages


@pytest.mark.parametrize("proxy", ("never", "always"))
def test_a_run_solved_beside_writes_the_same_files_warnings_and_stages(tmp_path, caplog,
                                                                       monkeypatch, proxy):
    # cache=False: the sim mesh (and a proxy's closest-point tree) are built in the child
    here = _run(tmp_path / "here", False, caplog, monkeypatch, sim_proxy=proxy, cache=False)
    beside = _run(tmp_path / "beside", True, caplog, monkeypatch, sim_proxy=proxy, cache=False)
    assert here[0].keys() == beside[0].keys() and len(here[0]) >= 10
    for name in here[0]:
        assert here[0][name] == beside[0][name], name
    assert here[1] == beside[1]  # the same warnings, issued in the parent
    assert here[2] == beside[2]  # the stages in the pipeline's order
    assert here[2].index("unwrap") < here[2].index("simmesh") < here[2].index("solve")


def test_the_cli_streams_progress_in_order_with_the_child_solving(tmp_path):
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / "c"),
           solve_beside.ENV: "1"}
    proc = cli_forks.run([str(SPOT), "--preset", "glass", "--impact", ",".join(map(str, IMPACT)),
                          "--sim-faces", "6000", "--res", "64", "-o", str(out), "--progress",
                          "jsonl"], cwd=tmp_path, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    events = [json.loads(line) for line in proc.stdout.splitlines()]
    stages = [e["stage"] for e in events if e["event"] == "stage"]
    assert stages[:6] == ["load", "unwrap", "simmesh", "stress", "solve", "bake"]
    assert [e["t"] for e in events] == sorted(e["t"] for e in events)
    said = [e["message"] for e in events if e["event"] == "warning"]
    assert said == events[-1]["summary"]["warnings"]
    assert any("outside the 0-1 UV square" in m for m in said)  # spot's, from the UV stage


def _child_only(fn):
    """``fn`` in the child, a plain solve in the parent (to tell the two apart)."""
    parent = os.getpid()

    def call(x, *, timings):
        if os.getpid() != parent:
            return fn(x, timings)
        timings["here"] = 1.0
        return x * 2

    return call


def test_the_childs_result_times_and_warnings_reach_the_parent():
    def work(x, timings):
        timings["solve"] = 0.5
        logging.getLogger("crackbake.test").warning("from the child %d", x)
        warnings.warn(f"child warning {x}", UserWarning, stacklevel=1)
        return np.arange(x)

    handle = solve_beside.start(_child_only(work), 5)
    assert handle is not None
    timings: dict = {}
    seen: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record):
            seen.append(record)

    keep = Keep()
    logging.getLogger("crackbake.test").addHandler(keep)
    try:
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            value = handle.result(timings)
    finally:
        logging.getLogger("crackbake.test").removeHandler(keep)
    assert np.array_equal(value, np.arange(5)) and not handle.fell_back
    assert timings == {"solve": 0.5}
    assert [r.getMessage() for r in seen] == ["from the child 5"]
    assert [str(w.message) for w in said] == ["child warning 5"]


def test_an_error_in_the_child_is_raised_in_the_parent():
    def fail(x, timings):
        raise CrackbakeError(f"bad input {x}")

    handle = solve_beside.start(_child_only(fail), 7)
    with pytest.raises(CrackbakeError, match="bad input 7") as caught:
        handle.result({})
    assert any("child process" in note for note in caught.value.__notes__)
    _assert_reaped(handle)


@pytest.mark.parametrize("how", ("unpicklable", "died"))
def test_a_child_without_a_result_leaves_the_solve_to_the_parent(how):
    def odd(x, timings):
        if how == "died":
            os._exit(9)
        return lambda: x  # does not pickle

    handle = solve_beside.start(_child_only(odd), 4)
    timings: dict = {}
    assert handle.result(timings) == 8 and handle.fell_back
    assert timings == {"here": 1.0}
    _assert_reaped(handle)


def test_a_parent_that_fails_first_stops_and_reaps_the_child():
    import time

    def slow(x, timings):
        time.sleep(60)
        return x

    handle = solve_beside.start(_child_only(slow), 1)
    pid = handle.pid

    def fail_first():
        raise CrackbakeError("refused in the UV stage")

    with pytest.raises(CrackbakeError, match="UV stage"):
        handle.result({}, fail_first)
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # already reaped: no zombie left


def _assert_reaped(handle) -> None:
    assert handle.pid == 0


def test_no_fork_beside_another_thread_and_the_default_follows_the_cores(monkeypatch):
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, name="someone-else")
    other.start()
    try:
        assert not solve_beside.can_fork()
        assert solve_beside.start(_child_only(lambda x, t: x), 1) is None
    finally:
        stop.set()
        other.join()
    assert solve_beside.can_fork()
    monkeypatch.setenv(solve_beside.ENV, "0")
    assert not solve_beside.wanted() and solve_beside.wanted(True)
    monkeypatch.setenv(solve_beside.ENV, "1")
    assert solve_beside.wanted() and not solve_beside.wanted(False)
    monkeypatch.delenv(solve_beside.ENV)
    cores = len(os.sched_getaffinity(0))
    assert solve_beside.wanted() == (cores >= solve_beside.MIN_CORES)


def test_a_pickled_surface_index_answers_the_same_without_its_tree():
    rng = np.random.default_rng(1)
    vertices = rng.normal(size=(200, 3))
    faces = rng.integers(0, 200, (300, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                  & (faces[:, 0] != faces[:, 2])]
    index = SurfaceIndex(vertices, faces)
    copy = pickle.loads(pickle.dumps(index))
    points = rng.normal(size=(50, 3))
    for a, b in zip(index.closest(points), copy.closest(points), strict=True):
        assert np.array_equal(a, b)
