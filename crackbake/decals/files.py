"""Decal texture sets and ``decals.json``: the projector of each impact, ready for engines.

Per decal ``i`` the files are (row 0 = top of the image = projector local +Y, all untagged
linear data):

- ``decal_<i>_alpha.png``: 8-bit grey crack coverage (the decal's opacity);
- ``decal_<i>_normal.png``: 8-bit RGB normal in the projector's frame (T = +X image right,
  B = +Y image up, N = +Z towards the projector), ``n * 0.5 + 0.5``, Y convention in the JSON;
- ``decal_<i>_orm.png``: 8-bit R occlusion (1 open), G roughness, B metallic (0);
- ``decal_<i>_height.png``: 16-bit grey ``1 - depth / height_scale`` (1 = the surface).

``decals.json`` (:data:`FORMAT` version :data:`VERSION`) gives each decal's projector as a 4x4
row-major matrix (projector local -> mesh, column vectors, right-handed, mesh units), its box,
files, and ready blocks for Unity (URP/HDRP ``DecalProjector``), Unreal (``DecalComponent``) and
Godot 4 (``Decal``); the engine conventions these follow are explained in the README's decal
section and :func:`engine_blocks`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from crackbake.bake.raster import CrackMaps
from crackbake.decals.projector import ANGLE_FADE_DEG, Projector
from crackbake.exchange.pngenc import png_bytes, write_bytes
from crackbake.exchange.targets import data_scales, pack, quantise

FORMAT = "crackbake-decals"
VERSION = 1

#: Mesh axes -> engine axes assumed for the engine blocks (the mesh is +Y up, 1 unit = 1 m,
#: as glTF and OBJ; each a 3x3 matrix acting on column vectors, with its unit scale).
#: Unity: left-handed Y-up, x negated (what glTFast does on import).  Unreal: left-handed Z-up,
#: centimetres, (x, y, z) -> (x, z, y) * 100.  Godot: right-handed Y-up like glTF, unchanged.
ENGINE_AXES: dict[str, tuple[np.ndarray, float]] = {
    "unity": (np.diag([-1.0, 1.0, 1.0]), 1.0),
    "unreal": (np.array([[1.0, 0, 0], [0, 0, 1], [0, 1, 0]]), 100.0),
    "godot": (np.eye(3), 1.0),
}


def quaternion(rot: np.ndarray) -> list[float]:
    """Unit quaternion (x, y, z, w) of a proper rotation matrix (columns = rotated axes)."""
    r = np.asarray(rot, np.float64)
    # Shepperd: divide by the largest of 4w^2, 4x^2, 4y^2, 4z^2 (stable near 180 degrees).
    trace = np.trace(r)
    k = int(np.argmax([trace, r[0, 0], r[1, 1], r[2, 2]]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1], s * s / 4]) / s
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = 2.0 * np.sqrt(max(1.0 + r[i, i] - r[j, j] - r[m, m], 0.0))
        q = np.empty(4)
        q[i] = s / 4
        q[j] = (r[j, i] + r[i, j]) / s
        q[m] = (r[m, i] + r[i, m]) / s
        q[3] = (r[m, j] - r[j, m]) / s
    return [float(v) for v in q / np.linalg.norm(q)]


def unreal_rotator(x_axis: np.ndarray, y_axis: np.ndarray, z_axis: np.ndarray) -> list[float]:
    """(Pitch, Yaw, Roll) degrees of the rotation with these axes, as Unreal's
    ``FMatrix::Rotator`` derives them (Z up, left-handed)."""
    pitch = np.arctan2(x_axis[2], np.hypot(x_axis[0], x_axis[1]))
    yaw = np.arctan2(x_axis[1], x_axis[0])
    sy_axis = np.array([-np.sin(yaw), np.cos(yaw), 0.0])  # Y axis of (pitch, yaw, roll 0)
    roll = np.arctan2(np.dot(z_axis, sy_axis), np.dot(y_axis, sy_axis))
    return [float(np.degrees(a)) for a in (pitch, yaw, roll)]


def _vec(v) -> list[float]:
    return [float(x) for x in v]


def engine_blocks(p: Projector) -> dict:
    """Each engine's component settings for projector ``p`` (engine world coordinates).

    Axes are given as the engine-space directions of the component's local axes; ``rotation``
    as a quaternion (x, y, z, w) of those axes (and Unreal's rotator).

    - Unity ``DecalProjector`` projects along local +Z; its shader reads ``uv = positionDS.xz``
      in a decal space rotated by ``Euler(-90, 0, 0)`` from the component, so u runs along local
      +X and v along local +Y (Unity's v = 0 is the image bottom): local X = image right,
      Y = image up, Z = -N (into the surface).  Position on the projector's face, pivot
      (0, 0, d/2) puts the box centre on the impact.
    - Unreal ``DecalComponent`` projects along local +X; its deferred decal shader maps
      ``DecalUVs = (0.5 + 0.5 * z / Ez, 0.5 + 0.5 * y / Ey)`` (v = 0 is the image top): local
      X = -N, Y = image down, Z = image right; ``DecalSize`` = half extents (d, h, w) / 2 in cm.
    - Godot ``Decal`` projects from +Y to -Y; its shader samples ``uv = local.xz`` mapped from
      [-extents, extents] to [0, 1] (v = 0 is the image top): local X = image right, Y = N,
      Z = image down; ``size`` = (w, d, h), centred.
    """
    x, y, n = p.axes
    c, w, h, d = p.centre, p.width, p.height, p.depth
    out = {}
    local = {
        "unity": (x, y, -n),
        "unreal": (-n, -y, x),
        "godot": (x, n, -y),
    }
    for engine, (axes_mesh) in local.items():
        conv, scale = ENGINE_AXES[engine]
        axes = [conv @ a for a in axes_mesh]
        rot = np.stack(axes, axis=1)
        block = {
            "mesh_to_engine": {"matrix": conv.tolist(), "scale": scale},
            "local_axes": {k: _vec(a) for k, a in zip("xyz", axes, strict=True)},
            "rotation_xyzw": quaternion(rot),
        }
        if engine == "unity":
            block.update({
                "component": "DecalProjector (URP/HDRP)",
                "position": _vec(scale * (conv @ (c + 0.5 * d * n))),
                "size": [w * scale, h * scale, d * scale],
                "pivot": [0.0, 0.0, 0.5 * d * scale],
                "uv_scale": [1.0, 1.0],
                "uv_bias": [0.0, 0.0],
                # The fade the decal was baked with, so the surfaces beyond it get none either.
                "start_angle_fade": ANGLE_FADE_DEG[0],
                "end_angle_fade": ANGLE_FADE_DEG[1],
            })  # fmt: skip
        elif engine == "unreal":
            block.update({
                "component": "DecalComponent",
                "location_cm": _vec(scale * (conv @ c)),
                "rotator_pyr_deg": unreal_rotator(*axes),
                "decal_size_cm": [0.5 * d * scale, 0.5 * h * scale, 0.5 * w * scale],
            })  # fmt: skip
        else:
            block.update({
                "component": "Decal",
                "origin": _vec(scale * (conv @ c)),
                "basis_columns": [_vec(a) for a in axes],
                "size": [w * scale, d * scale, h * scale],
            })  # fmt: skip
        out[engine] = block
    return out


def decal_files(i: int) -> dict[str, str]:
    """Role -> file name of decal ``i``."""
    return {role: f"decal_{i}_{role}.png" for role in ("alpha", "normal", "orm", "height")}


def write_decal_set(
    path: Callable[[str], Path], decals: list[tuple[Projector, CrackMaps, dict]], normal_y: str
) -> list[str]:
    """Write every decal's PNGs and ``decals.json``.

    Parameters
    ----------
    path : callable
        Output file name -> path to write (``OutputStage.path``, or a folder's ``__truediv__``).
    decals : list of (Projector, CrackMaps, dict)
        Each decal's projector, its bake (:func:`crackbake.decals.projector.bake_decal`) and the
        impact it came from (``{"point", "radius", "strength"}``).
    normal_y : {"gl", "dx"}
        Normal map Y convention of the files.

    Returns
    -------
    list of str
        The names written, ``decals.json`` last.
    """
    entries, names = [], []
    for i, (proj, maps, impact) in enumerate(decals):
        files = decal_files(i)
        scale = data_scales(maps)["depth"]
        height = 1.0 - np.asarray(maps.depth, np.float32) / np.float32(scale)
        pixels = {
            "alpha": quantise(maps.mask, 8),
            "normal": pack("normal", maps, 8, normal_y),
            "orm": pack("orm", maps, 8),
            "height": quantise(height, 16),
        }
        for role, name in files.items():
            write_bytes(path(name), png_bytes(pixels[role]))
            names.append(name)
        entries.append({
            "index": i,
            "impact": impact,
            "matrix": proj.matrix.tolist(),
            "width": proj.width,
            "height": proj.height,
            "depth": proj.depth,
            "resolution": int(maps.res),
            "files": files,
            "height_scale": float(scale),
            "angle_fade_deg": list(ANGLE_FADE_DEG),
            "engines": engine_blocks(proj),
        })  # fmt: skip
    doc = manifest(entries, normal_y)
    write_bytes(path("decals.json"), (json.dumps(doc, indent=2) + "\n").encode())
    return [*names, "decals.json"]


def manifest(entries: list[dict], normal_y: str) -> dict:
    """The ``decals.json`` document around the per-decal entries."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "units": "mesh",
        "handedness": "right",
        "matrix": "4x4 row-major, projector local -> mesh, column vectors: p = M @ [x, y, z, 1]",
        "projector_frame": {
            "x": "image right (u)", "y": "image up (v)", "z": "towards the projector",
            "projects_along": "-z",
            "box": "centred on the origin: |x| <= width/2, |y| <= height/2, |z| <= depth/2",
            "uv": "u = x / width + 0.5, v = y / height + 0.5; image row 0 = v 1 (top)",
        },  # fmt: skip
        "normal_map": {
            "space": "projector frame: T = +x, B = +y, N = +z; n * 0.5 + 0.5",
            "y": normal_y,
        },
        "alpha": "crack coverage 0..1 (decal opacity)",
        "orm": "R occlusion (1 = open), G roughness, B metallic",
        "height": "1 - depth / height_scale (mesh units); 1 = the surface",
        "engine_assumptions": (
            "mesh +Y up, 1 unit = 1 m; Unity x -> -x (glTFast import), Unreal (x, y, z) -> "
            "(x, z, y) * 100 cm, Godot unchanged; each block's mesh_to_engine states it"
        ),
        "decals": entries,
    }
