"""Tile benchmark: ``crackbake tile --preset mud --size 2 --res 2048``.

Issue 11's floor: a 2048² mud tile in <= 15 s on the 2-core llvmpipe machine, numba
compilation excluded.  A 64² tile runs first in the same process (it pays numba's kernel
load/compile and the shader compiles); the timed run is the second, written to a temporary
folder.  Prints the stage times (stress = periodic sim mesh + field, solve = crack growth,
bake = the GPU bake with the 3x3 copies, write = PNG set + EXR + JSON) and the verdict.

Usage::

    python benchmarks/bench_tile.py [--res 2048] [--size 2] [--preset mud] [--keep DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

LIMIT_S = 15.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=2048)
    ap.add_argument("--size", type=float, default=2.0)
    ap.add_argument("--preset", default="mud")
    ap.add_argument("--keep", type=Path, help="Write the timed tile here (kept).")
    args = ap.parse_args()

    from crackbake.tile import TileParams, build_tile

    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        build_tile(TileParams(out=Path(tmp) / "warm", preset=args.preset, res=64,
                              sim_faces=2000))
        print(f"warm-up (numba + shaders): {time.perf_counter() - t:.2f} s")
        out = args.keep or Path(tmp) / "tile"
        params = TileParams(out=out, preset=args.preset, size=args.size, res=args.res)
        t = time.perf_counter()
        manifest = build_tile(params)
        total = time.perf_counter() - t
    times = manifest["timings_s"]
    print(f"{args.preset} tile {args.size:g}, {args.res}², {manifest['solver']['cracks']} cracks, "
          f"{manifest['solver']['pieces']} pieces")
    print("  " + ", ".join(f"{k} {v:.2f} s" for k, v in times.items()))
    verdict = "OK" if total <= LIMIT_S else "TOO SLOW"
    print(f"total {total:.2f} s (limit {LIMIT_S:g} s): {verdict}")


if __name__ == "__main__":
    main()
