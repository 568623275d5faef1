"""The tile's bake and files: periodic maps, the PNG set, the EXR master, cracks.json.

The bake is :func:`crackbake.bake.raster.bake_cracks` on the plate mesh (UVs ``(x, y) / size``,
tangents the plate's axes) with every crack piece also shifted by one period in x, y and both
(the 3x3 copies that lie within the bake's reach of the tile): a texel near one edge sees the
cracks just past the opposite edge, so every map (mask, width, depth, time, distance, id,
normal, occlusion) continues across the border.
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from crackbake import __version__
from crackbake.exchange.exr import write_exr
from crackbake.exchange.layers import crack_attributes, crack_planes, run_attributes
from crackbake.exchange.materials import base_color, downsample
from crackbake.exchange.pngenc import png_bytes, write_bytes
from crackbake.exchange.targets import TARGETS, pack, quantise
from crackbake.network import Segments

#: The stem of the tile's file names (``tile_basecolor.png``, ...).
STEM = "tile"
#: Longest edge of ``tile_3x3.png``, pixels.
PICTURE_MAX = 1536


def tile_segments(pieces: list, period: float, reach: float) -> Segments:
    """The pieces' segments plus their copies shifted by ``(i, j) * period``, ``i, j`` in
    -1..1, keeping copies that come within ``reach`` of the tile ``[0, period]²``."""
    a, b, w, d, t, cid = [], [], [], [], [], []
    for pc in pieces:
        p = pc.points
        a.append(p[:-1])
        b.append(p[1:])
        w.append(np.column_stack([pc.width[:-1], pc.width[1:]]))
        d.append(np.column_stack([pc.depth[:-1], pc.depth[1:]]))
        t.append(np.column_stack([pc.time[:-1], pc.time[1:]]))
        cid.append(np.full(len(p) - 1, pc.crack, np.int64))
    if not a:
        z2 = np.zeros((0, 2))
        return Segments(np.zeros((0, 3)), np.zeros((0, 3)), z2, z2, z2, np.zeros(0, np.int64))
    a, b = np.concatenate(a), np.concatenate(b)
    w, d, t, cid = (np.concatenate(x) for x in (w, d, t, cid))
    parts = []
    for i in (-1, 0, 1):
        for j in (-1, 0, 1):
            off = np.array([i * period, j * period, 0.0])
            lo = np.minimum(a, b)[:, :2] + off[:2]
            hi = np.maximum(a, b)[:, :2] + off[:2]
            keep = np.all((hi >= -reach) & (lo <= period + reach), axis=1)
            parts.append((a[keep] + off, b[keep] + off, keep))
    keep_all = [k for *_, k in parts]
    return Segments(
        a=np.concatenate([p[0] for p in parts]), b=np.concatenate([p[1] for p in parts]),
        width=np.concatenate([w[k] for k in keep_all]),
        depth=np.concatenate([d[k] for k in keep_all]),
        time=np.concatenate([t[k] for k in keep_all]),
        crack_id=np.concatenate([cid[k] for k in keep_all]),
    )


def bake_tile(pieces: list, uvmesh, period: float, res: int, profile: float, ctx, look=None):
    """The tile's :class:`~crackbake.bake.raster.CrackMaps` (periodic).

    ``look``: the preset's :class:`crackbake.looks.Look`, without its chipping (its noise lives
    in world space, which does not repeat with the tile's period: it would show a seam)."""
    from dataclasses import replace

    from crackbake.bake.raster import bake_cracks
    from crackbake.params import DEFAULT_MAX_DISTANCE_FRACTION

    reach = DEFAULT_MAX_DISTANCE_FRACTION * period * np.sqrt(2.0)
    segs = tile_segments(pieces, period, reach)
    if len(segs.a):
        reach = max(reach, float(segs.width.max()))
    return bake_cracks(
        uvmesh.vertices, uvmesh.faces, uvmesh.uv, segs, res, max_distance=reach,
        profile_shape=profile, ctx=ctx, normals=uvmesh.normals, tangents=uvmesh.tangents,
        look=None if look is None else replace(look, chipping=0.0),
    )  # fmt: skip


def cracks_doc(pieces: list, period: float) -> dict:
    """``cracks.json``: the pieces in tile coordinates, the period, units."""
    return {
        "crackbake": __version__,
        "kind": "tile cracks",
        "period": [period, period],
        "frame": "tile plate: x, y in [0, period] (mesh units), z = 0; u = x / period, "
                 "v = y / period; a piece ending on a border continues from the opposite one",
        "pieces": [
            {"crack": int(pc.crack), "points": np.round(pc.points[:, :2], 9).tolist(),
             "width": np.round(pc.width, 9).tolist(), "depth": np.round(pc.depth, 9).tolist(),
             "time": np.round(pc.time, 6).tolist()}
            for pc in pieces
        ],
    }  # fmt: skip


def write_tile(stage, params, maps, pieces: list, stats: dict, timings: dict, t0: float) -> dict:
    """Write the PNG set, ``tile_cracks.exr``, ``tile_3x3.png``, ``cracks.json`` and
    ``manifest.json`` into the open :class:`~crackbake.transaction.stage.OutputStage`."""
    t = time.perf_counter()
    run = {"mesh": "tile", "preset": params.preset, "size": params.size, "res": params.res,
           "seed": params.seed, "impacts": params.impacts, "sim_faces": params.sim_faces,
           "exr_compression": params.exr_compression}
    base = base_color(maps.mask, occlusion=maps.occlusion, look=getattr(maps, "look", None))
    depth_scale = max(float(np.max(maps.depth)), 1e-12)
    jobs = []
    for f in TARGETS["gltf"].files:
        if f.content == "depth":
            continue  # the height map below replaces it
        jobs.append((f.name.format(stem=STEM), f.content, f.bits))
    images = {name: (lambda c=c, b=b: pack(c, maps, b, "gl", base=lambda: base))
              for name, c, b in jobs}
    # Height: 1 = the surface, 0 = the deepest crack (engines' height maps are white-up).
    images[f"{STEM}_height.png"] = lambda: quantise(
        depth_scale - np.asarray(maps.depth, np.float32), 16, depth_scale)
    images[f"{STEM}_3x3.png"] = lambda: np.tile(np.round(
        downsample(base, PICTURE_MAX // 3)).astype(np.uint8), (3, 3, 1))

    def encode(name):
        srgb = name.endswith(("_basecolor.png", "_3x3.png"))
        write_bytes(stage.path(name), png_bytes(images[name](), srgb=srgb))

    def exr():
        planes = crack_planes(maps.channels())
        attrs = crack_attributes(__version__, maps.max_distance, maps.profile_shape,
                                 channels=planes)
        attrs["crackbake:tilePeriod"] = float(params.size)
        # owner and comments name the run, as the bake's EXRs do
        attrs.update(run_attributes(__version__, run))
        write_exr(stage.path(f"{STEM}_cracks.exr"), planes, attributes=attrs,
                  compression=params.exr_compression)

    with ThreadPoolExecutor(max_workers=4) as pool:
        futures = [pool.submit(exr)] + [pool.submit(encode, n) for n in images]
        for f in futures:
            f.result()
    stage.path("cracks.json").write_text(
        json.dumps(cracks_doc(pieces, params.size)) + "\n", encoding="utf-8")
    timings["write"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    manifest = {
        "crackbake": __version__,
        "kind": "tile",
        "period": [params.size, params.size],
        "params": {k: v for k, v in run.items() if k != "mesh"},
        "depth_scale": depth_scale,
        "normal_y": "gl",
        "solver": {k: v for k, v in stats.items() if isinstance(v, (int, float, str))},
        "files": stage.records(),
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }  # fmt: skip
    stage.path("manifest.json").write_text(json.dumps(manifest, indent=1) + "\n", "utf-8")
    return manifest
