"""Decal benchmark: the ``--decal`` stage (projector bake + angle fade + PNG writes) against a UV
bake of the same size, on spot's glass star, where every decal texel lies in the star's dense
centre.

The crack network is spot's glass preset around one impact (the case of issue 19: ``crackbake
examples/spot.obj --preset glass --impact 0.334,0.044,0.287 --decal 0.3``), solved once and
cached as a sidecar in the temp folder (``--cracks`` gives another).  For each resolution a fresh
child process bakes the decal (``bake_decals``, as the pipeline does), writes its texture set, and
bakes the UV maps (with the normal map) at the same resolution for comparison, so every row pays
first-run costs (shader JIT) as a CLI run does.  CPU seconds count every thread (llvmpipe's
too): on a loaded machine they say more than wall seconds.

Usage::

    python benchmarks/bench_decal.py [--res 1024 2048 4096] [--cracks cracks.json]
                                     [--save DIR] [--markdown]

``--save DIR`` keeps each row's decal channels as ``DIR/decal_<res>.npz`` (for comparing two
versions texel by texel) and its written PNGs under ``DIR/<res>/``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
IMPACT = (0.334, 0.044, 0.287)
SIZE = 0.3


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def network_sidecar(path: Path | None) -> Path:
    """The glass network's sidecar: ``path``, or solved once and cached in the temp folder."""
    if path is not None:
        return path
    cache = Path(tempfile.gettempdir()) / "crackbake_bench_decal_glass"
    sidecar = cache / "cracks.json"
    if not sidecar.exists():
        print("solving spot's glass network once (cached in", cache, ")", file=sys.stderr)
        impact = ",".join(str(x) for x in IMPACT)
        subprocess.run(
            [sys.executable, "-m", "crackbake", str(ROOT / "examples" / "spot.obj"), "--preset",
             "glass", "--impact", impact, "--res", "256", "--formats", "exr", "-q", "-o",
             str(cache)], check=True,
        )  # fmt: skip
    return sidecar


def child(res: int, cracks: Path, save: Path | None) -> dict:
    from crackbake.bake.context import create_context
    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs
    from crackbake.decals.files import write_decal_set
    from crackbake.decals.projector import bake_decals
    from crackbake.io.mesh import load_mesh
    from crackbake.io.sidecar import read_sidecar
    from crackbake.network import segments
    from crackbake.params import Impact

    mesh = load_mesh(ROOT / "examples" / "spot.obj")
    segs = segments(read_sidecar(cracks, mesh))
    ctx = create_context()
    uvm = with_tangents(prepare_uvs(mesh, mode="keep", res=res, cache=False, ctx=ctx))
    row: dict = {"res": res, "segments": len(segs.a)}

    # The UV bake of the same size, as the pipeline bakes it (normal map included).
    t, c = time.perf_counter(), _cpu()
    maps = bake_cracks(uvm.vertices, uvm.faces, uvm.uv, segs, res, ctx=ctx,
                       normals=uvm.normals, tangents=uvm.tangents)  # fmt: skip
    row["uv_bake_s"], row["uv_bake_cpu_s"] = time.perf_counter() - t, _cpu() - c

    impacts = [Impact(point=IMPACT)]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) if save is None else save / str(res)
        out.mkdir(parents=True, exist_ok=True)
        t, c = time.perf_counter(), _cpu()
        decals = bake_decals(uvm, segs, maps, impacts, SIZE, res, ctx=ctx)
        row["decal_bake_s"], row["decal_bake_cpu_s"] = time.perf_counter() - t, _cpu() - c
        t = time.perf_counter()
        write_decal_set(lambda name: out / name, decals, "gl")
        row["decal_write_s"] = time.perf_counter() - t
    row["decal_stage_s"] = row["decal_bake_s"] + row["decal_write_s"]
    dec = decals[0][1]
    for k in ("candidates", "render", "readback", "normals", "dilate"):
        row[f"decal_{k}_s"] = dec.timings.get(k, 0.0)
    row["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if save is not None:
        np.savez(save / f"decal_{res}.npz", **{k: np.asarray(v) for k, v in
                                               dec.channels().items()}, inside=dec.inside)
    ctx.release()
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, nargs="+", default=[1024, 2048, 4096])
    ap.add_argument("--cracks", type=Path)
    ap.add_argument("--save", type=Path)
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.cracks, args.save)))
        return
    cracks = network_sidecar(args.cracks)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    rows = []
    for res in args.res:
        cmd = [sys.executable, __file__, "--child", str(res), "--cracks", str(cracks)]
        if args.save:
            args.save.mkdir(parents=True, exist_ok=True)
            cmd += ["--save", str(args.save)]
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), file=sys.stderr)
    cols = ["res", "segments", "decal_stage_s", "decal_bake_cpu_s", "decal_render_s",
            "uv_bake_s", "uv_bake_cpu_s", "peak_rss_mb"]  # fmt: skip
    if args.markdown:
        print("| " + " | ".join(cols) + " |")
        print("|" + "---|" * len(cols))
        for r in rows:
            print("| " + " | ".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c])
                                    for c in cols) + " |")  # fmt: skip
    else:
        print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
