"""Resolution independence on a real asset: spot through the real stages, two sim sizes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crackbake.mesh import load_mesh
from crackbake.params import Impact, RunParams
from crackbake.pipeline import solver_params, stress_sources
from crackbake.simmesh import build_simmesh
from crackbake.solver.iben import RES_TOLERANCE, solve_iben
from crackbake.stress import stress_field

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
IMPACT = (0.334, 0.044, 0.287)  # on spot's flank, as in benchmarks/bench_pipeline.py


def _run(preset: str, faces: int) -> tuple[int, float]:
    mesh = load_mesh(SPOT)
    impacts = (Impact(IMPACT),) if preset == "glass" else ()
    params, relative = RunParams(
        mesh=SPOT, preset=preset, impacts=impacts, sim_faces=faces
    ).validate().resolved()
    sim = build_simmesh(mesh, detail=params.detail, target_faces=params.sim_faces,
                        seed=params.seed)
    field = stress_field(sim, mesh, stress_sources(params, mesh, relative), seed=params.seed)
    res = solve_iben(sim, field, solver_params(params, mesh, relative))
    length = sum(float(np.linalg.norm(np.diff(c.points, axis=0), axis=1).sum())
                 for c in res.cracks)
    return len(res.cracks), length


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("preset", ["crackle", "mud", "glass"])
def test_spot_resolution_independence(preset):
    """Doubling the sim faces keeps crack count and total length within RES_TOLERANCE.

    glass: an impact (ImpactSource at IMPACT, the preset's radius 0.15 x the bounding-box
    diagonal) at 100k vs 200k sim faces, a localized field (the near-crack rule of
    crackbake.solver.iben applies).
    """
    sizes = (100_000, 200_000) if preset == "glass" else (50_000, 100_000)
    n0, l0 = _run(preset, sizes[0])
    n1, l1 = _run(preset, sizes[1])
    print(preset, n0, n1, l0, l1)
    assert abs(l1 / l0 - 1) <= RES_TOLERANCE
    assert abs(n1 / n0 - 1) <= RES_TOLERANCE
