"""Text-level checks of OBJ files that trimesh's loader passes over silently.

trimesh reads a UTF-8 byte-order mark as part of the first vertex line (dropping that vertex and
failing later with "index 2929 is out of bounds"), drops face lines with fewer than three corners
without a word, reads ``f 0 1 2`` as the last vertex (OBJ counts from 1), and parses a vertex line
cut short by reading the next line's numbers.  These checks run on the raw bytes with regular
expressions (C speed: a 50 MB file costs a fraction of a second) and say what is wrong.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

from crackbake.errors import CrackbakeError, CrackbakeWarning

BOM = b"\xef\xbb\xbf"
# A vertex line with fewer than three coordinates; a face line with fewer than three corners.
_SHORT_V = re.compile(rb"^v[ \t]+(?:[^\s#]+[ \t]+)?[^\s#]*[ \t]*(?:#[^\n]*)?\r?$", re.M)
_SHORT_F = re.compile(rb"^f[ \t]+(?:[^\s#]+[ \t]+)?[^\s#]*[ \t]*(?:#[^\n]*)?\r?$", re.M)
# A face corner whose vertex index is 0 ("0", "0/1", "0//2").
_ZERO_INDEX = re.compile(rb"^f[ \t][^\n#]*?(?<=[ \t])0(?=[/ \t\r\n#]|\Z)", re.M)
_FACE_LINE = re.compile(rb"^f[ \t]+([^\n#]*)", re.M)
_VERTEX_LINE = re.compile(rb"^v[ \t]", re.M)


def _line_no(data: bytes, pos: int) -> int:
    return data.count(b"\n", 0, pos) + 1


def prepare_obj(data: bytes, path: Path) -> bytes:
    """Check the OBJ text; return the bytes trimesh should read.

    Strips a UTF-8 byte-order mark and drops a last line cut off mid-way (a truncated file), with
    a warning for the cut.

    Raises
    ------
    CrackbakeError
        Vertex index 0, or a vertex line with fewer than three coordinates before the last line.
    """
    if data.startswith(BOM):
        data = data[len(BOM):]
    zero = _ZERO_INDEX.search(data)
    if zero:
        raise CrackbakeError(
            f"{path}: line {_line_no(data, zero.start())} uses vertex index 0, but OBJ indices "
            "start at 1 (1 is the first vertex, -1 the last); fix the exporter or the file"
        )
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
    short_v = _SHORT_V.search(data)
    if short_v:
        raise CrackbakeError(
            f"{path}: line {_line_no(data, short_v.start())} is a vertex with fewer than three "
            "coordinates; the file is corrupt or truncated, re-export it"
        )
    return data


def warn_dropped_faces(data: bytes, faces_loaded: int, path: Path) -> None:
    """Warn when face lines were dropped: each valid line gives at least one triangle."""
    short = len(_SHORT_F.findall(data))
    if short:
        warnings.warn(
            f"{path.name}: {short} face line{'s' if short != 1 else ''} with fewer than three "
            f"corners dropped ({faces_loaded} triangles loaded); the file may be truncated or "
            "corrupt",
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
