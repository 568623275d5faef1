"""``--frames N``: the growth as a PNG sequence, from a real bake of a hand-made network."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import tiny_network
from PIL import Image
from test_pngenc import COLOUR_CHUNKS, png_chunks

from crackbake.cli import main
from crackbake.errors import CrackbakeError
from crackbake.io.sidecar import write_sidecar
from crackbake.params import RunParams
from crackbake.precompile import plate_obj

ROOT = Path(__file__).resolve().parents[1]
RES = 128


def _box(image: np.ndarray, box: tuple[float, float, float, float]) -> np.ndarray:
    """Texels of the plate region x0..x1, y0..y1 (UV = (x, y); texel (0, 0) is UV (0, 1))."""
    x0, x1, y0, y1 = box
    return image[int((1 - y1) * RES):int((1 - y0) * RES), int(x0 * RES):int(x1 * RES)]


def test_frames_grow_monotonically_to_the_mask(tmp_path):
    mesh = plate_obj(tmp_path / "square.obj", 1, uv_margin=0.0)
    side = tmp_path / "in.json"
    write_sidecar(tiny_network(), side)  # crack a: time 0 -> 0.5 -> 1; crack b: 0.2 -> 0.6
    out = tmp_path / "out"
    args = [str(mesh), "--cracks", str(side), "--frames", "5", "--res", str(RES),
            "--formats", "png", "-o", str(out), "-q"]
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in out.glob("square_growth_*.png"))
    assert names == [f"square_growth_{k:04d}.png" for k in range(5)]
    listed = {f["name"] for f in json.loads((out / "manifest.json").read_text())["files"]}
    assert set(names) <= listed
    frames = [np.asarray(Image.open(out / n)) for n in names]
    mask = np.asarray(Image.open(out / "square_mask.png"))
    assert all(f.dtype == np.uint8 and f.shape == (RES, RES) for f in frames)
    for a, b in zip(frames[:-1], frames[1:], strict=True):
        assert np.all(b >= a)  # a texel revealed stays revealed
        assert np.all((a == 0) | (a == mask))  # shown texels are the mask's own values
    np.testing.assert_array_equal(frames[-1], mask)
    assert np.count_nonzero(frames[0]) < np.count_nonzero(frames[2]) < np.count_nonzero(mask)
    # Frame 2 is t = 0.5.  Crack a's first segment (time <= 0.42 for x <= 0.45) shows whole;
    # its second beyond x = 0.62 (time >= 0.65) and b above y = 0.83 (time >= 0.53) not yet.
    first, late_a, late_b = (0.2, 0.45, 0.05, 0.15), (0.62, 0.85, 0.1, 0.4), (0.05, 0.15, 0.83, 0.9)
    np.testing.assert_array_equal(_box(frames[2], first), _box(mask, first))
    assert np.count_nonzero(_box(mask, first)) > 0
    for box in (late_a, late_b):
        assert np.count_nonzero(_box(frames[2], box)) == 0 < np.count_nonzero(_box(mask, box))
    assert not COLOUR_CHUNKS & set(png_chunks((out / names[0]).read_bytes()))  # data, like the mask


@pytest.mark.parametrize("n", [1, 0, -3])
def test_fewer_than_two_frames_are_refused(n):
    with pytest.raises(CrackbakeError, match=r"^--frames .* out of range; use a number from 2"):
        RunParams(mesh=Path("m.obj"), frames=n).validate()


def test_cli_refuses_one_frame_in_one_line(tmp_path):
    mesh = plate_obj(tmp_path / "square.obj", 1, uv_margin=0.0)
    proc = subprocess.run([sys.executable, "-m", "crackbake", str(mesh), "--frames", "1",
                           "-o", str(tmp_path / "out")], capture_output=True, text=True,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--frames 1" in lines[0], proc.stderr
    assert not (tmp_path / "out").exists()
