"""The simulation stages' own compute on the README's spot run, in one process (issue 25).

``crackbake examples/spot.obj --preset glass --impact 0.334,0.044,0.287``: the sim mesh, the
stress field, the solve and the impacts' star check, run N times in one interpreter through
``pipeline.solve()``'s body (no warm-up thread, no GL, no bake threads beside it), each after
``geometry.forget()`` as a fresh run starts.  The first run pays the imports and the numba
loads and is left out, so the figures are the stages' own work: the main thread's CPU seconds
per stage (``time.thread_time``: steady under load, where wall seconds are not) and the whole
body's, min and median of the other runs.  The solver's whole-mesh updates run on threads
(``iben.update.update_all``) and are not in the main thread's figure; ``bench_stages.py`` gives
the per-stage process CPU of fresh processes, all threads.

Usage::

    python benchmarks/bench_sim_stages.py [-n 6] [--repo OTHER_CHECKOUT]

``--repo`` runs the same in a checkout of another tree (its numba cache warm in
``NUMBA_CACHE_DIR``), alternating with this one, and adds its columns.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMPACT = "0.334,0.044,0.287"
STAGES = ("simmesh", "stress", "solve", "star", "all")


def measure(n: int) -> dict[str, list[float]]:
    """Run the stages ``n`` times here; per stage, the main thread's CPU seconds of runs 2..n."""
    from crackbake import pipeline
    from crackbake.geometry import forget
    from crackbake.io.mesh import load_mesh
    from crackbake.params import RunParams, parse_impact
    from crackbake.simulate import simmesh, stress
    from crackbake.simulate.setup import stress_sources

    spent: dict[str, float] = {}

    def timed(owner, name: str, label: str) -> None:
        inner = getattr(owner, name)

        def wrapper(*args, **kwargs):
            t = time.thread_time()
            try:
                return inner(*args, **kwargs)
            finally:
                spent[label] = spent.get(label, 0.0) + time.thread_time() - t

        setattr(owner, name, wrapper)

    # _solve imports these by name when called: the wrappers are what it finds.
    timed(simmesh, "build_simmesh", "simmesh")
    timed(stress, "stress_field", "stress")
    timed(pipeline, "_grow", "solve")
    timed(pipeline, "_warn_no_star", "star")
    mesh = load_mesh(ROOT / "examples" / "spot.obj")
    params, relative = RunParams(mesh=ROOT / "examples" / "spot.obj", preset="glass",
                                 impacts=(parse_impact(IMPACT),)).resolved()
    sources = stress_sources(params, mesh, relative)
    rows: dict[str, list[float]] = {k: [] for k in STAGES}
    for i in range(n):
        spent.clear()
        forget()
        t = time.thread_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            pipeline._solve(mesh, params, relative, {}, sources)
        spent["all"] = time.thread_time() - t
        if i:
            for k in STAGES:
                rows[k].append(spent.get(k, 0.0))
    forget()
    return rows


def child(repo: Path, n: int) -> dict[str, list[float]]:
    env = dict(os.environ, PYTHONPATH=str(repo))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "-n", str(n),
                          "--json"], env=env, cwd=repo, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=6, help="runs per process, the first left out")
    ap.add_argument("--repo", type=Path, help="another checkout, alternating with this one")
    ap.add_argument("--rounds", type=int, default=2, help="processes per tree [2]")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.json:
        print(json.dumps(measure(max(a.n, 2))))
        return
    trees = {"this": ROOT} | ({"other": a.repo.resolve()} if a.repo else {})
    rows: dict = {t: {k: [] for k in STAGES} for t in trees}
    for _ in range(a.rounds):
        for t, repo in trees.items():
            for k, v in child(repo, max(a.n, 2)).items():
                rows[t][k] += v
    print(f"main-thread CPU ms per stage, {a.rounds} x {max(a.n, 2) - 1} warm runs; "
          f"load average {os.getloadavg()[0]:.1f}")
    head = "".join(f"{t + ' min':>12}{t + ' median':>14}" for t in trees)
    print(f"{'stage':8}{head}")
    for k in STAGES:
        cells = "".join(f"{1e3 * min(rows[t][k]):12.1f}{1e3 * statistics.median(rows[t][k]):14.1f}"
                        for t in trees)
        print(f"{k:8}{cells}")


if __name__ == "__main__":
    main()
