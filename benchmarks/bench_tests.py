"""Benchmark of the test suite's CPU work, file by file: what ``make test`` spends its cores on.

Run: ``python benchmarks/bench_tests.py [--repo PATH] [--kernels] [FILE ...]`` (default: every
``tests/test_*.py``).  Each file runs alone in a fresh ``pytest -q`` process with the environment
``make test`` gives it (``CRACKBAKE_REFERENCE=require`` and the reference clients when
``.venv-blender`` and ``.node`` exist), one after another; its CPU time is the user + system
seconds of that process and every process it waited for (the CLI runs, the xatlas workers, the
Blender checks), so a number does not depend on how busy the machine is the way wall seconds
do.  ``--kernels`` first compiles the kernels as ``make test`` does (``crackbake.precompile``
into an empty ``NUMBA_CACHE_DIR``, then a copy for ``tests/test_precompile.py``), times it, and
runs the files with that cache.  ``--repo`` may point at another checkout (``git worktree add
/tmp/old COMMIT``) to compare: its own ``tests/`` run against its own package.

Prints one line per file (CPU s, wall s, pytest's summary) and the total.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd: list[str], env: dict, cwd: Path) -> tuple[float, float, str]:
    """CPU seconds (this process's waited-for children), wall seconds, last output line."""
    c0, t0 = _children_cpu(), time.perf_counter()
    r = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    last = (r.stdout.strip().splitlines() or [f"exit {r.returncode}"])[-1]
    return _children_cpu() - c0, time.perf_counter() - t0, last


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", help="test files (default: every tests/test_*.py)")
    ap.add_argument("--repo", type=Path, default=HERE, help="checkout to measure")
    ap.add_argument("--kernels", action="store_true", help="compile the kernels as make test does")
    args = ap.parse_args()
    repo = args.repo.resolve()
    files = args.files or sorted(
        str(p.relative_to(repo)) for p in (repo / "tests").glob("test_*.py"))
    env = {**os.environ, "PYTHONPATH": str(repo), "CRACKBAKE_REFERENCE": "require"}
    if (repo / ".venv-blender" / "bin" / "python").exists():
        env["CRACKBAKE_BLENDER_PYTHON"] = str(repo / ".venv-blender" / "bin" / "python")
    if (repo / ".node").is_dir():
        env["CRACKBAKE_GLTF_VALIDATOR"] = str(repo / ".node")
    total = 0.0
    with tempfile.TemporaryDirectory(prefix="bench-tests-") as tmp:
        if args.kernels:
            cache, copy = Path(tmp) / "numba-test", Path(tmp) / "numba-precompiled"
            env["NUMBA_CACHE_DIR"] = str(cache)
            cpu, wall, last = timed([sys.executable, "-m", "crackbake.precompile"], env, repo)
            shutil.copytree(cache, copy)
            env["CRACKBAKE_PRECOMPILED_CACHE"] = str(copy)
            total += cpu
            print(f"{'kernels (make test set-up)':36s} {cpu:8.1f} {wall:8.1f}  {last}", flush=True)
        for name in files:
            cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", name]
            cpu, wall, last = timed(cmd, env, repo)
            total += cpu
            print(f"{Path(name).name:36s} {cpu:8.1f} {wall:8.1f}  {last}", flush=True)
    print(f"{'total CPU s':36s} {total:8.1f}")


if __name__ == "__main__":
    main()
