"""Growth connectivity of ``crack.time``: the share of the revealed length connected to the
impact (glass) or to the largest revealed piece (no impact), per case.

Run from the repo root: ``python benchmarks/bench_growth.py [case ...]``.  Cases: the plate
(3 seeds, glass preset, impact at the centre), spot's default example, thesis on the plate, and
mud / crackle on the plate and spot.  Prints one line per case (``metrics.growth`` summary).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from crackbake.io.mesh import load_mesh
from crackbake.metrics.growth import growth_curve
from crackbake.network import from_solver
from crackbake.params import RunParams, parse_impact
from crackbake.pipeline import solve
from crackbake.precompile import plate_obj
from crackbake.simulate.timing import grow_from_impacts

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"

CASES = {
    **{f"plate_glass_s{s}": ("plate", dict(preset="glass", seed=s), "0.5,0.5,0")
       for s in (0, 1, 2)},
    "spot_glass": ("spot", dict(preset="glass"), "0.334,0.044,0.287"),
    "plate_thesis": ("plate", dict(preset="glass", method="thesis"), "0.5,0.5,0"),
    "spot_thesis": ("spot", dict(preset="glass", method="thesis"), "0.334,0.044,0.287"),
    "plate_mud": ("plate", dict(preset="mud"), None),
    "spot_crackle": ("spot", dict(preset="crackle"), None),
}


def measure(name: str, tmp: Path) -> dict:
    where, kw, impact = CASES[name]
    path = SPOT if where == "spot" else plate_obj(tmp / "plate.obj", 16, uv_margin=0.0)
    run = RunParams(mesh=path, impacts=(parse_impact(impact),) if impact else (), **kw)
    run = run.validate()
    run, relative = run.resolved()
    t = time.perf_counter()
    mesh = load_mesh(path)
    network, _stats, solved = solve(mesh, run, relative, {})
    seconds = time.perf_counter() - t
    # The solver's own time, before crackbake.simulate.timing re-timed it.
    raw = from_solver(solved.result.cracks, mesh, impacts=solved.field.impacts)
    t = time.perf_counter()
    grow_from_impacts(raw)
    retime = time.perf_counter() - t
    before, after = growth_curve(raw).summary(), growth_curve(network).summary()
    return {"case": name, "cracks": len(network.cracks), "solve_s": round(seconds, 1),
            "retime_s": round(retime, 3), "mode": after["mode"],
            "before": {k: before[k] for k in ("weighted_mean", "min_t>=0.1")},
            "after": {k: after[k] for k in ("weighted_mean", "min_t>=0.1")},
            "share_at_after": after["share_at"]}


def main(names: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name in names or list(CASES):
            print(json.dumps(measure(name, Path(tmp))), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
