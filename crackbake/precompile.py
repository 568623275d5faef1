"""Compile the numba kernels into their on-disk cache before the first real run.

numba compiles each kernel the first time it is called and caches the machine code on disk
(``cache=True``; next to the sources, or under ``NUMBA_CACHE_DIR``).  Without this step the
first run after an install spends about 30 s compiling on a 2-core machine.  ``make setup``
calls ``python -m crackbake.precompile``; run it yourself after ``pip install`` (in a Docker
image build, for example) so the first real run starts warm.

The kernels are compiled by real runs of the command on a small generated plate, one per
solver path (the I&O solver with an impact, with shrinkage, and the thesis solver) and one per
output path (a projected decal on a textured plate for Blender, a tile), each in its own
process, in two lanes that compile side by side.  The package's Python bytecode is brought up
to date first (:func:`compile_bytecode`).
Typing is what costs (not LLVM), and every kernel signature a real run uses is the one these
runs use, so a later run on any mesh loads them from the cache.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

#: One small run per solver path and per output path a first run would otherwise compile for:
#: name -> the command line after ``crackbake`` (``{plate}``: the generated plate, ``{textured}``:
#: the same with a base-colour texture; ``--res 256 -q -o <scratch>/<name>`` is added).
CASES: dict[str, list[str]] = {
    "iben": ["{plate}", "--preset", "glass", "--impact", "0.5,0.5,0:0.3", "--sim-faces", "3000"],
    "thesis": ["{plate}", "--preset", "mud", "--method", "thesis", "--sim-faces", "3000"],
    "shrinkage": ["{plate}", "--preset", "mud", "--sim-faces", "3000"],
    # the projector bake (crackbake.bake.cells), the asset's own texture under the cracks and
    # Blender's 16-bit normal map; thesis, so that it waits on nothing the I&O lane compiles
    "decal": ["{textured}", "--preset", "glass", "--method", "thesis", "--impact",
              "0.5,0.5,0:0.3", "--sim-faces", "3000", "--decal", "0.3", "--decal-res", "256",
              "--target", "blender"],
    "tile": ["tile", "--preset", "mud"],
}

#: Cases run one after another in one lane; lanes run side by side.  The two I&O cases share
#: most kernels, so the second waits for the first and finds them cached.  Measured in a fresh
#: clone's ``make test`` (2 cores): iben 73 s, shrinkage 17 s, thesis 49 s, decal 23 s, tile
#: 21 s, and the warm-ups of kernels the small plates never reach: ``halving`` (above 2048²,
#: about 6 s), ``collapse`` (the proxy's decimation above 200k faces, about 15 s) and
#: ``preview`` (the up axis of a mesh with volume, about 2 s), ``stress`` (the proxy's stress
#: bake), ``grid`` (the crack bake's face pass above 100k faces) and ``objload`` (the OBJ
#: reader's kernels, for files of 16 MiB or more) and ``stats`` (the statistics of every EXR
#: plane type: the runs write half and float planes only), a few seconds each; so the lanes
#: take about 100 s and 110 s.
LANES: tuple[tuple[str, ...], ...] = (("iben", "shrinkage", "halving", "preview", "stress",
                                       "objload"),
                                      ("thesis", "decal", "tile", "collapse", "grid", "stats"))

#: The warm-ups: kernels no small run reaches, compiled by calling their module's ``warm``.
WARM_UPS = {"halving": "crackbake.exchange.halving",
            "collapse": "crackbake.simulate.simmesh.collapse",
            "preview": "crackbake.bake.preview",
            "stress": "crackbake.bake.stress",
            "grid": "crackbake.bake.grid",
            "objload": "crackbake.io.obj_kernels",
            "stats": "crackbake.exchange.stats_kernels"}


def textured_plate_obj(path: Path) -> Path:
    """:func:`plate_obj` with a material whose base colour is a small PNG beside it."""
    import numpy as np
    from PIL import Image

    plate_obj(path)
    path.write_text(f"mtllib {path.stem}.mtl\nusemtl base\n" + path.read_text())
    path.with_suffix(".mtl").write_text(f"newmtl base\nmap_Kd {path.stem}.png\n")
    ramp = np.linspace(60, 200, 64, dtype=np.uint8)
    Image.fromarray(np.dstack([np.tile(ramp, (64, 1))] * 3)).save(path.with_suffix(".png"))
    return path


def plate_obj(path: Path, n: int = 12, uv_margin: float = 0.1) -> Path:
    """Write a flat unit square of ``2 n^2`` triangles as OBJ; return ``path``.

    UVs are ``margin + (1 - 2 margin) * (x, y)``: the default margin leaves empty texels around
    the island, so the bake's gutter fill (the dilation kernels) runs too.
    """
    m = float(uv_margin)
    lines = []
    for j in range(n + 1):
        for i in range(n + 1):
            lines.append(f"v {i / n:.6f} {j / n:.6f} 0")
            lines.append(f"vt {m + (1 - 2 * m) * i / n:.6f} {m + (1 - 2 * m) * j / n:.6f}")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            b, c, d = a + 1, a + n + 2, a + n + 1
            lines.append(f"f {a}/{a} {b}/{b} {c}/{c}")
            lines.append(f"f {a}/{a} {c}/{c} {d}/{d}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _run_case(name: str, folder: Path) -> float:
    if name in WARM_UPS:
        cmd = [sys.executable, "-c", f"from {WARM_UPS[name]} import warm; warm()"]
    else:
        names = {"plate": folder / "plate.obj", "textured": folder / "textured.obj"}
        args = [a.format(**names) for a in CASES[name]]
        cmd = [sys.executable, "-m", "crackbake", *args, "--res", "256", "-q", "-o",
               str(folder / name)]
    # A cache folder of the case's own, empty: every case runs as the first run on its asset
    # (an unwrap, tangent frames or a gutter plan read from the user's cache would leave their
    # kernels uncompiled), and the user's cache is left alone.
    env = dict(os.environ, CRACKBAKE_CACHE_DIR=str(folder / f"cache-{name}"))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"precompile run '{name}' failed: {proc.stderr.strip()[-500:]}")
    return time.perf_counter() - t0


def compile_bytecode(package: Path | None = None) -> bool:
    """Byte-compile the package's modules whose ``.pyc`` is missing or older than the source;
    True when every module compiled.

    Where ``PYTHONDONTWRITEBYTECODE`` is set (many containers and CI images) Python never writes
    a ``.pyc`` itself, so a module edited after ``make setup`` (which compiles every module) was
    compiled from source by every process: 36 stale modules cost 0.13-0.2 s of each run's
    start-up in a development checkout.  ``package``: another crackbake source folder (a
    benchmark's other tree); default this one.
    """
    import compileall

    folder = Path(__file__).resolve().parent if package is None else Path(package)
    return bool(compileall.compile_dir(str(folder), quiet=2, workers=0))


def precompile(jobs: int | None = None) -> dict[str, float]:
    """Run the :data:`LANES` of :data:`CASES` in parallel processes; wall seconds per case.

    Parameters
    ----------
    jobs : int, optional
        Processes at once (default: the CPU count, at most ``len(LANES)``).
    """
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(LANES)))
    with tempfile.TemporaryDirectory(prefix="crackbake-precompile-") as tmp:
        folder = Path(tmp)
        plate_obj(folder / "plate.obj")
        textured_plate_obj(folder / "textured.obj")
        with ThreadPoolExecutor(jobs) as pool:
            futures = [pool.submit(_run_lane, lane, folder) for lane in LANES]
            times: dict[str, float] = {}
            for f in futures:
                times.update(f.result())
        return times


def _run_lane(lane: tuple[str, ...], folder: Path) -> dict[str, float]:
    return {name: _run_case(name, folder) for name in lane}


def main() -> None:
    ap = argparse.ArgumentParser(
        prog="python -m crackbake.precompile", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--jobs", type=int, default=None, help="processes at once (default: cores)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    compile_bytecode()
    try:
        times = precompile(args.jobs)
    except RuntimeError as exc:
        print(f"crackbake: error: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
    print(f"crackbake: kernels compiled in {time.perf_counter() - t0:.1f} s ({parts})")


if __name__ == "__main__":
    main()
