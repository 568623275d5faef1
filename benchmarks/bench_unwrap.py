"""Time xatlas unwraps (:func:`crackbake.bake.uv.unwrap`, the real child process) per phase and
report the share of the texture each uses.

Two tables:

* speed: generated scan-like meshes (:func:`crackbake.bake.uv.shapes.scan_blob`, a closed bumpy
  surface of the given face counts, no UVs, 0.15 m diagonal: a head scan in metres), with the
  seconds spent growing charts and packing (from the worker's progress lines), the wall time,
  the worker's CPU time (user + sys: on a shared machine the wall time mostly measures the
  load), the chart count and the coverage;
* coverage: a flat relief (open heightfield and closed slab), a small scan-like blob, spot
  (``examples/spot.obj``, its own UVs ignored, as ``--uv unwrap`` does) and the meshes in
  ``../shared/meshes`` when present.

* memory (``--memory``): the xatlas worker's peak RSS against the face count (scan-like
  meshes; each row in a fresh process, whose ``RUSAGE_CHILDREN`` peak is that one worker's),
  with the parent's own peak beside it, for :mod:`crackbake.memory`'s xatlas term.

Usage::

    python benchmarks/bench_unwrap.py [--faces 100000 270000] [--res 2048] [--skip-coverage]
    python benchmarks/bench_unwrap.py --faces [--meshes DIR]   # the coverage table only
    python benchmarks/bench_unwrap.py --memory [--faces 20000 50000 100000 270000]
"""

from __future__ import annotations

import argparse
import json
import logging
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

from crackbake.bake.uv import unwrap
from crackbake.bake.uv.shapes import relief_plane, scan_blob
from crackbake.bake.uv.uvmesh import uv_area_coverage
from crackbake.io.mesh import Mesh, load_mesh

ROOT = Path(__file__).resolve().parents[1]
# ../shared/meshes beside the checkout, or two levels up from a worktree.
SHARED = next((p for p in (ROOT.parent / "shared" / "meshes",
                           ROOT.parent.parent / "shared" / "meshes") if p.is_dir()),
              ROOT.parent / "shared" / "meshes")  # fmt: skip


class _Phases(logging.Handler):
    """Time of the worker's first packing line: the end of chart growing."""

    def __init__(self, t0: float) -> None:
        super().__init__(logging.INFO)
        self.t0, self.pack_start, self.last = t0, None, ""

    def emit(self, record: logging.LogRecord) -> None:
        self.last = record.getMessage()
        if self.pack_start is None and self.last.startswith("packing"):
            self.pack_start = time.perf_counter() - self.t0


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def measure(mesh: Mesh, res: int) -> dict:
    """Unwrap ``mesh`` without the cache; seconds per phase, CPU seconds, coverage."""
    log = logging.getLogger("crackbake.bake.uv.unwrap")
    log.setLevel(logging.INFO)
    t0, cpu0 = time.perf_counter(), _child_cpu()
    phases = _Phases(t0)
    log.addHandler(phases)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = unwrap(mesh, res, cache=False, timeout=3600)
    finally:
        log.removeHandler(phases)
    wall = time.perf_counter() - t0
    charts = phases.pack_start if phases.pack_start is not None else float("nan")
    return {
        "faces": len(mesh.faces),
        "charts_s": charts,
        "pack_s": wall - charts,
        "wall_s": wall,
        "cpu_s": _child_cpu() - cpu0,
        "coverage": uv_area_coverage(result.uv, result.faces),
    }


def _row(name: str, m: dict) -> str:
    return (f"| {name} | {m['faces']:,} | {m['charts_s']:.1f} | {m['pack_s']:.1f} | "
            f"{m['wall_s']:.1f} | {m['cpu_s']:.1f} | {m['coverage']:.1%} |")  # fmt: skip


def memory_row(n_faces: int, res: int) -> dict:
    """One unwrap of a fresh scan-like mesh in this (fresh) process: the worker's peak RSS."""
    from crackbake.memory import XATLAS_BASE, XATLAS_PER_FACE

    mesh = scan_blob(n_faces, 0.15)
    m = measure(mesh, res)
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    return {"faces": m["faces"], "worker_peak_mb": child / 2**20,
            "parent_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "model_mb": (XATLAS_BASE + XATLAS_PER_FACE * m["faces"]) / 2**20,
            "wall_s": m["wall_s"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="*", default=[100_000, 270_000])
    ap.add_argument("--res", type=int, default=2048)
    ap.add_argument("--skip-coverage", action="store_true", help="only the speed table")
    ap.add_argument("--meshes", type=Path, default=SHARED, help="folder of extra .obj meshes")
    ap.add_argument("--memory", action="store_true", help="the worker's peak RSS table only")
    ap.add_argument("--memory-child", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory_child:
        print(json.dumps(memory_row(args.memory_child, args.res)))
        return
    if args.memory:
        print("| faces | worker peak RSS MB | model MB | parent peak RSS MB | wall s |\n"
              "|---:|---:|---:|---:|---:|", flush=True)
        for n in args.faces or [20_000, 50_000, 100_000, 270_000]:
            out = subprocess.run([sys.executable, __file__, "--memory-child", str(n), "--res",
                                  str(args.res)], capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            print(f"| {r['faces']:,} | {r['worker_peak_mb']:.0f} | {r['model_mb']:.0f} | "
                  f"{r['parent_peak_mb']:.0f} | {r['wall_s']:.1f} |", flush=True)
        return

    head = ("| mesh | faces | charts s | pack s | wall s | worker CPU s | coverage |\n"
            "|---|---:|---:|---:|---:|---:|---:|")  # fmt: skip
    if args.faces:
        print(f"speed, {args.res}px:\n{head}", flush=True)
        for n in args.faces:
            print(_row(f"scan_blob {n // 1000}k", measure(scan_blob(n, 0.15), args.res)),
                  flush=True)  # fmt: skip
    if args.skip_coverage:
        return
    cases = [
        ("relief (open heightfield)", lambda: relief_plane(80, 0.3)),
        ("relief slab (closed)", lambda: relief_plane(60, 0.3, thickness=0.02)),
        ("scan_blob 5k", lambda: scan_blob(5000, 0.15)),
        ("spot --uv unwrap", lambda: load_mesh(ROOT / "examples" / "spot.obj")),
    ]
    if args.meshes.is_dir():
        cases += [(p.name, lambda p=p: load_mesh(p)) for p in sorted(args.meshes.glob("*.obj"))]
    print(f"\ncoverage, {args.res}px:\n{head}", flush=True)
    for name, make in cases:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh = make()
        print(_row(name, measure(mesh, args.res)), flush=True)


if __name__ == "__main__":
    main()
