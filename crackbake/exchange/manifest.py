"""``manifest.json``: what a run read, the parameters it used, what it wrote and how long it took.

Written into the staging folder last; the set appears as a whole, so a manifest present means
the files it lists are complete (see :class:`crackbake.transaction.stage.OutputStage`).
"""

from __future__ import annotations

import json
from pathlib import Path

from crackbake import __version__
from crackbake.bake.raster import CrackMaps
from crackbake.bake.uv import UVMesh
from crackbake.errors import CrackbakeError
from crackbake.exchange.layers import CRACK_LAYERS
from crackbake.exchange.targets import describe
from crackbake.io.mesh import Mesh
from crackbake.network import CrackNetwork
from crackbake.params import RunParams
from crackbake.transaction.stage import sha256_file


def effective_params(
    params: RunParams, solver_stats: dict, maps: CrackMaps, uvmesh: UVMesh
) -> dict:
    """Every parameter as the run used it: the options, solver figures and derived bake values."""
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
    return effective


def inputs(params: RunParams) -> dict:
    """Path and SHA-256 of every input file (mesh, weight map, sidecar)."""
    found = {"mesh": {"path": str(params.mesh), "sha256": sha256_file(params.mesh)}}
    if params.weight_map is not None:
        found["weight_map"] = {
            "path": str(params.weight_map),
            "sha256": sha256_file(params.weight_map),
        }
    if params.cracks is not None:
        found["cracks"] = {"path": str(params.cracks), "sha256": sha256_file(params.cracks)}
    return found


def build_manifest(
    params: RunParams,
    effective: dict,
    mesh: Mesh,
    uvmesh: UVMesh,
    network: CrackNetwork,
    maps: CrackMaps,
    renderer: dict,
    files: list[dict],
    timings: dict[str, float],
) -> dict:
    """The content of ``manifest.json``.

    Parameters
    ----------
    params : RunParams
        The (resolved) run parameters.
    effective : dict
        :func:`effective_params` of the run.
    mesh, uvmesh, network, maps
        The stages' results.
    renderer : dict
        :func:`crackbake.bake.context.renderer_info` of the context that baked.
    files : list of dict
        ``{"name", "bytes", "sha256"}`` of every file written except the manifest.
    timings : dict of str to float
        Seconds per stage, wall clock (rounded to 0.1 ms here).
    """
    udim = getattr(maps, "pages", None) is not None
    coverage = maps.coverage() if udim else float(maps.inside.mean())
    depth_max = max(float(p.depth.max()) for p in maps.pages) if udim else float(maps.depth.max())
    manifest = {
        "crackbake": __version__,
        "inputs": inputs(params),
        "params": effective,
        "mesh": mesh.describe(),
        "uv": {
            "method": uvmesh.method,
            # Share of the texture inside islands: the bake's footprint (texel centres on a
            # face), so overlapping kept islands count once.
            "coverage": round(coverage, 4),
            "vertices": int(len(uvmesh.vertices)),
            "overlap_fraction": float(uvmesh.overlap_fraction),
            "padding_px": int(uvmesh.padding_px),
        },
        "cracks": network.stats(),
        "maps": {
            "resolution": params.res,
            "depth_png_scale": depth_max,
            "max_distance": maps.max_distance,
            "covered_fraction": coverage,
            "exr_channels": {
                name: ("half" if layer.half and not params.float32 else "float")
                for role in maps.channels()
                for layer in [CRACK_LAYERS[role]]
                for name in layer.names
            },
            "textures": describe(params.target, params.normal_y, Path(params.mesh).stem, maps),
        },
        "renderer": renderer,
        "files": files,
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }
    if udim:
        manifest["uv"]["udim"] = udim_entry(maps, Path(params.mesh).stem, files)
    return manifest


def udim_entry(maps, stem: str, files: list[dict]) -> dict:
    """The manifest's ``uv.udim``: the tiles (UDIM number, integer (u, v) corner, coverage,
    files), the per-tile resolution and the GLB's packing grid (columns, rows)."""
    from crackbake.bake.udim import grid_size

    names = [f["name"] for f in files]
    tiles = []
    for number, tile, page in zip(maps.numbers, maps.tiles, maps.pages, strict=True):
        tag = f".{number}."
        tiles.append({
            "udim": number,
            "u": int(tile[0]),
            "v": int(tile[1]),
            "coverage": round(float(page.inside.mean()), 4),
            "files": [n for n in names if tag in n],
        })  # fmt: skip
    return {
        "tiles": tiles,
        "resolution_per_tile": int(maps.res),
        "pattern": f"{stem}_<map>.<UDIM>.<ext>",
        "glb_grid": list(grid_size(len(tiles))),  # columns, rows
    }



def write_manifest(path: str | Path, manifest: dict) -> None:
    """Write ``manifest`` as indented JSON with a final newline.

    Raises
    ------
    CrackbakeError
        The file cannot be written (no space, no permission), as the other writers say it.
    """
    text = json.dumps(manifest, indent=2) + "\n"
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CrackbakeError(
            f"cannot write manifest '{path}': {exc.strerror or exc}; "
            "check that the folder exists, is writable and has space"
        ) from exc
