"""Write-stage benchmark: every file of a run (EXR, the target's PNGs, GLB, preview) against the
bake that produced the maps.

Spot (its own UVs) with a crack network of about 1,000 segments is baked once at each
resolution; then :func:`crackbake.exchange.bundle.write_outputs` writes the full set into an
output stage ``--repeat`` times (the first write pays first-use costs: the preview's shader
compile, page faults; the best of the rest is the warm figure).  Normal and occlusion maps and
tangents come from the real bake when the installed crackbake has them, else from a stand-in
of the same shapes and types (image-space depth gradient, occlusion 1 - 0.7 mask, per-vertex
UV-gradient tangents), so the write has every map to encode either way.

Each row gives wall and CPU seconds (all threads, this process): on a busy machine the CPU
figures are the steadier comparison (the write's CPU / cores is its wall time on an idle one).

Usage::

    python benchmarks/bench_write.py [--res 2048 4096] [--target gltf unreal] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def stand_in_tangents(uvm) -> np.ndarray:
    """(V, 4) per-vertex tangents from each face's UV gradient, Gram-Schmidt on the normal."""
    v, f, uv, n = uvm.vertices, uvm.faces, uvm.uv, uvm.normals
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    d1, d2 = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    det = np.where(np.abs(det) > 1e-20, det, 1e-20)
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det[:, None]
    tv, bv = np.zeros_like(v), np.zeros_like(v)
    for k in range(3):
        np.add.at(tv, f[:, k], t)
        np.add.at(bv, f[:, k], b)
    tv -= n * (tv * n).sum(1, keepdims=True)
    tv /= np.maximum(np.linalg.norm(tv, axis=1, keepdims=True), 1e-12)
    w = np.where((np.cross(n, tv) * bv).sum(1) < 0, -1.0, 1.0)
    return np.column_stack([tv, w])


def stand_in_surface(maps):
    """Normal (res, res, 3) float32 and occlusion (res, res) float16 of the right types."""
    d = maps.depth / max(float(maps.depth.max()), 1e-30)
    gy, gx = np.gradient(d.astype(np.float32))
    k = np.float32(0.15 * maps.res / 64)
    n = np.stack([-gx * k, gy * k, np.ones_like(gx)], -1)  # row 0 = top: +v is -row
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    occ = (1.0 - 0.7 * maps.mask.astype(np.float32)).astype(np.float16)
    return n.astype(np.float32), occ


def prepared(res: int):
    """Spot, its UV mesh (with tangents), the network and the maps (with normal, occlusion)."""
    from bench_bake import random_network, spot_path

    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.uv import prepare_uvs
    from crackbake.io.mesh import load_mesh
    from crackbake.network import segments

    mesh = load_mesh(spot_path())
    network = random_network(mesh)
    uvm = prepare_uvs(mesh, mode="keep", res=res, cache=False)
    real = False
    try:
        from crackbake.bake.tangents import with_tangents

        uvm = with_tangents(uvm)
        real = True
    except ImportError:
        uvm = replace(uvm, tangents=stand_in_tangents(uvm))
    t, cpu = time.perf_counter(), time.process_time()
    try:
        maps = bake_cracks(uvm.vertices, uvm.faces, uvm.uv, segments(network), res,
                           tangents=uvm.tangents)  # fmt: skip
    except TypeError:
        maps = bake_cracks(uvm.vertices, uvm.faces, uvm.uv, segments(network), res)
    bake = (time.perf_counter() - t, time.process_time() - cpu)
    if maps.normal is None:
        real = False
        maps.normal, maps.occlusion = stand_in_surface(maps)
    return mesh, uvm, network, maps, bake, real


def main() -> None:
    from crackbake.bake.context import create_context
    from crackbake.exchange.bundle import write_outputs
    from crackbake.params import RunParams
    from crackbake.transaction.stage import OutputStage

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, nargs="+", default=[4096])
    ap.add_argument("--target", nargs="+", default=["gltf"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--keep", type=Path, help="write the last set into KEEP/<res>-<target>")
    args = ap.parse_args()
    ctx = create_context()
    rows = []
    print("| res | target | bake s wall / CPU | write s (first) | write s warm wall / CPU "
          "| warm median wall / CPU | files | MB | maps | load |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for res in args.res:
        mesh, uvm, network, maps, bake, real = prepared(res)
        for target in args.target:
            params = RunParams(mesh=Path(mesh.source), res=res, target=target)
            times, cpus = [], []
            for i in range(args.repeat):
                last = args.keep is not None and i == args.repeat - 1
                out = args.keep / f"{res}-{target}" if last else Path(tempfile.mkdtemp()) / "o"
                with OutputStage(out) as stage:
                    t, cpu = time.perf_counter(), time.process_time()
                    write_outputs(stage, "spot", params, mesh, uvm, network, maps, ctx)
                    times.append(time.perf_counter() - t)
                    cpus.append(time.process_time() - cpu)
                    records = stage.records()
                    if last:
                        stage.commit()
            mb = sum(r["bytes"] for r in records) / 1e6
            warm = 1 + int(np.argmin(times[1:])) if len(times) > 1 else 0
            rest = slice(1 if len(times) > 1 else 0, None)
            med, med_cpu = float(np.median(times[rest])), float(np.median(cpus[rest]))
            row = {"res": res, "target": target, "bake": bake[0], "bake_cpu": bake[1],
                   "write_first": times[0], "write_warm": times[warm],
                   "write_warm_cpu": cpus[warm], "write_median": med,
                   "write_median_cpu": med_cpu, "files": len(records), "MB": mb,
                   "real_maps": real, "cores": os.cpu_count(),
                   "load_avg": os.getloadavg()[0]}  # fmt: skip
            rows.append(row)
            print(f"| {res} | {target} | {bake[0]:.2f} / {bake[1]:.2f} | {times[0]:.2f} "
                  f"| {times[warm]:.2f} / {cpus[warm]:.2f} | {med:.2f} / {med_cpu:.2f} "
                  f"| {len(records)} | {mb:.1f} "
                  f"| {'baked' if real else 'stand-in'} | {row['load_avg']:.1f} |",
                  flush=True)  # fmt: skip
    ctx.release()
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
