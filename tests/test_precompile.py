"""crackbake.precompile: the set-up step that fills numba's cache before the first run."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from crackbake.io.mesh import load_mesh
from crackbake.precompile import plate_obj

REPO = Path(__file__).resolve().parent.parent
# `make test` compiles the kernels once, with `python -m crackbake.precompile` into an empty
# NUMBA_CACHE_DIR, and names a copy taken before any test ran: that copy is what a fresh
# precompile writes, so the test checks it instead of compiling everything a second time.
PRECOMPILED = os.environ.get("CRACKBAKE_PRECOMPILED_CACHE")

# Counts the kernels numba compiles (not loads from the cache) during one CLI run.
_PROBE = """
import json, sys
from numba.core import event
compiled = []
class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Count())
from crackbake.cli import main
try:
    main(sys.argv[1:], prog_name="crackbake")
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "compiled": sorted(set(compiled))}))
"""


def test_plate_obj_is_a_flat_square_with_inset_uvs(tmp_path):
    path = tmp_path / "plate.obj"
    plate_obj(path, n=4)
    mesh = load_mesh(path)
    assert len(mesh.faces) == 32
    assert np.allclose(mesh.vertices[:, 2], 0.0)
    assert mesh.uv is not None
    # A margin around the island: the bake has empty texels, so the dilation kernels run.
    assert mesh.uv.min() == pytest.approx(0.1) and mesh.uv.max() == pytest.approx(0.9)


@pytest.mark.slow
def test_first_run_after_precompile_compiles_nothing(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    if PRECOMPILED:
        assert any(Path(PRECOMPILED).rglob("*.nbi")), f"no kernels in {PRECOMPILED}"
        shutil.copytree(PRECOMPILED, tmp_path / "cache")  # the runs must not add to the original
    else:
        pre = subprocess.run([sys.executable, "-m", "crackbake.precompile"], env=env,
                             capture_output=True, text=True, timeout=600)
        assert pre.returncode == 0, pre.stderr
        assert "kernels compiled" in pre.stdout
    # glass: an impact and a decal; crackle on thesis: the other solver; glaze: growth
    # (--shrink-rate).
    for options in (["--preset", "glass", "--impact", "0.334,0.044,0.287", "--decal", "0.4",
                     "--decal-res", "512"],
                    ["--preset", "crackle", "--method", "thesis"],
                    ["--preset", "glaze"]):
        out = tmp_path / f"out_{options[1]}"
        run = subprocess.run(
            [sys.executable, "-c", _PROBE, str(REPO / "examples" / "spot.obj"), *options,
             "--res", "512", "-q", "-o", str(out)],
            env=env, capture_output=True, text=True, timeout=300,
        )
        result = json.loads(run.stdout.strip().splitlines()[-1])
        assert result["code"] in (0, None), run.stderr
        assert result["compiled"] == [], f"compiled at first run: {result['compiled']}"


def test_each_case_runs_with_an_empty_cache_of_its_own(tmp_path, monkeypatch):
    """A precompile case never reads the user's cache (an unwrap, tangent frames or a gutter
    plan found there would leave their kernels uncompiled) nor writes it."""
    from crackbake import precompile as pc

    user = tmp_path / "user-cache"
    monkeypatch.setenv("CRACKBAKE_CACHE_DIR", str(user))
    monkeypatch.setitem(pc.CASES, "probe", ["{plate}", "--preset", "mud", "--method", "thesis",
                                            "--sim-faces", "300"])  # fmt: skip
    plate_obj(tmp_path / "plate.obj", n=4)
    pc._run_case("probe", tmp_path)
    assert not user.exists()
    own = {p.name.split("-")[0] for p in (tmp_path / "cache-probe").iterdir()}
    assert own == {"gutter", "tangents", "uvcheck", "up", "simmesh"}
