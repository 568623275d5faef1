"""Stress-map benchmark: the extra bake time of the stress EXR's planes on spot, real solve.

Loads spot (its own UVs), builds the default simulation mesh, solves a glass impact plus a
weak shrinkage with iben, then bakes both stress fields (:func:`crackbake.bake.stress.bake_stress`)
at each resolution, twice in the same process: the first row pays numba's cached-kernel load and
the shader compile, the second is the warm cost a run pays on top of the crack bake.  Optionally
writes a false-colour PNG of the final p1 (``--png``).

Usage::

    python benchmarks/bench_stress.py [--res 2048 4096] [--png /tmp/stress_p1.png]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def tangents_of(uvmesh) -> np.ndarray:
    """MikkTSpace tangents when crackbake has them, else per-vertex UV-gradient tangents
    (same cost class for the bake; the benchmark times the bake, not the frame)."""
    try:
        from crackbake.bake.tangents import with_tangents
    except ImportError:
        with_tangents = None
    if with_tangents is not None:
        return with_tangents(uvmesh)
    v, f, uv, n = uvmesh.vertices, uvmesh.faces, uvmesh.uv, uvmesh.normals
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    d1, d2 = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    safe = np.where(np.abs(det) > 1e-20, det, 1.0)
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / safe[:, None]
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / safe[:, None]
    tv = np.zeros_like(v)
    bv = np.zeros_like(v)
    for k in range(3):
        np.add.at(tv, f[:, k], t)
        np.add.at(bv, f[:, k], b)
    tv -= n * np.einsum("ij,ij->i", tv, n)[:, None]
    tv /= np.maximum(np.linalg.norm(tv, axis=1), 1e-20)[:, None]
    w = np.where(np.einsum("ij,ij->i", np.cross(n, tv), bv) < 0, -1.0, 1.0)
    return np.column_stack([tv, w])


def false_colour(p1: np.ndarray, path: str) -> None:
    """Diverging map: blue (compression) - white (0) - red (tension), scaled to the 99th
    percentile of |p1|."""
    from PIL import Image

    scale = float(np.percentile(np.abs(p1), 99)) or 1.0
    x = np.clip(p1 / scale, -1.0, 1.0)
    rgb = np.empty(p1.shape + (3,), np.float32)
    rgb[..., 0] = np.where(x > 0, 1.0, 1.0 + x)
    rgb[..., 1] = 1.0 - np.abs(x)
    rgb[..., 2] = np.where(x < 0, 1.0, 1.0 - x)
    Image.fromarray((rgb * 255 + 0.5).astype(np.uint8)).save(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, nargs="+", default=[2048, 4096])
    ap.add_argument("--png", default=None, help="false-colour PNG of the final p1")
    ap.add_argument("--tile", type=int, default=None, help="band limit (default: the bake's)")
    ap.add_argument("--repeat", type=int, default=2, help="bakes per resolution (first + warm)")
    args = ap.parse_args()

    from crackbake.bake.context import create_context
    from crackbake.bake.stress import bake_stress
    from crackbake.bake.uv import prepare_uvs
    from crackbake.io.mesh import load_mesh
    from crackbake.simulate.simmesh import build_simmesh
    from crackbake.simulate.solver import SolverParams
    from crackbake.simulate.solver.iben import solve_iben
    from crackbake.simulate.stress import ImpactSource, ShrinkSource, stress_field

    mesh = load_mesh(str(ROOT / "examples" / "spot.obj"))
    ctx = create_context()
    uvmesh = prepare_uvs(mesh, mode="keep", res=2048, padding=None, ctx=ctx)
    tangents = tangents_of(uvmesh)
    t = time.perf_counter()
    sim = build_simmesh(mesh)
    point = mesh.vertices[mesh.faces[len(mesh.faces) // 3]].mean(axis=0)
    field = stress_field(sim, mesh, [ImpactSource(point=point), ShrinkSource(strength=0.3)])
    result = solve_iben(sim, field, SolverParams(seed=1))
    print(f"spot: {len(mesh.faces)} faces, sim {len(sim.faces)} -> {len(result.faces)} faces, "
          f"{len(result.cracks)} cracks, solve {time.perf_counter() - t:.1f} s")
    print("| res | run | total s | prepare | GL setup | render | readback | nearest "
          "| fill+principal |")
    print("|---|---|---|---|---|---|---|---|---|")
    cols = ("prepare", "setup", "render", "readback", "nearest", "principal")
    for res in args.res:
        rows = []
        for k in range(args.repeat):
            t = time.perf_counter()
            extra = {} if args.tile is None else {"tile": args.tile}
            maps = bake_stress(uvmesh, result, res, tangents=tangents, initial=sim, ctx=ctx,
                               **extra)
            rows.append([time.perf_counter() - t] + [maps.timings[c] for c in cols])
            run = "first" if k == 0 else "warm"
            print(f"| {res} | {run} | " + " | ".join(f"{x:.2f}" for x in rows[-1]) + " |")
            if args.png and res == args.res[0] and k == 0:
                false_colour(maps.stress.p1, args.png)
                false_colour(maps.stress0.p1, args.png.replace(".png", "_initial.png"))
            del maps
        if len(rows) > 1:
            # The machine is shared: the least time of each stage over the warm runs.
            best = np.min(np.array(rows[1:]), axis=0)
            print(f"| {res} | best warm | " + " | ".join(f"{x:.2f}" for x in best) + " |")
    ctx.release()


if __name__ == "__main__":
    main()
