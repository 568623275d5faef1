"""Decal-library benchmark: ``crackbake decals --preset glass -n 16 --size 0.5 --res 1024``.

Issue 11's floor: a 16-variant 1024² glass library in <= 30 s on the 2-core llvmpipe machine,
numba compilation excluded.  A one-variant 64² library runs first in the same process (it pays
numba's kernel load/compile and the shader compiles); the timed run is the second, written to a
temporary folder.  Prints the stage times (solve = simmesh + stress + crack growth of every
variant, bake = the GPU bakes, write = atlases + contact sheet + JSON) and the verdict.

Usage::

    python benchmarks/bench_library.py [-n 16] [--res 1024] [--preset glass] [--keep DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

LIMIT_S = 30.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=16)
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--size", type=float, default=0.5)
    ap.add_argument("--preset", default="glass")
    ap.add_argument("--keep", type=Path, help="Write the timed library here (kept).")
    args = ap.parse_args()

    from crackbake.decals.library import LibraryParams, build_library

    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        build_library(LibraryParams(out=Path(tmp) / "warm", preset=args.preset, n=1, res=64))
        print(f"warm-up (numba + shaders): {time.perf_counter() - t:.2f} s")
        out = args.keep or Path(tmp) / "lib"
        params = LibraryParams(out=out, preset=args.preset, n=args.n, size=args.size, res=args.res)
        t = time.perf_counter()
        doc = build_library(params)
        wall = time.perf_counter() - t
    a = doc["atlas"]
    print(f"{args.n} x {args.res}² {args.preset} -> {a['width']}x{a['height']} atlas")
    for stage, secs in doc["timings_s"].items():
        print(f"  {stage:<6} {secs:7.2f} s")
    verdict = "within" if wall <= LIMIT_S else "OVER"
    print(f"wall {wall:.2f} s ({verdict} the {LIMIT_S:.0f} s floor)")


if __name__ == "__main__":
    main()
