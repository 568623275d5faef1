"""``--min-px`` end to end: a crack 0.2 texel wide, baked by the command from a sidecar.

The drawn half width is max(physical, min_px / 2 texels): at --min-px 1 the crack is drawn one
texel wide, so the texel its axis passes through is fully covered (255 in the 8-bit mask) and the
one-texel anti-aliasing ramp covers exactly one texel across in total, while ``crack.width`` in
the EXR keeps the physical width; at --min-px 0 the mask holds the covered fraction, 0.2.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from crackbake.cli import main
from crackbake.exchange.exr import read_exr
from crackbake.io.mesh import load_mesh
from crackbake.io.sidecar import write_sidecar
from crackbake.network import Crack, CrackNetwork, mesh_info
from crackbake.precompile import plate_obj

RES = 256
ROW = RES // 2  # the crack runs through this row's texel centres


def _bake(tmp_path: Path, min_px: str) -> Path:
    mesh = plate_obj(tmp_path / "plate.obj", 1, uv_margin=0.0)
    w = 0.2 / RES
    y = 1.0 - (ROW + 0.5) / RES
    crack = Crack(id=0, points=np.array([[0.55, y, 0.0], [0.95, y, 0.0]]), faces=np.array([0, 0]),
                  time=np.array([0.0, 1.0]), width=np.array([w, w]), depth=np.array([w, w]))
    side = tmp_path / "cracks.json"
    write_sidecar(CrackNetwork(cracks=[crack], mesh=mesh_info(load_mesh(mesh))), side)
    out = tmp_path / f"out{min_px}"
    args = [str(mesh), "--cracks", str(side), "--res", str(RES), "--formats", "exr,png",
            "--min-px", min_px, "-o", str(out), "-q"]
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize("min_px, peak", [("1", 255), ("0", round(0.2 * 255))])
def test_min_px_thin_crack_reads_in_the_8bit_mask(tmp_path, min_px, peak):
    out = _bake(tmp_path, min_px)
    mask = np.asarray(Image.open(out / "plate_mask.png")).astype(np.float64)
    mask = mask if mask.ndim == 2 else mask[..., 0]
    col = mask[:, int(0.75 * RES)]
    assert col.max() == pytest.approx(peak, abs=1)
    assert col.argmax() == ROW
    # Across the crack: one texel at --min-px 1, the physical 0.2 texel at --min-px 0.
    assert col.sum() / 255 == pytest.approx(float(min_px) or 0.2, abs=0.01)
    channels, _ = read_exr(out / "plate_cracks.exr")
    width = np.asarray(channels["crack.width.V"], np.float64)
    assert width[ROW, int(0.75 * RES)] == pytest.approx(0.2 / RES, rel=2e-3)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["params"]["min_px"] == float(min_px)


def test_min_px_negative_is_refused(tmp_path):
    mesh = plate_obj(tmp_path / "plate.obj", 1)
    result = CliRunner().invoke(main, [str(mesh), "--min-px", "-1", "-o", str(tmp_path / "o")])
    assert result.exit_code != 0
    assert "--min-px -1 is out of range" in result.output
