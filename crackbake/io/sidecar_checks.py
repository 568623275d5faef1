"""Validation of a parsed ``cracks.json``: each check names the crack and the fix.

Used by :func:`crackbake.io.sidecar.from_dict`; every failure is a one-line
:class:`CrackbakeError` prefixed with the file name.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh
from crackbake.network import Crack
from crackbake.params import LENGTH_MAX, RADIUS_REL_MAX, RANGES, STRESS_MAX

FORMAT = "crackbake-cracks"
VERSION = 1
UNITS = "mesh"

_CRACK_ARRAYS = ("points", "faces", "time", "width", "depth")
_CRACK_KEYS = ("id", *_CRACK_ARRAYS)
_MESH_KEYS = ("vertices", "faces", "bbox_min", "bbox_max")
# Relative to the mesh diagonal: a bbox that moved more than this is a different mesh; a point
# farther than the plane tolerance from its face was probably made for a different mesh or with a
# broken projection, but the bake still works, so that one only warns.
BBOX_TOLERANCE = 1e-6
PLANE_TOLERANCE = 1e-3
#: Largest crack id: ``crack.id`` is a float32 channel, which holds integers exactly only up to
#: 2**24; -1 there means "no crack", so ids start at 0.
ID_MAX = 2**24 - 1
#: Deepest nesting of lists and objects a sidecar may hold.  A crackbake sidecar nests 5 deep
#: (cracks -> crack -> points -> point); params values a few more.  Deeper files are refused
#: before any recursive code (the JSON writer, numpy) walks them.
DEPTH_MAX = 32


def fail(source: str, message: str) -> CrackbakeError:
    return CrackbakeError(f"{source}: {message}")


def _short(value: Any) -> str:
    """``repr`` of a JSON value cut to one readable line (a 10**6-digit id stays short)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**30:
        return f"{'-' if value < 0 else ''}2**{abs(value).bit_length() - 1} or more"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def check_depth(data: Any, source: str) -> None:
    """Refuse lists and objects nested deeper than :data:`DEPTH_MAX` (walked without recursion)."""
    stack = [(data, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            children = value.values()
        elif isinstance(value, list):
            children = value
        else:
            continue
        if depth > DEPTH_MAX:
            raise fail(
                source,
                f"nests lists or objects more than {DEPTH_MAX} deep; a cracks.json nests 5 "
                "deep, so this is not one (re-make it with crackbake)",
            )
        stack.extend((v, depth + 1) for v in children if isinstance(v, dict | list))


def _array(value: Any, source: str, where: str, key: str, integer: bool = False) -> np.ndarray:
    """Convert one JSON array, refusing non-numbers (bools and strings included)."""
    what = "integers" if integer else "numbers"
    try:
        # JSON true/false are Python bools, an int subclass numpy would take as 1/0.
        arr = None if _has_bool(value) else np.asarray(value)
    except ValueError:  # ragged nested lists
        arr = None
    # An empty list comes back as float64; it is a valid (if short) array of either kind.
    ok = (
        arr is not None
        and arr.ndim > 0
        and (arr.size == 0 or arr.dtype.kind in ("iu" if integer else "iuf"))
    )
    if not ok:
        raise fail(
            source, f"{where} '{key}' is not an array of {what}; write it as a list of {what}"
        )
    return arr.astype(np.int64 if integer else np.float64)


def _has_bool(value: Any) -> bool:
    """Whether a JSON value (nested lists) holds ``true`` or ``false`` anywhere."""
    if isinstance(value, bool):
        return True
    if isinstance(value, list):
        return any(v is True or v is False or (isinstance(v, list) and _has_bool(v))
                   for v in value)
    return False


def parse_crack(raw: Any, index: int, source: str) -> Crack:
    if not isinstance(raw, dict):
        raise fail(
            source,
            f"cracks[{index}] is not an object; each crack must be "
            f'{{"id", "points", "faces", "time", "width", "depth"}}',
        )
    missing = [k for k in _CRACK_KEYS if k not in raw]
    if missing:
        raise fail(
            source,
            f"cracks[{index}] is missing {', '.join(repr(k) for k in missing)}; "
            "every crack needs id, points, faces, time, width and depth",
        )
    cid = raw["id"]
    if not isinstance(cid, int) or isinstance(cid, bool):
        raise fail(source, f"cracks[{index}] has id {_short(cid)}; crack ids must be integers")
    if not 0 <= cid <= ID_MAX:
        raise fail(
            source,
            f"cracks[{index}] has id {_short(cid)}; crack ids must lie in 0..{ID_MAX} "
            "(crack.id stores them as float32; -1 there means no crack)",
        )
    where = f"crack {cid}"
    points = _array(raw["points"], source, where, "points")
    if points.ndim != 2 or points.shape[1] != 3:
        raise fail(
            source,
            f"{where} has points of shape {points.shape}; points must be a list "
            "of [x, y, z] triples",
        )
    n = len(points)
    if n < 2:
        raise fail(
            source,
            f"{where} has {n} point{'s' if n != 1 else ''}; a crack needs at "
            "least 2 points (drop it or add points)",
        )
    arrays = {"points": points}
    for key in _CRACK_ARRAYS[1:]:
        arr = _array(raw[key], source, where, key, integer=key == "faces")
        if arr.ndim != 1 or len(arr) != n:
            count = len(arr) if arr.ndim == 1 else f"shape {arr.shape}"
            raise fail(
                source,
                f"{where} has {n} points but {count} {key}; every per-point array "
                "must have one entry per point",
            )
        arrays[key] = arr
    for key in ("points", "time", "width", "depth"):
        if not np.isfinite(arrays[key]).all():
            raise fail(
                source, f"{where} has NaN or infinite {key}; every value must be a finite number"
            )
    for key in ("width", "depth"):
        if (arrays[key] < 0).any():
            raise fail(
                source,
                f"{where} has negative {key} ({float(arrays[key].min()):g}); {key} must be >= 0",
            )
        if (arrays[key] > LENGTH_MAX).any():
            raise fail(
                source,
                f"{where} has {key} {float(arrays[key].max()):g}; {key} must be at most "
                f"{LENGTH_MAX:g} mesh units (the --crack-width range)",
            )
    big = float(np.abs(points).max())
    if big > LENGTH_MAX:
        raise fail(
            source,
            f"{where} has a point coordinate of {big:g}; points must lie on the mesh, within "
            f"{LENGTH_MAX:g} mesh units of the origin",
        )
    t = arrays["time"]
    if ((t < 0) | (t > 1)).any():
        raise fail(
            source,
            f"{where} has time outside [0, 1] (range {float(t.min()):g}..{float(t.max()):g}); "
            "rescale time to 0..1",
        )
    return Crack(id=cid, **arrays)


def parse_mesh_block(raw: Any, source: str) -> dict:
    if not isinstance(raw, dict):
        raise fail(
            source,
            '"mesh" is not an object; it must hold source, vertices, faces, bbox_min and bbox_max',
        )
    missing = [k for k in _MESH_KEYS if k not in raw]
    if missing:
        raise fail(
            source,
            f'"mesh" is missing {", ".join(repr(k) for k in missing)}; it must '
            "hold source, vertices, faces, bbox_min and bbox_max",
        )
    for key in ("vertices", "faces"):
        v = raw[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < 0:
            raise fail(source, f'"mesh"."{key}" is {v!r}; it must be a count (integer >= 0)')
    box = {}
    for key in ("bbox_min", "bbox_max"):
        arr = _array(raw[key], source, '"mesh"', key)
        if arr.shape != (3,) or not np.isfinite(arr).all():
            raise fail(source, f'"mesh"."{key}" is not 3 finite numbers; write it as [x, y, z]')
        box[key] = [float(x) for x in arr]
    return {
        "source": str(raw.get("source", "")),
        "vertices": raw["vertices"],
        "faces": raw["faces"],
        **box,
    }


def check_mesh(info: dict, mesh: Mesh, source: str) -> None:
    name = mesh.source or mesh.name
    v, f = len(mesh.vertices), len(mesh.faces)
    if info["vertices"] != v or info["faces"] != f:
        raise fail(
            source,
            f"was made for a mesh with {info['vertices']} vertices and "
            f"{info['faces']} faces but {name} has {v} vertices and {f} faces; "
            "bake it on the mesh it was made for",
        )
    diag = mesh.diagonal
    moved = max(
        float(np.abs(np.asarray(info["bbox_min"]) - mesh.bbox_min).max()),
        float(np.abs(np.asarray(info["bbox_max"]) - mesh.bbox_max).max()),
    )
    if moved > BBOX_TOLERANCE * max(diag, np.finfo(np.float64).tiny):
        raise fail(
            source,
            f"was made for a mesh with bounding box {info['bbox_min']}..."
            f"{info['bbox_max']} but {name} spans {mesh.bbox_min.tolist()}..."
            f"{mesh.bbox_max.tolist()} (moved or scaled); bake it on the mesh it was "
            "made for",
        )


def warn_off_surface(cracks: list[Crack], mesh: Mesh, source: str) -> None:
    if not cracks:
        return
    points = np.concatenate([c.points for c in cracks])
    faces = np.concatenate([c.faces for c in cracks])
    tri = mesh.vertices[mesh.faces[faces]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    # Zero-area faces have no plane; their points count as on it.
    n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
    dist = np.abs(np.einsum("ij,ij->i", points - tri[:, 0], n))
    off = dist > PLANE_TOLERANCE * mesh.diagonal
    if off.any():
        owner = np.repeat([c.id for c in cracks], [len(c.points) for c in cracks])
        ids = np.unique(owner[off])
        shown = ", ".join(str(i) for i in ids[:5]) + (", ..." if len(ids) > 5 else "")
        warnings.warn(
            f"{source}: {int(off.sum())} crack points (cracks {shown}) lie up to "
            f"{float(dist.max()):.3g} units off their face's plane; the sidecar may have been "
            "made for a different mesh",
            CrackbakeWarning,
            stacklevel=3,
        )


def check_header(data: Any, source: str) -> None:
    """Refuse anything that is not a version-1 crackbake sidecar in mesh units."""
    if not isinstance(data, dict):
        raise fail(
            source,
            f"top level is a JSON {type(data).__name__}, not an object; is this "
            "a crackbake cracks.json?",
        )
    if data.get("format") != FORMAT:
        raise fail(
            source,
            f'"format" is {data.get("format")!r}, not "{FORMAT}"; this is not '
            "a crackbake cracks.json",
        )
    version = data.get("version")
    if version != VERSION or isinstance(version, bool) or not isinstance(version, int):
        raise fail(
            source,
            f'unsupported "version" {version!r} (this crackbake reads version '
            f"{VERSION}); re-make the file with this crackbake",
        )
    missing = [k for k in ("mesh", "cracks") if k not in data]
    if missing:
        raise fail(
            source,
            f"missing {', '.join(repr(k) for k in missing)}; a cracks.json needs "
            "format, version, mesh and cracks",
        )
    units = data.get("units", UNITS)
    if units != UNITS:
        raise fail(
            source, f'"units" is {units!r}; only "{UNITS}" (the mesh\'s own units) is supported'
        )


def parse_extras(data: dict, source: str) -> tuple[dict, list, int]:
    """The optional ``params``, ``impacts`` and ``stats.solver_steps``, checked."""
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise fail(source, '"params" is not an object; write it as {"name": value, ...}')
    _check_params(params, source)
    impacts = data.get("impacts", [])
    if not isinstance(impacts, list) or not all(isinstance(i, dict) for i in impacts):
        raise fail(
            source,
            '"impacts" is not a list of objects; write it as '
            '[{"point": [x, y, z], "radius": r, "strength": s}, ...]',
        )
    for i, imp in enumerate(impacts):
        _check_impact(imp, f'"impacts"[{i}]', source)
    stats = data.get("stats", {})
    steps = stats.get("solver_steps", 0) if isinstance(stats, dict) else 0
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        raise fail(source, f'"stats"."solver_steps" is {steps!r}; it must be an integer >= 0')
    return params, impacts, steps


def _check_value(value: Any, name: str, low: float, high: float, unit: str, low_open: bool,
                 source: str) -> None:
    """The CLI's range check (:data:`crackbake.params.RANGES`) for one sidecar value."""
    if value is None:
        return
    ok = _is_number(value) and (low < value if low_open else low <= value) and value <= high
    if not ok:
        above = f"above {low:g}" if low_open else f"from {low:g}"
        raise fail(
            source,
            f"{name} is {_short(value)}; it must be a number {above} up to {high:g}{unit} "
            "(the command line's range)",
        )


def _is_number(value: Any) -> bool:
    """A finite JSON number (not a bool; an integer too large for a float is not one)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _check_params(params: dict, source: str) -> None:
    """Every recorded parameter with a command-line range must lie in it."""
    for key, bounds in RANGES.items():
        _check_value(params.get(key), f'"params"."{key}"', *bounds, source)
    seed = params.get("seed")
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)
                             or not 0 <= seed < 2**63):
        raise fail(source, f'"params"."seed" is {_short(seed)}; it must be a non-negative '
                           "64-bit integer (the --seed range)")
    impacts = params.get("impacts")
    if isinstance(impacts, list):
        for i, imp in enumerate(impacts):
            if isinstance(imp, dict):
                _check_impact(imp, f'"params"."impacts"[{i}]', source)


def _check_impact(imp: dict, where: str, source: str) -> None:
    """An impact's point, radius and strength within the command line's bounds."""
    point = imp.get("point")
    ok = (isinstance(point, list) and len(point) == 3
          and all(_is_number(c) and abs(c) <= LENGTH_MAX for c in point))
    if not ok:
        raise fail(
            source,
            f'{where}."point" is {_short(point)}; it must be [x, y, z], finite numbers within '
            f"{LENGTH_MAX:g} mesh units",
        )
    _check_value(imp.get("radius"), f'{where}."radius"', 0.0, LENGTH_MAX, " mesh units", True,
                 source)
    _check_value(imp.get("radius_rel"), f'{where}."radius_rel"', 0.0, RADIUS_REL_MAX,
                 " bounding-box diagonals", True, source)
    _check_value(imp.get("strength"), f'{where}."strength"', 0.0, STRESS_MAX, "", True, source)
