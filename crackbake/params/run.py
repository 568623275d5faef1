"""Typed run parameters and their validation.

Everything the CLI can set lives in :class:`RunParams`; the library validates it (so scripts get
the same clear errors as the command line) and the manifest records it.
"""

from __future__ import annotations

import numbers
import sys
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from crackbake.errors import CrackbakeError
from crackbake.params.defaults import (
    MIN_PX_DEFAULT,
    PROFILE_DEFAULT,
    RES_DEFAULT,
    SEED_DEFAULT,
    SIM_PROXY_DEFAULT,
    SOLVER_DEFAULTS,
    TARGET_DEFAULT,
    TILE_DEFAULT,
    UNWRAP_TIMEOUT_DEFAULT,
    UV_DEFAULT,
)
from crackbake.params.impacts import Impact, check_impact
from crackbake.params.presets import load_preset
from crackbake.params.ranges import (
    CYCLES_MAX,
    EXR_COMPRESSION_DEFAULT,
    EXR_COMPRESSIONS,
    FORMATS,
    FORMATS_DEFAULT,
    FRAMES_MAX,
    LENGTH_MAX,
    MAX_MEMORY_GIB,
    METHODS,
    NORMAL_Y,
    RANGES,
    RES_MAX,
    RES_MIN,
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
)


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
        ``stress`` (``<stem>_stress.exr``, the solver's stress fields; not with ``--cracks``),
        ``usd`` (``<stem>.usda`` with its material) and ``usdz`` (``<stem>.usdz`` for AR Quick
        Look); both need usd-core and are not defaults.
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
    exr_compression : str
        Lossless compression of the EXR files, one of :data:`EXR_COMPRESSIONS`.
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
    thickness : float or None
        Plate thickness, mm, for impacts given a speed (:attr:`Impact.speed`); None: 1 mm.
    material : str or None
        The plate's material for impacts given a speed: ``glass`` or ``plexiglas``
        (:data:`crackbake.params.speed.MATERIALS`); None: glass.
    cycles : int
        Dryings of a shrinkage network, 1..:data:`crackbake.params.ranges.CYCLES_MAX`; each
        after the first re-cracks along the previous pattern and moves its junctions toward
        120 degrees (:mod:`crackbake.simulate.cycles`).  1: the solved network as it is.
    look : dict
        Overrides of the preset's ``[look]`` table (``--look KEY=VALUE``): crack colour and
        composite mode, roughness, normal strength, width variation, chipping, curl
        (:mod:`crackbake.looks`); :meth:`crack_look` gives the result.
    """

    mesh: Path
    out: Path | None = None
    impacts: tuple[Impact, ...] = ()
    cracks: Path | None = None
    res: int = RES_DEFAULT
    uv: str = UV_DEFAULT
    padding: int | None = None
    dilate: int | None = None
    max_distance: float | None = None
    profile: float = PROFILE_DEFAULT
    min_px: float = MIN_PX_DEFAULT
    seed: int = SEED_DEFAULT
    formats: tuple[str, ...] = FORMATS_DEFAULT
    stress_res: int | None = None
    frames: int | None = None
    decal: float | None = None
    decal_res: int | None = None
    float32: bool = False
    exr_compression: str = EXR_COMPRESSION_DEFAULT
    target: str = TARGET_DEFAULT
    normal_y: str | None = None
    up: str | None = None
    object_name: str | None = None
    allow_outside_textures: bool = False
    unwrap_timeout: float = UNWRAP_TIMEOUT_DEFAULT
    max_memory: float | None = None
    cache: bool = True
    tile: int = TILE_DEFAULT
    # --- solver and stress (None: from the preset, else SOLVER_DEFAULTS) ---
    preset: str | None = None
    method: str | None = None
    detail: float | None = None
    sim_faces: int | None = None
    sim_proxy: str = SIM_PROXY_DEFAULT
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
    thickness: float | None = None
    material: str | None = None
    cycles: int = 1
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
        check_range("--padding", self.padding, 0, RES_MAX, " texels")
        check_range("--stress-res", self.stress_res, RES_MIN, RES_MAX, " texels")
        check_range("--frames", self.frames, 2, FRAMES_MAX, " frames")
        check_range("--decal", self.decal, 0.0, LENGTH_MAX, " mesh units", True)
        check_range("--decal-res", self.decal_res, RES_MIN, RES_MAX, " texels")
        if (self.decal is not None or self.decal_res is not None) and not self.impacts:
            raise CrackbakeError(
                "--decal needs --impact X,Y,Z (one decal is centred on each impact); "
                "add an impact or drop --decal"
            )
        if self.decal_res is not None and self.decal is None:
            raise CrackbakeError("--decal-res needs --decal SIZE; add --decal or drop --decal-res")
        check_range("--dilate", self.dilate, 0, RES_MAX, " texels")
        if not self.formats:
            raise CrackbakeError(f"--formats is empty; use a subset of {','.join(FORMATS)}")
        bad = [f for f in self.formats if f not in FORMATS]
        if bad:
            raise CrackbakeError(
                f"--formats: unknown format '{bad[0]}'; use a subset of {','.join(FORMATS)}"
            )
        for fmt in ("usd", "usdz"):
            if fmt in self.formats:
                from crackbake.exchange.usd import require_pxr

                require_pxr(fmt)  # now, not after the solver
        if self.exr_compression not in EXR_COMPRESSIONS:
            raise CrackbakeError(
                f"--exr-compression '{self.exr_compression}' is unknown or lossy; use one of "
                f"{', '.join(EXR_COMPRESSIONS)}"
            )
        if self.target not in TARGETS:
            raise CrackbakeError(
                f"--target '{self.target}' is unknown; use one of {', '.join(TARGETS)}"
            )
        if self.normal_y is not None and self.normal_y not in NORMAL_Y:
            raise CrackbakeError(f"--normal-y '{self.normal_y}' is unknown; use gl or dx")
        if self.up is not None and self.up not in UP_AXES:
            raise CrackbakeError(f"--up '{self.up}' is unknown; use one of {', '.join(UP_AXES)}")
        check_range("--unwrap-timeout", self.unwrap_timeout, *UNWRAP_TIMEOUT_RANGE, " s")
        check_range("--max-memory", self.max_memory, 0.0, MAX_MEMORY_GIB, " GiB", True)
        if isinstance(self.cycles, bool) or not isinstance(self.cycles, numbers.Integral):
            raise CrackbakeError(f"--cycles '{self.cycles}' is not a whole number; give 1 or more")
        check_range("--cycles", self.cycles, 1, CYCLES_MAX, " dryings")
        if self.cycles > 1 and self.cracks is not None:
            raise CrackbakeError("--cycles re-cracks a solved network; with --cracks the network "
                                 "is baked as given: drop --cycles (or --cracks)")
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
            check_range("--" + name.replace("_", "-"), getattr(self, name), *bounds)
        for imp in self.impacts:
            check_impact(imp)
        self._check_speed_options()
        self.crack_look()
        for d in self.directions:
            check_range("--direction strength", d[3], -STRESS_MAX, STRESS_MAX)
        if self.weight_map is not None:
            if Path(self.weight_map).is_dir():
                raise CrackbakeError(
                    f"--weight-map {self.weight_map}: is a folder; pass an image file"
                )
            if not Path(self.weight_map).exists():
                raise CrackbakeError(f"--weight-map {self.weight_map}: file not found")
        return self

    def _check_speed_options(self) -> None:
        """``thickness`` and ``material`` act on impacts given a speed only."""
        from crackbake.params.speed import THICKNESS_MAX, check_material

        check_material(self.material)
        check_range("--thickness", self.thickness, 0.0, THICKNESS_MAX, " mm", True)
        if (self.thickness is not None or self.material is not None) and not any(
                i.speed is not None for i in self.impacts):
            given = "--thickness" if self.thickness is not None else "--material"
            raise CrackbakeError(
                f"{given} sets the plate an impact speed breaks; give an impact as "
                "--impact X,Y,Z:speed=V (m/s) or drop it"
            )

    def resolved(self) -> tuple[RunParams, dict]:
        """Fill unset solver options from the preset, then from :data:`SOLVER_DEFAULTS`.

        Returns
        -------
        params : RunParams
            Every solver field set (``None`` only where ``None`` is the default).
        relative : dict
            Preset settings relative to the mesh size (``crack_width_rel``,
            ``impact_radius_rel``: fractions of the bounding-box diagonal) or to the crack
            pattern (``crack_width_cell``: the mean width over the cell size, which then sets
            the widths after the solve), used where the absolute option is unset;
            ``sim_size_set``: the user gave ``detail`` or
            ``sim_faces`` (else an impact on a thin feature may refine the sim mesh).
        """
        preset = load_preset(self.preset) if self.preset else {}
        names = {f.name for f in fields(self)}
        changes = {}
        for key, default in SOLVER_DEFAULTS.items():
            if getattr(self, key) is None:
                changes[key] = preset.get(key, default)
        unknown = set(preset) - names - {"description", "needs_impact", "crack_width_rel",
                                          "crack_width_cell", "impact_radius_rel"} - {"look"}
        if unknown:
            raise CrackbakeError(f"preset '{self.preset}' has unknown keys {sorted(unknown)}")
        relative = {k: preset[k] for k in ("crack_width_rel", "crack_width_cell",
                                           "impact_radius_rel") if k in preset}
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
        # Only runs with a speed impact name the plate (older sidecars stay as they were).
        if not any(i.speed is not None for i in self.impacts):
            d.pop("thickness")
            d.pop("material")
        extra = d.pop("extra")
        d.update(extra)
        return d

