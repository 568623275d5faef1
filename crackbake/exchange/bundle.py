"""The files one run writes: EXR master, PNGs, GLB, preview, sidecar and OBJ polylines."""

from __future__ import annotations

import numpy as np

from crackbake import __version__
from crackbake.bake.preview import preview_direction, render_preview
from crackbake.bake.raster import CHANNELS, CrackMaps
from crackbake.bake.uv import UVMesh
from crackbake.exchange.exr import write_exr
from crackbake.exchange.glb import write_glb
from crackbake.exchange.materials import GLB_TEXTURE_MAX, base_color
from crackbake.exchange.output import OutputStage
from crackbake.exchange.png import write_png
from crackbake.io.mesh import Mesh
from crackbake.io.obj_lines import write_obj
from crackbake.io.sidecar import write_sidecar
from crackbake.network import CrackNetwork
from crackbake.params import RunParams


def exr_channels(maps: CrackMaps, float32: bool) -> dict[str, np.ndarray]:
    """The EXR master's planes: :data:`CHANNELS` types (half where bounded), or all float32."""
    chans = maps.channels()
    if float32:
        return {k: v.astype(np.float32, copy=False) for k, v in chans.items()}
    # Types follow CHANNELS: half for bounded data, float where range or precision needs it.
    out = {}
    for name, arr in chans.items():
        want = np.float16 if CHANNELS[name] == "half" else np.float32
        out[name] = arr if arr.dtype == want else arr.astype(want)
    return out


def write_outputs(
    stage: OutputStage,
    stem: str,
    params: RunParams,
    mesh: Mesh,
    uvmesh: UVMesh,
    network: CrackNetwork,
    maps: CrackMaps,
    ctx=None,
) -> None:
    """Write the requested maps, the GLB, the preview and the network into ``stage``.

    Parameters
    ----------
    stage : OutputStage
        Staging folder; nothing reaches the output folder until the caller commits.
    stem : str
        Prefix of the map file names (the mesh file's stem).
    params : RunParams
        ``formats`` and ``float32`` decide what is written.
    mesh, uvmesh, network, maps
        The stages' results.
    ctx : moderngl.Context, optional
        The run's GL context, for the preview; a temporary one when not given.
    """
    depth_max = float(maps.depth.max())
    if "exr" in params.formats:
        write_exr(
            stage.path(f"{stem}_cracks.exr"),
            exr_channels(maps, params.float32),
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
        picture = render_preview(
            uvmesh.vertices,
            uvmesh.faces,
            uvmesh.uv,
            uvmesh.normals,
            base_color(maps.mask),
            view_dir=preview_direction(mesh, network),
            ctx=ctx,
        )
        write_png(stage.path("preview.png"), picture, bits=8)
    write_sidecar(network, stage.path("cracks.json"))
    write_obj(network, stage.path("cracks.obj"))
