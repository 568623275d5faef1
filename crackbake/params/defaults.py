"""Every default of a run, in one place: what an option is when it is left out.

The command's help shows these values (``crackbake --help`` builds its ``[...]`` from them), the
library's dataclasses use them, and the stages that resolve a left-out option read them from
here.  Presets (``presets/*.toml``) override :data:`SOLVER_DEFAULTS` per material.
"""

from __future__ import annotations

#: Texture edge in texels (``--res``).
RES_DEFAULT = 2048
#: Default edge of the stress maps: the stress lives on the simulation mesh (about 100k faces, a
#: few hundred triangles across), so 1024 texels already give each sim triangle several texels.
STRESS_RES_DEFAULT = 1024
#: Default least drawn crack width in texels (``--min-px``): the drawn maps show every crack at
#: least this wide so a hairline still reaches full mask at the chosen resolution; ``crack.width``
#: keeps the physical width.
MIN_PX_DEFAULT = 1.0
#: Default decal texture edge: min(--res, this).
DECAL_RES_DEFAULT = 1024
#: Depth profile exponent across a crack (``--profile``; 1 = V-shaped).
PROFILE_DEFAULT = 1.0
#: ``--uv``: keep usable UVs, else unwrap.
UV_DEFAULT = "auto"
#: ``--sim-proxy``: a decimated stand-in only for assets far denser than the sim mesh.
SIM_PROXY_DEFAULT = "auto"
#: ``--target``: the engine profile.
TARGET_DEFAULT = "gltf"
#: ``--seed``.
SEED_DEFAULT = 0
#: Seconds xatlas may run (``--unwrap-timeout``).
UNWRAP_TIMEOUT_DEFAULT = 300.0
#: Largest framebuffer edge of one bake pass (the bake tiles bigger textures): a pass draws a
#: full-width band of at most ``TILE_DEFAULT**2`` texels.  2048: a 4096² bake draws four bands
#: into render targets a quarter the size (96 instead of 384 MB, allocated and zero-filled by
#: llvmpipe in every run), and its stage is as fast or faster (docs/benchmarks.md, "Bands").
TILE_DEFAULT = 2048
#: Simulation mesh size in faces when neither ``--detail`` nor ``--sim-faces`` is given.
SIM_FACES_DEFAULT = 100_000
#: Impact radius, as a fraction of the bounding-box diagonal, when neither the impact nor the
#: preset gives one.
IMPACT_RADIUS_REL_DEFAULT = 0.15
#: Widest crack opening, as a fraction of the bounding-box diagonal, when neither
#: ``--crack-width`` nor the preset's ``crack_width_rel`` gives one.
CRACK_WIDTH_REL_DEFAULT = 0.001
#: Radius of a crack's stress shadow, a fraction of the bounding-box diagonal, when neither
#: ``--spacing`` nor the preset sets it (the iben solver's ``SHADOW_REL``; tests/test_params.py
#: holds the two equal).
SPACING_DEFAULT = 0.1
#: Clamp of the distance channel (``--max-distance``), as a fraction of the bounding-box diagonal.
DEFAULT_MAX_DISTANCE_FRACTION = 0.02
#: xatlas chart gutter (``--padding``): one texel per this many texels of ``res`` ...
PADDING_RES_PER_TEXEL = 256
#: ... and never fewer than this many texels.
PADDING_MIN = 2

#: ``crackbake decals``: a library's defaults (:class:`crackbake.decals.LibraryParams`).
DECALS_DEFAULTS: dict = {
    "preset": "glass",
    "n": 16,
    "size": 0.5,
    "res": 1024,
    "seed": 0,
    "normal_y": "gl",
    "out": "decals",
}
#: ``crackbake tile``: a tile's defaults (:class:`crackbake.tile.TileParams`); ``impacts`` is
#: the number of random impacts for presets that need them (glass).
TILE_DEFAULTS: dict = {
    "preset": "mud",
    "size": 2.0,
    "res": 2048,
    "seed": 0,
    "impacts": 3,
    "sim_faces": 60_000,
    "out": "tile",
}


def default_padding(res: int) -> int:
    """Chart gutter for a page of ``res`` texels: about ``res / 256``, at least 2 texels.

    Mip-mapping halves the gutter per level; res/256 keeps islands apart down to the 1/128-size
    mip and 2 texels keeps bilinear filtering clean at small sizes.
    """
    return max(PADDING_MIN, int(round(res / PADDING_RES_PER_TEXEL)))


#: Solver and stress defaults when neither the command line nor a preset sets them.
SOLVER_DEFAULTS: dict = {
    "method": "iben",
    "toughness": 0.7,
    "tip_factor": 0.75,
    "relax_steps": 10,
    "relax_rate": 0.6,
    "relax_share": 0.05,
    "max_cracks": 500,
    "max_steps": 100000,
    "max_crack_length": None,
    "crack_width": None,
    "depth_ratio": 0.5,
    "shrink": None,
    "shrink_rate": 0.0,
    "hoop": 1.25,
    "noise": 0.0,
    "spacing": None,
    "curvature_bias": None,
    "curvature_density": None,
    "sim_faces": SIM_FACES_DEFAULT,
    "detail": None,
}
