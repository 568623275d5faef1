"""Triangle-strip PLY files (``tristrips`` elements, as old scanners write them).

trimesh reads only ``face`` elements, and its binary reader assumes every list of an element has
the length of the first, which strips never do; so a PLY whose header declares strips is read
here: the header, then each element in order (fixed-size elements in one ``frombuffer``, list
elements entry by entry), and the strips become triangles (:func:`strip_triangles`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.io.safe_open import open_regular, read_bytes

# Elements holding triangle strips (``-1`` restarts a strip) and their index property.
STRIP_ELEMENTS = ("tristrips", "tristrip", "triangle_strips")
STRIP_PROPERTIES = ("vertex_indices", "vertex_index")

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_HEADER_MAX = 1 << 16


def strip_triangles(strips: list[np.ndarray]) -> np.ndarray:
    """Triangles (T, 3) of triangle strips, each a run of vertex indices where ``-1`` restarts.

    Triangle ``k`` of a run is ``(s[k], s[k+1], s[k+2])`` for even ``k`` and
    ``(s[k+1], s[k], s[k+2])`` for odd ``k``, so every triangle keeps the first one's winding;
    triangles repeating an index (strips join runs through such degenerate triangles) are left
    out, and the parity runs on through them.

    Parameters
    ----------
    strips : list of (n_i,) int arrays

    Returns
    -------
    (T, 3) int64
    """
    flat = np.concatenate(
        [np.append(np.asarray(s, np.int64).reshape(-1), -1) for s in strips] or [np.full(1, -1)]
    )
    if len(flat) < 3:
        return np.zeros((0, 3), np.int64)
    a, b, c = flat[:-2], flat[1:-1], flat[2:]
    # Position of each window in its run: its index minus the run's first index.
    k = np.arange(len(a))
    starts = np.r_[True, flat[:-1] < 0][: len(a)]
    run_start = np.maximum.accumulate(np.where(starts, k, 0))
    odd = (k - run_start) % 2 == 1
    tri = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    ok = (tri >= 0).all(axis=1) & (a != b) & (b != c) & (a != c)
    return tri[ok]


def declares_strips(path: Path) -> bool:
    """True when the PLY header declares a triangle-strip element."""
    with open_regular(path) as fh:
        head = fh.read(_HEADER_MAX)
    end = head.find(b"end_header")
    names = re.findall(rb"^\s*element\s+(\S+)", head[: end if end >= 0 else None], re.M)
    return any(n.decode("ascii", "replace") in STRIP_ELEMENTS for n in names)


def _header(data: bytes, path: Path):
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise CrackbakeError(f"{path}: not a PLY file (no 'ply' ... 'end_header'); check it")
    body = data.index(b"\n", end) + 1
    fmt, elements = None, []
    for line in data[:end].decode("ascii", "replace").splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if words[1] == "list":
                elements[-1][2].append((words[4], _TYPES[words[2]], _TYPES[words[3]]))
            else:
                elements[-1][2].append((words[2], _TYPES[words[1]], None))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise CrackbakeError(f"{path}: unknown PLY format '{fmt}'; check the file")
    return fmt, elements, body


def read_strip_ply(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Vertices, vertex properties and triangles of a triangle-strip PLY.

    Returns
    -------
    vertices : (V, 3) float64
    properties : dict of name -> (V,) array
        Every vertex property (``x``, ``y``, ``z`` too), the file's dtype.
    faces : (F, 3) int64
        The strips' triangles plus any ``face`` element's (fans of its polygons).

    Raises
    ------
    CrackbakeError
        A truncated or malformed file, or indices past the vertices.
    """
    data = read_bytes(path)
    try:
        fmt, elements, pos = _header(data, path)
        values: dict[str, dict[str, list | np.ndarray]] = {}
        if fmt == "ascii":
            tokens = data[pos:].split()
            t = 0
            for name, count, props in elements:
                cols: dict[str, list] = {p[0]: [] for p in props}
                for _ in range(count):
                    for pname, _dtype, item in props:
                        if item is None:
                            cols[pname].append(float(tokens[t]))
                            t += 1
                        else:
                            n = int(tokens[t])
                            cols[pname].append(np.array(tokens[t + 1 : t + 1 + n], np.int64))
                            t += 1 + n
                values[name] = cols
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            for name, count, props in elements:
                if all(item is None for _, _, item in props):
                    dt = np.dtype([(p, order + d) for p, d, _ in props])
                    arr = np.frombuffer(data, dt, count, pos)
                    pos += count * dt.itemsize
                    values[name] = {p: arr[p] for p, _, _ in props}
                    continue
                cols = {p[0]: [] for p in props}
                for _ in range(count):
                    for pname, dtype, item in props:
                        if item is None:
                            dt = np.dtype(order + dtype)
                            cols[pname].append(np.frombuffer(data, dt, 1, pos)[0])
                            pos += dt.itemsize
                        else:
                            ct = np.dtype(order + dtype)
                            n = int(np.frombuffer(data, ct, 1, pos)[0])
                            pos += ct.itemsize
                            it = np.dtype(order + item)
                            cols[pname].append(np.frombuffer(data, it, n, pos).astype(np.int64))
                            pos += n * it.itemsize
                values[name] = cols
    except (IndexError, ValueError, KeyError) as exc:
        raise CrackbakeError(
            f"{path}: could not read the triangle-strip PLY ({type(exc).__name__}: {exc}); "
            "check that the file is complete"
        ) from exc
    vertex = values.get("vertex", {})
    if not all(k in vertex for k in "xyz"):
        raise CrackbakeError(f"{path}: the PLY has no vertex x, y, z; check the file")
    vertices = np.stack([np.asarray(vertex[k], np.float64) for k in "xyz"], axis=1)
    props = {k: np.asarray(v) for k, v in vertex.items()}
    strips = []
    for name in STRIP_ELEMENTS:
        for prop in STRIP_PROPERTIES:
            strips += list(values.get(name, {}).get(prop, []))
    faces = [strip_triangles(strips)]
    for prop in STRIP_PROPERTIES:
        for poly in values.get("face", {}).get(prop, []):
            poly = np.asarray(poly, np.int64)
            if len(poly) >= 3:
                faces.append(np.c_[np.full(len(poly) - 2, poly[0]), poly[1:-1], poly[2:]])
    faces = np.concatenate(faces).astype(np.int64)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise CrackbakeError(
            f"{path}: the triangle strips index vertex {int(faces.max())} of {len(vertices)}; "
            "repair the mesh first"
        )
    return vertices, props, faces
