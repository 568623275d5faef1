"""Benchmark of the iben crack solver on jittered plates (glass impact and uniform shrinkage).

Run: ``python benchmarks/bench_solver.py [--sizes 100000 400000 1000000]``.  A tiny warm-up run
first loads / compiles the numba kernels, so the times exclude compilation.  Prints a markdown
table: faces, field, wall seconds of the solve, setup seconds (everything but the crack loop),
crack events, distinct cracks, total crack length (plate units), ms per crack event (the loop
only, setup excluded, so it is comparable across sizes).

Floors (issue): glass at 100k faces <= 3 s; ms/event at 400k <= 1.5x that at 100k for both
fields; 1M faces <= 30 s.
"""

from __future__ import annotations

import argparse
import time
from types import SimpleNamespace

import numpy as np
from scipy.spatial import Delaunay

from crackbake.simulate.solver import SolverParams
from crackbake.simulate.solver.iben import solve_iben


def plate(n_faces: int, seed: int = 1) -> SimpleNamespace:
    """Jittered triangulated unit plate with about ``n_faces`` faces."""
    n = max(2, int(round(np.sqrt(n_faces / 2))))
    h = 1.0 / n
    x, y = np.meshgrid(np.arange(n + 1) * h, np.arange(n + 1) * h, indexing="ij")
    p = np.stack([x.ravel(), y.ravel()], 1)
    inner = (p > 1e-9).all(1) & (p < 1 - 1e-9).all(1)
    p[inner] += np.random.default_rng(seed).uniform(-0.35, 0.35, (inner.sum(), 2)) * h
    tri = Delaunay(p).simplices.astype(np.int64)
    v = np.concatenate([p, np.zeros((len(p), 1))], 1)
    cr = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])[:, 2]
    tri[cr < 0] = tri[cr < 0][:, [0, 2, 1]]
    tri = tri[np.abs(cr) > 1e-12 * h * h]
    return SimpleNamespace(vertices=v, faces=tri, asset_face=np.arange(len(tri)), edge_length=h)


def impact_field(sim, centre=(0.5, 0.5, 0.0), radius=0.25) -> SimpleNamespace:
    """Glass impact: w (r r^T + 1.25 c c^T), w = 2 cos(d / r) inside d <= pi r / 2."""
    c = sim.vertices[sim.faces].mean(1) - np.asarray(centre)
    d = np.linalg.norm(c, axis=1)
    w = np.where(d <= np.pi * radius / 2, 2 * np.cos(d / radius), 0.0)
    r = c / np.maximum(d, 1e-12)[:, None]
    t = np.cross([0.0, 0.0, 1.0], r)
    s = w[:, None, None] * (np.einsum("ea,eb->eab", r, r) + 1.25 * np.einsum("ea,eb->eab", t, t))
    return SimpleNamespace(stress=s, growth=None, weight=w, impacts=[])


def shrink_field(sim, s=1.0) -> SimpleNamespace:
    st = np.zeros((len(sim.faces), 3, 3))
    st[:, 0, 0] = st[:, 1, 1] = s
    return SimpleNamespace(stress=st, growth=None, weight=np.ones(len(sim.faces)), impacts=[])


GLASS = SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6, max_cracks=400,
                     max_steps=200_000)
SHRINK = SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6, max_cracks=3000,
                      max_steps=200_000)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100_000, 400_000, 1_000_000])
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs per case; the fastest is reported (shared machines are noisy)")
    args = ap.parse_args()
    warm = plate(2000)
    solve_iben(warm, impact_field(warm), GLASS)
    print("| faces | field | wall s | setup s | events | cracks | length | ms/event |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for size in args.sizes:
        sim = plate(size)
        for name, field, params in (("glass", impact_field(sim), GLASS),
                                    ("shrink", shrink_field(sim), SHRINK)):
            best = None
            for _ in range(max(1, args.repeat)):
                t = time.perf_counter()
                r = solve_iben(sim, field, params)
                wall = time.perf_counter() - t
                if best is None or wall < best[0]:
                    best = (wall, r)
            wall, r = best
            loop = r.stats["loop_seconds"]
            ms = 1000 * loop / max(r.stats["events"], 1)
            length = sum(np.linalg.norm(np.diff(c.points, axis=0), axis=1).sum()
                         for c in r.cracks)
            print(f"| {len(sim.faces)} | {name} | {wall:.2f} | {wall - loop:.2f} "
                  f"| {r.stats['events']} | {r.stats['cracks']} | {length:.1f} | {ms:.3f} |",
                  flush=True)


if __name__ == "__main__":
    main()
