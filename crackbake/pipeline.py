"""One crackbake run: the stages chained exactly as the ``crackbake`` command does.

mesh -> crack network (sidecar, or the solver) -> UVs -> GPU bake -> files.  Each stage is its
own module; this one only orders them, times them and hands one GL context to every GPU stage.
Progress is reported through :mod:`logging` (logger ``"crackbake.pipeline"``); the record that
starts a stage carries its id (``extra={"stage": ...}``, one of :data:`crackbake.progress.STAGES`).
"""

from __future__ import annotations

import logging
import re
import threading
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from crackbake.errors import CrackbakeWarning
from crackbake.io.mesh import Mesh, load_mesh
from crackbake.looks import FEWEST_CELLS, WIDTH_NOISE_SCALE, open_to_cells, vary_widths
from crackbake.params import DECAL_RES_DEFAULT, STRESS_RES_DEFAULT, RunParams
from crackbake.transaction.interrupt import run_staged
from crackbake.transaction.stage import OutputStage

if TYPE_CHECKING:
    from crackbake.bake.raster import CrackMaps
    from crackbake.bake.stress import StressMaps
    from crackbake.bake.uv import UVMesh
    from crackbake.network import CrackNetwork

# The stages' modules (GL, numba kernels, scipy, trimesh) are imported where a stage runs, not
# here: a run refused by its cheap checks (the output folder, the mesh file, the sidecar, the
# memory estimate) exits before paying for them, in a fraction of the start-up.

logger = logging.getLogger(__name__)


@dataclass(eq=False)
class Solved:
    """The solve stages' own data, kept for stress maps and inspection.

    Attributes
    ----------
    sim : crackbake.simulate.simmesh.SimMesh
        The simulation mesh as built (before cracks split it).
    field : crackbake.simulate.stress.StressField
        The initial stress field on ``sim``.
    result : crackbake.simulate.solver.SolverResult
        Final (split) sim mesh, initial and final stress, separation values, polylines.
    """

    sim: object
    field: object
    result: object


@dataclass
class RunResult:
    """What a run produced.

    Attributes
    ----------
    out_dir : Path
        Folder holding the outputs.
    files : list of dict
        ``{"name", "bytes", "sha256"}`` for every file written except the manifest.
    manifest : dict
        The content of ``manifest.json``.
    """

    out_dir: Path
    files: list[dict]
    manifest: dict
    mesh: Mesh | None = None
    network: CrackNetwork | None = None
    maps: CrackMaps | None = None
    solved: Solved | None = None
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        """Machine-readable summary (the CLI's ``--json`` output)."""
        return {
            "out_dir": str(self.out_dir),
            "files": [f["name"] for f in self.files] + ["manifest.json"],
            "mesh": self.manifest["mesh"],
            "uv": self.manifest["uv"],
            "cracks": self.manifest["cracks"],
            "timings_s": self.manifest["timings_s"],
            "warnings": self.warnings,
        }


def run(params: RunParams, *, manifest_extra: dict | None = None) -> RunResult:
    """Run crackbake end to end and write the output folder.

    The output folder is checked and locked before anything else (see :class:`OutputStage`),
    every input is checked before the solver runs, and the new set replaces the folder's
    contents in one rename at the end.  SIGINT and SIGTERM stop the run cleanly: the folder
    keeps its previous set.

    Parameters
    ----------
    params : RunParams
        Validated here.
    manifest_extra : dict, optional
        Top-level keys added to ``manifest.json`` (a batch records its job there); the other
        files are unchanged.

    Returns
    -------
    RunResult

    Raises
    ------
    CrackbakeError
        Any bad input or unusable output folder; the output folder is unchanged.
    RunInterrupted
        SIGINT or SIGTERM arrived; its message says what the output folder holds, its
        ``exit_code`` is 128 + the signal number.
    """
    params.validate()
    stage = OutputStage(params.out_dir)
    return run_staged(stage, lambda: _run(params, stage, manifest_extra or {}))


def _run(params: RunParams, stage: OutputStage, manifest_extra: dict) -> RunResult:
    """The stages in order, cheap checks first, writing into the open ``stage``."""
    timings: dict[str, float] = {}
    t_start = time.perf_counter()

    logger.info("loading %s", params.mesh, extra={"stage": "load"})
    t = time.perf_counter()
    mesh = load_mesh(params.mesh, params.object_name, params.allow_outside_textures)
    timings["load"] = time.perf_counter() - t
    # Imported once the mesh is read: the launch-to-first-stage time is imports (issue 25).
    from crackbake.memory import check_memory, estimate_peak, run_sizes
    from crackbake.simulate.setup import check_scale, stress_sources

    check_scale(mesh)  # before any work: the float32 bake cannot resolve extreme scales
    # Before the heavy stages: a run that cannot fit is refused now, not killed at 20 GB.
    sizes = run_sizes(params.resolved()[0], mesh)
    tiles = _udim_pages(mesh, params)
    if tiles > 1:  # every tile's maps are held until the write: T pages of res^2
        sizes["res"] = int(np.ceil(params.res * np.sqrt(tiles)))
    check_memory(estimate_peak(**sizes), params.max_memory)

    solver_stats: dict = {}
    solved = None
    if params.cracks is not None:
        if params.impacts and params.decal is None:  # with --decal they place the decals
            warnings.warn(
                "--impact is ignored with --cracks (the network is baked as given)",
                CrackbakeWarning,
                stacklevel=3,
            )
        logger.info("reading crack network %s", params.cracks, extra={"stage": "cracks"})
        t = time.perf_counter()
        from crackbake.io.sidecar import read_sidecar

        network = read_sidecar(params.cracks, mesh)
        timings["cracks"] = time.perf_counter() - t
    else:
        params, relative = params.resolved()
        sources = stress_sources(params, mesh, relative)  # weight maps, impacts: checked here

    from crackbake.bake.context import create_context, renderer_info

    # The inputs are checked: the bake's readback images are made now, on a thread, while the
    # start-up (EGL, the UV stage) holds the GIL on one core
    # (crackbake.bake.prefetch.ImagePrefetch); the render targets come later.
    images = _images_ahead(params, tiles)
    # One GL context for the UV check, the bake and the preview.  The UVs only depend on the
    # mesh, so they are prepared (and --uv keep refused) before the solver runs.
    try:
        ctx = create_context()
    except BaseException:
        if images is not None:
            images.close()
        raise
    targets = gutter = stress_ahead = preview_ahead = warming = None
    try:
        # A re-bake has no solver to hide the targets' allocation behind: it starts before the
        # UV stage (which then shares the machine with it); a solving run starts it after its
        # last GL call before the bake (the coverage), to run beside the solver.
        if params.cracks is not None:
            targets, images = _targets_ahead(ctx, params, tiles, images), None
        uvmesh = _uvs(ctx, mesh, params, timings)
        if uvmesh.udim is not None and targets is not None:  # pages of their own
            targets.close()
            targets = None
        gutter = _bake_ahead(ctx, uvmesh, params, timings)
        if params.cracks is None:
            warming = _warm_ahead(params, uvmesh)
            _field_kernels(warming)  # before the preview's and the solver's threads load theirs
        else:
            warming = _rebake_kernels(params, uvmesh)
        preview_ahead = _preview_ahead(mesh, uvmesh, params)
        if params.cracks is None and uvmesh.udim is None:
            targets, images = _targets_ahead(ctx, params, 1, images), None
        if params.cracks is None:
            network, solver_stats, solved = solve(mesh, params, relative, timings, sources,
                                                  warming=warming)
        # The stress bake's rows (closest asset points, nodal values: CPU only) are computed on
        # a thread while the crack bake runs; its draw waits for them.
        stress_ahead = _stress_ahead(uvmesh, solved, params)
        maps = _bake(ctx, uvmesh, network, params, timings, targets, gutter)
        # The writers are imported here, not before the UV stage: each stage imports its own
        # modules (the bake's GL and numba kernels, the stress bake's scipy.spatial) where it runs.
        from crackbake.exchange.bundle import Writer
        from crackbake.exchange.manifest import build_manifest, effective_params, write_manifest

        effective = effective_params(params, solver_stats, maps, uvmesh)
        # The crack maps' files encode on threads while the stress bake draws (issue 25);
        # leaving the block waits for every file, whatever happened inside it.
        with Writer(stage, Path(params.mesh).stem, params, mesh, uvmesh, network, maps, ctx,
                    effective, preview=preview_ahead) as writer:  # fmt: skip
            stress = _bake_stress(ctx, uvmesh, solved, params, timings, stress_ahead)
            logger.info("writing %s", params.out_dir, extra={"stage": "write"})
            t = time.perf_counter()
            writer.finish(stress)
        _decals(ctx, uvmesh, network, maps, params, stage, timings)
        files = stage.records()
        timings["write"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - t_start
        manifest = build_manifest(
            params, effective, mesh, uvmesh, network, maps, renderer_info(ctx), files, timings
        )
        manifest.update(manifest_extra)
        write_manifest(stage.path("manifest.json"), manifest)
        stage.commit()
    finally:
        for ahead in (images, targets, gutter, stress_ahead, preview_ahead, warming):
            # threads end first
            if ahead is not None:
                ahead.close()
        ctx.release()
    return RunResult(
        out_dir=Path(params.out_dir),
        files=files,
        manifest=manifest,
        mesh=mesh,
        network=network,
        maps=maps,
        solved=solved,
    )


def _udim_pages(mesh: Mesh, params: RunParams) -> int:
    """How many UDIM tiles the run will bake (1 when the UVs are not a UDIM layout), before
    the UV stage: the memory estimate counts a page per tile."""
    if mesh.uv is None or params.uv == "unwrap":
        return 1
    from crackbake.bake.uv.check import is_udim, udim_tiles

    corners = np.asarray(mesh.uv, np.float64)[mesh.faces]
    if not np.isfinite(corners).all() or not is_udim(corners, np.asarray(mesh.faces)):
        return 1
    return len(np.unique(udim_tiles(corners), axis=0))


def _uvs(ctx, mesh: Mesh, params: RunParams, timings: dict[str, float]) -> UVMesh:
    """The UV stage, timed as ``unwrap``."""
    from crackbake.jit import light_cache_loads

    light_cache_loads()  # before the first kernel: numba's loads without its compiler's set-up
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs

    logger.info("preparing UVs", extra={"stage": "unwrap"})
    t = time.perf_counter()
    uvmesh = prepare_uvs(
        mesh,
        mode=params.uv,
        res=params.res,
        padding=params.padding,
        timeout=params.unwrap_timeout,
        cache=params.cache,
        ctx=ctx,
    )
    timings["unwrap"] = time.perf_counter() - t
    t = time.perf_counter()
    # Before the bake: the normal map is encoded in exactly the frames the GLB carries.
    uvmesh = with_tangents(uvmesh, cache=params.cache)
    timings["tangents"] = time.perf_counter() - t
    return uvmesh


def _images_ahead(params: RunParams, tiles: int):
    """The crack bake's readback images (:func:`~crackbake.bake.crack_targets.image_specs`)
    made on a thread of their own (:class:`crackbake.bake.prefetch.ImagePrefetch`), for
    :func:`_targets_ahead`; None for a UDIM set (pages of their own)."""
    if tiles > 1:
        return None
    from crackbake.bake.crack_targets import image_specs
    from crackbake.bake.prefetch import ImagePrefetch

    return ImagePrefetch(image_specs(params.res, True))


def _targets_ahead(ctx, params: RunParams, tiles: int, images=None):
    """The crack bake's render targets and readback images, allocated on a thread of their own
    (:class:`crackbake.bake.prefetch.TargetPrefetch`): their sizes follow from ``--res`` and
    ``--tile`` alone, so the allocation runs beside the solver, or in a ``--cracks`` re-bake
    (no solver to hide it) beside the UV stage.  The bake's UV placement always has tangents
    (:func:`_uvs`): the normal map's targets.  None for a UDIM set (pages of their own)."""
    if tiles > 1:
        if images is not None:
            images.close()
        return None
    # Both numba-free: a re-bake starts the allocation before the bake's modules import numba.
    from crackbake.bake.crack_targets import image_specs, target_specs
    from crackbake.bake.prefetch import TargetPrefetch

    return TargetPrefetch(ctx, target_specs(params.res, params.tile, True),
                          image_specs(params.res, True), images=images)  # fmt: skip


def _field_kernels(warming: _Warming | None = None) -> None:
    """The stress field's numba kernels loaded now, on the run's thread, while no other thread
    loads any (:func:`crackbake.simulate.stress.fields.field_kernels`), then ``warming``'s
    thread let go on to the solver's: loaded at their first calls, in the field, they waited
    on numba's lock for the preview's and the solver's warm-up loads, which other threads make
    slowly while this one holds the GIL."""
    from crackbake.jit import preload
    from crackbake.simulate.stress.fields import field_kernels

    try:
        for kernel in field_kernels():
            preload(kernel)
    finally:
        if warming is not None:
            warming.loaded.set()


class _Warming:
    """The solver's warm-up thread (:func:`crackbake.simulate.warm.start`), started before
    the field's kernels load: it imports the solver meanwhile, then loads the solver's kernels
    once ``loaded`` is set, and the later stages' (``later``) while the solver runs.
    ``plate=False``: the later stages' kernels only (a re-bake's)."""

    def __init__(self, later: tuple = (), plate: bool = True) -> None:
        from crackbake.simulate import warm

        if plate:
            # The stages' own modules first, on this thread: the warm-up thread then imports
            # only the solver's, and no two threads import one package at once.  No scipy: its
            # 0.35 s of imports came for KD-trees and graph pieces (crackbake.nearest has them).
            from crackbake.simulate import simmesh, stress, timing  # noqa: F401

        self.stop = threading.Event()
        self.loaded = threading.Event()
        self.thread = warm.start(later, self.stop, self.loaded, plate)

    def close(self) -> None:
        """Stop it after the kernel it is loading and wait for it (no numba load left running
        past the run, or its error)."""
        self.loaded.set()
        self.stop.set()
        self.thread.join()


def _rebake_kernels(params: RunParams, uvmesh: UVMesh) -> _Warming | None:
    """A re-bake's later kernels: the bake's loaded now, on the run's thread, before any other
    thread loads one (as :func:`_field_kernels` does for the field), then the encoders' on a
    thread while the bake draws, as a solving run loads them beside its solver.  The encoders'
    first calls loaded them in the write stage, one at a time under numba's lock (about 0.25 s
    of loads on 2 cores).  The writer's own modules are left to the run's thread, after the
    bake; None where there are no such kernels."""
    from importlib import import_module

    from crackbake.jit import preload

    names = [name for name in _later_kernels(params, uvmesh, solving=False) if ":" in name]
    for name in names:
        if name.startswith("crackbake.bake."):
            module, _, kernel = name.partition(":")
            preload(getattr(import_module(module), kernel))
    later = tuple(name for name in names if not name.startswith("crackbake.bake."))
    if not later:
        return None
    warming = _Warming(later, plate=False)
    warming.loaded.set()
    return warming


def _warm_ahead(params: RunParams, uvmesh: UVMesh) -> _Warming | None:
    """The solver's warm-up thread for an iben run, started; None for another solver."""
    if (params.method or "iben") != "iben":
        return None
    return _Warming(_later_kernels(params, uvmesh))


def _bake_ahead(ctx, uvmesh: UVMesh, params: RunParams, timings: dict[str, float]):
    """The crack bake's gutter fill, planned from the faces' coverage on a thread of its own
    to run beside the solver (:class:`crackbake.bake.dilation.PlanAhead`; the coverage draw
    timed as ``coverage``).  None for a UDIM set."""
    if uvmesh.udim is not None:
        return None
    from crackbake.bake.dilation import PlanAhead
    from crackbake.bake.raster import coverage
    from crackbake.bake.uv.uvmesh import bake_arrays

    t = time.perf_counter()
    arrays = bake_arrays(uvmesh)
    with_normals = arrays["tangents"] is not None
    inside = coverage(ctx, arrays["uv"], arrays["faces"], params.res, params.tile, with_normals)
    gutter = PlanAhead(inside, params.dilate, cache=params.cache)
    timings["coverage"] = time.perf_counter() - t
    return gutter


def _bake(
    ctx, uvmesh: UVMesh, network: CrackNetwork, params: RunParams, timings: dict[str, float],
    targets=None, gutter=None,
) -> CrackMaps:
    """The GPU bake, timed as ``bake``."""
    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.uv.uvmesh import bake_arrays
    from crackbake.network import segments

    logger.info("baking %dx%d", params.res, params.res, extra={"stage": "bake"})
    t = time.perf_counter()
    # The faces plus the copies of faces straying past the page, wrapped where engines show them.
    arrays = bake_arrays(uvmesh)
    if uvmesh.udim is not None:  # one page per UDIM tile, the whole network on each
        from crackbake.bake.udim import bake_udim

        maps = bake_udim(
            arrays, uvmesh.udim, segments(network), params.res,
            max_distance=params.max_distance, profile_shape=params.profile,
            min_px=params.min_px, dilate_px=params.dilate, tile=params.tile, ctx=ctx,
            look=params.crack_look(), seed=params.seed,
        )  # fmt: skip
        timings["bake"] = time.perf_counter() - t
        return maps
    maps = bake_cracks(
        arrays["vertices"],
        arrays["faces"],
        arrays["uv"],
        segments(network),
        params.res,
        max_distance=params.max_distance,
        profile_shape=params.profile,
        min_px=params.min_px,
        dilate_px=params.dilate,
        tile=params.tile,
        ctx=ctx,
        normals=arrays["normals"],
        tangents=arrays["tangents"],
        look=params.crack_look(),
        seed=params.seed,
        targets=targets,
        gutter=gutter,
    )
    timings["bake"] = time.perf_counter() - t
    return maps


def _decals(ctx, uvmesh, network, maps, params: RunParams, stage, timings) -> None:
    """One projected decal per impact (``--decal``) and ``decals.json``, timed as ``decals``."""
    if params.decal is None:
        return
    from crackbake.decals.files import write_decal_set
    from crackbake.decals.projector import bake_decals
    from crackbake.exchange.targets import normal_convention
    from crackbake.network import segments

    logger.info("baking %d decal(s)", len(params.impacts), extra={"stage": "decals"})
    t = time.perf_counter()
    res = params.decal_res or min(params.res, DECAL_RES_DEFAULT)
    decals = bake_decals(uvmesh, segments(network), maps, params.impacts, params.decal, res,
                         params.tile, ctx)  # fmt: skip
    write_decal_set(stage.path, decals, normal_convention(params.target, params.normal_y))
    timings["decals"] = time.perf_counter() - t


class _Ahead:
    """``fn(*args)`` on a thread of its own, started now: later work that needs no GL and
    does not wait on what the run's thread does meanwhile.  It raises no warning (they would
    land in whatever the run's thread is recording)."""

    def __init__(self, name: str, fn, *args) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self._pool = ThreadPoolExecutor(1, thread_name_prefix=f"crackbake-{name}")
        self.future = self._pool.submit(fn, *args)

    def result(self):
        """Its result (the thread's error, if it failed)."""
        return self.future.result()

    def close(self) -> None:
        """Wait for the thread (a run never leaves it running)."""
        self._pool.shutdown(wait=True, cancel_futures=True)


def _stress_ahead(uvmesh: UVMesh, solved: Solved | None, params: RunParams) -> _Ahead | None:
    """The stress bake's rows (:func:`crackbake.bake.stress.stress_rows`) started on a
    thread, or None where the run bakes no stress, or pages of a UDIM set (each tile its own
    rows)."""
    if solved is None or "stress" not in params.formats or uvmesh.udim is not None:
        return None
    from crackbake.bake.stress import stress_rows

    return _Ahead("stress", stress_rows, uvmesh, solved.result, uvmesh.tangents, solved.sim)


def _preview_ahead(mesh: Mesh, uvmesh: UVMesh, params: RunParams) -> _Ahead | None:
    """The preview's mesh-only work (:func:`crackbake.bake.preview.preview_ahead`: its up axis,
    the faces' cross products and the views' area scores, its culling check), worked out on a
    thread while the run solves; None without a preview, or for pages of a UDIM set."""
    if "preview" not in params.formats or uvmesh.udim is not None:
        return None
    from crackbake.bake.preview import preview_ahead

    return _Ahead("preview", preview_ahead, mesh, uvmesh.vertices, uvmesh.faces, params.up,
                  params.cache)


def _bake_stress(
    ctx, uvmesh: UVMesh, solved: Solved | None, params: RunParams, timings: dict[str, float],
    ahead: _Ahead | None = None,
) -> StressMaps | None:
    """The stress-field maps, timed as ``stress_bake``; None when nothing was solved.
    ``ahead``: their rows, started on a thread (:func:`_stress_ahead`)."""
    if solved is None or "stress" not in params.formats:
        return None  # a --cracks re-bake has no stress field
    from crackbake.bake.stress import bake_stress

    res = params.stress_res or min(params.res, STRESS_RES_DEFAULT)
    logger.info("baking the stress field %dx%d", res, res, extra={"stage": "stress_bake"})
    t = time.perf_counter()
    if uvmesh.udim is not None:  # a page per tile, the tile moved onto the 0-1 page
        from crackbake.bake.udim import tile_uvmesh

        pages = [
            bake_stress(tile_uvmesh(uvmesh, tile), solved.result, res, tangents=uvmesh.tangents,
                        initial=solved.sim, dilate_px=params.dilate, tile=params.tile, ctx=ctx)
            for tile in uvmesh.udim
        ]  # fmt: skip
        timings["stress_bake"] = time.perf_counter() - t
        return pages
    stress = bake_stress(
        uvmesh,
        solved.result,
        res,
        tangents=uvmesh.tangents,
        initial=solved.sim,
        dilate_px=params.dilate,
        tile=params.tile,
        ctx=ctx,
        rows=None if ahead is None else ahead.result(),
    )
    timings["stress_bake"] = time.perf_counter() - t
    return stress


def solve(
    mesh: Mesh,
    params: RunParams,
    relative: dict,
    timings: dict[str, float],
    sources: list | None = None,
    later: tuple = (),
    warming: _Warming | None = None,
) -> tuple[CrackNetwork, dict, Solved]:
    """Simulation mesh, stress field and crack solver: the network for a resolved run.

    Stage times are added to ``timings`` (``simmesh``, ``stress``, ``solve``).  ``sources``
    are the run's :func:`~crackbake.simulate.setup.stress_sources` when the caller built them.
    ``later``: numba kernels of the stages after it, loaded from the cache on the solver's
    warm-up thread once it is done (:func:`crackbake.simulate.warm.start`).  ``warming``: that
    thread, started by the caller (the pipeline starts it before the field's kernels load);
    closed here either way.

    Returns
    -------
    network : CrackNetwork
    stats : dict
        JSON-ready solver figures for the manifest.
    solved : Solved
        Sim mesh, stress field and the solver's full result.
    """
    if sources is None:
        from crackbake.simulate.setup import stress_sources

        sources = stress_sources(params, mesh, relative)
    if warming is None and (params.method or "iben") == "iben":
        # The solver's kernels load on a thread while the sim mesh and the field are built,
        # then the later stages' while it solves.
        warming = _Warming(later)
        warming.loaded.set()
    try:
        return _solve(mesh, params, relative, timings, sources)
    finally:
        if warming is not None:  # no numba load left running past the run (or its error)
            warming.close()
        from crackbake.geometry import forget

        forget()  # the sim mesh's memoised edges, shells and patches: this run's only


def _later_kernels(params: RunParams, uvmesh: UVMesh, solving: bool = True) -> tuple[str, ...]:
    """The numba kernels a UV-placed bake of ``params`` calls after the solver, for the warm-up
    thread to load from the cache while the solver runs: the bake's and the stress bake's
    (on the run's thread), the encoders' (the write threads, whose first calls each loaded under
    numba's one compiler lock, 0.4 s serialised); then the writer's modules.  Named
    (``"module:kernel"``, ``"module"``), not imported: their modules import on that thread too,
    not on the run's (16 ms of CPU, 26-54 ms of the run's thread with its waits for the GIL).
    Empty for UDIM pages and projected decals (other kernels).  ``solving=False``: a re-bake's
    (no solve's end, no stress bake)."""
    if uvmesh.udim is not None or params.decal is not None:
        return ()
    b, x = "crackbake.bake.", "crackbake.exchange."
    later = []
    if solving:  # the solve's end (the arrival times, the star check) first
        later += ["crackbake.simulate.timing:_arrival", "crackbake.nearest:_grid",
                  "crackbake.nearest:_query"]
    # then the bake's
    later += [b + "grid:_bin_candidates", b + "grid:slice_members", b + "normal_map:crack_texels",
              b + "dilation:_gather"]
    formats = set(params.formats)
    if solving and "stress" in formats:
        later += [b + "stress_fields:_node_sums", b + "stress_fields:_corner_rows",
                  b + "dilation:_nearest_row_per_column", b + "dilation:_nearest_source",
                  b + "stress:_fill_principal"]  # fmt: skip
    if "exr" in formats or (solving and "stress" in formats):
        later += [x + "exrzip:_to_half", x + "exrzip:_predict_channel",
                  x + "stats_kernels:float_stats", x + "stats_kernels:half_stats"]
    if {"png", "glb", "preview", "usd", "usdz"} & formats:
        later += [x + "packing:_data16_band", x + "halving:_base_color_half",
                  x + "halving:_normal_half", x + "halving:_mip_half", x + "packing:_base_color",
                  x + "packing:_normal_q", x + "packing:_lut_planes", x + "packing:_take",
                  x + "packing:_quantise"]  # fmt: skip
    if "preview" in formats:
        later.append("crackbake.geometry_kernels:facing_sum_kernel")
    # the write stage's modules last (about 30 ms of imports, OpenEXR's bindings among them)
    later += [x + "bundle", x + "manifest"]
    return tuple(later)


def _solve(mesh: Mesh, params: RunParams, relative: dict, timings: dict[str, float],
           sources: list) -> tuple[CrackNetwork, dict, Solved]:
    """:func:`solve` once the sources are built and the solver's kernels are loading."""
    from crackbake.io.sidecar import jsonable
    from crackbake.network import from_solver
    from crackbake.simulate.setup import sidecar_params, solver_params, with_spacing
    from crackbake.simulate.simmesh import build_simmesh, onto_asset
    from crackbake.simulate.stress import impact_refinement, noise_origin, stress_field
    from crackbake.simulate.timing import grow_from_impacts

    logger.info("building the simulation mesh", extra={"stage": "simmesh"})
    t = time.perf_counter()
    # Held back until the sim mesh is final: a rebuild for a thin feature repeats them.
    first: list = []
    second: list = []
    try:
        with warnings.catch_warnings(record=True) as first:
            sim = build_simmesh(mesh, detail=params.detail, target_faces=params.sim_faces,
                                seed=params.seed, proxy_above=params.proxy_above,
                                cache=params.cache)
            timings["simmesh"] = time.perf_counter() - t
            logger.info("stress field on %d simulation faces", len(sim.faces),
                        extra={"stage": "stress"})
            t = time.perf_counter()
            field = stress_field(sim, mesh, sources, seed=params.seed)
        local = None if relative.get("sim_size_set") else impact_refinement(field, sim)
        if local is not None:
            sources = _fitted_sources(sources, field)
            # An impact on a thin feature: its star needs a finer sim mesh, round it only (the
            # other impacts' stars keep theirs).
            logger.info("impact(s) on a thin feature: sim edge %.4g -> %s within %s",
                        sim.edge_length, ", ".join(f"{h:.4g}" for h in local.edges),
                        ", ".join(f"{r:.3g}" for r in local.radii))
            with warnings.catch_warnings(record=True) as second:
                origin = noise_origin(sim)
                sim = build_simmesh(mesh, detail=sim.edge_length, seed=params.seed,
                                    proxy=sim.proxy, proxy_above=params.proxy_above, local=local,
                                    cache=params.cache)
                field = stress_field(sim, mesh, sources, seed=params.seed, noise_origin=origin)
    finally:
        _warn_once(first, second)
    field = with_spacing(field, params, mesh.diagonal)
    timings["stress"] = time.perf_counter() - t
    sp = solver_params(params, mesh, relative)
    logger.info("growing cracks (%s)", sp.method, extra={"stage": "solve"})
    if sim.proxy is not None:
        # The asset's AABB tree, which the cracks are moved onto after the solve, is built
        # meanwhile in a child process (libigl holds the GIL through the build: 2.6 s at 1.5M
        # faces); started now, not with the cached sim mesh, so it does not slow the field.
        sim.proxy.surface.start_worker()
    t = time.perf_counter()
    try:
        result = _grow(sim, field, sp)
    except BaseException:
        if sim.proxy is not None:  # no query will come: no worker left waiting for one
            sim.proxy.surface.stop_worker()
        raise
    timings["solve"] = time.perf_counter() - t
    logger.info(
        "%s cracks started, %d polylines, %s steps%s",
        result.stats.get("cracks", len(result.cracks)),
        len(result.cracks),
        result.steps,
        f" ({result.stats['stopped']})" if "stopped" in result.stats else "",
    )
    effective = params.to_dict()
    effective.update(
        {
            "crack_width": sp.crack_width,
            "sim_faces_built": int(len(sim.faces)),
            "sim_edge_length": float(sim.edge_length),
            "sim_proxy_faces": 0 if sim.proxy is None else int(len(sim.proxy.faces)),
        }
    )
    network = from_solver(
        onto_asset(result.cracks, sim.proxy),  # cracks grown on a proxy move onto the asset
        mesh,
        params=sidecar_params(effective),
        impacts=field.impacts,
        solver_steps=result.steps,
    )
    if params.cycles > 1:
        from crackbake.simulate.cycles import redry

        logger.info("%d drying cycles", params.cycles)
        t = time.perf_counter()
        network = redry(network, mesh.vertices, mesh.faces, params.cycles, params.seed)
        timings["cycles"] = time.perf_counter() - t
    network = grow_from_impacts(network)  # crack.time grows out of the impact (timing.py)
    _warn_no_star(network, sim, sources)
    look = params.crack_look()
    # Widths that swell and narrow along each crack (the look's width_variation), in the
    # network itself so cracks.json, crack.width and the drawn maps agree.
    network = vary_widths(network, look.width_variation, params.seed,
                          WIDTH_NOISE_SCALE * mesh.diagonal)
    share = relative.get("crack_width_cell")
    if share is not None and params.crack_width is None:
        _open_to_cells(network, share, mesh, params.preset)
    stats = {k: v for k, v in result.stats.items() if not k.startswith("time")}
    stats.update({"sim_faces": int(len(sim.faces)), "steps": int(result.steps)})
    return network, jsonable(stats), Solved(sim=sim, field=field, result=result)


def _open_to_cells(network: CrackNetwork, share: float, mesh: Mesh, preset: str | None) -> None:
    """The preset's gaps sized by the cells the cracks cut (:func:`crackbake.looks.open_to_cells`),
    the sidecar's ``crack_width`` (the solver's widest opening) scaled with them; a warning where
    too few cells leave the widths at the preset's ``crack_width_rel``."""
    factor, cells = open_to_cells(network, share, mesh.vertices, mesh.faces)
    if cells < FEWEST_CELLS:
        warnings.warn(
            f"preset {preset} opens its cracks {share:.1%} of the cell size, but they cut only "
            f"{cells} cell(s) (fewer than {FEWEST_CELLS}): the widths stay at the preset's "
            "crack_width_rel of the diagonal; give --crack-width to set them",
            CrackbakeWarning, stacklevel=2)
        return
    # The solver's widest opening as it would have been given (--crack-width), before the noise.
    network.params["crack_width"] = float(network.params["crack_width"]) * factor
    logger.info("widths sized by %d cells: x %.3g (mean width %.1f %% of the cell size)",
                cells, factor, 100 * share, extra={"stage": "solve"})


def _fitted_sources(sources: list, field) -> list:
    """``sources`` with each impact's radius the one ``field`` used (a default radius fitted
    to a thin feature): a rebuilt sim mesh keeps the radius the refinement was sized for."""
    from dataclasses import replace

    from crackbake.simulate.stress import ImpactSource

    out = []
    used = iter(field.impacts)
    for s in sources:
        if isinstance(s, ImpactSource):
            radius = next(used)["radius"]
            s = replace(s, radius=radius, fit=None) if s.fit else s
        out.append(s)
    return out


def _warn_kind(w) -> tuple:
    """A warning's category and text with its numbers blanked: the same warning about a
    rebuilt sim mesh differs only in figures (a snapped point, an edge length)."""
    return w.category, re.sub(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", "#", str(w.message))


def _warn_once(first: list, second: list) -> None:
    """Re-issue the warnings of the first sim mesh and, when it was rebuilt, of the second, each
    kind once: a kind both gave is said as the rebuilt mesh says it (the figures the run used),
    in the first's order."""
    latest = {_warn_kind(w): w for w in second}
    said = set()
    for w in [*first, *second]:
        kind = _warn_kind(w)
        if kind in said:
            continue
        said.add(kind)
        w = latest.get(kind, w)
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)


def _warn_no_star(network: CrackNetwork, sim, sources: list) -> None:
    """One warning for the impacts that grew no star (too few radial arms cross the circle at
    0.3 of their reach, :func:`crackbake.metrics.star.missing_stars`, over touching shells
    as one surface) and one for those whose arms wander (a web of cells, not a star:
    :func:`crackbake.metrics.star.web_stars`), when impacts are the only stress: shrinkage,
    tension or curvature terms grow cell webs on purpose."""
    from crackbake.metrics.star import (
        STAR_MIN_ARMS,
        STAR_MIN_EDGES,
        impact_reach,
        missing_stars,
        star_checks,
        web_stars,
    )
    from crackbake.simulate.stress import CurvatureSource, DirectionalSource, ShrinkSource

    if not network.impacts or any(
        isinstance(s, (ShrinkSource, DirectionalSource, CurvatureSource)) for s in sources
    ):
        return
    # Over touching shells as one surface, as the solver cracks them: an eye's own short
    # cracks crossing the circle where its shell ends must not count as a star's arms.
    checks = star_checks(network, sim.vertices, sim.faces, link=float(sim.edge_length))
    _warn_web(web_stars(network, checks=checks), sim)
    missing = missing_stars(network, checks=checks)
    if not missing:
        return
    said = "; ".join(
        f"({', '.join(f'{float(x):.4g}' for x in imp['point'])}) {arms}" for imp, arms in missing
    )
    radius = min(imp["radius"] for imp, _ in missing)
    edge = float(sim.edge_length)
    spans = 0.3 * impact_reach(radius) / max(edge, 1e-300)
    if spans < STAR_MIN_EDGES:  # the sim mesh cannot resolve the arms
        why = (f"the sim mesh is too coarse ({spans:.1f} edges across that circle): give a finer "
               f"--detail (about {0.3 * impact_reach(radius) / (2 * STAR_MIN_EDGES):.3g}) or a "
               "larger radius")
    else:
        why = (f"the surface there is likely narrower than the star: give a smaller radius "
               f"(--impact X,Y,Z:{0.5 * radius:.3g}), a broader point, or a finer --detail "
               f"(now {edge:.3g})")
    warnings.warn(
        f"no star formed at {len(missing)} impact(s) (radial arms at 0.3 reach, a star has "
        f"{STAR_MIN_ARMS} or more): {said}; {why}",
        CrackbakeWarning,
        stacklevel=3,
    )


def _warn_web(webs: list, sim) -> None:
    """One line per impact whose arms wander (``web_stars``' entries): a web of cells grew
    where a star should, with its likely cause and fix.  Where the surface turns sharply within
    the star's reach (suzanne's low-poly brow between the eyes; subdivided, the same point grows
    a star) the fold; on a smooth part simulated on too coarse a sim mesh (a plate on 5,000 sim
    faces) the sim mesh; else neither, and another seed or radius."""
    from crackbake.metrics.star import (
        STAR_MIN_RADIAL,
        WEB_FOLD_DEG,
        WEB_MIN_EDGES,
        impact_reach,
        surface_fold,
    )

    edge = max(float(sim.edge_length), 1e-300)
    for imp, _, radial in webs:
        at = ",".join(f"{float(x) + 0.0:.4g}" for x in imp["point"])
        within = 0.3 * impact_reach(imp["radius"])
        fold = surface_fold(sim.vertices, sim.faces, imp["point"], within)
        spans = within / edge
        if fold >= WEB_FOLD_DEG:
            why = (f"where the surface folds sharply (it turns {fold:.0f} degrees within the "
                   "star's reach); give a point on a smoother part, or subdivide the mesh")
        elif spans < WEB_MIN_EDGES:
            finer = within / (1.5 * WEB_MIN_EDGES)
            more = len(sim.faces) * (edge / finer) ** 2
            why = (f"where the sim mesh is too coarse ({spans:.1f} edges across the star's "
                   f"reach): give --sim-faces {_round_up(more)} or a finer --detail "
                   f"(about {finer:.3g})")
        else:
            why = "on a smooth, finely meshed part; give another --seed or a larger radius"
        warnings.warn(
            f"the impact at ({at}) grew a web of cells, not a star: its arms wander (straightness "
            f"{radial:.2f}, a star's over {STAR_MIN_RADIAL:.2f}) {why}",
            CrackbakeWarning,
            stacklevel=4,
        )


def _round_up(n: float) -> int:
    """``n`` rounded up to two significant figures (a face count to suggest)."""
    step = 10 ** max(int(np.floor(np.log10(max(n, 1.0)))) - 1, 0)
    return int(np.ceil(n / step) * step)


def _grow(sim, field, sp):
    """Run the solver ``sp.method`` names; warn when iben stopped at its step limit."""
    if sp.method == "thesis":
        from crackbake.simulate.solver.thesis import solve_thesis

        return solve_thesis(sim, field, sp)
    from crackbake.simulate.solver.iben import solve_iben

    result = solve_iben(sim, field, sp)
    if result.stats.get("stopped") == "max steps":
        warnings.warn(
            f"the solver stopped at --max-steps {sp.max_steps} with cracks still growing; "
            "raise --max-steps for the complete pattern",
            CrackbakeWarning,
            stacklevel=3,
        )
    return result
