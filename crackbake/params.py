"""Typed run parameters and their validation.

Everything the CLI can set lives in :class:`RunParams`; the library validates it (so scripts get
the same clear errors as the command line) and the manifest records it.
"""

from __future__ import annotations

import math
import numbers
import sys
import tomllib
from dataclasses import asdict, dataclass, field, fields, replace
from functools import cache
from pathlib import Path

from crackbake.errors import CrackbakeError

FORMATS = ("exr", "png", "glb", "preview", "stress")
#: Default edge of the stress maps: the stress lives on the simulation mesh (about 100k faces, a
#: few hundred triangles across), so 1024 texels already give each sim triangle several texels.
STRESS_RES_DEFAULT = 1024
#: Default least drawn crack width in texels (``--min-px``): the drawn maps show every crack at
#: least this wide so a hairline still reaches full mask at the chosen resolution; ``crack.width``
#: keeps the physical width.
MIN_PX_DEFAULT = 1.0
#: Default decal texture edge: min(--res, this).
DECAL_RES_DEFAULT = 1024
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
#: Largest framebuffer edge of one bake pass (the bake tiles bigger textures): default, range.
TILE_DEFAULT, TILE_MIN, TILE_MAX = 4096, 256, 16384
#: Simulation mesh size in faces when neither ``--detail`` nor ``--sim-faces`` is given.
SIM_FACES_DEFAULT = 100_000
#: Impact radius, as a fraction of the bounding-box diagonal, when neither the impact nor the
#: preset gives one.
IMPACT_RADIUS_REL_DEFAULT = 0.15
#: Largest impact radius given as a fraction of the bounding-box diagonal (``--impact ...:Rd``).
RADIUS_REL_MAX = 10.0
PRESET_DIR = Path(__file__).resolve().parent / "presets"

#: Largest length in mesh units (widths, radii, distances): squared distances must stay finite in
#: the bake's float32 (3.4e38), with room for sums.
LENGTH_MAX = 1e15
#: Largest stress scale (impact/direction strength, shrink, toughness; 1 = a preset's own): the
#: solver sums squares of stresses, and 1e300 overflowed to a field with no cracks at all.
STRESS_MAX = 1e6
#: Largest simulation mesh (the same bound the sim mesh builder enforces).
SIM_FACES_MAX = 20_000_000
UNWRAP_TIMEOUT_RANGE = (1e-3, 1e6)
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


def _check_range(
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


def _check_impact(imp: Impact) -> None:
    """The bounds :func:`parse_impact` applies, for impacts built in code."""
    try:
        xyz = [float(c) for c in imp.point]
    except (TypeError, ValueError):
        xyz = []
    if len(xyz) != 3 or not all(math.isfinite(c) for c in xyz):
        shown = ", ".join(f"{c:g}" for c in xyz) if xyz else repr(imp.point)
        raise CrackbakeError(f"impact point ({shown}): must be three finite numbers x, y, z")
    _check_range("impact radius", imp.radius, 0.0, LENGTH_MAX, " mesh units", True)
    _check_range("impact radius", imp.radius_rel, 0.0, RADIUS_REL_MAX, " bounding-box diagonals",
                 True)
    if imp.radius is not None and imp.radius_rel is not None:
        raise CrackbakeError(
            "impact radius: give it in mesh units (radius) or as a fraction of the bounding-box "
            "diagonal (radius_rel), not both"
        )
    _check_range("impact strength", imp.strength, 0.0, STRESS_MAX, "", True)

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


@cache
def preset_names() -> tuple[str, ...]:
    """Names of the bundled material presets."""
    return tuple(sorted(p.stem for p in PRESET_DIR.glob("*.toml")))


@cache
def load_preset(name: str) -> dict:
    """The settings of a bundled preset (``presets/<name>.toml``)."""
    if name not in preset_names():
        raise CrackbakeError(
            f"--preset '{name}' is unknown; use one of {', '.join(preset_names())}"
        )
    with open(PRESET_DIR / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)


@dataclass(frozen=True)
class Impact:
    """An impact point: where the surface was hit, how wide and how hard.

    Attributes
    ----------
    point : tuple of 3 float
        Mesh units; snapped to the nearest surface point by the solver.
    radius : float or None
        Mesh units; ``None`` picks a default from the mesh size.
    strength : float
        Relative strength (1 = the preset's default).
    radius_rel : float or None
        The radius as a fraction of the mesh's bounding-box diagonal (``--impact X,Y,Z:0.2d``),
        instead of ``radius``.
    """

    point: tuple[float, float, float]
    radius: float | None = None
    strength: float = 1.0
    radius_rel: float | None = None

    def resolved_radius(self, diagonal: float, default_rel: float) -> float:
        """The radius in mesh units on a mesh of bounding-box ``diagonal``.

        ``radius`` when given, else ``radius_rel`` (or ``default_rel`` when neither is set)
        times ``diagonal``.
        """
        if self.radius is not None:
            return float(self.radius)
        rel = self.radius_rel if self.radius_rel is not None else default_rel
        return float(rel) * float(diagonal)

    def to_dict(self) -> dict:
        d = {"point": list(self.point), "radius": self.radius, "strength": self.strength}
        if self.radius_rel is not None:
            d["radius_rel"] = self.radius_rel
        return d


def parse_direction(text: str) -> tuple[float, float, float, float]:
    """Parse ``X,Y,Z[:STRENGTH]`` (directional tension)."""
    syntax = "expected X,Y,Z[:STRENGTH], e.g. --direction 0,1,0:1.5"
    parts = text.strip().split(":")
    try:
        xyz = [float(c) for c in parts[0].split(",")]
        strength = float(parts[1]) if len(parts) > 1 else 1.0
    except ValueError:
        raise CrackbakeError(f"--direction '{text}': {syntax}") from None
    if len(parts) > 2 or len(xyz) != 3 or not all(math.isfinite(c) for c in [*xyz, strength]):
        raise CrackbakeError(f"--direction '{text}': {syntax}")
    if not any(xyz):
        raise CrackbakeError(f"--direction '{text}': the direction must not be zero")
    if abs(strength) > STRESS_MAX or max(abs(c) for c in xyz) > LENGTH_MAX:
        raise CrackbakeError(
            f"--direction '{text}': the strength must lie within +-{STRESS_MAX:g} and the "
            f"direction components within +-{LENGTH_MAX:g}"
        )
    return (xyz[0], xyz[1], xyz[2], strength)


def parse_impact(text: str) -> Impact:
    """Parse ``X,Y,Z[:RADIUS[:STRENGTH]]``; ``RADIUS`` in mesh units, or with a ``d`` suffix
    (``0.2d``) as a fraction of the mesh's bounding-box diagonal.

    Raises
    ------
    CrackbakeError
        Malformed text, with the expected syntax.
    """
    syntax = ("expected X,Y,Z[:RADIUS[:STRENGTH]] with RADIUS in mesh units or a fraction of "
              "the bounding-box diagonal (0.2d), e.g. --impact 0.1,0.2,0.9:0.3:1.5")
    parts = text.strip().split(":")
    if not 1 <= len(parts) <= 3:
        raise CrackbakeError(f"--impact '{text}': {syntax}")
    raw = parts[1].strip() if len(parts) > 1 else ""
    relative = raw[-1:].lower() == "d"
    try:
        xyz = tuple(float(c) for c in parts[0].split(","))
        radius = float(raw[:-1] if relative else raw) if raw != "" else None
        strength = float(parts[2]) if len(parts) > 2 else 1.0
    except ValueError:
        raise CrackbakeError(f"--impact '{text}': {syntax}") from None
    if len(xyz) != 3 or not all(math.isfinite(c) for c in xyz):
        raise CrackbakeError(f"--impact '{text}': {syntax}")
    high, unit = (RADIUS_REL_MAX, "bounding-box diagonals") if relative else (LENGTH_MAX,
                                                                             "mesh units")
    if radius is not None and not (math.isfinite(radius) and 0 < radius <= high):
        raise CrackbakeError(
            f"--impact '{text}': the radius must be a number above 0 up to {high:g} ({unit})"
        )
    if not (math.isfinite(strength) and 0 < strength <= STRESS_MAX):
        raise CrackbakeError(
            f"--impact '{text}': the strength must be a number above 0 up to {STRESS_MAX:g} "
            "(1 = the preset's own)"
        )
    if relative:
        return Impact(point=xyz, strength=strength, radius_rel=radius)  # type: ignore[arg-type]
    return Impact(point=xyz, radius=radius, strength=strength)  # type: ignore[arg-type]


@dataclass(frozen=True)
class RunParams:
    """Every parameter of one crackbake run.

    Attributes
    ----------
    mesh : Path
        Input mesh.
    out : Path or None
        Output folder; ``None`` means ``./<mesh-stem>_cracks/``.
    impacts : tuple of Impact
        Impact points for the solver.
    cracks : Path or None
        A ``cracks.json`` sidecar to bake instead of solving.
    res : int
        Texture edge in texels, :data:`RES_MIN`..:data:`RES_MAX`.
    uv : str
        ``auto`` (keep usable UVs, else unwrap), ``keep`` or ``unwrap``.
    padding : int or None
        xatlas chart gutter in texels; ``None`` = about res/256, at least 2.
    dilate : int or None
        Gutter fill limit in texels; ``None`` fills every empty texel.
    max_distance : float or None
        Clamp of the distance channel, mesh units; ``None`` = 2 % of the bounding-box diagonal.
    profile : float
        Depth profile exponent across a crack (1 = V).
    min_px : float
        Least drawn crack width in texels (mask, depth, normal, occlusion, decals); the width
        channel keeps the physical width.  0 = the physical width only.
    seed : int
        Random seed.
    formats : tuple of str
        Subset of ``exr``, ``png``, ``glb``, ``preview`` (a shaded picture, ``preview.png``) and
        ``stress`` (``<stem>_stress.exr``, the solver's stress fields; not with ``--cracks``).
    decal : float or None
        Decal width = height, mesh units: one projected decal per impact (needs ``impacts``).
    decal_res : int or None
        Decal texture edge in texels; ``None`` = ``min(res, DECAL_RES_DEFAULT)``.
    stress_res : int or None
        Edge of the stress maps in texels; ``None`` = ``min(res, STRESS_RES_DEFAULT)``.
    frames : int or None
        Growth frames ``<stem>_growth_NNNN.png`` (2..:data:`FRAMES_MAX`); ``None``: none.
    float32 : bool
        Write every EXR channel as 32-bit float.
    target : str
        Engine profile deciding the PNG set: one of :data:`TARGETS`.
    normal_y : str or None
        ``gl`` or ``dx`` normal-map Y convention; ``None`` = the target's own.
    up : str or None
        The preview's up axis, one of :data:`UP_AXES`; ``None``: +Y (the OBJ, PLY and glTF
        convention) unless the mesh clearly stands on its -Z side
        (:func:`crackbake.bake.preview.up_axis`).
    object_name : str or None
        Object to pick from a multi-object file.
    allow_outside_textures : bool
        Read the material libraries, textures and glTF buffers the mesh names even outside its
        folder (refused with a warning by default).
    unwrap_timeout : float
        Seconds xatlas may run.
    max_memory : float or None
        GiB the run may use, in place of the detected limit (cgroup, ``RLIMIT_AS`` or physical
        memory) the estimated peak is checked against (:mod:`crackbake.memory`).
    cache : bool
        Use the unwrap cache.
    tile : int
        Largest framebuffer edge of the bake.
    preset : str or None
        Material preset (``presets/<name>.toml``) supplying defaults for unset solver options.
    method : str or None
        ``iben`` (Iben & O'Brien) or ``thesis`` (the MSc variant).
    detail, sim_faces
        Simulation mesh target edge length (mesh units) or face count.
    sim_proxy : str
        ``auto``: an asset over twice the wanted sim faces (and over 200k faces) is simulated
        on a decimated proxy of itself (:mod:`crackbake.simulate.simmesh.proxy`); ``always``:
        every asset is (a clean isotropic sim mesh for assets of long thin triangles);
        ``never``: the sim mesh always refines the asset's own faces.
    toughness, tip_factor, relax_steps, relax_rate, relax_share, max_cracks, max_steps,
    max_crack_length, crack_width, depth_ratio
        Solver settings (:class:`crackbake.simulate.solver.SolverParams`).
    shrink, shrink_rate, directions, curvature_bias, curvature_density, weight_map,
    weight_attribute, weight_invert, noise, hoop
        Stress sources (:mod:`crackbake.simulate.stress`); ``directions`` holds (x, y, z, strength).
    spacing : float or None
        Radius of each crack's stress shadow, a fraction of the bounding-box diagonal (the
        solver's own 0.1 when unset): how close parallel cracks may run, so smaller gives
        smaller cells.  Impacts narrow it further near their star.
    look : dict
        Overrides of the preset's ``[look]`` table (``--look KEY=VALUE``): crack colour and
        composite mode, roughness, normal strength, width variation, chipping, curl
        (:mod:`crackbake.looks`); :meth:`crack_look` gives the result.
    """

    mesh: Path
    out: Path | None = None
    impacts: tuple[Impact, ...] = ()
    cracks: Path | None = None
    res: int = 2048
    uv: str = "auto"
    padding: int | None = None
    dilate: int | None = None
    max_distance: float | None = None
    profile: float = 1.0
    min_px: float = MIN_PX_DEFAULT
    seed: int = 0
    formats: tuple[str, ...] = FORMATS
    stress_res: int | None = None
    frames: int | None = None
    decal: float | None = None
    decal_res: int | None = None
    float32: bool = False
    target: str = "gltf"
    normal_y: str | None = None
    up: str | None = None
    object_name: str | None = None
    allow_outside_textures: bool = False
    unwrap_timeout: float = 300.0
    max_memory: float | None = None
    cache: bool = True
    tile: int = TILE_DEFAULT
    # --- solver and stress (None: from the preset, else SOLVER_DEFAULTS) ---
    preset: str | None = None
    method: str | None = None
    detail: float | None = None
    sim_faces: int | None = None
    sim_proxy: str = "auto"
    toughness: float | None = None
    tip_factor: float | None = None
    relax_steps: int | None = None
    relax_rate: float | None = None
    relax_share: float | None = None
    max_cracks: int | None = None
    max_steps: int | None = None
    max_crack_length: float | None = None
    crack_width: float | None = None
    depth_ratio: float | None = None
    shrink: float | None = None
    shrink_rate: float | None = None
    directions: tuple[tuple[float, float, float, float], ...] = ()
    curvature_bias: float | None = None
    curvature_density: float | None = None
    weight_map: Path | None = None
    weight_attribute: str | None = None
    weight_invert: bool = False
    noise: float | None = None
    hoop: float | None = None
    spacing: float | None = None
    look: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    @property
    def proxy_above(self) -> int | None:
        """``build_simmesh``'s ``proxy_above`` for ``sim_proxy`` (None: the automatic limit)."""
        return {"auto": None, "always": 0, "never": sys.maxsize}[self.sim_proxy]

    @property
    def out_dir(self) -> Path:
        return self.out if self.out is not None else Path(f"{Path(self.mesh).stem}_cracks")

    def validate(self) -> RunParams:
        """Check every value; return self so calls chain."""
        if self.out is not None and not str(self.out).strip():
            raise CrackbakeError("-o '' names no folder; give an output folder or leave -o out")
        if not RES_MIN <= self.res <= RES_MAX:
            raise CrackbakeError(
                f"--res {self.res} is out of range; use a value from {RES_MIN} to {RES_MAX}"
            )
        if self.uv not in UV_MODES:
            raise CrackbakeError(f"--uv '{self.uv}' is unknown; use one of {', '.join(UV_MODES)}")
        if self.sim_proxy not in SIM_PROXY_MODES:
            raise CrackbakeError(f"--sim-proxy '{self.sim_proxy}' is unknown; use one of "
                                 f"{', '.join(SIM_PROXY_MODES)}")
        _check_range("--padding", self.padding, 0, RES_MAX, " texels")
        _check_range("--stress-res", self.stress_res, RES_MIN, RES_MAX, " texels")
        _check_range("--frames", self.frames, 2, FRAMES_MAX, " frames")
        _check_range("--decal", self.decal, 0.0, LENGTH_MAX, " mesh units", True)
        _check_range("--decal-res", self.decal_res, RES_MIN, RES_MAX, " texels")
        if (self.decal is not None or self.decal_res is not None) and not self.impacts:
            raise CrackbakeError(
                "--decal needs --impact X,Y,Z (one decal is centred on each impact); "
                "add an impact or drop --decal"
            )
        if self.decal_res is not None and self.decal is None:
            raise CrackbakeError("--decal-res needs --decal SIZE; add --decal or drop --decal-res")
        _check_range("--dilate", self.dilate, 0, RES_MAX, " texels")
        if not self.formats:
            raise CrackbakeError(f"--formats is empty; use a subset of {','.join(FORMATS)}")
        bad = [f for f in self.formats if f not in FORMATS]
        if bad:
            raise CrackbakeError(
                f"--formats: unknown format '{bad[0]}'; use a subset of {','.join(FORMATS)}"
            )
        if self.target not in TARGETS:
            raise CrackbakeError(
                f"--target '{self.target}' is unknown; use one of {', '.join(TARGETS)}"
            )
        if self.normal_y is not None and self.normal_y not in NORMAL_Y:
            raise CrackbakeError(f"--normal-y '{self.normal_y}' is unknown; use gl or dx")
        if self.up is not None and self.up not in UP_AXES:
            raise CrackbakeError(f"--up '{self.up}' is unknown; use one of {', '.join(UP_AXES)}")
        _check_range("--unwrap-timeout", self.unwrap_timeout, *UNWRAP_TIMEOUT_RANGE, " s")
        _check_range("--max-memory", self.max_memory, 0.0, MAX_MEMORY_GIB, " GiB", True)
        if not TILE_MIN <= self.tile <= TILE_MAX:
            raise CrackbakeError(
                f"tile size {self.tile} is out of range; use {TILE_MIN}..{TILE_MAX}"
            )
        check_seed(self.seed)
        if self.preset is not None:
            load_preset(self.preset)
        if self.method is not None and self.method not in METHODS:
            raise CrackbakeError(
                f"--method '{self.method}' is unknown; use one of {', '.join(METHODS)}"
            )
        for name, bounds in RANGES.items():
            _check_range("--" + name.replace("_", "-"), getattr(self, name), *bounds)
        for imp in self.impacts:
            _check_impact(imp)
        self.crack_look()
        for d in self.directions:
            _check_range("--direction strength", d[3], -STRESS_MAX, STRESS_MAX)
        if self.weight_map is not None:
            if Path(self.weight_map).is_dir():
                raise CrackbakeError(
                    f"--weight-map {self.weight_map}: is a folder; pass an image file"
                )
            if not Path(self.weight_map).exists():
                raise CrackbakeError(f"--weight-map {self.weight_map}: file not found")
        return self

    def resolved(self) -> tuple[RunParams, dict]:
        """Fill unset solver options from the preset, then from :data:`SOLVER_DEFAULTS`.

        Returns
        -------
        params : RunParams
            Every solver field set (``None`` only where ``None`` is the default).
        relative : dict
            Preset settings relative to the mesh size (``crack_width_rel``,
            ``impact_radius_rel``: fractions of the bounding-box diagonal), used where the
            absolute option is unset; ``sim_size_set``: the user gave ``detail`` or
            ``sim_faces`` (else an impact on a thin feature may refine the sim mesh).
        """
        preset = load_preset(self.preset) if self.preset else {}
        names = {f.name for f in fields(self)}
        changes = {}
        for key, default in SOLVER_DEFAULTS.items():
            if getattr(self, key) is None:
                changes[key] = preset.get(key, default)
        unknown = set(preset) - names - {"description", "needs_impact", "crack_width_rel",
                                          "impact_radius_rel"} - {"look"}
        if unknown:
            raise CrackbakeError(f"preset '{self.preset}' has unknown keys {sorted(unknown)}")
        relative = {k: preset[k] for k in ("crack_width_rel", "impact_radius_rel") if k in preset}
        relative["needs_impact"] = bool(preset.get("needs_impact", False))
        relative["sim_size_set"] = self.detail is not None or self.sim_faces is not None
        return replace(self, **changes), relative

    def crack_look(self):
        """The :class:`crackbake.looks.Look` of this run: the preset's ``[look]`` table, then
        ``look``'s overrides, over the defaults (each checked: a one-line error otherwise)."""
        from crackbake.looks import resolve_look

        return resolve_look(load_preset(self.preset) if self.preset else {}, self.look)

    def to_dict(self) -> dict:
        """JSON-ready dict of every effective parameter (paths as strings)."""
        d = asdict(self)
        d["mesh"] = str(self.mesh)
        d["out"] = str(self.out_dir)
        d["cracks"] = str(self.cracks) if self.cracks is not None else None
        d["impacts"] = [i.to_dict() for i in self.impacts]
        d["formats"] = list(self.formats)
        d["weight_map"] = str(self.weight_map) if self.weight_map is not None else None
        d["directions"] = [list(x) for x in self.directions]
        d["look"] = self.crack_look().to_dict()
        extra = d.pop("extra")
        d.update(extra)
        return d
