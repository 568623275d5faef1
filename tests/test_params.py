"""crackbake.params: every default in one place, and the command's help built from it."""

from __future__ import annotations

import os
import subprocess
import sys

import crackbake.params as P

# Changes defaults in crackbake.params, then prints the help of the three commands: each value
# the help states must follow (nothing typed twice).
_HELP = """
import sys
import crackbake.params as P
P.SOLVER_DEFAULTS.update(hoop=9.25, toughness=0.55, max_cracks=777)
P.RES_DEFAULT, P.SIM_FACES_DEFAULT, P.SEED_DEFAULT = 1536, 54321, 11
P.PADDING_RES_PER_TEXEL, P.PADDING_MIN = 512, 3
P.DEFAULT_MAX_DISTANCE_FRACTION, P.CRACK_WIDTH_REL_DEFAULT, P.SPACING_DEFAULT = 0.07, 0.004, 0.2
P.TILE_DEFAULTS.update(impacts=5, sim_faces=12345, size=3.5)
P.DECALS_DEFAULTS.update(n=21, size=0.75)
from crackbake.cli import main
for args in (["--help"], ["tile", "--help"], ["decals", "--help"]):
    try:
        main(args, prog_name="crackbake")
    except SystemExit:
        pass
"""


def test_help_states_the_params_defaults():
    r = subprocess.run([sys.executable, "-c", _HELP], capture_output=True, text=True,
                       timeout=120, env={**os.environ, "COLUMNS": "200"})
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())  # click wraps lines
    for shown in ("[9.25]", "[0.55]", "[777]", "[default: 1536]", "[54321]",
                  "[about res/512, at least 3]", "[7% of the bounding-box diagonal]",
                  "[0.4% of diagonal]", "[0.2; crackle 0.025]",
                  "Random seed. [default: 11]",
                  "(glass) [5]", "in faces [12345]", "mesh units. [default: 3.5]",
                  "Number of variants. [default: 21]", "Decal width/height, mesh units. "
                  "[default: 0.75]"):
        assert shown in text, shown


def test_defaults_used_by_the_stages_live_in_params():
    """The bake and the unwrap resolve a left-out --max-distance and --padding from here."""
    from crackbake.bake import raster
    from crackbake.bake.uv import default_padding

    assert raster.DEFAULT_MAX_DISTANCE_FRACTION is P.DEFAULT_MAX_DISTANCE_FRACTION
    assert default_padding is P.default_padding
    assert [P.default_padding(r) for r in (64, 512, 1024, 4096)] == [2, 2, 4, 16]


def test_spacing_default_is_the_solvers_shadow_radius():
    from crackbake.simulate.solver.iben.constants import SHADOW_REL

    assert P.SPACING_DEFAULT == SHADOW_REL


def test_public_names_import_from_the_package():
    for name in ("RunParams", "Impact", "parse_impact", "parse_direction", "load_preset",
                 "preset_names", "RANGES", "SOLVER_DEFAULTS", "check_range", "FORMATS"):
        assert getattr(P, name) is not None
    assert set(P.__all__) <= set(dir(P))
