"""Scale benchmark: ``crackbake MESH --preset crackle --res R`` on spot subdivided to 1M+ faces.

Spot (5,856 faces) is split by loop-free midpoint subdivision, its UVs interpolated at the edge
midpoints, ``n`` times (4**n times the faces: n=3 -> 375k, n=4 -> 1.5M) and written as OBJ into
a cache folder.  Each row is one fresh ``crackbake`` process (the real command, as a user runs
it); a sampling thread in a small wrapper records the peak RSS of each stage from the pipeline's
log lines, and the stage times come from the run's ``manifest.json``.

Usage::

    python benchmarks/bench_scale.py [--levels 2 3 4] [--res 2048 4096] [--preset crackle]
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
CACHE = Path(tempfile.gettempdir()) / "crackbake_bench_scale"
STAGES = ("load", "simmesh", "stress", "solve", "unwrap", "bake", "write", "total")

# The pipeline's log messages that open each stage (crackbake.pipeline's logger.info calls).
_STAGE_OF_MESSAGE = (
    ("loading ", "load"),
    ("building the simulation mesh", "simmesh"),
    ("stress field on", "stress"),
    ("growing cracks", "solve"),
    ("preparing UVs", "unwrap"),
    ("baking ", "bake"),
    ("writing ", "write"),
)


def spot_path() -> Path:
    shared = ROOT.parent / "shared" / "meshes" / "spot.obj"
    return shared if shared.exists() else ROOT / "examples" / "spot.obj"


def subdivided_spot(levels: int, folder: Path = CACHE) -> Path:
    """Spot subdivided ``levels`` times, written (once) as an OBJ with UVs; its path."""
    path = folder / f"spot_sub{levels}.obj"
    if path.exists():
        return path
    import trimesh

    from crackbake.io.mesh import load_mesh

    mesh = load_mesh(spot_path())
    v, f, t = mesh.vertices, mesh.faces, mesh.uv
    for _ in range(levels):  # each triangle into four at its edge midpoints, UVs interpolated
        v, f, attr = trimesh.remesh.subdivide(v, f, vertex_attributes={"uv": t})
        t = attr["uv"]
    folder.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as fh:
        np.savetxt(fh, v, fmt="v %.7f %.7f %.7f")
        np.savetxt(fh, t, fmt="vt %.7f %.7f")
        np.savetxt(fh, np.repeat(f + 1, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
    os.replace(tmp, path)
    return path


def stage_rss(argv: list[str]) -> dict:
    """Run the crackbake CLI in this process; peak RSS per stage (GiB) from a sampling thread."""
    import logging
    import threading
    import time

    current = {"stage": "start"}
    peak: dict[str, float] = {}
    done = threading.Event()

    def rss() -> float:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**30

    def sample() -> None:
        while not done.is_set():
            s = current["stage"]
            peak[s] = max(peak.get(s, 0.0), rss())
            time.sleep(0.02)

    class StageHandler(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            msg = record.getMessage()
            for prefix, stage in _STAGE_OF_MESSAGE:
                if msg.startswith(prefix):
                    s = current["stage"]
                    peak[s] = max(peak.get(s, 0.0), rss())
                    current["stage"] = stage

    log = logging.getLogger("crackbake.pipeline")
    log.addHandler(StageHandler())
    log.setLevel(logging.INFO)
    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    from crackbake.cli import main

    code = 0
    try:
        main(argv, standalone_mode=False)
    except SystemExit as exc:  # pragma: no cover - click exits on errors
        code = int(exc.code or 0)
    done.set()
    thread.join()
    with open("/proc/self/status") as fh:
        hwm = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM")) / 2**20
    return {"rss": peak, "hwm": hwm, "code": code}


def run_row(levels: int, res: int, preset: str) -> dict:
    mesh = subdivided_spot(levels)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        argv = [str(mesh), "--preset", preset, "--res", str(res), "-o", str(out), "--quiet"]
        r = subprocess.run(
            [sys.executable, __file__, "--child-json", json.dumps(argv)],
            capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"},
        )  # fmt: skip
        if r.returncode != 0:
            tail = (r.stderr.strip().splitlines() or ["?"])[-1]
            return {"levels": levels, "res": res, "error": f"exit {r.returncode}: {tail}"}
        child = json.loads(r.stdout.strip().splitlines()[-1])
        manifest = json.loads((out / "manifest.json").read_text())
    return {
        "levels": levels,
        "faces": manifest["mesh"]["faces"],
        "res": res,
        "timings": manifest["timings_s"],
        "rss": child["rss"],
        "hwm": child["hwm"],
        "cracks": manifest["cracks"],
    }


def format_row(row: dict) -> str:
    if "error" in row:
        return f"| sub{row['levels']} | {row['res']} | {row['error']} |"
    t, rss = row["timings"], row["rss"]
    times = " | ".join(f"{t[s]:.1f}" if s in t else "-" for s in STAGES)
    mem = " | ".join(f"{rss[s]:.2f}" if s in rss else "-" for s in STAGES[:-1])
    return f"| {row['faces']:,} | {row['res']} | {times} | {mem} | {row['hwm']:.2f} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4])
    ap.add_argument("--res", type=int, nargs="+", default=[2048, 4096])
    ap.add_argument("--preset", default="crackle")
    ap.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    ap.add_argument("--child-json", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child_json:
        print(json.dumps(stage_rss(json.loads(args.child_json))))
        return
    head = ["faces", "res"] + [f"{s} s" for s in STAGES] + [f"{s} GiB" for s in STAGES[:-1]]
    print("| " + " | ".join(head + ["peak GiB"]) + " |")
    print("|" + "---|" * (len(head) + 1))
    rows = []
    for levels in args.levels:
        for res in args.res:
            row = run_row(levels, res, args.preset)
            rows.append(row)
            print(format_row(row), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
