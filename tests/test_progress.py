"""``--progress jsonl`` (crackbake.progress): the event stream a GUI reads, from real runs."""

from __future__ import annotations

import io
import json
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

import cli_forks
import pytest

from crackbake.progress import STAGES, JsonlProgress, stage_start
from tests.test_bad_inputs import PLATE

REPO = Path(__file__).resolve().parents[1]
SPOT = REPO / "examples" / "spot.obj"


def _env(tmp_path: Path) -> dict:
    return {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / "c")}


def crackbake(args: list[str], cwd: Path) -> tuple[int, list[dict], str]:
    """Run the command; its exit code, the stdout events (every line must parse) and stderr."""
    proc = cli_forks.run(args, cwd=cwd, env=_env(cwd), timeout=300)
    return proc.returncode, [json.loads(line) for line in proc.stdout.splitlines()], proc.stderr


@pytest.fixture
def plate(tmp_path) -> Path:
    path = tmp_path / "plate.obj"
    path.write_text(PLATE)
    return path


def test_stage_fractions_rise_in_pipeline_order():
    starts = [stage_start(s) for s in STAGES]
    assert starts[0] == 0.0 and all(a < b for a, b in zip(starts, starts[1:], strict=False))
    assert starts[-1] < 1.0


def test_a_run_streams_stages_then_the_summary(plate, tmp_path):
    out = tmp_path / "out"
    code, events, stderr = crackbake(
        [str(plate), "--shrink", "1", "--res", "64", "-o", str(out), "--progress", "jsonl"],
        tmp_path)
    assert code == 0, stderr
    kinds = [e["event"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "done" and "error" not in kinds
    stages = [e["stage"] for e in events if e["event"] == "stage"]
    # the pipeline's order, solve and bake among them
    assert stages == [s for s in STAGES if s in stages]
    assert {"load", "unwrap", "solve", "bake", "write"} <= set(stages)
    fractions = [e["fraction"] for e in events if "fraction" in e]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    times = [e["t"] for e in events]
    assert times == sorted(times)
    summary = events[-1]["summary"]
    assert Path(summary["out_dir"]) == out
    assert sorted(summary["files"]) == sorted(p.name for p in out.iterdir())
    # stderr keeps its human lines
    assert f"wrote {len(summary['files'])} files to {out}/" in stderr


def test_warnings_are_events_as_well_as_stderr_lines(plate, tmp_path):
    # --impact with --cracks is ignored with a warning
    first = tmp_path / "first"
    assert crackbake([str(plate), "--shrink", "1", "--res", "64", "-o", str(first),
                      "--formats", "exr"], tmp_path)[0] == 0
    code, events, stderr = crackbake(
        [str(plate), "--cracks", str(first / "cracks.json"), "--impact", "0.5,0.5,0",
         "--res", "64", "-o", str(tmp_path / "second"), "--progress", "jsonl"], tmp_path)
    assert code == 0, stderr
    said = [e["message"] for e in events if e["event"] == "warning"]
    assert said and said[0].startswith("--impact is ignored with --cracks")
    assert f"warning: {said[0]}" in stderr.splitlines()
    assert said == events[-1]["summary"]["warnings"]
    assert [e["stage"] for e in events if e["event"] == "stage"][:2] == ["load", "cracks"]


def test_an_error_is_the_last_event(tmp_path):
    code, events, stderr = crackbake([str(tmp_path / "missing.obj"), "--progress", "jsonl"],
                                     tmp_path)
    assert code == 2
    last = events[-1]
    assert last["event"] == "error" and last["exit_code"] == 2 and not last["cancelled"]
    assert stderr.strip().splitlines()[-1] == f"error: {last['message']}"
    assert "missing.obj" in last["message"]


def test_progress_and_json_together_are_refused(plate, tmp_path):
    code, events, stderr = crackbake([str(plate), "--progress", "jsonl", "--json"], tmp_path)
    assert code == 2 and events == []
    assert stderr.startswith("error: --progress jsonl and --json both write to stdout")
    assert not (tmp_path / "plate_cracks").exists()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_mid_solve_ends_with_a_cancelled_event(tmp_path, sig):
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "crackbake", str(SPOT), "--preset", "mud", "--sim-faces", "20000",
         "--res", "256", "--formats", "exr", "-o", str(out), "--progress", "jsonl"],
        cwd=tmp_path, env=_env(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True,
        # a shell's background job ignores SIGINT and its children inherit that; the signal
        # must reach crackbake as a terminal's Ctrl-C would
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    events = []
    try:
        for line in proc.stdout:
            events.append(json.loads(line))
            if events[-1].get("stage") == "solve":
                proc.send_signal(sig)
                break
        events += [json.loads(line) for line in proc.stdout]
        code = proc.wait(timeout=120)
    finally:
        proc.kill()
        proc.wait()
    assert code == 128 + sig, (events, proc.stderr.read())
    last = events[-1]
    assert last == {**last, "event": "error", "exit_code": 128 + sig, "cancelled": True}
    assert last["message"] == "interrupted; no outputs were written"
    assert [p.name for p in tmp_path.iterdir() if p.name != "c"] == []  # no staging left


def test_a_closed_stream_does_not_stop_the_run():
    stream = io.StringIO()
    events = JsonlProgress(stream, t0=0.0)
    log = logging.getLogger("crackbake.pipeline")
    with events:
        log.info("baking %dx%d", 8, 8, extra={"stage": "bake"})
        log.info("a detail")
        stream.close()
        log.info("writing", extra={"stage": "write"})  # dropped, no exception
    events.done({"files": []})
    assert events.stream is None and events.fraction == 1.0
    assert events not in logging.getLogger("crackbake").handlers
