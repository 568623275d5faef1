"""Ranges and choices: the bounds of every option and the one-line errors past them.

The messages name the option as the command line does (``--res 3 is out of range; ...``), so a
script calling the library gets the same errors as the command.
"""

from __future__ import annotations

import math
import numbers

from crackbake.errors import CrackbakeError

#: Every ``--formats`` choice.  ``usd`` and ``usdz`` need the ``usd`` extra (usd-core), so they
#: are not defaults.
FORMATS = ("exr", "png", "glb", "preview", "stress", "usd", "usdz")
#: What a run writes when ``--formats`` is not given.
FORMATS_DEFAULT = ("exr", "png", "glb", "preview", "stress")
#: ``--exr-compression``: the lossless OpenEXR methods (a lossy one would change data values).
EXR_COMPRESSIONS = ("zip", "piz", "zips", "none")
EXR_COMPRESSION_DEFAULT = "zip"
#: Most ``--frames`` (the frame number has four digits).
FRAMES_MAX = 10_000
UV_MODES = ("auto", "keep", "unwrap")
#: ``--sim-proxy``: when the simulation runs on a decimated stand-in of the asset.
SIM_PROXY_MODES = ("auto", "always", "never")
#: Engine profiles (``--target``; the table is :data:`crackbake.exchange.targets.TARGETS`).
TARGETS = ("gltf", "unity", "unity-hdrp", "unreal", "godot", "blender")
#: Normal-map Y conventions (``--normal-y``): OpenGL (+Y, green up) or DirectX (-Y).
NORMAL_Y = ("gl", "dx")
#: ``--up`` axes of the preview (None: +Y unless the mesh clearly stands on -Z).
UP_AXES = ("x", "y", "z", "-x", "-y", "-z")
METHODS = ("iben", "thesis")
RES_MIN, RES_MAX = 64, 16384
#: Range of the largest framebuffer edge of one bake pass (the bake tiles bigger textures).
TILE_MIN, TILE_MAX = 256, 16384
#: Largest impact radius given as a fraction of the bounding-box diagonal (``--impact ...:Rd``).
RADIUS_REL_MAX = 10.0

#: Largest length in mesh units (widths, radii, distances): squared distances must stay finite in
#: the bake's float32 (3.4e38), with room for sums.
LENGTH_MAX = 1e15
#: Largest stress scale (impact/direction strength, shrink, toughness; 1 = a preset's own): the
#: solver sums squares of stresses, and 1e300 overflowed to a field with no cracks at all.
STRESS_MAX = 1e6
#: Largest simulation mesh (the same bound the sim mesh builder enforces).
SIM_FACES_MAX = 20_000_000
UNWRAP_TIMEOUT_RANGE = (1e-3, 1e6)
#: Most ``--cycles`` (wetting and drying cycles; the experiment ran 25 and by 50 the pattern has
#: long stopped changing).
CYCLES_MAX = 100
#: Largest ``--max-memory``, GiB (a petabyte: any real machine).
MAX_MEMORY_GIB = 1e6
#: Range of every bounded option: name -> (low, high, unit shown in messages, low excluded).
#: Ints include both ends.
RANGES: dict[str, tuple[float, float, str, bool]] = {
    "profile": (0.01, 100.0, " (1 = V-shaped crack)", False),
    "min_px": (0.0, 1000.0, " texels (0 = the physical width only)", False),
    "max_distance": (0.0, LENGTH_MAX, " mesh units", True),
    "detail": (0.0, LENGTH_MAX, " mesh units", True),
    "max_crack_length": (0.0, LENGTH_MAX, " mesh units", True),
    "crack_width": (0.0, LENGTH_MAX, " mesh units", True),
    "toughness": (0.0, STRESS_MAX, "", True),
    "relax_rate": (0.0, 100.0, "", True),
    "hoop": (0.0, 100.0, "", True),
    "depth_ratio": (0.0, 1000.0, "", False),
    "shrink_rate": (0.0, 100.0, "", False),
    "noise": (0.0, 10.0, "", False),
    "spacing": (0.0, 1.0, " of the bounding-box diagonal", True),
    "shrink": (-STRESS_MAX, STRESS_MAX, "", False),
    "curvature_bias": (-100.0, 100.0, "", False),
    "curvature_density": (-100.0, 100.0, "", False),
    "tip_factor": (0.0, 1.0, "", False),
    "relax_share": (0.0, 1.0, "", False),
    "relax_steps": (0, 1000, "", False),
    "max_cracks": (1, 10_000_000, "", False),
    "max_steps": (1, 1_000_000_000, "", False),
    "sim_faces": (100, SIM_FACES_MAX, " faces", False),
}


def check_seed(seed: int) -> None:
    """Refuse a ``--seed`` outside the non-negative 64-bit integers (one-line error)."""
    if not 0 <= seed < 2**63:
        raise CrackbakeError(f"--seed {seed} must be a non-negative 64-bit integer")


def check_sim_faces(sim_faces: int | None) -> None:
    """Refuse a ``--sim-faces`` outside 100..:data:`SIM_FACES_MAX` (``None``: the default)."""
    if sim_faces is not None and not 100 <= sim_faces <= SIM_FACES_MAX:
        raise CrackbakeError(
            f"--sim-faces {sim_faces} is out of range; use 100 to {SIM_FACES_MAX}"
        )


def is_length(x) -> bool:
    """Whether ``x`` is a real number (not a bool) in ``(0, LENGTH_MAX]`` mesh units."""
    return (isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)
            and 0 < x <= LENGTH_MAX)


def check_range(
    flag: str, value, low: float, high: float, unit: str = "", low_open: bool = False
) -> None:
    """Refuse ``value`` outside ``low..high`` (NaN and infinities included); ``None`` passes."""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise CrackbakeError(f"{flag} '{value}' is not a number; give a number")
    # numpy scalars from scripts: plain Python numbers, so messages never show np.int64(...).
    value = int(value) if isinstance(value, numbers.Integral) else float(value)
    ok = math.isfinite(value) and (low < value if low_open else low <= value) and value <= high
    if not ok:
        above = f"above {low:g}" if low_open else f"from {low:g}"
        shown = str(value) if isinstance(value, int) else f"{value:g}"
        raise CrackbakeError(
            f"{flag} {shown} is out of range; use a number {above} up to {high:g}{unit}"
        )
