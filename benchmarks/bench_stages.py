"""Per-stage wall and CPU seconds of the README's spot run, fresh processes (issue 25).

``crackbake examples/spot.obj --preset glass --impact 0.334,0.044,0.287 --res 4096``, run N
times as new interpreters in two modes: as is (the manifest's ``timings_s``: wall seconds per
stage), and with the pipeline's stage clock swapped for the process CPU clock, so the same
``timings_s`` hold the CPU seconds each stage cost the process (all its threads: the bake's
prefetch threads and the solver's kernel warm-up count where they run).  On a busy machine the
CPU figures are the steadier comparison; the load average before each run is shown.

Usage::

    python benchmarks/bench_stages.py [-n 3] [--repo OTHER_CHECKOUT] [--res 4096]

``--repo`` runs the same against another checkout (``git worktree add /tmp/old main``), run
by run interleaved with this one; both need a warm numba cache (``NUMBA_CACHE_DIR``,
``python -m crackbake.precompile``) for their own paths.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMPACT = "0.334,0.044,0.287"
STAGES = ("load", "unwrap", "tangents", "coverage", "simmesh", "stress", "solve", "bake",
          "stress_bake", "write", "total")
#: Run in the child with ``-c`` for the CPU mode: the command, its stage clock the CPU's.
CPU_CLOCK = (
    "import sys, time, types\n"
    "import crackbake.pipeline as pipeline\n"
    "pipeline.time = types.SimpleNamespace(perf_counter=time.process_time)\n"
    "sys.argv = ['crackbake'] + sys.argv[1:]\n"
    "from crackbake.entry import main\n"
    "main()\n"
)


def run(repo: Path, out: Path, res: int, cpu: bool) -> dict:
    """One fresh process on ``repo``'s code: wall, process CPU, load average, stage times."""
    extra = os.environ.get("PYTHONPATH")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo), *([extra] if extra else [])]))
    if out.exists():
        shutil.rmtree(out)
    args = [str(repo / "examples" / "spot.obj"), "--preset", "glass", "--impact", IMPACT,
            "--res", str(res), "-q", "-o", str(out)]
    head = ["-c", CPU_CLOCK] if cpu else ["-m", "crackbake"]
    load = os.getloadavg()[0]
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *head, *args], env=env, cwd=repo,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{repo}: the spot run failed: {err}")
    timings = json.loads((out / "manifest.json").read_text())["timings_s"]
    return {"wall": wall, "cpu": usage.ru_utime + usage.ru_stime, "loadavg": load,
            **{k: float(v) for k, v in timings.items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=3, help="runs per tree and mode (median)")
    ap.add_argument("--repo", type=Path, help="another checkout, interleaved with this one")
    ap.add_argument("--res", type=int, default=4096)
    a = ap.parse_args()
    trees = {"this": ROOT} | ({"other": a.repo.resolve()} if a.repo else {})
    rows: dict = {(t, m): [] for t in trees for m in ("wall", "cpu")}
    with tempfile.TemporaryDirectory(prefix="bench_stages_") as scratch:
        for i in range(a.n):
            for mode in ("wall", "cpu"):
                order = list(trees) if i % 2 == 0 else list(trees)[::-1]
                for tag in order:
                    out = Path(scratch) / f"{tag}_{mode}"
                    rows[tag, mode].append(run(trees[tag], out, a.res, mode == "cpu"))
    cols = [(t, m) for t in trees for m in ("wall", "cpu")]
    print(f"median of {a.n}; 'wall' columns: seconds; 'cpu' columns: process CPU-s")
    print(f"{'figure':12s}" + "".join(f"{t + ' ' + m:>14s}" for t, m in cols))
    for k in ("wall", "cpu", "loadavg", *STAGES):
        vals = [statistics.median(r.get(k, 0.0) for r in rows[c]) for c in cols]
        print(f"{k:12s}" + "".join(f"{v:14.3f}" for v in vals))


if __name__ == "__main__":
    main()
