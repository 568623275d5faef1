"""A vectorised Wavefront OBJ reader that gives the arrays trimesh's loader gives, without trimesh.

Importing trimesh (with scipy) is most of a small mesh's load, and its OBJ parser splits the
text in Python (5.9 s for a 1.5M-face OBJ).  This reader classifies lines with numpy from the
token counts :func:`crackbake.io.obj_checks.scan` already computes, parses every ``v``/``vt``/
``vn`` block and every face index with one ``numpy.fromstring`` call each, and reproduces
trimesh's conventions exactly (``load(..., process=False)``, trimesh 5.2), so a mesh loads
into the same arrays whichever reader ran:

- faces are grouped by ``usemtl`` material into one geometry per material, in reverse order of
  their first face (trimesh builds its scene from the last group); a file with one group is
  one mesh, whose ``vn`` normals are kept (a scene's copies lose them);
- a vertex is split for every distinct (``v``, ``vt``[, ``vn``]) index tuple a face corner
  uses, ordered by ``v`` index after a sort of the tuples by their last index, and only
  referenced vertices are kept; negative indices count from the end of the whole file;
- quads become ``(0, 1, 2), (2, 3, 0)``: all first halves before all second halves when every
  face of the group is a quad, interleaved (with fans for larger polygons) when sizes mix;
  face lines with fewer than three corners are dropped;
- geometry names (for ``--object``): the material when the material library defines more
  than one material, else the file's first ``o`` name when it comes before any face, else the
  file name; repeats get ``_1``, ``_2``...

Anything outside that well-trodden subset (vertex colours, tabs after a keyword, comments after
data, ``\\`` line continuations, unknown keywords, out-of-range indices, other encodings...)
returns ``None`` and the caller falls back to trimesh, whose behaviour on such files is kept
as it was.  The material library is read (only to count its materials, with the safety rules
of :mod:`crackbake.io.safe_open`) only when there are several material groups; textures are
never read here (:mod:`crackbake.io.texture` reads the one the bake uses).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.io import obj_checks
from crackbake.io.obj_checks import ObjScan
from crackbake.io.safe_open import read_bytes

__all__ = ["ObjPart", "read_obj"]

_LF, _SPACE, _TAB, _HASH, _SLASH = 10, 32, 9, 35, 47
# Line kinds.
_BLANK, _V, _VT, _VN, _F, _O, _G, _S, _USEMTL, _MTLLIB, _COMMENT, _OTHER = range(12)
_FACE_BLANKS = bytes.maketrans(b"f/", b"  ")
_V_BLANK = bytes.maketrans(b"v", b" ")
# More separate runs of one line kind than this: gather its bytes with a mask, not slices.
_RUNS_SLICED = 256


@dataclass
class ObjPart:
    """One geometry of an OBJ file as trimesh would build it.

    Attributes
    ----------
    name : str
        Geometry (and scene node) name.
    vertices : (V, 3) float64
    faces : (F, 3) int64
    uv : (V, 2) float64 or None
    normals : (V, 3) float64 or None
        The file's ``vn`` normals per vertex (only for a file of one geometry).
    source : (V,) int64
        Each vertex's ``v`` line, 0-based: ``vertices == positions[source]``.
    positions : (P, 3) float64
        Every ``v`` of the file (shared by the parts): welding them is welding the parts'
        vertices, for half the work where UV seams split many.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    normals: np.ndarray | None
    source: np.ndarray
    positions: np.ndarray


class _Unsupported(Exception):
    """The file leaves the subset this reader reproduces: let trimesh read it."""


def read_obj(
    data: bytes, scan: ObjScan, path: Path, allow_outside: bool = False, jit: bool | None = None
) -> list[ObjPart] | None:
    """The geometries of an OBJ file, as trimesh's loader would give them, or None.

    Parameters
    ----------
    data : bytes
        The file's bytes after :func:`crackbake.io.obj_checks.prepare_obj_scan`.
    scan : ObjScan
        That function's scan of ``data`` (line ends and token counts).
    path : Path
        The file (names, and the folder its material library is looked up in).
    allow_outside : bool
        Let the material library lie outside the file's folder.
    jit : bool, optional
        Classify the lines, parse the numbers and convert the indices with the numba
        kernels of :mod:`crackbake.io.obj_kernels` (the same arrays); by default for text of
        :data:`crackbake.io.obj_checks.JIT_BYTES` or more.

    Returns
    -------
    list of ObjPart or None
        One part for a single geometry, else the scene's geometries in trimesh's order; None
        when the file needs trimesh's reader (see the module docstring).
    """
    if jit is None:
        jit = len(data) >= obj_checks.JIT_BYTES
    try:
        return _read(data, scan, path, allow_outside, jit)
    except _Unsupported:
        return None


def _read(data: bytes, scan: ObjScan, path: Path, allow_outside: bool,
          jit: bool) -> list[ObjPart]:
    if b"\\" in data and (b"\\\n" in data or b"\\\r\n" in data):
        raise _Unsupported  # line continuations
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        raise _Unsupported
    if not data.isascii():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            raise _Unsupported from None
    if not data.endswith(b"\n"):
        data = data + b"\n"  # as the scan read it
    ends = scan.line_ends
    tokens = scan.line_tokens
    if ends is None or tokens is None or not len(ends) or ends[-1] != len(data) - 1:
        raise _Unsupported
    a = np.frombuffer(data, dtype=np.uint8)
    starts = np.empty_like(ends)
    starts[0] = 0
    starts[1:] = ends[:-1] + 1
    kinds = _kinds(data, a, starts, ends, tokens, jit)

    lines = {k: np.flatnonzero(kinds == k) for k in (_V, _VT, _VN, _F, _USEMTL)}
    if not len(lines[_F]) or not len(lines[_V]):
        raise _Unsupported  # no faces: a point cloud or nothing, trimesh says which
    v = _floats(data, a, starts, ends, tokens, lines[_V], b"v", (3, 4, 5), jit)[:, :3]
    vt = _floats(data, a, starts, ends, tokens, lines[_VT], b"vt", (2, 3), jit)
    vn = _floats(data, a, starts, ends, tokens, lines[_VN], b"vn", (3,), jit)
    vt = vt[:, :2] if vt is not None else None

    f_lines = lines[_F]
    corners = tokens[f_lines].astype(np.int64) - 1
    slashes, (per_ref, has_vt, has_vn) = _corner_layout(data, starts, ends, f_lines)
    ints = _face_ints(data, a, starts, ends, f_lines, slashes * corners.sum(),
                      corners.sum() * per_ref, jit)  # fmt: skip
    ints = ints.reshape(-1, per_ref)
    cv = _indices(ints, 0, len(v), jit, zero_ok=True)
    ct = _indices(ints, 1, 0 if vt is None else len(vt), jit) if has_vt else None
    cn = _indices(ints, per_ref - 1, 0 if vn is None else len(vn), jit) if has_vn else None

    groups = _material_groups(data, starts, ends, f_lines, lines[_USEMTL])
    first_corner = np.concatenate(([0], np.cumsum(corners)))
    parts = []
    # trimesh pops its groups from the end: its scene lists them last first.
    for material, which in reversed(groups):
        sizes = corners[which]
        same = bool((sizes == sizes[0]).all())
        keep = sizes >= 3
        which, sizes = which[keep], sizes[keep]
        if not len(which) or (same and not keep.all()):
            raise _Unsupported
        if len(which) == len(f_lines):  # every face line: the corners as they are
            corner = slice(None)
        else:
            corner = _ranges(first_corner[which], sizes)
        tri = _triangles(sizes, same)  # (T, 3) into ``corner``, None: in order
        source, uv, normals, index = _unmerge(
            len(v), vt, vn, cv[corner], None if ct is None else ct[corner],
            None if cn is None else cn[corner],
        )  # fmt: skip
        parts.append([material, source, index.reshape(-1, 3) if tri is None else index[tri],
                      uv, normals])  # fmt: skip
    if len(parts) == 1:
        _, source, faces, uv, normals = parts[0]
        return [ObjPart(path.stem, v[source], faces, uv, normals, source, v)]
    names = _names(data, a, starts, ends, kinds, [p[0] for p in parts], path, allow_outside)
    return [ObjPart(n, v[p[1]], p[2], p[3], None, p[1], v)
            for n, p in zip(names, parts, strict=True)]  # fmt: skip


def _kinds(data: bytes, a: np.ndarray, starts, ends, tokens, jit: bool) -> np.ndarray:
    """Each line's kind; raises :class:`_Unsupported` on a line this reader does not take."""
    kinds = _jit().line_kinds(a, ends, tokens) if jit else _first_kinds(a, starts, tokens)
    for i in np.flatnonzero(kinds == _OTHER):
        head = data[starts[i] : starts[i] + 7]
        if head == b"usemtl ":
            kinds[i] = _USEMTL
        elif head == b"mtllib ":
            kinds[i] = _MTLLIB
        else:
            raise _Unsupported
    # trimesh cuts face groups at "usemtl " wherever it appears, and reads the first
    # "mtllib" anywhere: only take files where those are the directives themselves.
    usemtl = int(np.count_nonzero(kinds == _USEMTL))
    if data.count(b"usemtl ") != usemtl:
        raise _Unsupported
    first_lib = data.find(b"mtllib")
    if first_lib >= 0 and (first_lib and data[first_lib - 1] != _LF or
                           kinds[np.searchsorted(ends, first_lib)] != _MTLLIB):
        raise _Unsupported
    # a "#" after data on a line: numpy's parse would stop there
    hashes = np.flatnonzero(a == _HASH) if b"#" in data else ()
    if len(hashes) and (kinds[np.searchsorted(ends, hashes)] != _COMMENT).any():
        raise _Unsupported
    return kinds


def _first_kinds(a: np.ndarray, starts, tokens) -> np.ndarray:
    """Each line's kind from its first three bytes (``_OTHER``: to be looked at)."""
    n = len(a)
    b0 = a[starts]
    b1 = a[np.minimum(starts + 1, n - 1)]
    b2 = a[np.minimum(starts + 2, n - 1)]
    kinds = np.full(len(starts), _OTHER, dtype=np.int8)
    kinds[(b0 == _LF) | (tokens == 0)] = _BLANK
    space1 = b1 == _SPACE
    kinds[(b0 == ord("v")) & space1] = _V
    kinds[(b0 == ord("v")) & (b1 == ord("t")) & (b2 == _SPACE)] = _VT
    kinds[(b0 == ord("v")) & (b1 == ord("n")) & (b2 == _SPACE)] = _VN
    kinds[(b0 == ord("f")) & space1] = _F
    kinds[(b0 == ord("o")) & space1] = _O
    kinds[(b0 == ord("g")) & space1] = _G
    kinds[(b0 == ord("s")) & space1] = _S
    kinds[b0 == _HASH] = _COMMENT
    return kinds


def _jit():
    """:mod:`crackbake.io.obj_kernels` (imports numba: large files only)."""
    from crackbake.io import obj_kernels

    return obj_kernels


def _gather(data: bytes, a: np.ndarray, starts, ends, which: np.ndarray) -> bytes:
    """The lines ``which`` (whole, newline included) as one bytes, after a newline."""
    if not len(which):
        return b"\n"
    cut = np.flatnonzero(np.diff(which) != 1) + 1
    first = np.concatenate(([0], cut))
    last = np.concatenate((cut - 1, [len(which) - 1]))
    if len(first) <= _RUNS_SLICED:  # exporters write each kind in a few blocks
        return b"\n" + b"".join(
            data[starts[which[i]] : ends[which[j]] + 1] for i, j in zip(first, last, strict=True)
        )
    mark = np.zeros(len(a) + 1, dtype=np.int8)
    np.add.at(mark, starts[which[first]], 1)
    np.add.at(mark, ends[which[last]] + 1, -1)
    return b"\n" + a[np.cumsum(mark[:-1], dtype=np.int8).view(bool)].tobytes()


def _parse(text: bytes, dtype) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):  # a token numpy cannot read
            raise _Unsupported from None


def _floats(data, a, starts, ends, tokens, which, word: bytes, widths,
            jit: bool = False) -> np.ndarray | None:
    """The numbers of the ``word`` lines ``which``, (N, width of the first line), or None."""
    if not len(which):
        return None
    width = int(tokens[which[0]]) - 1
    if width not in widths:
        raise _Unsupported
    if jit:  # the numbers numpy parses alike; anything else goes on to numpy's parse
        values, ok = _jit().parse_floats(a, starts, ends, which, len(word), width * len(which))
        if ok:
            return values.reshape(-1, width)
    block = _gather(data, a, starts, ends, which)
    # blank the keyword: "v" by a table (no number holds a "v"), the others where they are
    block = block.translate(_V_BLANK) if word == b"v" else block.replace(b"\n" + word, b"\n ")
    if b"e" in block and (b"+e" in block or b"-e" in block):
        raise _Unsupported  # trimesh edits these spellings before its parse
    values = _parse(block, np.float64)
    if len(values) != width * len(which):
        raise _Unsupported
    return values.reshape(-1, width)


def _face_ints(data, a, starts, ends, f_lines, slashes: int, count: int, jit: bool) -> np.ndarray:
    """The integers of the face lines ``f_lines`` (``count`` of them, with ``slashes``
    slashes in all, else :class:`_Unsupported`), in order."""
    if jit:  # plain integers only; anything else goes on to numpy's parse
        ints, found, ok = _jit().parse_faces(a, starts, ends, f_lines, count)
        if ok:
            if found != slashes:
                raise _Unsupported
            return ints
    block = _gather(data, a, starts, ends, f_lines)
    # every corner as the first: its slashes, then (after the parse) its integers
    if block.count(b"/") != slashes:
        raise _Unsupported
    block = block.translate(_FACE_BLANKS)  # the keyword and the slashes to spaces, one pass
    ints = _parse(block, np.int64)
    if len(ints) != count:
        raise _Unsupported
    return ints


def _corner_layout(data, starts, ends, f_lines) -> tuple[int, tuple[int, bool, bool]]:
    """The first face corner's slashes, and its integers and whether it names a ``vt`` and
    a ``vn`` (the caller checks that every corner has that layout)."""
    first = data[starts[f_lines[0]] : ends[f_lines[0]]].split()[1]
    slashes = first.count(b"/")
    if slashes == 0:
        return slashes, (1, False, False)
    if slashes == 1:
        return slashes, (2, True, False)
    if slashes == 2:
        return slashes, (2, False, True) if b"//" in first else (3, True, True)
    raise _Unsupported


def _indices(ints: np.ndarray, column: int, count: int, jit: bool,
             zero_ok: bool = False) -> np.ndarray:
    """OBJ indices (``ints[:, column]``) to the 0-based ones trimesh uses (negative ones kept:
    they index from the end); :class:`_Unsupported` when one is out of range."""
    if jit:
        out, ok = _jit().corner_indices(ints, column, count, zero_ok)
        if not ok:
            raise _Unsupported
        return out
    raw = ints[:, column]
    if len(raw) and (raw.max() > count or raw.min() < -count):
        raise _Unsupported
    if not zero_ok and (raw == 0).any():
        raise _Unsupported  # trimesh reads index 0 as index 1
    return raw - (raw > 0)


def _material_groups(
    data: bytes, starts, ends, f_lines, usemtl_lines
) -> list[tuple[str | None, np.ndarray]]:
    """(material, positions in ``f_lines``) per material, in order of the first face."""
    if not len(usemtl_lines):
        return [(None, np.arange(len(f_lines)))]
    names = [None] + [data[starts[i] + 6 : ends[i]].decode("utf-8").strip() for i in usemtl_lines]
    code = np.searchsorted(usemtl_lines, f_lines)  # 0: before any usemtl
    seen, first = np.unique(code, return_index=True)
    group_of: dict[str | None, int] = {}
    group = np.zeros(len(names), dtype=np.int64)
    for c in seen[np.argsort(first)]:  # the same material under several usemtl lines: one group
        group[c] = group_of.setdefault(names[c], len(group_of))
    per_face = group[code]
    order = np.argsort(per_face, kind="stable")
    bounds = np.searchsorted(per_face[order], np.arange(len(group_of) + 1))
    return [(m, order[bounds[g] : bounds[g + 1]]) for m, g in group_of.items()]


def _ranges(first: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(first[i], first[i] + sizes[i])``."""
    head = np.cumsum(sizes) - sizes
    return np.arange(int(sizes.sum()), dtype=np.int64) + np.repeat(first - head, sizes)


def _triangles(sizes: np.ndarray, same: bool) -> np.ndarray | None:
    """Triangles (T, 3) over the concatenated corners of polygons of ``sizes`` (all >= 3), in
    trimesh's order; ``same``: every face line of the group had one size (trimesh's array
    path; else its line-by-line fans)."""
    head = np.cumsum(sizes) - sizes
    if (sizes == 3).all():
        return None  # the corners in threes
    if same and sizes[0] == 4:  # trimesh triangulates a quad array: all first halves first
        q = np.arange(int(sizes.sum()), dtype=np.int64).reshape(-1, 4)
        return np.vstack((q[:, [0, 1, 2]], q[:, [2, 3, 0]]))
    if same:
        raise _Unsupported  # all n-gons (n > 4): trimesh's array triangulation, not its fans
    count = sizes - 2
    poly = np.repeat(np.arange(len(sizes)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    base = head[poly]
    tri = np.stack((base, base + k + 1, base + k + 2), axis=1)
    second = (sizes[poly] == 4) & (k == 1)  # a quad's second triangle is (2, 3, 0)
    tri[second] = np.stack((base[second] + 2, base[second] + 3, base[second]), axis=1)
    return tri


def _unmerge(n_v: int, vt, vn, cv, ct, cn):
    """The ``v`` line (0-based) of each distinct index tuple the corners use, in trimesh's
    order, their UVs and normals, and each corner's new vertex index."""
    columns = [c for c in (cv, ct, cn) if c is not None]
    if len(columns) == 1:  # positions only: the referenced vertices, in file order
        used = np.zeros(n_v, dtype=bool)
        used[cv] = True
        new = np.zeros(n_v, dtype=np.int64)
        new[used] = np.arange(int(used.sum()))
        return np.flatnonzero(used), None, None, new[cv]
    rows, inverse = _distinct_tuples(columns)
    tuples = [c[rows] for c in columns]
    order = tuples[0].argsort()  # numpy's default sort, as trimesh's: ties as it has them
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    source = tuples[0][order]
    source[source < 0] += n_v
    uv = vt[tuples[1][order]] if ct is not None else None
    normals = vn[tuples[-1][order]] if cn is not None and vn is not None else None
    return source, uv, normals, rank[inverse]


def _distinct_tuples(columns: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """One corner of each distinct index tuple, in trimesh's order of the tuples, and each
    corner's tuple.

    trimesh sorts the tuples by one integer packing the columns (the first in the low bits)
    when they fit in 64 // k bits each, else by the bytes of the rows.  Which corner of a tuple is
    taken does not matter (they hold the same indices), so numpy's quicksort does."""
    k = len(columns)
    bits = 64 // k
    limit = 2 ** (bits - 1) - 1
    low = [int(c.min()) for c in columns]
    high = [int(c.max()) for c in columns]
    if max(high) < limit and min(low) > -limit:
        # The same order from fewer bits: each column offset by its minimum and given just
        # the bits its range needs, the last column highest.  When the corner's number fits
        # below them, one plain sort (SIMD, 8x faster than an argsort here) gives the order.
        widths = [(h - lo).bit_length() for lo, h in zip(low, high, strict=True)]
        spare = 64 - sum(widths)
        n_bits = max(len(columns[0]) - 1, 1).bit_length()
        shift = n_bits if n_bits <= spare else 0
        key = np.zeros(len(columns[0]), dtype=np.uint64)
        for c, lo, w in zip(columns, low, widths, strict=True):
            key |= (c - lo).astype(np.uint64) << np.uint64(shift)
            shift += w
        if n_bits <= spare:
            key |= np.arange(len(key), dtype=np.uint64)
            key.sort()
            perm = (key & np.uint64((1 << n_bits) - 1)).astype(np.int64)
            ordered = key >> np.uint64(n_bits)
        else:
            perm = key.argsort()
            ordered = key[perm]
        first = np.empty(len(key), dtype=bool)
        first[0] = True
        np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
        inverse = np.empty(len(key), dtype=np.int64)
        inverse[perm] = np.cumsum(first) - 1
        return perm[first], inverse
    rows = np.ascontiguousarray(np.column_stack(columns))
    key = rows.view(np.dtype((np.void, 8 * k))).reshape(-1)
    _, unique, inverse = np.unique(key, return_index=True, return_inverse=True)
    return unique, inverse.reshape(-1)


def _names(data, a, starts, ends, kinds, materials, path: Path, allow_outside: bool) -> list[str]:
    """trimesh's geometry names for the groups (in scene order) of a multi-group file."""
    by_material = _material_count(data, path, allow_outside) > 1
    marks = np.flatnonzero(np.isin(kinds, (_USEMTL, _O, _F, _G, _S)))
    obj = None
    if len(marks) and kinds[marks[0]] == _O:
        i = marks[0]
        obj = data[starts[i] : ends[i]].decode("utf-8").strip()[2:].strip()
    names: list[str] = []
    for material in materials:
        if by_material and material is not None:
            name = material
        elif obj is not None:
            name = obj
        else:
            name = os.path.basename(str(path))
        if name in names:
            n = 1
            while f"{name}_{n}" in names:
                n += 1
            name = f"{name}_{n}"
        names.append(name)
    return names


def _material_count(data: bytes, path: Path, allow_outside: bool) -> int:
    """How many materials trimesh would load from the file's first ``mtllib``: 0 when it
    cannot be read (missing, outside the folder, not a regular file).  Only the library is
    read, with :func:`crackbake.io.safe_open.read_bytes`; never the textures it names."""
    at = data.find(b"mtllib")
    if at < 0:
        return 0
    end = data.find(b"\n", at)
    name = data[at + 6 : end].decode("utf-8").strip()
    parent = Path(os.path.abspath(path)).parent.resolve()
    for candidate in (name.strip(), name.strip().lstrip("/"), os.path.split(name)[-1]):
        found = (parent / candidate.strip()).resolve()
        if not allow_outside and not found.is_relative_to(parent):
            continue
        if found.exists():
            try:
                text = read_bytes(found, label=f"{path.name}: '{name}'")
            except CrackbakeError:
                return 0
            break
    else:
        return 0
    try:
        lines = text.decode("utf-8").strip().splitlines()
    except UnicodeDecodeError:
        raise _Unsupported from None
    materials = set()
    for line in lines:
        split = line.strip().split()
        if len(split) > 1 and split[0].lower() == "newmtl":
            materials.add(" ".join(split[1:]))
    return len(materials)
