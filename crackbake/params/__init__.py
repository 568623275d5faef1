"""Run parameters: every default, range and choice of an option, the presets, and
:class:`RunParams`, validated once.

- ``defaults.py``: what every option is when it is left out (the help text shows these);
- ``ranges.py``: the bounds and choices of the options and their one-line errors;
- ``presets.py``: the bundled material presets (``presets/*.toml``);
- ``impacts.py``: ``--impact`` and ``--direction``, parsed and bounded;
- ``run.py``: :class:`RunParams`, the parameters of one run.

Every public name is importable from ``crackbake.params`` itself.
"""

from crackbake.params.defaults import (
    CRACK_WIDTH_REL_DEFAULT,
    DECAL_RES_DEFAULT,
    DECALS_DEFAULTS,
    DEFAULT_MAX_DISTANCE_FRACTION,
    IMPACT_RADIUS_REL_DEFAULT,
    MIN_PX_DEFAULT,
    PADDING_MIN,
    PADDING_RES_PER_TEXEL,
    PROFILE_DEFAULT,
    RES_DEFAULT,
    SEED_DEFAULT,
    SIM_FACES_DEFAULT,
    SIM_PROXY_DEFAULT,
    SOLVER_DEFAULTS,
    SPACING_DEFAULT,
    STRESS_RES_DEFAULT,
    TARGET_DEFAULT,
    TILE_DEFAULT,
    TILE_DEFAULTS,
    UNWRAP_TIMEOUT_DEFAULT,
    UV_DEFAULT,
    default_padding,
)
from crackbake.params.impacts import (
    Impact,
    check_impact,
    parse_direction,
    parse_impact,
)
from crackbake.params.presets import (
    PRESET_DIR,
    load_preset,
    preset_names,
)
from crackbake.params.ranges import (
    EXR_COMPRESSION_DEFAULT,
    EXR_COMPRESSIONS,
    FORMATS,
    FORMATS_DEFAULT,
    FRAMES_MAX,
    LENGTH_MAX,
    MAX_MEMORY_GIB,
    METHODS,
    NORMAL_Y,
    RADIUS_REL_MAX,
    RANGES,
    RES_MAX,
    RES_MIN,
    SIM_FACES_MAX,
    SIM_PROXY_MODES,
    STRESS_MAX,
    TARGETS,
    TILE_MAX,
    TILE_MIN,
    UNWRAP_TIMEOUT_RANGE,
    UP_AXES,
    UV_MODES,
    check_range,
    check_seed,
    check_sim_faces,
    is_length,
)

# RunParams (a frozen dataclass of some sixty fields: its generated methods cost more to build
# than the rest of the package) is imported on first use: ``crackbake --help`` needs only the
# defaults and choices above (issue 25).
_LAZY = {"RunParams": "crackbake.params.run"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'crackbake.params' has no attribute '{name}'")


__all__ = [
    "CRACK_WIDTH_REL_DEFAULT",
    "DECALS_DEFAULTS",
    "DECAL_RES_DEFAULT",
    "DEFAULT_MAX_DISTANCE_FRACTION",
    "EXR_COMPRESSIONS",
    "EXR_COMPRESSION_DEFAULT",
    "FORMATS",
    "FORMATS_DEFAULT",
    "FRAMES_MAX",
    "IMPACT_RADIUS_REL_DEFAULT",
    "LENGTH_MAX",
    "MAX_MEMORY_GIB",
    "METHODS",
    "MIN_PX_DEFAULT",
    "NORMAL_Y",
    "PADDING_MIN",
    "PADDING_RES_PER_TEXEL",
    "PRESET_DIR",
    "PROFILE_DEFAULT",
    "RADIUS_REL_MAX",
    "RANGES",
    "RES_DEFAULT",
    "RES_MAX",
    "RES_MIN",
    "SEED_DEFAULT",
    "SIM_FACES_DEFAULT",
    "SIM_FACES_MAX",
    "SIM_PROXY_DEFAULT",
    "SIM_PROXY_MODES",
    "SOLVER_DEFAULTS",
    "SPACING_DEFAULT",
    "STRESS_MAX",
    "STRESS_RES_DEFAULT",
    "TARGETS",
    "TARGET_DEFAULT",
    "TILE_DEFAULT",
    "TILE_DEFAULTS",
    "TILE_MAX",
    "TILE_MIN",
    "UNWRAP_TIMEOUT_DEFAULT",
    "UNWRAP_TIMEOUT_RANGE",
    "UP_AXES",
    "UV_DEFAULT",
    "UV_MODES",
    "Impact",
    "RunParams",
    "check_impact",
    "check_range",
    "check_seed",
    "check_sim_faces",
    "default_padding",
    "is_length",
    "load_preset",
    "parse_direction",
    "parse_impact",
    "preset_names",
]
