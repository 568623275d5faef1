"""Text-level checks of OBJ files that trimesh's loader passes over silently.

trimesh reads a UTF-8 byte-order mark as part of the first vertex line (dropping that vertex and
failing later with "index 2929 is out of bounds"), drops face lines with fewer than three corners
without a word, reads ``f 0 1 2`` as the last vertex (OBJ counts from 1), and parses a vertex line
cut short by reading the next line's numbers.  These checks run on the raw bytes, vectorised
with numpy (regular expressions took 6 s on a 1M-face file), and say what is wrong.  Their
scan also gives each line's end and token count, from which :mod:`crackbake.io.obj_reader`
reads the file (it reproduces trimesh's reader, so the checks hold for both).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning

BOM = b"\xef\xbb\xbf"
# A vertex line with fewer than three coordinates; a face line with fewer than three corners
# (only matched at one known line start: these patterns are too slow to search a whole file).
_SHORT_V = re.compile(rb"v[ \t]+(?:[^\s#]+[ \t]+)?[^\s#]*[ \t]*(?:#[^\n]*)?\r?$", re.M)
_SHORT_F = re.compile(rb"f[ \t]+(?:[^\s#]+[ \t]+)?[^\s#]*[ \t]*(?:#[^\n]*)?\r?$", re.M)
_FACE_LINE = re.compile(rb"^f[ \t]+([^\n#]*)", re.M)
_VERTEX_LINE = re.compile(rb"^v[ \t]", re.M)
#: Text at least this long (16 MiB, about 230k faces) is scanned and read by the numba kernels of
#: :mod:`crackbake.io.obj_kernels`: below it numba's import and cache loads cost more than
#: they save.
JIT_BYTES = 1 << 24
# Bytes scanned per numpy pass: bounds the scan's memory (about 10 bytes per byte scanned).
_CHUNK = 1 << 22
_SPACE, _TAB, _LF, _ZERO = 32, 9, 10, 48
# Byte -> is whitespace / ends a vertex index (whitespace or "/"): one gather instead of compares.
_WS = np.zeros(256, dtype=bool)
_WS[[32, 9, 13, 10]] = True
_END_INDEX = _WS.copy()
_END_INDEX[ord("/")] = True


@dataclass
class ObjScan:
    """What :func:`scan` found: 1-based line numbers (``None``: no such line) and counts."""

    first_short_vertex: int | None = None
    first_zero_index: int | None = None
    short_faces: int = 0
    #: Byte offset of each line's newline (L,) int64 and each line's whitespace-separated
    #: token count, keyword included (L,) int32: what the OBJ reader classifies lines with.
    line_ends: np.ndarray | None = None
    line_tokens: np.ndarray | None = None


def _scan_chunk(a: np.ndarray, scan: ObjScan, line0: int) -> tuple[np.ndarray, np.ndarray]:
    """Scan one chunk of whole lines (``a`` ends with a newline); return the offsets of its
    newlines in ``a`` and each line's token count."""
    control = np.flatnonzero(a < _SPACE)  # mostly the newlines
    kind = a[control]
    nl = control[kind == _LF]
    # When the only control bytes are whitespace, a compare finds the whitespace (5x faster
    # than the table)
    plain = bool(_WS[kind].all())
    starts = np.concatenate(([0], nl[:-1] + 1))
    second = a[np.minimum(starts + 1, len(a) - 1)]
    spaced = (second == _SPACE) | (second == _TAB)
    is_v = (a[starts] == ord("v")) & spaced
    is_f = (a[starts] == ord("f")) & spaced
    ws = a <= _SPACE if plain else _WS[a]
    token = ~ws
    token[1:] &= ws[:-1]  # a token starts after whitespace
    first = np.flatnonzero(token)
    # per line, the keyword included (a newline starts no token)
    tokens = np.diff(np.searchsorted(first, nl), prepend=0).astype(np.int32)
    short_v = np.flatnonzero(is_v & (tokens < 4))
    if len(short_v) and scan.first_short_vertex is None:
        scan.first_short_vertex = line0 + int(short_v[0]) + 1
    scan.short_faces += int(np.count_nonzero(is_f & (tokens < 4)))
    zero = first[a[first] == _ZERO]
    zero = zero[_END_INDEX[a[np.minimum(zero + 1, len(a) - 1)]]]  # a "0" or "0/..." token
    if len(zero) and scan.first_zero_index is None:
        lines = np.searchsorted(nl, zero)
        on_face = lines[is_f[lines]]
        if len(on_face):
            scan.first_zero_index = line0 + int(on_face[0]) + 1
    return nl, tokens


def scan(data: bytes, jit: bool | None = None) -> ObjScan:
    """Short vertex lines, short face lines and vertex index 0, found with numpy in chunks.

    About 0.1 s per 10 MB; a comment at the end of a line counts as more tokens, so a short
    line with a trailing comment goes unnoticed (trimesh drops those comments anyway).
    ``jit``: scan in one numba pass instead (the same scan, 10x faster); by default for text
    of :data:`JIT_BYTES` or more.
    """
    if not data.endswith(b"\n"):
        data = data + b"\n"
    if jit if jit is not None else len(data) >= JIT_BYTES:
        return _scan_jit(data)
    out, start, line0 = ObjScan(), 0, 0
    ends, tokens = [], []
    while start < len(data):
        end = data.find(b"\n", min(start + _CHUNK, len(data) - 1))
        a = np.frombuffer(data, dtype=np.uint8, count=end + 1 - start, offset=start)
        nl, count = _scan_chunk(a, out, line0)
        ends.append(nl + start)
        tokens.append(count)
        line0 += len(nl)
        start = end + 1
    out.line_ends = np.concatenate(ends) if ends else np.zeros(0, np.int64)
    out.line_tokens = np.concatenate(tokens) if tokens else np.zeros(0, np.int32)
    return out


def _scan_jit(data: bytes) -> ObjScan:
    """:func:`scan` with :func:`crackbake.io.obj_kernels.scan_lines` (``data`` ends in a
    newline)."""
    from crackbake.io.obj_kernels import scan_lines

    a = np.frombuffer(data, dtype=np.uint8)
    ends, tokens, short_v, short_faces, zero = scan_lines(a, data.count(b"\n"))
    return ObjScan(
        first_short_vertex=int(short_v) + 1 if short_v >= 0 else None,
        first_zero_index=int(zero) + 1 if zero >= 0 else None,
        short_faces=int(short_faces),
        line_ends=ends,
        line_tokens=tokens,
    )


def _line_no(data: bytes, pos: int) -> int:
    return data.count(b"\n", 0, pos) + 1


def prepare_obj_scan(data: bytes, path: Path, jit: bool | None = None) -> tuple[bytes, ObjScan]:
    """Check the OBJ text; return the bytes to read and their :class:`ObjScan` (its
    ``short_faces``: the face lines with fewer than three corners, which the readers drop);
    ``jit`` as :func:`scan` takes it.

    Strips a UTF-8 byte-order mark and drops a last line cut off mid-way (a truncated file), with
    a warning for the cut.

    Raises
    ------
    CrackbakeError
        Vertex index 0, or a vertex line with fewer than three coordinates before the last line.
    """
    if data.startswith(BOM):
        data = data[len(BOM):]
    last_start = data.rfind(b"\n", 0, len(data) - 1) + 1
    if not data.endswith(b"\n") and (
        _SHORT_V.match(data, last_start) or _SHORT_F.match(data, last_start)
    ):
        warnings.warn(
            f"{path.name}: the last line (line {_line_no(data, last_start)}) is cut off "
            "mid-way; dropped it. The file looks truncated: re-export it for the whole mesh",
            CrackbakeWarning,
            stacklevel=3,
        )
        data = data[:last_start]
    found = scan(data, jit)
    if found.first_zero_index is not None:
        raise CrackbakeError(
            f"{path}: line {found.first_zero_index} uses vertex index 0, but OBJ indices "
            "start at 1 (1 is the first vertex, -1 the last); fix the exporter or the file"
        )
    if found.first_short_vertex is not None:
        raise CrackbakeError(
            f"{path}: line {found.first_short_vertex} is a vertex with fewer than three "
            "coordinates; the file is corrupt or truncated, re-export it"
        )
    return data, found


def warn_dropped_faces(short_faces: int, faces_loaded: int, path: Path) -> None:
    """Warn about the face lines trimesh dropped (fewer than three corners)."""
    if short_faces:
        warnings.warn(
            f"{path.name}: {short_faces} face line{'s' if short_faces != 1 else ''} with fewer "
            f"than three corners dropped ({faces_loaded} triangles loaded); the file may be "
            "truncated or corrupt",
            CrackbakeWarning,
            stacklevel=3,
        )


def explain_bad_index(data: bytes, path: Path) -> CrackbakeError | None:
    """The error for faces that index vertices the file does not have, or None."""
    n_vertices = len(_VERTEX_LINE.findall(data))
    bad_lines, first = 0, None
    for match in _FACE_LINE.finditer(data):
        for corner in match.group(1).split():
            head = corner.split(b"/", 1)[0]
            try:
                index = int(head)
            except ValueError:
                continue
            if index > n_vertices or index < -n_vertices:
                bad_lines += 1
                first = first or (_line_no(data, match.start()), index)
                break
    if first is None:
        return None
    return CrackbakeError(
        f"{path}: {bad_lines} face line{'s use' if bad_lines != 1 else ' uses'} vertices the "
        f"file does not have (line {first[0]}: vertex {first[1]}, but only {n_vertices} "
        "vertices); the file is truncated or corrupt, re-export it"
    )


_VT_LINE = re.compile(rb"^vt[ \t]", re.M)


def explain_bad_uv_index(data: bytes) -> str | None:
    """Where face corners name texture coordinates (``f v/vt``) the file does not have, or None.

    trimesh then drops every UV of the mesh without a word; called only when a file with
    ``vt`` lines loaded without UVs, so the Python loop over face lines is not on the fast path.
    """
    if b"/" not in data:  # no corner names a texture coordinate
        return None
    n_vt = len(_VT_LINE.findall(data))
    bad_lines, first = 0, None
    for match in _FACE_LINE.finditer(data):
        for corner in match.group(1).split():
            parts = corner.split(b"/")
            try:
                index = int(parts[1]) if len(parts) > 1 and parts[1] else None
            except ValueError:
                continue
            if index is not None and (index == 0 or index > n_vt or index < -n_vt):
                bad_lines += 1
                first = first or (_line_no(data, match.start()), index)
                break
    if first is None:
        return None
    return (f"{bad_lines} face line{'s use' if bad_lines != 1 else ' uses'} texture coordinates "
            f"the file does not have (line {first[0]}: vt {first[1]}, but only {n_vt} vt lines)")
