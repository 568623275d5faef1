"""Decal libraries (``crackbake decals``): N crack variants on a flat plate, baked one by one.

Each variant is a square plate of side ``size`` (mesh units) in z = 0 with UVs ``u = x / size``,
``v = y / size``: its UV bake *is* the decal texture, the tangent frame is the plate's axes
(T = +X = image right, B = +Y = image up, N = +Z).  The variants run the real pipeline stages
(:func:`crackbake.pipeline.solve`, :func:`crackbake.bake.uv.prepare_uvs`,
:func:`crackbake.bake.tangents.with_tangents`, :func:`crackbake.bake.raster.bake_cracks`) with
their own seed and, for presets that need one (glass), an impact jittered about the centre;
:mod:`crackbake.decals.atlas` packs them into atlases and writes ``decals.json``.
"""

from __future__ import annotations

import logging
import math
import numbers
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.params import (
    DECALS_DEFAULTS,
    IMPACT_RADIUS_REL_DEFAULT,
    LENGTH_MAX,
    NORMAL_Y,
    RES_MIN,
    Impact,
    RunParams,
    check_seed,
    check_sim_faces,
    is_length,
    load_preset,
)

logger = logging.getLogger(__name__)

#: Variants per library: 1..N_MAX.
N_MAX = 256
#: Largest texture of one variant, texels per side (an atlas of 16 is 6x that wide).
VARIANT_RES_MAX = 4096
#: Cells per side of the plate mesh: small faces keep the bake's per-face crack candidate lists
#: short (a 4x4-cell plate baked 1024² in 6.7 s, this one in 0.4 s, same maps).
PLATE_CELLS = 64
#: Glass impacts land within +-IMPACT_JITTER * size of the plate centre, per axis.
IMPACT_JITTER = 0.12


@dataclass(frozen=True)
class LibraryParams:
    """Every parameter of one decal library.

    Attributes
    ----------
    out : Path
        Output folder (replaced as a whole, see :class:`crackbake.transaction.stage.OutputStage`).
    preset : str
        Material preset (``glass`` gets one jittered impact per variant, the others none).
    n : int
        Number of variants, 1..:data:`N_MAX`.
    size : float
        Plate side in mesh units (the decal's width and height).
    res : int
        Texels per side of one variant, :data:`~crackbake.params.RES_MIN`..
        :data:`VARIANT_RES_MAX`.
    seed : int
        Library seed; variant ``i`` depends only on (seed, i), so a bigger ``n`` keeps the first
        variants.
    normal_y : {"gl", "dx"}
        Normal-map Y convention of the normal atlas.
    depth : float or None
        Projector depth of each decal, mesh units; ``None`` = size / 4.
    sim_faces : int or None
        Simulation mesh size per variant; ``None`` = the preset's / the default.
    """

    out: Path
    preset: str = DECALS_DEFAULTS["preset"]
    n: int = DECALS_DEFAULTS["n"]
    size: float = DECALS_DEFAULTS["size"]
    res: int = DECALS_DEFAULTS["res"]
    seed: int = DECALS_DEFAULTS["seed"]
    normal_y: str = DECALS_DEFAULTS["normal_y"]
    depth: float | None = None
    sim_faces: int | None = None
    extra: dict = field(default_factory=dict)

    def validate(self) -> LibraryParams:
        """Check every value (one-line :class:`CrackbakeError`); return self."""
        if not str(self.out).strip():
            raise CrackbakeError("-o '' names no folder; give an output folder with -o")
        load_preset(self.preset)  # unknown preset: lists the names
        if not _integer(self.n) or not 1 <= self.n <= N_MAX:
            raise CrackbakeError(f"-n {self.n} is out of range; use 1 to {N_MAX} variants")
        if not is_length(self.size):
            raise CrackbakeError(
                f"--size {self.size} is not a plate size; use a number above 0 up to "
                f"{LENGTH_MAX:g} mesh units"
            )
        if not _integer(self.res) or not RES_MIN <= self.res <= VARIANT_RES_MAX:
            raise CrackbakeError(
                f"--res {self.res} is out of range; use {RES_MIN} to {VARIANT_RES_MAX} texels "
                "per variant"
            )
        if self.normal_y not in NORMAL_Y:
            raise CrackbakeError(f"--normal-y '{self.normal_y}' is unknown; use gl or dx")
        if self.depth is not None and not is_length(self.depth):
            raise CrackbakeError(f"--depth {self.depth} must be a number above 0 (mesh units)")
        check_sim_faces(self.sim_faces)
        check_seed(self.seed)
        from crackbake.decals.atlas import atlas_layout

        atlas_layout(self.n, self.res)  # refuses an atlas too big to write
        return self

    @property
    def projector_depth(self) -> float:
        return float(self.depth) if self.depth is not None else self.size / 4.0


def _integer(x) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)




@dataclass(frozen=True)
class Variant:
    """One variant's recipe: name, solver seed and impact (plate frame, mesh units)."""

    index: int
    name: str
    seed: int
    impact: Impact | None


@dataclass(eq=False)
class Baked:
    """A baked variant: its recipe, crack maps (:class:`~crackbake.bake.raster.CrackMaps`),
    crack count and stage times (s)."""

    variant: Variant
    maps: object
    cracks: int
    timings: dict[str, float]


def variants(params: LibraryParams) -> list[Variant]:
    """The ``n`` recipes, each from ``SeedSequence([seed, i])`` alone (deterministic, stable
    under a change of ``n``).  Glass-like presets (``needs_impact``) get one impact at the
    plate centre jittered by up to :data:`IMPACT_JITTER` * size per axis."""
    preset = load_preset(params.preset)
    needs_impact = bool(preset.get("needs_impact", False))
    # The radius the pipeline would pick on this plate, made explicit so decals.json records it.
    rel = preset.get("impact_radius_rel", IMPACT_RADIUS_REL_DEFAULT)
    radius = float(rel * params.size * math.sqrt(2.0))
    out = []
    for i in range(params.n):
        rng = np.random.default_rng(np.random.SeedSequence([params.seed, i]))
        seed = int(rng.integers(0, 2**31 - 1))
        impact = None
        if needs_impact:
            jx, jy = rng.uniform(-IMPACT_JITTER, IMPACT_JITTER, 2) * params.size
            c = params.size / 2
            impact = Impact(point=(c + float(jx), c + float(jy), 0.0), radius=radius)
        out.append(Variant(i, f"{params.preset}_{i:02d}", seed, impact))
    return out


def plate_mesh(size: float, cells: int = PLATE_CELLS):
    """The decal plate: (0, 0)..(size, size) in z = 0, 2 cells² counter-clockwise triangles,
    UVs ``(x, y) / size``, normals +Z; a :class:`crackbake.io.mesh.Mesh`."""
    from crackbake.io.mesh import Mesh

    t = np.linspace(0.0, size, cells + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    xy = np.stack([x.ravel(), y.ravel()], 1)
    idx = np.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    vertices = np.column_stack([xy, np.zeros(len(xy))])
    normals = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    return Mesh(vertices=vertices, faces=faces.astype(np.int64), uv=xy / size,
                normals=normals, source="decal_plate.obj", name="decal_plate")  # fmt: skip


def bake_variant(ctx, mesh, uvmesh, params: LibraryParams, variant: Variant) -> Baked:
    """Solve and bake one variant on the plate with the pipeline's own stages."""
    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.uv.uvmesh import bake_arrays
    from crackbake.network import segments
    from crackbake.pipeline import solve

    run = RunParams(
        mesh=Path(mesh.source),
        preset=params.preset,
        impacts=() if variant.impact is None else (variant.impact,),
        seed=variant.seed,
        res=params.res,
        sim_faces=params.sim_faces,
    ).validate()
    run, relative = run.resolved()
    timings: dict[str, float] = {}
    network, _stats, _solved = solve(mesh, run, relative, timings)
    t = time.perf_counter()
    arrays = bake_arrays(uvmesh)  # with the copies of faces straying past the page
    maps = bake_cracks(
        arrays.pop("vertices"), arrays.pop("faces"), arrays.pop("uv"), segments(network),
        params.res, profile_shape=run.profile, ctx=ctx, look=run.crack_look(), seed=variant.seed,
        **arrays,
    )  # fmt: skip
    timings["bake"] = time.perf_counter() - t
    return Baked(variant, maps, len(network.cracks), timings)


def bake_variants(params: LibraryParams, chunk: list[Variant]) -> list[Baked]:
    """Bake the variants of ``chunk`` in this process, on one GL context and one plate."""
    from crackbake.bake.context import create_context
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs

    mesh = plate_mesh(params.size)
    ctx = create_context()
    try:
        uvmesh = with_tangents(prepare_uvs(mesh, "keep", params.res, cache=False, ctx=ctx))
        baked = []
        for v in chunk:
            logger.info("variant %d/%d (%s)", v.index + 1, params.n, v.name)
            baked.append(bake_variant(ctx, mesh, uvmesh, params, v))
        return baked
    finally:
        ctx.release()


def build_library(params: LibraryParams, address: str | None = None) -> dict:
    """Bake every variant and write the library folder atomically.

    ``address``: a running Ray cluster (``auto``, ``HOST:PORT``, ``ray://...``) whose workers
    bake the variants, in chunks, one fresh process each (:func:`crackbake.batch.run.map_variants`);
    the atlases are packed and written here.  Each variant depends only on (seed, index), so the
    files are the same either way.

    Returns
    -------
    dict
        The ``decals.json`` document written (plus ``timings_s``).

    Raises
    ------
    CrackbakeError
        Bad parameters or an unusable output folder (left unchanged).
    """
    from crackbake.transaction.interrupt import run_staged
    from crackbake.transaction.stage import OutputStage

    params = params.validate()
    stage = OutputStage(params.out)
    return run_staged(stage, lambda: _build(params, stage, address))


def _build(params: LibraryParams, stage, address: str | None = None) -> dict:
    """The variants' solves and bakes, then the files, inside the open ``stage``."""
    from crackbake.decals.atlas import write_library

    t0 = time.perf_counter()
    timings: dict[str, float] = {"solve": 0.0, "bake": 0.0}
    if address is None:
        baked = bake_variants(params, variants(params))
    else:
        from crackbake.batch.run import Plan, map_variants

        baked = map_variants(params, variants(params), Plan(address=address))
    for b in baked:
        timings["solve"] += sum(b.timings[k] for k in ("simmesh", "stress", "solve"))
        timings["bake"] += b.timings["bake"]
    doc = write_library(stage, params, baked, timings, t0)
    stage.commit()
    return doc


__all__ = [
    "Baked",
    "LibraryParams",
    "Variant",
    "bake_variant",
    "bake_variants",
    "build_library",
    "plate_mesh",
    "variants",
]
