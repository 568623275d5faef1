"""``--spacing``: each crack's stress-shadow radius, the knob that sets how fine a network gets."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from crackbake.cli import main
from crackbake.io.mesh import load_mesh
from crackbake.metrics.cells import network_stats
from crackbake.params import RunParams
from crackbake.precompile import plate_obj
from crackbake.simulate.setup import with_spacing


def _run(tmp_path: Path, name: str, *extra: str) -> dict:
    mesh = plate_obj(tmp_path / "plate.obj", 8, uv_margin=0.0)
    out = tmp_path / name
    res = CliRunner().invoke(main, [str(mesh), "--preset", "crackle", "--sim-faces", "20000",
                                    "--res", "256", "--formats", "png", "-q", "-o", str(out),
                                    *extra])
    assert res.exit_code == 0, res.output
    return json.loads((out / "cracks.json").read_text())


def _cells(doc: dict, tmp_path: Path) -> tuple[int, float]:
    cracks = doc["cracks"]
    plate = load_mesh(tmp_path / "plate.obj")
    st = network_stats([np.asarray(c["points"]) for c in cracks],
                       [np.asarray(c["width"]) for c in cracks], plate.vertices, plate.faces,
                       [np.asarray(c["faces"]) for c in cracks])
    return st.cells, st.mean_cell_area


def test_smaller_spacing_gives_smaller_cells(tmp_path):
    wide = _cells(_run(tmp_path, "wide", "--spacing", "0.1"), tmp_path)
    fine = _cells(_run(tmp_path, "fine", "--spacing", "0.03"), tmp_path)
    # The shadow sets how close parallel cracks may run: a third of the radius gives several
    # times more cells of a fraction of the area (the count of cells is not pinned).
    assert fine[0] > 2 * wide[0]
    assert fine[1] < 0.5 * wide[1]


def test_spacing_is_recorded_and_the_preset_sets_it(tmp_path):
    run = RunParams(mesh=tmp_path / "m.obj", preset="crackle")
    assert run.resolved()[0].spacing == pytest.approx(0.025)
    assert RunParams(mesh=tmp_path / "m.obj", preset="mud").resolved()[0].spacing is None
    doc = _run(tmp_path, "rec", "--spacing", "0.05")
    assert doc["params"]["spacing"] == pytest.approx(0.05)


def test_spacing_caps_an_impact_shadow_and_never_widens_it():
    run = SimpleNamespace(spacing=0.1)
    assert with_spacing(SimpleNamespace(shadow_radius=None), run, 2.0).shadow_radius == 0.2
    assert with_spacing(SimpleNamespace(shadow_radius=0.05), run, 2.0).shadow_radius == 0.05
    assert with_spacing(SimpleNamespace(shadow_radius=0.5), run, 2.0).shadow_radius == 0.2
    unset = SimpleNamespace(shadow_radius=0.5)
    assert with_spacing(unset, SimpleNamespace(spacing=None), 2.0).shadow_radius == 0.5


@pytest.mark.parametrize("value", ["0", "-0.1", "1.5", "nan"])
def test_bad_spacing_is_one_line_error(tmp_path, value):
    mesh = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    out = tmp_path / "out"
    res = CliRunner().invoke(main, [str(mesh), "--spacing", value, "-o", str(out)])
    assert res.exit_code == 2
    lines = [ln for ln in res.output.strip().splitlines() if ln]
    assert len(lines) == 1 and "--spacing" in lines[0], res.output
    assert not out.exists()
