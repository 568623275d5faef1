"""The bake stage of one CLI run, pass by pass (issue 25's floor: 4096² on llvmpipe <= 1.5 s).

Each repeat is a fresh process running ``crackbake examples/spot.obj --preset glass --impact
0.334,0.044,0.287 --res 4096`` in-process (the CLI's own path, so the bake pays what a one-shot
run pays: GL targets allocated, shaders from Mesa's cache), and reports the ``bake`` stage
and its passes from ``CrackMaps.timings``:

- ``candidates``: the per-bin segment lists (numba, CPU);
- ``setup``: programs, buffers and the GL targets (llvmpipe zero-fills each new texture);
- ``surface``: the faces at their UVs -> world position, footprint, bin (GL);
- ``cracks``: the per-texel crack measure (GL; ``ctx.finish`` fenced, so GL time lands here);
  ``render`` is the two (older trees time only that);
- ``readback``: the channels into numpy; ``normals``: the compute pass at the crack texels;
- ``dilate``: the gutter fill (``edt``: its nearest-island transform and plan when the bake
  works it out itself; the rest the copies); ``plan_wait``: the time the bake waited for the
  plan worked out ahead (``crackbake.bake.dilation.PlanAhead``);
- done ahead, outside the bake stage (newer trees): ``coverage`` (the stage drawing the faces'
  coverage before the solver, wall s), and the CPU-s of the two threads that run beside the
  solver, ``targets_thread`` (the render targets' allocation, ``crackbake.bake.prefetch``) and
  ``plan_thread`` (the gutter plan).

``--cpu`` times the passes in CPU seconds of the whole process (all threads: llvmpipe's
rasteriser threads and numba's included) instead of wall seconds: on a shared machine wall
times swing with the load, CPU times much less (a pass's wall time on an idle machine is about
its CPU time divided by the threads it keeps busy).  ``--tree`` runs the same in other source
trees (an older checkout: before/after in one go, the runs alternating).

Usage::

    python benchmarks/bench_bake_passes.py [--repeat 5] [--res 4096] [--cpu]
                                           [--tree OTHER_CHECKOUT ...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
IMPACT = "0.334,0.044,0.287"  # on spot's flank, as the command
PASSES = ("candidates", "setup", "surface", "cracks", "render", "readback", "normals", "dilate",
          "edt", "plan_wait", "coverage", "targets_thread", "plan_thread")


def child(res: int, cpu: bool) -> dict:
    import types

    import crackbake.bake.dilation as dilation
    import crackbake.bake.raster as raster
    import crackbake.pipeline as pipeline
    from crackbake.cli.bake import bake

    clock = time.process_time if cpu else time.perf_counter
    raster.time = types.SimpleNamespace(perf_counter=clock)  # the passes' clock
    extra: dict[str, float] = {}

    def timed(module, name, key, timer=clock):
        """Wrap ``module.name`` to record its first call's time as ``key``."""
        inner = getattr(module, name)

        def wrapper(*args, **kw):
            t = timer()
            out = inner(*args, **kw)
            extra.setdefault(key, timer() - t)
            return out

        setattr(module, name, wrapper)

    if hasattr(dilation, "fill_plan"):  # the crack maps' plan, when worked out in the bake
        timed(dilation, "fill_plan", "edt")
        timed(dilation.PlanAhead, "plan_for", "plan_wait")
        timed(dilation.PlanAhead, "_work", "plan_thread", time.thread_time)
        from crackbake.bake import prefetch

        timed(prefetch.TargetPrefetch, "_allocate", "targets_thread", time.thread_time)
    else:  # older trees: the crack maps' transform (the stress bake's comes next)
        timed(dilation, "nearest_island", "edt")
    results = []
    run = pipeline.run

    def kept(params, **kw):
        results.append(run(params, **kw))
        return results[-1]

    pipeline.run = kept
    with tempfile.TemporaryDirectory() as tmp:
        bake.main([str(ROOT / "examples" / "spot.obj"), "--preset", "glass", "--impact", IMPACT,
                   "--res", str(res), "-q", "-o", str(Path(tmp) / "out")],
                  standalone_mode=False)  # fmt: skip
    result = results[0]
    row = {k: float(v) for k, v in result.maps.timings.items()}
    row.update(extra)
    row["bake_stage_wall"] = float(result.manifest["timings_s"]["bake"])
    if "coverage" in result.manifest["timings_s"]:
        row["coverage"] = float(result.manifest["timings_s"]["coverage"])
    row["renderer"] = result.manifest.get("renderer", {}).get("renderer", "")
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=4096)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--cpu", action="store_true", help="passes in process CPU seconds")
    ap.add_argument("--tree", type=Path, nargs="*", default=[],
                    help="other source trees to run too (before/after)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.cpu)))
        return
    trees = [ROOT, *[t.resolve() for t in args.tree]]
    rows: dict[Path, list[dict]] = {t: [] for t in trees}
    for k in range(args.repeat + 1):  # round 0 warms numba's cache and Mesa's shader cache
        for tree in trees:
            cmd = [sys.executable, __file__, "--child", str(args.res)] + (["--cpu"] if args.cpu
                                                                          else [])
            env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONWARNINGS": "ignore"}
            r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tree)
            if r.returncode != 0:
                sys.exit(f"{tree}: {r.stderr.strip().splitlines()[-1]}")
            if k:
                rows[tree].append(json.loads(r.stdout.strip().splitlines()[-1]))
    unit = "CPU-s" if args.cpu else "s"
    print(f"spot glass --res {args.res}, median of {args.repeat} fresh processes, passes in "
          f"{unit}; bake stage in wall s; {rows[ROOT][0]['renderer']}")
    keys = [k for k in PASSES if any(k in r for t in trees for r in rows[t])]
    print("| tree | " + " | ".join(keys) + " | bake stage (wall s) |")
    print("|---" * (len(keys) + 2) + "|")
    for tree in trees:
        med = {k: np.median([r.get(k, 0.0) for r in rows[tree]]) for k in keys}
        stage = np.median([r["bake_stage_wall"] for r in rows[tree]])
        print(f"| {tree.name} | " + " | ".join(f"{med[k]:.2f}" for k in keys)
              + f" | {stage:.2f} |")  # fmt: skip


if __name__ == "__main__":
    main()
