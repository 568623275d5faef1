"""The crack network: polylines on the surface, the ``cracks.json`` sidecar and OBJ lines.

A :class:`CrackNetwork` is what the solver produces and the bake consumes.  It is written as the
sidecar described in DESIGN.md §3 so a network can be re-baked without solving again, and as OBJ
``l`` lines so artists can inspect it in a DCC tool.  Reading validates everything a hand-edited or
stale sidecar can get wrong and refuses it with a one-line :class:`CrackbakeError`.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh

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


@dataclass(eq=False)
class Crack:
    """One crack: a polyline on the surface with per-point attributes.

    Attributes
    ----------
    id : int
        Unique within its network; baked into the ``crack.id`` channel.
    points : (N, 3) float64
        Positions on the surface, mesh units, N >= 2.
    faces : (N,) int64
        Output-mesh face holding each point.
    time : (N,) float64
        In [0, 1]: the order in which each point cracked (0 first).
    width : (N,) float64
        Opening width >= 0, mesh units.
    depth : (N,) float64
        Depth >= 0, mesh units.
    """

    id: int
    points: np.ndarray
    faces: np.ndarray
    time: np.ndarray
    width: np.ndarray
    depth: np.ndarray

    def __post_init__(self) -> None:
        # Coerce once here so every consumer can rely on the documented dtypes (callers often
        # pass lists or float32 arrays); no copy is made when the input already fits.
        self.id = int(self.id)
        self.points = np.asarray(self.points, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int64)
        self.time = np.asarray(self.time, dtype=np.float64)
        self.width = np.asarray(self.width, dtype=np.float64)
        self.depth = np.asarray(self.depth, dtype=np.float64)

    @property
    def length(self) -> float:
        """Polyline length, mesh units."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


@dataclass(eq=False)
class CrackNetwork:
    """All cracks on one mesh plus what made them.

    Attributes
    ----------
    cracks : list of Crack
    mesh : dict
        ``{"source", "vertices", "faces", "bbox_min", "bbox_max"}`` of the mesh the cracks lie on
        (see :func:`mesh_info`).
    params : dict
        Every effective parameter (JSON-compatible values).
    impacts : list of dict
        ``[{"point": [x, y, z], "radius": r, "strength": s}]``, mesh units.
    solver_steps : int
        Solver iterations that produced the network (0 when not solved).
    """

    cracks: list[Crack]
    mesh: dict
    params: dict = field(default_factory=dict)
    impacts: list[dict] = field(default_factory=list)
    solver_steps: int = 0

    def stats(self) -> dict:
        """Summary counts: ``{"cracks", "points", "total_length", "solver_steps"}``.

        ``total_length`` is the sum of all segment lengths, mesh units.
        """
        seg = segments(self)
        total = float(np.linalg.norm(seg.b - seg.a, axis=1).sum()) if len(seg.a) else 0.0
        return {
            "cracks": len(self.cracks),
            "points": int(sum(len(c.points) for c in self.cracks)),
            "total_length": total,
            "solver_steps": int(self.solver_steps),
        }


@dataclass(frozen=True, eq=False)
class Segments:
    """The network as flat per-segment arrays, the form the GPU bake consumes.

    Segment ``k`` joins ``a[k]`` to ``b[k]``; paired attributes hold the value at ``a`` in column
    0 and at ``b`` in column 1.

    Attributes
    ----------
    a, b : (S, 3) float64
        Start and end points, mesh units.
    width : (S, 2) float64
        Opening width at a and b, mesh units.
    depth : (S, 2) float64
        Depth at a and b, mesh units.
    time : (S, 2) float64
        Crack time at a and b, in [0, 1].
    crack_id : (S,) int64
        Id of the crack each segment belongs to.
    """

    a: np.ndarray
    b: np.ndarray
    width: np.ndarray
    depth: np.ndarray
    time: np.ndarray
    crack_id: np.ndarray


def segments(network: CrackNetwork) -> Segments:
    """Flatten the network into its segments (S = sum over cracks of N - 1).

    Parameters
    ----------
    network : CrackNetwork

    Returns
    -------
    Segments
        In crack order, then along each crack.
    """
    cracks = [c for c in network.cracks if len(c.points) >= 2]
    if not cracks:
        empty2 = np.zeros((0, 2), dtype=np.float64)
        return Segments(
            a=np.zeros((0, 3), dtype=np.float64),
            b=np.zeros((0, 3), dtype=np.float64),
            width=empty2,
            depth=empty2.copy(),
            time=empty2.copy(),
            crack_id=np.zeros(0, dtype=np.int64),
        )
    points = np.concatenate([c.points for c in cracks])
    counts = np.array([len(c.points) for c in cracks], dtype=np.int64)
    # Every point starts a segment except the last point of each crack.
    start = np.ones(len(points), dtype=bool)
    start[np.cumsum(counts) - 1] = False
    ia = np.flatnonzero(start)
    ib = ia + 1

    def pair(name: str) -> np.ndarray:
        values = np.concatenate([getattr(c, name) for c in cracks])
        return np.stack([values[ia], values[ib]], axis=1)

    ids = np.array([c.id for c in cracks], dtype=np.int64)
    return Segments(
        a=points[ia],
        b=points[ib],
        width=pair("width"),
        depth=pair("depth"),
        time=pair("time"),
        crack_id=np.repeat(ids, counts - 1),
    )


def mesh_info(mesh: Mesh) -> dict:
    """The sidecar's ``"mesh"`` block for a mesh.

    Returns
    -------
    dict
        ``{"source": str, "vertices": V, "faces": F, "bbox_min": [3], "bbox_max": [3]}``.
    """
    return {
        "source": str(mesh.source),
        "vertices": int(len(mesh.vertices)),
        "faces": int(len(mesh.faces)),
        "bbox_min": [float(x) for x in mesh.bbox_min],
        "bbox_max": [float(x) for x in mesh.bbox_max],
    }


def jsonable(value: Any) -> Any:
    """Plain-Python copy of a params/impacts value (numpy scalars and arrays become lists)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def to_dict(network: CrackNetwork) -> dict:
    """The sidecar as a dict, in the DESIGN.md §3 key order.

    Parameters
    ----------
    network : CrackNetwork

    Returns
    -------
    dict
        ``format, version, units, mesh, params, impacts, cracks, stats``; per-point arrays are
        plain lists (points as ``[[x, y, z], ...]``).
    """
    m = network.mesh
    return {
        "format": FORMAT,
        "version": VERSION,
        "units": UNITS,
        "mesh": {
            "source": str(m.get("source", "")),
            "vertices": int(m["vertices"]),
            "faces": int(m["faces"]),
            "bbox_min": [float(x) for x in m["bbox_min"]],
            "bbox_max": [float(x) for x in m["bbox_max"]],
        },
        "params": jsonable(dict(network.params)),
        "impacts": jsonable(list(network.impacts)),
        "cracks": [
            {
                "id": int(c.id),
                "points": c.points.tolist(),
                "faces": c.faces.tolist(),
                "time": c.time.tolist(),
                "width": c.width.tolist(),
                "depth": c.depth.tolist(),
            }
            for c in network.cracks
        ],
        "stats": network.stats(),
    }


def _fail(source: str, message: str) -> CrackbakeError:
    return CrackbakeError(f"{source}: {message}")


def _array(value: Any, source: str, where: str, key: str, integer: bool = False) -> np.ndarray:
    """Convert one JSON array, refusing non-numbers (bools and strings included)."""
    what = "integers" if integer else "numbers"
    try:
        arr = np.asarray(value)
    except ValueError:  # ragged nested lists
        arr = None
    # An empty list comes back as float64; it is a valid (if short) array of either kind.
    ok = (
        arr is not None
        and arr.ndim > 0
        and (arr.size == 0 or arr.dtype.kind in ("iu" if integer else "iuf"))
    )
    if not ok:
        raise _fail(
            source, f"{where} '{key}' is not an array of {what}; write it as a list of {what}"
        )
    return arr.astype(np.int64 if integer else np.float64)


def _parse_crack(raw: Any, index: int, source: str) -> Crack:
    if not isinstance(raw, dict):
        raise _fail(
            source,
            f"cracks[{index}] is not an object; each crack must be "
            f'{{"id", "points", "faces", "time", "width", "depth"}}',
        )
    missing = [k for k in _CRACK_KEYS if k not in raw]
    if missing:
        raise _fail(
            source,
            f"cracks[{index}] is missing {', '.join(repr(k) for k in missing)}; "
            "every crack needs id, points, faces, time, width and depth",
        )
    cid = raw["id"]
    if not isinstance(cid, int) or isinstance(cid, bool):
        raise _fail(source, f"cracks[{index}] has id {cid!r}; crack ids must be integers")
    where = f"crack {cid}"
    points = _array(raw["points"], source, where, "points")
    if points.ndim != 2 or points.shape[1] != 3:
        raise _fail(
            source,
            f"{where} has points of shape {points.shape}; points must be a list "
            "of [x, y, z] triples",
        )
    n = len(points)
    if n < 2:
        raise _fail(
            source,
            f"{where} has {n} point{'s' if n != 1 else ''}; a crack needs at "
            "least 2 points (drop it or add points)",
        )
    arrays = {"points": points}
    for key in _CRACK_ARRAYS[1:]:
        arr = _array(raw[key], source, where, key, integer=key == "faces")
        if arr.ndim != 1 or len(arr) != n:
            count = len(arr) if arr.ndim == 1 else f"shape {arr.shape}"
            raise _fail(
                source,
                f"{where} has {n} points but {count} {key}; every per-point array "
                "must have one entry per point",
            )
        arrays[key] = arr
    for key in ("points", "time", "width", "depth"):
        if not np.isfinite(arrays[key]).all():
            raise _fail(
                source, f"{where} has NaN or infinite {key}; every value must be a finite number"
            )
    for key in ("width", "depth"):
        if (arrays[key] < 0).any():
            raise _fail(
                source, f"{where} has negative {key} ({arrays[key].min()!r}); {key} must be >= 0"
            )
    t = arrays["time"]
    if ((t < 0) | (t > 1)).any():
        raise _fail(
            source,
            f"{where} has time outside [0, 1] (range {t.min()!r}..{t.max()!r}); "
            "rescale time to 0..1",
        )
    return Crack(id=cid, **arrays)


def _parse_mesh_block(raw: Any, source: str) -> dict:
    if not isinstance(raw, dict):
        raise _fail(
            source,
            '"mesh" is not an object; it must hold source, vertices, faces, bbox_min and bbox_max',
        )
    missing = [k for k in _MESH_KEYS if k not in raw]
    if missing:
        raise _fail(
            source,
            f'"mesh" is missing {", ".join(repr(k) for k in missing)}; it must '
            "hold source, vertices, faces, bbox_min and bbox_max",
        )
    for key in ("vertices", "faces"):
        v = raw[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < 0:
            raise _fail(source, f'"mesh"."{key}" is {v!r}; it must be a count (integer >= 0)')
    box = {}
    for key in ("bbox_min", "bbox_max"):
        arr = _array(raw[key], source, '"mesh"', key)
        if arr.shape != (3,) or not np.isfinite(arr).all():
            raise _fail(source, f'"mesh"."{key}" is not 3 finite numbers; write it as [x, y, z]')
        box[key] = [float(x) for x in arr]
    return {
        "source": str(raw.get("source", "")),
        "vertices": raw["vertices"],
        "faces": raw["faces"],
        **box,
    }


def _check_mesh(info: dict, mesh: Mesh, source: str) -> None:
    name = mesh.source or mesh.name
    v, f = len(mesh.vertices), len(mesh.faces)
    if info["vertices"] != v or info["faces"] != f:
        raise _fail(
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
        raise _fail(
            source,
            f"was made for a mesh with bounding box {info['bbox_min']}..."
            f"{info['bbox_max']} but {name} spans {mesh.bbox_min.tolist()}..."
            f"{mesh.bbox_max.tolist()} (moved or scaled); bake it on the mesh it was "
            "made for",
        )


def _warn_off_surface(cracks: list[Crack], mesh: Mesh, source: str) -> None:
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


def from_dict(data: Any, source: str = "cracks.json", mesh: Mesh | None = None) -> CrackNetwork:
    """Build a validated network from a sidecar dict.

    Parameters
    ----------
    data : dict
        Parsed sidecar JSON.
    source : str
        Name used in error messages.
    mesh : Mesh, optional
        The mesh it will be baked on; when given, counts and bounding box must match the
        sidecar's ``"mesh"`` block, face indices are checked against it, and points off their
        face's plane trigger a :class:`CrackbakeWarning`.

    Raises
    ------
    CrackbakeError
        Anything malformed; the message names the crack and the fix.
    """
    if not isinstance(data, dict):
        raise _fail(
            source,
            f"top level is a JSON {type(data).__name__}, not an object; is this "
            "a crackbake cracks.json?",
        )
    if data.get("format") != FORMAT:
        raise _fail(
            source,
            f'"format" is {data.get("format")!r}, not "{FORMAT}"; this is not '
            "a crackbake cracks.json",
        )
    version = data.get("version")
    if version != VERSION or isinstance(version, bool) or not isinstance(version, int):
        raise _fail(
            source,
            f'unsupported "version" {version!r} (this crackbake reads version '
            f"{VERSION}); re-make the file with this crackbake",
        )
    missing = [k for k in ("mesh", "cracks") if k not in data]
    if missing:
        raise _fail(
            source,
            f"missing {', '.join(repr(k) for k in missing)}; a cracks.json needs "
            "format, version, mesh and cracks",
        )
    units = data.get("units", UNITS)
    if units != UNITS:
        raise _fail(
            source, f'"units" is {units!r}; only "{UNITS}" (the mesh\'s own units) is supported'
        )
    info = _parse_mesh_block(data["mesh"], source)
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise _fail(source, '"params" is not an object; write it as {"name": value, ...}')
    impacts = data.get("impacts", [])
    if not isinstance(impacts, list) or not all(isinstance(i, dict) for i in impacts):
        raise _fail(
            source,
            '"impacts" is not a list of objects; write it as '
            '[{"point": [x, y, z], "radius": r, "strength": s}, ...]',
        )
    stats = data.get("stats", {})
    steps = stats.get("solver_steps", 0) if isinstance(stats, dict) else 0
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        raise _fail(source, f'"stats"."solver_steps" is {steps!r}; it must be an integer >= 0')
    raw_cracks = data["cracks"]
    if not isinstance(raw_cracks, list):
        raise _fail(source, '"cracks" is not a list; write it as [{"id": 0, ...}, ...]')

    cracks = [_parse_crack(raw, i, source) for i, raw in enumerate(raw_cracks)]
    seen: set[int] = set()
    for c in cracks:
        if c.id in seen:
            raise _fail(source, f"crack id {c.id} is used twice; every crack needs a unique id")
        seen.add(c.id)

    if mesh is not None:
        _check_mesh(info, mesh, source)
    n_faces = info["faces"]
    for c in cracks:
        bad = (c.faces < 0) | (c.faces >= n_faces)
        if bad.any():
            f = int(c.faces[bad][0])
            raise _fail(
                source,
                f"crack {c.id} has face index {f} but the mesh has {n_faces} "
                f"faces (valid 0..{n_faces - 1}); the file is corrupt or made for another "
                "mesh",
            )
    if mesh is not None:
        _warn_off_surface(cracks, mesh, source)

    return CrackNetwork(
        cracks=cracks,
        mesh=info,
        params=params,
        impacts=impacts,
        solver_steps=steps,
    )


def _dump(value: Any, level: int) -> str:
    # Objects and lists of objects are expanded (two-space indent) so the file reads like a
    # document; any list holding no object is written on ONE line.  That keeps each per-point
    # array of a crack on a single line: a crack is a fixed 8-line block however many points it
    # has, files stay small (one point per line would put hundreds of thousands of lines in a big
    # network), and a diff of two sidecars still shows which crack and which attribute changed.
    pad = "  " * (level + 1)
    end = "  " * level
    if isinstance(value, dict):
        if not value:
            return "{}"
        items = [f"{pad}{json.dumps(str(k))}: {_dump(v, level + 1)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + end + "}"
    if isinstance(value, list) and any(isinstance(v, dict) for v in value):
        items = [f"{pad}{_dump(v, level + 1)}" for v in value]
        return "[\n" + ",\n".join(items) + "\n" + end + "]"
    # json writes floats with repr(), the shortest string that round-trips exactly.
    return json.dumps(value, allow_nan=False, ensure_ascii=False, separators=(", ", ": "))


def write_sidecar(network: CrackNetwork, path: str | Path) -> None:
    """Write ``cracks.json``; the same network always gives byte-identical bytes.

    The network is validated first (it must read back), floats are written with repr precision
    so they round-trip exactly, and the file holds no timings or dates.

    Parameters
    ----------
    network : CrackNetwork
    path : str or Path

    Raises
    ------
    CrackbakeError
        The network would not read back (e.g. NaN widths, duplicate ids), or the file cannot be
        written.
    """
    path = Path(path)
    data = to_dict(network)
    from_dict(data, source=str(path))
    try:
        text = _dump(data, 0) + "\n"
    except (TypeError, ValueError) as exc:  # a params value JSON cannot hold
        raise _fail(
            str(path),
            f"cannot write params/impacts as JSON ({exc}); use plain numbers, "
            "strings, lists and dicts",
        ) from exc
    try:
        path.write_bytes(text.encode("utf-8"))
    except OSError as exc:
        raise _fail(
            str(path),
            f"cannot write the file ({exc.strerror}); check the folder exists and is writable",
        ) from exc


def read_sidecar(path: str | Path, mesh: Mesh | None = None) -> CrackNetwork:
    """Read and validate ``cracks.json``.

    Parameters
    ----------
    path : str or Path
    mesh : Mesh, optional
        The mesh it will be baked on (see :func:`from_dict`).

    Raises
    ------
    CrackbakeError
        Unreadable file, not JSON, or any validation failure.
    """
    path = Path(path)
    source = str(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError as exc:
        raise _fail(source, "file not found; check the path") from exc
    except IsADirectoryError as exc:
        raise _fail(source, "is a directory; pass the cracks.json file") from exc
    except OSError as exc:
        raise _fail(source, f"cannot read the file ({exc.strerror}); check permissions") from exc
    except UnicodeDecodeError as exc:
        raise _fail(source, "is not UTF-8 text, so not JSON; pass a crackbake cracks.json") from exc
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _fail(
            source,
            f"is not valid JSON ({exc.msg} at line {exc.lineno} column "
            f"{exc.colno}); fix or re-make the file",
        ) from exc
    return from_dict(data, source=source, mesh=mesh)


def write_obj(network: CrackNetwork, path: str | Path) -> None:
    """Write the cracks as OBJ polylines for DCC import.

    Each crack becomes ``o crack_<id>`` followed by its ``v`` lines and one ``l`` line through
    all of them (Blender imports it as a chain of edges).  Coordinates use repr precision.

    Parameters
    ----------
    network : CrackNetwork
    path : str or Path
    """
    path = Path(path)
    lines = [
        "# crackbake crack network: one polyline per crack, mesh units",
        f"# cracks {len(network.cracks)}",
    ]
    first = 1  # OBJ indices are 1-based and global over the file
    for c in network.cracks:
        lines.append(f"o crack_{c.id}")
        lines.extend(f"v {x!r} {y!r} {z!r}" for x, y, z in c.points.tolist())
        n = len(c.points)
        if n >= 2:
            lines.append("l " + " ".join(str(i) for i in range(first, first + n)))
        first += n
    try:
        path.write_bytes(("\n".join(lines) + "\n").encode("utf-8"))
    except OSError as exc:
        raise _fail(
            str(path),
            f"cannot write the file ({exc.strerror}); check the folder exists and is writable",
        ) from exc


__all__ = [
    "Crack",
    "CrackNetwork",
    "Segments",
    "from_dict",
    "mesh_info",
    "read_sidecar",
    "segments",
    "to_dict",
    "write_obj",
    "write_sidecar",
]


def from_solver(
    paths: list,
    mesh: Mesh,
    params: dict | None = None,
    impacts: list[dict] | None = None,
    solver_steps: int = 0,
) -> CrackNetwork:
    """The crack network of a solver run.

    Parameters
    ----------
    paths : list of crackbake.simulate.solver.CrackPath
        Polylines with per-point asset faces, time, width and depth.
    mesh : Mesh
        The asset mesh the faces index.
    params : dict, optional
        Every effective parameter (stored in the sidecar).
    impacts : list of dict, optional
        Impacts as used (snapped points).
    solver_steps : int
        Steps the solver took.

    Returns
    -------
    CrackNetwork
        Cracks numbered 0.. in the solver's order; paths with fewer than 2 points are dropped.
    """
    cracks = []
    for path in paths:
        if len(path.points) < 2:
            continue
        cracks.append(
            Crack(
                id=len(cracks),
                points=np.asarray(path.points, np.float64),
                faces=np.asarray(path.asset_faces, np.int64),
                time=np.clip(np.asarray(path.time, np.float64), 0.0, 1.0),
                width=np.maximum(np.asarray(path.width, np.float64), 0.0),
                depth=np.maximum(np.asarray(path.depth, np.float64), 0.0),
            )
        )
    return CrackNetwork(
        cracks=cracks,
        mesh=mesh_info(mesh),
        params=dict(params or {}),
        impacts=list(impacts or []),
        solver_steps=int(solver_steps),
    )
