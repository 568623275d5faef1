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

Usage::

    python benchmarks/bench_unwrap.py [--faces 100000 270000] [--res 2048] [--skip-coverage]
    python benchmarks/bench_unwrap.py --faces [--meshes DIR]   # the coverage table only
"""

from __future__ import annotations

import argparse
import logging
import resource
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="*", default=[100_000, 270_000])
    ap.add_argument("--res", type=int, default=2048)
    ap.add_argument("--skip-coverage", action="store_true", help="only the speed table")
    ap.add_argument("--meshes", type=Path, default=SHARED, help="folder of extra .obj meshes")
    args = ap.parse_args()

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
