"""The ``cracks.json`` sidecar: writing it byte-reproducibly, reading it back.

Its format: docs/outputs.md, "cracks.json".

Reading validates everything a hand-edited or stale sidecar can get wrong and refuses it with a
one-line :class:`CrackbakeError` naming the crack and the fix.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from crackbake.io.mesh import Mesh
from crackbake.io.safe_open import read_bytes
from crackbake.io.sidecar_checks import (
    DEPTH_MAX,
    FORMAT,
    UNITS,
    VERSION,
    check_depth,
    check_header,
    check_mesh,
    fail,
    parse_crack,
    parse_extras,
    parse_mesh_block,
    warn_off_surface,
)
from crackbake.network import CrackNetwork

__all__ = ["from_dict", "jsonable", "read_sidecar", "to_dict", "write_sidecar"]


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
    """The sidecar as a dict, in the key order docs/outputs.md shows.

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
    check_depth(data, source)
    check_header(data, source)
    info = parse_mesh_block(data["mesh"], source)
    params, impacts, steps = parse_extras(data, source)
    raw_cracks = data["cracks"]
    if not isinstance(raw_cracks, list):
        raise fail(source, '"cracks" is not a list; write it as [{"id": 0, ...}, ...]')

    cracks = [parse_crack(raw, i, source) for i, raw in enumerate(raw_cracks)]
    seen: set[int] = set()
    for c in cracks:
        if c.id in seen:
            raise fail(source, f"crack id {c.id} is used twice; every crack needs a unique id")
        seen.add(c.id)

    if mesh is not None:
        check_mesh(info, mesh, source)
    n_faces = info["faces"]
    for c in cracks:
        bad = (c.faces < 0) | (c.faces >= n_faces)
        if bad.any():
            f = int(c.faces[bad][0])
            raise fail(
                source,
                f"crack {c.id} has face index {f} but the mesh has {n_faces} "
                f"faces (valid 0..{n_faces - 1}); the file is corrupt or made for another "
                "mesh",
            )
    if mesh is not None:
        warn_off_surface(cracks, mesh, source)

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
    try:
        data = to_dict(network)
    except RecursionError as exc:  # params nested past the interpreter's stack
        raise fail(
            str(path),
            f"params/impacts nest more than {DEPTH_MAX} deep; use flat values",
        ) from exc
    from_dict(data, source=str(path))
    try:
        text = _dump(data, 0) + "\n"
    except (TypeError, ValueError) as exc:  # a params value JSON cannot hold
        raise fail(
            str(path),
            f"cannot write params/impacts as JSON ({exc}); use plain numbers, "
            "strings, lists and dicts",
        ) from exc
    try:
        path.write_bytes(text.encode("utf-8"))
    except OSError as exc:
        raise fail(
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
        text = read_bytes(path).decode("utf-8")
    except FileNotFoundError as exc:
        raise fail(source, "file not found; check the path") from exc
    except IsADirectoryError as exc:
        raise fail(source, "is a directory; pass the cracks.json file") from exc
    except OSError as exc:
        raise fail(source, f"cannot read the file ({exc.strerror}); check permissions") from exc
    except UnicodeDecodeError as exc:
        raise fail(source, "is not UTF-8 text, so not JSON; pass a crackbake cracks.json") from exc
    try:
        data = json.loads(text)
    except RecursionError as exc:  # the decoder recurses once per nesting level
        raise fail(
            source,
            f"nests lists or objects thousands deep (a cracks.json nests 5 deep, at most "
            f"{DEPTH_MAX}); this is not a crackbake cracks.json",
        ) from exc
    except json.JSONDecodeError as exc:
        raise fail(
            source,
            f"is not valid JSON ({exc.msg} at line {exc.lineno} column "
            f"{exc.colno}); fix or re-make the file",
        ) from exc
    except ValueError as exc:  # an integer of thousands of digits (Python's int_max_str_digits)
        raise fail(source, f"holds a number JSON cannot hold here ({exc}); re-make the file") \
            from exc
    return from_dict(data, source=source, mesh=mesh)
