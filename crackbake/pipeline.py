"""One crackbake run: the stages chained exactly as the ``crackbake`` command does.

mesh -> crack network (sidecar, or the solver) -> UVs -> GPU bake -> files.  Each stage is its
own module; this one only orders them, times them and decides what gets written.
"""

from __future__ import annotations

import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from crackbake import __version__
from crackbake.bake.context import create_context, renderer_info
from crackbake.bake.preview import render_preview
from crackbake.bake.raster import CHANNELS, CrackMaps, bake_cracks
from crackbake.bake.uv import UVMesh, prepare_uvs
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.exchange.exr import write_exr
from crackbake.exchange.glb import write_glb
from crackbake.exchange.materials import GLB_TEXTURE_MAX, base_color
from crackbake.exchange.output import OutputStage, sha256_file
from crackbake.exchange.png import write_png
from crackbake.io.mesh import Mesh, load_mesh
from crackbake.io.obj_lines import write_obj
from crackbake.io.sidecar import jsonable, read_sidecar, write_sidecar
from crackbake.network import CrackNetwork, from_solver, segments
from crackbake.params import RunParams, preset_names
from crackbake.simulate.solver import SolverParams

ProgressFn = Callable[[str], None]


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


def preview_direction(mesh: Mesh, network: CrackNetwork) -> tuple[float, float, float]:
    """The camera direction (from the mesh towards the camera) that shows the most cracks.

    Candidates are the 17 directions of the upper half of a cube's corners, edges and faces
    (y is up), tilted 20 degrees upwards; each scores the crack length facing it, with the
    mesh area facing it breaking ties (and choosing the view when there are no cracks).
    """
    cand = np.array(
        [
            (x, y, z)
            for x in (-1, 0, 1)
            for y in (0, 1)
            for z in (-1, 0, 1)
            if (x, y, z) != (0, 0, 0)
        ],
        float,
    )
    cand /= np.linalg.norm(cand, axis=1, keepdims=True)
    cand[:, 1] += np.tan(np.radians(20))
    cand /= np.linalg.norm(cand, axis=1, keepdims=True)
    tri = mesh.vertices[mesh.faces]
    area_normals = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    score = np.maximum(area_normals @ cand.T, 0).sum(axis=0)
    score = 1e-3 * score / max(score.max(), 1e-300)
    if network.cracks:
        unit = area_normals / np.maximum(
            np.linalg.norm(area_normals, axis=1, keepdims=True), 1e-300
        )
        for crack in network.cracks:
            seg = np.linalg.norm(np.diff(crack.points, axis=0), axis=1)
            n = unit[crack.faces[:-1]]
            score += (seg[:, None] * np.maximum(n @ cand.T, 0)).sum(axis=0)
    return tuple(float(x) for x in cand[int(np.argmax(score))])


def _exr_channels(maps: CrackMaps, float32: bool) -> dict[str, np.ndarray]:
    chans = maps.channels()
    if float32:
        return {k: v.astype(np.float32, copy=False) for k, v in chans.items()}
    # Types follow CHANNELS: half for bounded data, float where range or precision needs it.
    out = {}
    for name, arr in chans.items():
        want = np.float16 if CHANNELS[name] == "half" else np.float32
        out[name] = arr if arr.dtype == want else arr.astype(want)
    return out


def run(params: RunParams, progress: ProgressFn | None = None) -> RunResult:
    """Run crackbake end to end and write the output folder.

    Parameters
    ----------
    params : RunParams
        Validated here.
    progress : callable, optional
        Called with a short message at the start of each stage.

    Returns
    -------
    RunResult

    Raises
    ------
    CrackbakeError
        Any bad input; nothing is left under a final output name.
    """
    say = progress or (lambda _msg: None)
    params.validate()
    timings: dict[str, float] = {}
    t_start = time.perf_counter()

    say(f"loading {params.mesh}")
    t = time.perf_counter()
    mesh = load_mesh(params.mesh, params.object_name)
    timings["load"] = time.perf_counter() - t

    solver_stats: dict = {}
    solved = None
    if params.cracks is not None:
        if params.impacts:
            warnings.warn(
                "--impact is ignored with --cracks (the network is baked as given)",
                CrackbakeWarning,
                stacklevel=2,
            )
        say(f"reading crack network {params.cracks}")
        t = time.perf_counter()
        network = read_sidecar(params.cracks, mesh)
        timings["cracks"] = time.perf_counter() - t
    else:
        params, relative = params.resolved()
        network, solver_stats, solved = solve(mesh, params, relative, say, timings)

    say("preparing UVs")
    t = time.perf_counter()
    uvmesh: UVMesh = prepare_uvs(
        mesh,
        mode=params.uv,
        res=params.res,
        padding=params.padding,
        timeout=params.unwrap_timeout,
        cache=params.cache,
    )
    timings["unwrap"] = time.perf_counter() - t

    say(f"baking {params.res}x{params.res}")
    t = time.perf_counter()
    ctx = create_context()
    try:
        gl_info = renderer_info(ctx)
        maps = bake_cracks(
            uvmesh.vertices,
            uvmesh.faces,
            uvmesh.uv,
            segments(network),
            params.res,
            max_distance=params.max_distance,
            profile_shape=params.profile,
            dilate_px=params.dilate,
            tile=params.tile,
            ctx=ctx,
        )
    finally:
        ctx.release()
    timings["bake"] = time.perf_counter() - t

    say(f"writing {params.out_dir}")
    t = time.perf_counter()
    out_dir = Path(params.out_dir)
    stem = Path(params.mesh).stem
    depth_max = float(maps.depth.max())
    effective = params.to_dict()
    if solver_stats:
        effective["solver"] = solver_stats
    effective.update(
        {
            "max_distance": maps.max_distance,
            "padding": uvmesh.padding_px,
            "uv_method": uvmesh.method,
        }
    )
    with OutputStage(out_dir) as stage:
        write_outputs(stage, stem, params, mesh, uvmesh, network, maps)
        files = stage.records()
        timings["write"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - t_start
        manifest = {
            "crackbake": __version__,
            "inputs": _inputs(params),
            "params": effective,
            "mesh": mesh.describe(),
            "uv": {
                "method": uvmesh.method,
                "vertices": int(len(uvmesh.vertices)),
                "overlap_fraction": float(uvmesh.overlap_fraction),
                "padding_px": int(uvmesh.padding_px),
            },
            "cracks": network.stats(),
            "maps": {
                "resolution": params.res,
                "depth_png_scale": depth_max,
                "max_distance": maps.max_distance,
                "covered_fraction": float(maps.inside.mean()),
                "exr_channels": {
                    k: ("float" if params.float32 else v) for k, v in CHANNELS.items()
                },
            },
            "renderer": gl_info,
            "files": files,
            "timings_s": {k: round(v, 4) for k, v in timings.items()},
        }
        Path(stage.path("manifest.json")).write_text(json.dumps(manifest, indent=2) + "\n")
        stage.commit(last=("manifest.json",))
    return RunResult(
        out_dir=out_dir,
        files=files,
        manifest=manifest,
        mesh=mesh,
        network=network,
        maps=maps,
        solved=solved,
    )


def stress_sources(params: RunParams, mesh: Mesh, relative: dict) -> list:
    """The stress sources a (resolved) parameter set asks for.

    Raises
    ------
    CrackbakeError
        When nothing would load the surface, or a preset needs an impact that is missing.
    """
    from crackbake.simulate.stress import (
        CurvatureSource,
        DirectionalSource,
        ImpactSource,
        NoiseSource,
        ShrinkSource,
        WeightSource,
        load_weight_map,
        vertex_weights,
    )

    if relative.get("needs_impact") and not params.impacts:
        raise CrackbakeError(
            f"preset '{params.preset}' needs an impact point; add --impact X,Y,Z "
            "(a point on or near the surface, mesh units)"
        )
    diagonal = mesh.diagonal
    sources: list = []
    for imp in params.impacts:
        radius = imp.radius
        if radius is None:
            radius = relative.get("impact_radius_rel", 0.15) * diagonal
        sources.append(ImpactSource(imp.point, radius, imp.strength, hoop=params.hoop))
    if params.shrink:
        sources.append(ShrinkSource(params.shrink, params.shrink_rate or 0.0))
    for x, y, z, strength in params.directions:
        sources.append(DirectionalSource((x, y, z), strength))
    if params.curvature_bias or params.curvature_density:
        sources.append(
            CurvatureSource(params.curvature_bias or 0.0, params.curvature_density or 0.0)
        )
    if not sources:
        raise CrackbakeError(
            "nothing to crack: give --impact X,Y,Z, --shrink S, --direction X,Y,Z, --curvature B "
            f"or a --preset ({', '.join(preset_names())}), or bake a network with --cracks"
        )
    if params.weight_map is not None or params.weight_attribute is not None:
        per_vertex = (
            vertex_weights(params.mesh, params.weight_attribute, params.object_name)
            if params.weight_attribute is not None
            else None
        )
        image = load_weight_map(params.weight_map) if params.weight_map is not None else None
        sources.append(WeightSource(per_vertex, image, params.weight_invert))
    if params.noise:
        sources.append(NoiseSource(params.noise))
    return sources


def solver_params(params: RunParams, mesh: Mesh, relative: dict) -> SolverParams:
    """:class:`SolverParams` from a resolved parameter set (relative widths made absolute)."""
    width = params.crack_width
    if width is None:
        width = relative.get("crack_width_rel", 0.001) * mesh.diagonal
    return SolverParams(
        method=params.method or "iben",
        toughness=params.toughness,
        tip_factor=params.tip_factor,
        relax_steps=params.relax_steps,
        relax_rate=params.relax_rate,
        relax_share=params.relax_share,
        max_cracks=params.max_cracks,
        max_steps=params.max_steps,
        max_crack_length=params.max_crack_length,
        crack_width=width,
        depth_ratio=params.depth_ratio,
        seed=params.seed,
    )


def solve(
    mesh: Mesh,
    params: RunParams,
    relative: dict,
    say: ProgressFn,
    timings: dict[str, float],
) -> tuple[CrackNetwork, dict, Solved]:
    """Simulation mesh, stress field and crack solver: the network for a resolved run.

    Stage times are added to ``timings`` (``simmesh``, ``stress``, ``solve``).

    Returns
    -------
    network : CrackNetwork
    stats : dict
        JSON-ready solver figures for the manifest.
    solved : Solved
        Sim mesh, stress field and the solver's full result.
    """
    from crackbake.simulate.simmesh import build_simmesh
    from crackbake.simulate.stress import stress_field

    sources = stress_sources(params, mesh, relative)
    say("building the simulation mesh")
    t = time.perf_counter()
    sim = build_simmesh(mesh, detail=params.detail, target_faces=params.sim_faces, seed=params.seed)
    timings["simmesh"] = time.perf_counter() - t
    say(f"stress field on {len(sim.faces)} simulation faces")
    t = time.perf_counter()
    field = stress_field(sim, mesh, sources, seed=params.seed)
    timings["stress"] = time.perf_counter() - t
    sp = solver_params(params, mesh, relative)
    say(f"growing cracks ({sp.method})")
    t = time.perf_counter()
    if sp.method == "thesis":
        from crackbake.simulate.solver.thesis import solve_thesis

        result = solve_thesis(sim, field, sp, progress=say)
    else:
        from crackbake.simulate.solver.iben import solve_iben

        result = solve_iben(sim, field, sp, progress=say)
        if result.stats.get("stopped") == "max steps":
            warnings.warn(
                f"the solver stopped at --max-steps {sp.max_steps} with cracks still growing; "
                "raise --max-steps for the complete pattern",
                CrackbakeWarning,
                stacklevel=2,
            )
    timings["solve"] = time.perf_counter() - t
    say(f"{result.stats.get('cracks', len(result.cracks))} cracks started, "
        f"{len(result.cracks)} polylines, {result.steps} steps"
        + (f" ({result.stats['stopped']})" if "stopped" in result.stats else ""))
    effective = params.to_dict()
    effective.update(
        {
            "crack_width": sp.crack_width,
            "sim_faces_built": int(len(sim.faces)),
            "sim_edge_length": float(sim.edge_length),
        }
    )
    network = from_solver(
        result.cracks,
        mesh,
        params=_sidecar_params(effective),
        impacts=field.impacts,
        solver_steps=result.steps,
    )
    stats = {k: v for k, v in result.stats.items() if not k.startswith("time")}
    stats.update({"sim_faces": int(len(sim.faces)), "steps": int(result.steps)})
    return network, jsonable(stats), Solved(sim=sim, field=field, result=result)


def _sidecar_params(effective: dict) -> dict:
    """Parameters stored in the sidecar: everything that shapes the network, no output paths."""
    drop = {
        "out",
        "formats",
        "float32",
        "unwrap_timeout",
        "cache",
        "tile",
        "res",
        "padding",
        "dilate",
        "max_distance",
        "profile",
        "cracks",
    }
    return jsonable({k: v for k, v in effective.items() if k not in drop})


def write_outputs(
    stage: OutputStage,
    stem: str,
    params: RunParams,
    mesh: Mesh,
    uvmesh: UVMesh,
    network: CrackNetwork,
    maps: CrackMaps,
) -> None:
    """Write the requested maps, the GLB, the preview and the network into ``stage``.

    Parameters
    ----------
    stage : OutputStage
        Staging folder; nothing reaches its final name until the caller commits.
    stem : str
        Prefix of the map file names (the mesh file's stem).
    params : RunParams
        ``formats`` and ``float32`` decide what is written.
    mesh, uvmesh, network, maps
        The stages' results.
    """
    depth_max = float(maps.depth.max())
    if "exr" in params.formats:
        write_exr(
            stage.path(f"{stem}_cracks.exr"),
            _exr_channels(maps, params.float32),
            attributes={
                "crackbake:version": __version__,
                "crackbake:units": "mesh",
                "crackbake:uvConvention": "texel (0,0) is UV (0,1): v up, top row first",
                "crackbake:depthProfile": f"V exponent {maps.profile_shape:g}",
                "crackbake:maxDistance": float(maps.max_distance),
            },
        )
    if "png" in params.formats:
        write_png(stage.path(f"{stem}_mask.png"), maps.mask, bits=8)
        scale = depth_max if depth_max > 0 else 1.0
        write_png(stage.path(f"{stem}_depth.png"), maps.depth / scale, bits=16)
    if "glb" in params.formats:
        write_glb(
            stage.path(f"{stem}.glb"),
            uvmesh.vertices,
            uvmesh.faces,
            uvmesh.uv,
            uvmesh.normals,
            base_color(maps.mask, GLB_TEXTURE_MAX),
            name=stem,
        )
    if "preview" in params.formats:
        write_png(
            stage.path("preview.png"),
            render_preview(
                uvmesh.vertices,
                uvmesh.faces,
                uvmesh.uv,
                uvmesh.normals,
                base_color(maps.mask),
                view_dir=preview_direction(mesh, network),
            ),
            bits=8,
        )
    write_sidecar(network, stage.path("cracks.json"))
    write_obj(network, stage.path("cracks.obj"))


def _inputs(params: RunParams) -> dict:
    inputs = {"mesh": {"path": str(params.mesh), "sha256": sha256_file(params.mesh)}}
    if params.weight_map is not None:
        inputs["weight_map"] = {
            "path": str(params.weight_map),
            "sha256": sha256_file(params.weight_map),
        }
    if params.cracks is not None:
        inputs["cracks"] = {"path": str(params.cracks), "sha256": sha256_file(params.cracks)}
    return inputs
