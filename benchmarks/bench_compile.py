"""Benchmark of the first-run cost: numba compiling the kernels, then loading them from the cache.

Run: ``python benchmarks/bench_compile.py [--repo PATH] [--repeat N]``.  Each part runs in a fresh
Python process with ``PYTHONPATH=REPO`` and ``NUMBA_CACHE_DIR`` pointing at a new empty temporary
folder (so the repository's ``__pycache__`` is neither read nor written): *cold* is the first
run in that empty cache (what a user pays once after ``pip install``), *warm* the second run in
the same cache.  Times are wall seconds of the whole process (interpreter start, imports,
compilation or cache loading, and the tiny run itself).

Parts: ``iben`` (a small plate glass solve), ``thesis`` (the same plate with the thesis
solver), ``bake`` (the dilation kernels on a small mask), ``cli`` (the whole command on
``examples/spot.obj --preset glass --impact 0.334,0.044,0.287 --res 512``; needs a GPU context).
``setup`` (``python -m crackbake.precompile``, what ``make setup`` runs, then the same CLI
run: *cold* is the precompile, *warm* the first real run after it).
``--repo`` may point at an older checkout (``git worktree add /tmp/old 7916bc4``): the parts
import from either package layout.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

_PLATE = """
import numpy as np
from types import SimpleNamespace
def plate(n):
    h = 1.0 / n
    x, y = np.meshgrid(np.arange(n + 1) * h, np.arange(n + 1) * h, indexing="ij")
    p = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    inner = (p[:, :2] > 1e-9).all(1) & (p[:, :2] < 1 - 1e-9).all(1)
    p[inner, :2] += np.random.default_rng(1).uniform(-0.3, 0.3, (inner.sum(), 2)) * h
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    i = i.ravel()
    f = np.concatenate([np.stack([i, i + n + 1, i + n + 2], 1), np.stack([i, i + n + 2, i + 1], 1)])
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    u, k = np.unique(e, axis=0, return_counts=True)
    boundary = np.zeros(len(p), bool)
    boundary[u[k == 1].ravel()] = True
    return SimpleNamespace(vertices=p, faces=f.astype(np.int64), asset_face=np.arange(len(f)),
                           edge_length=h, boundary=boundary)
sim = plate(30)
c = sim.vertices[sim.faces].mean(1) - np.array([0.5, 0.5, 0.0])
d = np.linalg.norm(c, axis=1)
w = np.where(d <= np.pi * 0.25 / 2, 2 * np.cos(d / 0.25), 0.0)
r = c / np.maximum(d, 1e-12)[:, None]
t = np.cross([0.0, 0.0, 1.0], r)
s = w[:, None, None] * (np.einsum("ea,eb->eab", r, r) + 1.25 * np.einsum("ea,eb->eab", t, t))
field = SimpleNamespace(stress=s, growth=None, weight=w, impacts=[])
try:
    from crackbake.simulate.solver import SolverParams
except ImportError:
    from crackbake.solver import SolverParams
params = SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6, max_cracks=50,
                      max_steps=2000)
"""

PARTS = {
    "iben": _PLATE + """
try:
    from crackbake.simulate.solver.iben import solve_iben
except ImportError:
    from crackbake.solver.iben import solve_iben
res = solve_iben(sim, field, params)
assert res.stats["events"] > 0
""",
    "thesis": _PLATE + """
try:
    from crackbake.simulate.solver.thesis import solve_thesis
except ImportError:
    from crackbake.solver.thesis import solve_thesis
solve_thesis(sim, field, params)
""",
    "bake": """
import numpy as np
try:
    from crackbake.bake.dilation import dilate
except ImportError:
    from crackbake.dilation import dilate
inside = np.zeros((128, 128), bool)
inside[20:60, 30:90] = True
imgs = [np.ones((128, 128), np.float32), np.ones((128, 128), np.float16),
        np.ones((128, 128), np.uint8)]
dilate(imgs, inside)
dilate(imgs, inside, limit=4, background=[0.0, 0.0, 0.0])
""",
}

CLI = ["examples/spot.obj", "--preset", "glass", "--impact", "0.334,0.044,0.287", "--res", "512"]


def run_part(repo: Path, part: str, cache: str, out: str) -> float:
    """Wall seconds of one fresh process running ``part`` from ``repo`` with cache ``cache``."""
    env = dict(os.environ, PYTHONPATH=str(repo), NUMBA_CACHE_DIR=cache)
    if part == "precompile":
        cmd = [sys.executable, "-m", "crackbake.precompile"]
    elif part == "cli":
        cmd = [sys.executable, "-c", "import sys; from crackbake.cli import main; sys.exit(main())",
               str(repo / CLI[0]), *CLI[1:], "-o", out]
    else:
        cmd = [sys.executable, "-c", PARTS[part]]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=repo, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{part} failed in {repo}:\n{proc.stderr[-2000:]}")
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", type=Path, action="append",
                    help="checkout(s) to measure (default: this one); repeat to compare")
    ap.add_argument("--parts", nargs="+", default=["iben", "thesis", "bake", "cli", "setup"],
                    choices=["iben", "thesis", "bake", "cli", "setup"])
    ap.add_argument("--repeat", type=int, default=1,
                    help="cold/warm pairs per part; the fastest is reported")
    args = ap.parse_args()
    repos = [r.resolve() for r in (args.repo or [HERE])]
    print("| checkout | part | cold s | warm s |")
    print("|---|---|---:|---:|")
    for part in args.parts:
        for repo in repos:
            cold, warm = [], []
            for _ in range(max(1, args.repeat)):
                with tempfile.TemporaryDirectory(prefix="crackbake-numba-") as tmp:
                    cache, out = os.path.join(tmp, "cache"), os.path.join(tmp, "out")
                    cold.append(run_part(repo, "precompile" if part == "setup" else part,
                                         cache, out))
                    warm.append(run_part(repo, "cli" if part == "setup" else part,
                                         cache, out + "2"))
            print(f"| {repo.name} | {part} | {min(cold):.1f} | {min(warm):.1f} |", flush=True)


if __name__ == "__main__":
    main()
