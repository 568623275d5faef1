"""Solve-side stages on a real asset: simulation mesh, stress field and solver, per preset.

Runs the library path of ``crackbake MESH --preset P`` (without the bake) on spot at several
simulation sizes, each in a fresh process after a warm-up run so numba's compiled kernels are
loaded from the cache, not compiled (first compilation is a one-off, done by the warm-up).
Prints a markdown table: ``started`` is the number of distinct cracks the
solver started (what ``--max-cracks`` bounds), ``polylines`` the network's polylines (cracks
split at junctions), ``length`` the total crack length in mesh units.

Usage::

    python benchmarks/bench_pipeline.py [--faces 100000 400000 1000000] [--presets glass crackle]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMPACT = (0.334, 0.044, 0.287)  # on spot's flank


def spot_path() -> Path:
    shared = ROOT.parent / "shared" / "meshes" / "spot.obj"
    return shared if shared.exists() else ROOT / "examples" / "spot.obj"


def child(preset: str, faces: int) -> dict:
    from crackbake.io.mesh import load_mesh
    from crackbake.params import Impact, RunParams
    from crackbake.pipeline import solve

    mesh = load_mesh(spot_path())
    impacts = (Impact(IMPACT),) if preset == "glass" else ()
    params, relative = RunParams(
        mesh=spot_path(), preset=preset, impacts=impacts, sim_faces=faces
    ).validate().resolved()
    timings: dict[str, float] = {}
    t = time.perf_counter()
    network, stats, _ = solve(mesh, params, relative, timings)
    timings["total"] = time.perf_counter() - t
    st = network.stats()
    return {
        "preset": preset,
        "sim_faces": stats["sim_faces"],
        **{k: timings[k] for k in ("simmesh", "stress", "solve", "total")},
        "steps": stats["steps"],
        "started": stats.get("cracks", st["cracks"]),
        "polylines": st["cracks"],
        "length": st["total_length"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[100_000, 400_000, 1_000_000])
    ap.add_argument("--presets", nargs="+", default=["glass", "crackle"])
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child[0], int(args.child[1]))))
        return
    cols = ["preset", "sim_faces", "simmesh", "stress", "solve", "total", "steps", "started",
            "polylines", "length"]
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    # Warm-up: loads (or on a fresh checkout compiles and caches) the numba kernels.
    subprocess.run([sys.executable, __file__, "--child", "glass", "5000"], capture_output=True)
    for preset in args.presets:
        for faces in args.faces:
            r = subprocess.run([sys.executable, __file__, "--child", preset, str(faces)],
                               capture_output=True, text=True)
            if r.returncode:
                print(f"| {preset} | {faces} | failed: {r.stderr.strip().splitlines()[-1]} |")
                continue
            row = json.loads(r.stdout.strip().splitlines()[-1])
            cells = [f"{row[c]:.2f}" if isinstance(row[c], float) else str(row[c]) for c in cols]
            print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
