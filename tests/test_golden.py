"""Golden runs: the crack networks and baked masks of fixed inputs and seeds, recorded once.

A restructuring must not change behaviour; these runs are its proof.  Each case runs the
``crackbake`` command in-process (the most stable public surface) and compares the
``cracks.json`` polylines (every point, face, time, width and depth, as written) and the
decoded 8-bit mask PNG with the values in ``tests/golden/golden.json``.

Re-record only on a deliberate change of behaviour: ``CRACKBAKE_RECORD_GOLDEN=1 pytest
tests/test_golden.py`` (and say why in the commit).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from crackbake.cli import main
from crackbake.precompile import plate_obj

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden" / "golden.json"
RECORD = os.environ.get("CRACKBAKE_RECORD_GOLDEN") == "1"


def _plate_obj(path: Path, n: int = 4) -> Path:
    """A 1 x 1 plate of n x n quads (2 n^2 triangles) with UVs equal to (x, y)."""
    return plate_obj(path, n, uv_margin=0.0)


CASES = {
    "plate_glass": ["--preset", "glass", "--impact", "0.5,0.5,0:0.25", "--sim-faces", "40000",
                    "--seed", "3"],
    "plate_shrink": ["--preset", "mud", "--sim-faces", "30000", "--seed", "5"],
    "plate_thesis": ["--preset", "glass", "--method", "thesis", "--impact", "0.4,0.55,0:0.3",
                     "--sim-faces", "30000", "--seed", "2"],
    "spot_glass": ["--preset", "glass", "--impact", "0.334,0.044,0.287", "--sim-faces",
                   "100000", "--seed", "0"],
}


def _digest(cracks: list[dict]) -> dict:
    """Exact fingerprint of the polylines plus readable summary figures for a failing diff."""
    blob = json.dumps(
        [[c["points"], c["faces"], c["time"], c["width"], c["depth"]] for c in cracks],
        separators=(",", ":"),
    ).encode()
    length = 0.0
    for c in cracks:
        p = np.asarray(c["points"], float)
        length += float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
    return {
        "cracks": len(cracks),
        "points": sum(len(c["points"]) for c in cracks),
        "length": round(length, 9),
        "sha256": hashlib.sha256(blob).hexdigest(),
    }


def _run(case: str, tmp_path: Path) -> dict:
    mesh = ROOT / "examples" / "spot.obj" if case.startswith("spot") else _plate_obj(
        tmp_path / "plate.obj")
    out = tmp_path / "out"
    args = [str(mesh), *CASES[case], "--res", "512", "--formats", "png", "-o", str(out), "-q"]
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    side = json.loads((out / "cracks.json").read_text())
    mask = np.asarray(Image.open(out / f"{mesh.stem}_mask.png"))
    record = _digest(side["cracks"])
    record["mask_sha256"] = hashlib.sha256(
        np.ascontiguousarray(mask).tobytes() + str(mask.shape).encode()).hexdigest()
    record["mask_mean"] = round(float(mask.mean()), 6)
    return record


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_golden_run(case, tmp_path):
    got = _run(case, tmp_path)
    golden = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    if RECORD:
        golden[case] = got
        GOLDEN.write_text(json.dumps(golden, indent=2, sort_keys=True) + "\n")
        pytest.skip("recorded")
    assert case in golden, f"no golden record for {case}: record with CRACKBAKE_RECORD_GOLDEN=1"
    assert got == golden[case]
