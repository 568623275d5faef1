"""Time MikkTSpace tangents (:mod:`crackbake.bake.tangents`) on a large mesh.

Builds a wavy sheet of ``2 n^2`` triangles (n = 708 gives about 1M) whose UVs are cut into
islands, half of them mirrored, with a few zero-UV-area triangles, then times
:func:`corner_tangents` and :func:`with_tangents`.

Usage::

    python benchmarks/bench_tangents.py [--n 708] [--repeat 3] [--zero-uv-every 997]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from crackbake.bake.tangents import corner_tangents, with_tangents
from crackbake.bake.uv.uvmesh import UVMesh
from crackbake.geometry import vertex_normals


def sheet(n: int, islands: int = 8, seed: int = 0, zero_every: int = 997) -> UVMesh:
    """A wavy (n+1)^2-vertex sheet; UVs split into ``islands`` x ``islands`` islands (vertices
    duplicated along the island borders), odd columns of islands mirrored in u; every
    ``zero_every``-th face gets zero UV area."""
    rng = np.random.default_rng(seed)
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    s = s + rng.uniform(-0.2, 0.2, s.shape) / n * ((s > 0) & (s < 1))
    z = 0.05 * np.sin(7 * s) * np.cos(5 * t)
    pos = np.stack([s, t, z], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    normals = vertex_normals(pos, faces)
    # Each face takes the island of its lowest corner; corners get per-island copies.
    island = (np.minimum(pos[faces, 0].min(1) * islands, islands - 1).astype(int) * islands
              + np.minimum(pos[faces, 1].min(1) * islands, islands - 1).astype(int))
    key = faces.astype(np.int64) * islands * islands + island[:, None]
    uniq, inverse = np.unique(key.reshape(-1), return_inverse=True)
    vmap = uniq // (islands * islands)
    isl = uniq % (islands * islands)
    u, v = pos[vmap, 0] * islands - isl // islands, pos[vmap, 1]
    mirrored = (isl // islands) % 2 == 1
    u = np.where(mirrored, 1.0 - u, u)
    uv = np.column_stack([((isl // islands) + u * 0.9) / islands, v])
    f = inverse.reshape(-1, 3)[::zero_every]
    uv[f[:, 2]] = uv[f[:, 1]]  # zero UV area
    return UVMesh(pos[vmap], inverse.reshape(-1, 3).astype(np.int64), uv, normals[vmap],
                  vmap, "kept", 0.0, 0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=708)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--zero-uv-every", type=int, default=997,
                    help="every k-th face gets zero UV area (the slower, order-dependent path)")
    args = ap.parse_args()
    mesh = sheet(args.n, zero_every=args.zero_uv_every)
    print(f"{len(mesh.faces):,} faces, {len(mesh.vertices):,} vertices")
    for name, fn in (
        ("corner_tangents", lambda: corner_tangents(mesh.vertices, mesh.faces, mesh.uv,
                                                    mesh.normals)),
        ("with_tangents", lambda: with_tangents(mesh)),
    ):
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - t0)
        extra = f", {len(out.vertices):,} vertices after splits" if name == "with_tangents" else ""
        print(f"{name}: best {min(times):.2f} s, median {np.median(times):.2f} s{extra}")


if __name__ == "__main__":
    main()
