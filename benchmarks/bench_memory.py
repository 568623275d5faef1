"""Memory benchmark: peak RSS and address space of real runs against faces, sim faces and
resolutions, and how well :mod:`crackbake.memory`'s model predicts them.

Each row is one fresh ``crackbake`` process (the real command, run in a small wrapper that
reads ``VmHWM``, the peak resident set, and ``VmPeak``, the peak address space, from
``/proc/self/status`` as it exits).  The series vary one size at a time from a small baseline:

* ``res``: spot (5,856 faces) at ``--res`` 1024..4096 without the stress maps;
* ``tile``: spot at ``--res`` 2048, 4096 and ``--stress-res 4096`` with a 1024 tile (the GL
  share stops growing at the tile; ``RunParams.tile``, no command-line option);
* ``stress``: spot at ``--res 256`` with ``--stress-res`` 1024..4096;
* ``sim``: spot at ``--res 256`` with ``--sim-faces`` 100k..1M (no stress maps);
* ``faces``: flat plates of 50k..800k faces (UVs kept) at ``--res 256``.

The table prints each measurement beside :func:`crackbake.memory.estimate_peak`'s estimate, and
``--fit`` prints the least-squares coefficients the model's constants came from.  Runs are
niced and one at a time (the machine is shared); each takes 5-60 s.

Usage::

    python benchmarks/bench_memory.py [--series res stress sim faces] [--fit] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
SPOT_IMPACT = ["--preset", "glass", "--impact", "0.334,0.044,0.287"]
NO_STRESS = ["--formats", "exr,png,glb,preview"]

# The wrapper: run the CLI in this process, then report the kernel's high-water marks.
_CHILD = """
import dataclasses, json, os, sys
import crackbake.cli.bake as bake
from crackbake.cli import main
if os.environ.get("BENCH_TILE"):  # RunParams.tile has no command-line option
    _params = bake.run_params
    bake.run_params = lambda m, o: dataclasses.replace(_params(m, o),
                                                       tile=int(os.environ["BENCH_TILE"]))
code = 0
try:
    main(sys.argv[2:], standalone_mode=False)
except SystemExit as exc:
    code = exc.code or 0
except Exception as exc:
    code = repr(exc)
status = dict(line.split(":", 1) for line in open("/proc/self/status") if ":" in line)
kib = lambda k: int(status[k].split()[0])
json.dump({"hwm": kib("VmHWM") / 2**20, "vm": kib("VmPeak") / 2**20, "code": code},
          open(sys.argv[1], "w"))
"""

SERIES: dict[str, list[dict]] = {
    "res": [{"mesh": "spot", "faces": 5856, "res": r, "sim": 100_000, "stress": None,
             "args": [*SPOT_IMPACT, *NO_STRESS, "--res", str(r)]} for r in (1024, 2048, 4096)],
    "tile": [{"mesh": "spot", "faces": 5856, "res": r, "sim": 100_000, "stress": None,
              "tile": 1024, "args": [*SPOT_IMPACT, *NO_STRESS, "--res", str(r)]}
             for r in (2048, 4096)]
    + [{"mesh": "spot", "faces": 5856, "res": 256, "sim": 100_000, "stress": 4096, "tile": 1024,
        "args": [*SPOT_IMPACT, "--res", "256", "--stress-res", "4096"]}],
    "stress": [{"mesh": "spot", "faces": 5856, "res": 256, "sim": 100_000, "stress": s,
                "args": [*SPOT_IMPACT, "--res", "256", "--stress-res", str(s)]}
               for s in (1024, 2048, 4096)],
    "sim": [{"mesh": "spot", "faces": 5856, "res": 256, "sim": n, "stress": None,
             "args": [*SPOT_IMPACT, *NO_STRESS, "--res", "256", "--sim-faces", str(n)]}
            for n in (100_000, 300_000, 1_000_000)],
    "faces": [{"mesh": f"plate{n}", "faces": 2 * n * n, "res": 256, "sim": 100_000,
               "stress": None, "n": n,
               "args": ["--preset", "glass", "--impact", "0.5,0.5,0", *NO_STRESS, "--res", "256",
                        "--uv", "keep"]}
              for n in (160, 320, 640)],
}


def _mesh(row: dict, folder: Path) -> Path:
    if row["mesh"] == "spot":
        return SPOT
    from crackbake.precompile import plate_obj

    path = folder / f"{row['mesh']}.obj"
    return path if path.exists() else plate_obj(path, row["n"])


def measure(row: dict, folder: Path) -> dict:
    """One fresh, niced crackbake process; its peak RSS and address space (GiB)."""
    mesh = _mesh(row, folder)
    report = folder / "report.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "CRACKBAKE_CACHE_DIR": str(folder / "cache"),
           "BENCH_TILE": str(row.get("tile", ""))}
    cmd = ["nice", sys.executable, "-c", _CHILD, str(report), str(mesh), "-o",
           str(folder / "out"), "-q", *row["args"]]
    subprocess.run(cmd, env=env, check=True, timeout=1800)
    got = json.loads(report.read_text())
    if got["code"] != 0:
        raise SystemExit(f"run {row['args']} failed: {got['code']}")
    return got


NAMES = ["BASE", "PER_FACE", "PER_SIM_FACE", "PER_TEXEL", "PER_GL_TEXEL", "PER_STRESS_TEXEL"]


def fit(rows: list[dict]) -> np.ndarray:
    """Least-squares coefficients of :data:`NAMES` (bytes) over the measured rows."""
    def terms(r):
        t, s = r.get("tile", 4096), r["stress"] or 0
        return [1.0, r["faces"], r["sim"], r["res"] ** 2, min(r["res"], t) ** 2, s * s]
    a = np.array([terms(r) for r in rows])
    b = np.array([r["hwm"] * 2**30 for r in rows])
    coef, *_ = np.linalg.lstsq(a, b, rcond=None)
    return coef


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--series", nargs="+", default=list(SERIES), choices=list(SERIES))
    ap.add_argument("--fit", action="store_true")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from crackbake.memory import estimate_peak

    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        folder = Path(tmp)
        print("| series | mesh | faces | res | stress res | sim faces | peak RSS GiB | "
              "VmPeak GiB | model GiB | error |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name in args.series:
            for row in SERIES[name]:
                got = measure(row, folder)
                est = estimate_peak(faces=row["faces"], sim_faces=row["sim"], res=row["res"],
                                    stress_res=row["stress"],
                                    tile=row.get("tile", 4096)).rss / 2**30
                row = {**row, **got, "series": name, "model": est}
                rows.append(row)
                print(f"| {name} | {row['mesh']} | {row['faces']:,} | {row['res']} | "
                      f"{row['stress'] or '-'} | {row['sim']:,} | {got['hwm']:.2f} | "
                      f"{got['vm']:.2f} | {est:.2f} | {(est - got['hwm']) / got['hwm']:+.0%} |",
                      flush=True)
    if args.fit:
        for n, c in zip(NAMES, fit(rows), strict=True):
            print(f"{n}: {c:,.1f} bytes")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
