"""Resolution independence: the crack pattern must not depend on the simulation edge length.

``RES_TOLERANCE`` (crackbake.simulate.solver.iben) is the documented bound on the change of the
number of cracks started and of the total crack length when the sim edge length halves, from the
default resolution (100k sim faces) upward.  Plates: a glass impact and uniform shrinkage at
about 100k, 400k and 1M faces (2 seeds each, compared by their means: a single run's count
moves by a crack or two either way).  Spot: every surface-wide preset and the glass impact
through the real stages at 100k and 400k faces.  The glass plates also check the concentric
links (tangential share > 0.13 at every size).

Runs of up to 1M faces take minutes, so this is a benchmark (exit 1 when a bound is broken),
not part of ``make test``.  The plate fields come from the tests' factories (tests/conftest.py).

Usage::

    python benchmarks/bench_resolution.py [--only plates|spot]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from conftest import impact_stress, sim_plate, uniform_stress  # noqa: E402

from crackbake.io.mesh import load_mesh  # noqa: E402
from crackbake.params import Impact, RunParams  # noqa: E402
from crackbake.simulate.setup import solver_params, stress_sources  # noqa: E402
from crackbake.simulate.simmesh import build_simmesh  # noqa: E402
from crackbake.simulate.solver import SolverParams  # noqa: E402
from crackbake.simulate.solver.iben import RES_TOLERANCE, solve_iben  # noqa: E402
from crackbake.simulate.stress import stress_field  # noqa: E402

SPOT = ROOT / "examples" / "spot.obj"
IMPACT = (0.334, 0.044, 0.287)  # on spot's flank, as in benchmarks/bench_pipeline.py
PARAMS = {
    "glass": SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6, max_cracks=400,
                          max_steps=200_000),
    "shrink": SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6, max_cracks=3000,
                           max_steps=200_000),
}
CELLS = {"100k": 224, "400k": 447, "1M": 707}  # 2 n^2 faces on an n x n grid
# Jittered unit plates (conftest.sim_plate) under a glass impact (radius 0.25, hoop 1.25) and
# uniform shrinkage.
FIELDS = {"glass": impact_stress, "shrink": uniform_stress}


def _length(res) -> float:
    return sum(float(np.linalg.norm(np.diff(c.points, axis=0), axis=1).sum())
               for c in res.cracks)


def _tangential_share(res, lo: float = 0.35, hi: float = 0.65) -> float:
    """Share of the crack length between ``lo`` and ``hi`` x the impact's reach (pi r / 2 of
    conftest.impact_stress at the plate centre) that runs within 60 degrees of the hoop direction:
    the concentric links.  Inside ``lo`` the cracks are radial; beyond ``hi`` the radial
    stress left between radial cracks is below the toughness, so links cannot form there."""
    reach = np.pi * 0.25 / 2
    total = tangential = 0.0
    for c in res.cracks:
        p = c.points[:, :2]
        mid = 0.5 * (p[1:] + p[:-1]) - 0.5
        d = np.diff(p, axis=0)
        dist = np.linalg.norm(mid, axis=1)
        seg = np.linalg.norm(d, axis=1)
        cos_radial = np.abs((d * mid).sum(1)) / np.maximum(seg * dist, 1e-12)
        sel = (dist > lo * reach) & (dist < hi * reach)
        total += seg[sel].sum()
        tangential += (seg * (cos_radial < 0.5))[sel].sum()
    return tangential / total if total > 0 else 0.0


def plate_runs():
    """(field, size) -> (mean cracks started, mean total length, mean tangential share) over
    seeds 0 and 1."""
    out = {}
    for size, n in CELLS.items():
        sims = [sim_plate(n, seed=seed + 1) for seed in (0, 1)]
        for name in PARAMS:
            runs = [solve_iben(sim, FIELDS[name](sim),
                               dataclasses.replace(PARAMS[name], seed=seed))
                    for seed, sim in enumerate(sims)]
            out[name, size] = (np.mean([r.stats["cracks"] for r in runs]),
                               np.mean([_length(r) for r in runs]),
                               np.mean([_tangential_share(r) for r in runs]))
    return out


def _spot(preset: str, faces: int) -> tuple[int, float]:
    mesh = load_mesh(SPOT)
    impacts = (Impact(IMPACT),) if preset == "glass" else ()
    params, relative = RunParams(
        mesh=SPOT, preset=preset, impacts=impacts, sim_faces=faces
    ).validate().resolved()
    sim = build_simmesh(mesh, detail=params.detail, target_faces=params.sim_faces,
                        seed=params.seed)
    field = stress_field(sim, mesh, stress_sources(params, mesh, relative), seed=params.seed)
    res = solve_iben(sim, field, solver_params(params, mesh, relative))
    return res.stats["cracks"], _length(res)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=["plates", "spot"])
    args = ap.parse_args()
    broken = []

    def check(label: str, a: tuple, b: tuple) -> None:
        (n0, l0), (n1, l1) = a[:2], b[:2]
        dn, dl = n1 / n0 - 1, l1 / l0 - 1
        ok = abs(dn) <= RES_TOLERANCE and abs(dl) <= RES_TOLERANCE
        print(f"| {label} | {n0:.1f} -> {n1:.1f} ({dn:+.0%}) | {l0:.2f} -> {l1:.2f} ({dl:+.0%}) "
              f"| {'ok' if ok else 'BROKEN'} |")
        if not ok:
            broken.append(label)

    print(f"bound: |change| <= {RES_TOLERANCE:.0%} of cracks started and total length\n")
    print("| case | cracks | length | |\n|---|---|---|---|")
    if args.only in (None, "plates"):
        runs = plate_runs()
        for name in PARAMS:
            for a, b in (("100k", "400k"), ("400k", "1M")):
                check(f"plate {name} {a} -> {b}", runs[name, a], runs[name, b])
        for size in CELLS:
            share = runs["glass", size][2]
            print(f"| plate glass {size}: tangential share {share:.3f} (> 0.13) | | | "
                  f"{'ok' if share > 0.13 else 'BROKEN'} |")
            if share <= 0.13:
                broken.append(f"tangential share {size}")
    if args.only in (None, "spot"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for preset in ("crackle", "mud", "glass"):
                # mud starts as many cracks as its budget allows at both sizes; its length
                # still has to agree.
                check(f"spot {preset} 100k -> 400k", _spot(preset, 100_000),
                      _spot(preset, 400_000))
    if broken:
        print("\nbroken: " + ", ".join(broken))
    return 1 if broken else 0


if __name__ == "__main__":
    raise SystemExit(main())
