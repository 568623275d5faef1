"""The numba path of the OBJ load (crackbake.io.obj_kernels): the numpy path's arrays, bit for bit.

Large files (from :data:`crackbake.io.obj_checks.JIT_BYTES`) are scanned, parsed and deduplicated
by numba kernels and their normals summed by numba (from :data:`crackbake.io.mesh.JIT_FACES`
faces).  Here the thresholds are lowered to zero so that small generated files take that path,
and each load is compared with the numpy path's load of the same file: arrays bit for bit,
warnings and errors word for word.  Each kernel is also checked against the numpy call it
replaces on inputs made to hit its edges (numbers numpy parses that the kernel leaves to it).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from crackbake.errors import CrackbakeError
from crackbake.geometry import welded_vertex_normals
from crackbake.geometry_kernels import area_counts, face_cross_kernel
from crackbake.io import mesh as mesh_module
from crackbake.io import obj_checks, obj_kernels, obj_reader
from crackbake.io.mesh import load_mesh

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


def _load(path: Path, monkeypatch, jit: bool, **kw):
    """(Mesh or the CrackbakeError, warnings) with the numba path on or off."""
    with monkeypatch.context() as m:
        m.setattr(obj_checks, "JIT_BYTES", 0 if jit else 1 << 62)
        m.setattr(mesh_module, "JIT_FACES", 0 if jit else 1 << 62)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                result = load_mesh(path, **kw)
            except CrackbakeError as exc:
                result = exc
    return result, [str(w.message) for w in caught]


def _same_both_ways(path: Path, monkeypatch, **kw):
    """Assert that both paths load ``path`` alike; the numba path's mesh (or error)."""
    ours, our_warnings = _load(path, monkeypatch, True, **kw)
    theirs, their_warnings = _load(path, monkeypatch, False, **kw)
    assert our_warnings == their_warnings
    if isinstance(theirs, CrackbakeError):
        assert isinstance(ours, CrackbakeError) and str(ours) == str(theirs)
        return ours
    assert not isinstance(ours, CrackbakeError), ours
    for key in ("vertices", "faces", "uv", "normals"):
        a, b = getattr(ours, key), getattr(theirs, key)
        assert (a is None) == (b is None), key
        if a is not None:
            assert a.dtype == b.dtype and a.shape == b.shape, key
            assert a.tobytes() == b.tobytes(), key
    assert (ours.name, ours.objects) == (theirs.name, theirs.objects)
    return ours


def _sheet(n: int, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bumpy (n x n)-quad sheet as triangles: vertices, faces, per-corner UVs with a seam."""
    xs, ys = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    v = np.c_[xs.ravel(), ys.ravel(), 0.1 * rng.standard_normal(xs.size)]
    idx = np.arange(len(v)).reshape(n + 1, n + 1)
    q = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    f = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    uv = v[f][..., :2] * 0.5 + 0.5
    uv[v[f][..., 0].mean(axis=1) > 0] += 0.25  # a seam down the middle
    return v, f, uv


def _line(word: str, row, spec: str) -> str:
    """``word`` and the numbers of ``row`` in the format ``spec`` (``r``: Python's repr)."""
    return " ".join([word] + [repr(x) if spec == "r" else format(x, spec) for x in row])


def _obj(v, f, uv=None, vfmt=".7f", ufmt=".7f", normals=None) -> str:
    """OBJ text: one ``vt`` per corner (UV seams split vertices), ``vn`` per vertex."""
    lines = [_line("v", row, vfmt) for row in np.asarray(v).tolist()]
    if uv is not None:
        lines += [_line("vt", row, ufmt) for row in uv.reshape(-1, 2).tolist()]
    if normals is not None:
        lines += [_line("vn", row, ".6f") for row in normals.tolist()]
    for i, face in enumerate(f):
        if uv is not None and normals is not None:
            corners = [f"{c + 1}/{3 * i + k + 1}/{c + 1}" for k, c in enumerate(face)]
        elif uv is not None:
            corners = [f"{c + 1}/{3 * i + k + 1}" for k, c in enumerate(face)]
        elif normals is not None:
            corners = [f"{c + 1}//{c + 1}" for c in face]
        else:
            corners = [str(c + 1) for c in face]
        lines.append("f " + " ".join(corners))
    return "\n".join(lines) + "\n"


def test_example_and_generated_sheets_load_alike(tmp_path, monkeypatch):
    m = _same_both_ways(EXAMPLE, monkeypatch)
    assert m.uv is not None and len(m.faces) > 5000
    rng = np.random.default_rng(3)
    v, f, uv = _sheet(12, rng)
    cases = {
        "seams": _obj(v, f, uv),
        "plain": _obj(v, f),
        "normals": _obj(v, f, normals=rng.standard_normal(v.shape)),
        "full": _obj(v, f, uv, normals=rng.standard_normal(v.shape)),
        "repr": _obj(v * 1e-3, f, uv, vfmt="r", ufmt=".3f"),  # 17 digits: numpy parses
        "exponents": _obj(v, f, uv, vfmt=".6e"),
        "integers": _obj(np.round(v * 100), f, uv, vfmt=".0f"),
        "negative_zero": _obj(np.where(v > 0, v, -0.0), f, uv, vfmt=".1f"),
        "crlf": _obj(v, f, uv).replace("\n", "\r\n"),
    }
    for name, text in cases.items():
        path = tmp_path / f"{name}.obj"
        path.write_text(text)
        mesh = _same_both_ways(path, monkeypatch)
        assert not isinstance(mesh, CrackbakeError), name
        assert len(mesh.faces) == len(f), name
    # the fast path reads this file's numbers itself (no fallback to numpy's parse)
    data = (tmp_path / "seams.obj").read_bytes()
    scan = obj_checks.scan(data, jit=True)
    a = np.frombuffer(data, np.uint8)
    starts = np.concatenate(([0], scan.line_ends[:-1] + 1))
    kinds = obj_kernels.line_kinds(a, scan.line_ends, scan.line_tokens)
    for kind, skip, count in ((1, 1, 3 * len(v)), (2, 2, 2 * uv.size // 2)):
        lines = np.flatnonzero(kinds == kind)
        assert obj_kernels.parse_floats(a, starts, scan.line_ends, lines, skip, count)[1]
    assert obj_kernels.parse_faces(a, starts, scan.line_ends, np.flatnonzero(kinds == 4),
                                   6 * len(f))[2]  # fmt: skip
    # the seams split vertices; every corner keeps its position and UV
    mesh = load_mesh(tmp_path / "seams.obj")
    assert len(mesh.vertices) > len(v)
    assert np.allclose(mesh.vertices[mesh.faces], v[f], atol=1e-7)
    assert np.allclose(mesh.uv[mesh.faces], uv, atol=1e-7)


@pytest.mark.parametrize(
    "text",
    [
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4\n",  # a short face line: warned
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 3 2 0\n",  # index 0: the error
        "v 0 0 0\nv 1 0 0\nv 0 1\nv 1 1 0\nf 1 2 3\n",  # a short vertex line: the error
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",  # a missing vertex: the error
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/7\n",  # a missing vt: warned
        "v 0 0 0\nv 1 0 0 # corner\nv 0 1 0\nf 1 2 3\n",  # comment after data
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 1\nf 1 2 3\n",  # a zero-area face: warned
        "v 0 0 0\nv 1 0 0\nv 0 0 0\nf 1 2 3\n",  # only zero-area faces: the error
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nf 1 2 3 4\nf -4 -3 -1\n",  # quad, negatives
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1/1 2/2 3/3\nf 2 4 3\n",  # mixed corner layouts
        "v 0 0 0\nv 1 0 0\nv +0 1 0\nf 1 2 3\n",  # "+": numpy's parse
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 +3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3f\n",  # "f" read as a space, as trimesh's reader
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1/1/1 2 3 4\n",  # slashes across corners
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\x0b\n",  # a vertical tab
        "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "v 0 0 0\nv 1.0.0 0 0\nv 0 1 0\nf 1 2 3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n",  # overflows int64
        "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",  # too large for the bake
        "\xef\xbb\xbfv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3",  # a byte-order mark, no last newline
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 3 2 1\n",  # two groups
    ],
)
def test_unusual_lines_load_alike(tmp_path, monkeypatch, text):
    path = tmp_path / "odd.obj"
    path.write_bytes(text.encode("latin-1"))
    _same_both_ways(path, monkeypatch)


def _numbers(rng, n: int) -> list[str]:
    """Spellings of numbers the fast path takes (mantissas below 2**53): fixed decimals, 22
    decimals, leading and trailing dots, signed zeros, integers."""
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-9, 5, n)  # |x| < 1e6
    out = []
    for i, value in enumerate(x):
        kind = i % 7
        if kind == 0:
            out.append(f"{value:.7f}")
        elif kind == 1:
            out.append(f"{value:.9f}")
        elif kind == 2:
            out.append(f"{abs(value) % 1 * 1e-7:.22f}")  # 22 decimals, 15 digits
        elif kind == 3:
            out.append(f"{abs(value) % 1:.6f}"[1:])  # ".123456"
        elif kind == 4:
            out.append("-" + f"{abs(value) % 1:.5f}"[1:])  # "-.12345"
        elif kind == 5:
            out.append(f"{int(value)}.")  # "12."
        else:
            out.append(("-0.000", "0", "-0", "00012")[i % 4])
    return out


def test_parse_floats_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(0)
    words = _numbers(rng, 30000)
    lines = ["v " + " ".join(words[i : i + 3]) for i in range(0, len(words), 3)]
    text = ("\n".join(lines) + "\n").encode()
    a = np.frombuffer(text, np.uint8)
    ends = np.flatnonzero(a == 10)
    starts = np.concatenate(([0], ends[:-1] + 1))
    values, ok = obj_kernels.parse_floats(a, starts, ends, np.arange(len(ends)), 1, len(words))
    assert ok
    expected = np.fromstring(b" ".join(w.encode() for w in words), dtype=np.float64, sep=" ")
    assert values.tobytes() == expected.tobytes()
    # what numpy reads but the fast path does not: left to numpy (ok False)
    for odd in (b"1e5", b"+1", b"nan", b"inf", b"12345678901234567", b"0." + b"1" * 23,
                b"0.1234567890123456789", b"1-2", b"-", b".", b"1.2.3", b"0x10"):  # fmt: skip
        line = b"v 0 " + odd + b" 1\n"
        b = np.frombuffer(line, np.uint8)
        _, ok = obj_kernels.parse_floats(b, np.array([0]), np.array([len(line) - 1]),
                                         np.array([0]), 1, 3)  # fmt: skip
        assert not ok, odd
    # the count must be the expected one
    _, ok = obj_kernels.parse_floats(a, starts, ends, np.arange(len(ends)), 1, len(words) - 1)
    assert not ok


def test_parse_faces_matches_the_translated_parse():
    rng = np.random.default_rng(1)
    corners = rng.integers(-50, 10**17, size=(2000, 3, 2))
    lines = ["f " + " ".join(f"{c[0]}/{c[1]}" for c in face) for face in corners]
    lines += ["f  7//-8   9//10\t11//12 "]
    text = ("\n".join(lines) + "\n").encode()
    a = np.frombuffer(text, np.uint8)
    ends = np.flatnonzero(a == 10)
    starts = np.concatenate(([0], ends[:-1] + 1))
    expected = np.fromstring(text.translate(bytes.maketrans(b"f/", b"  ")), np.int64, sep=" ")
    ints, slashes, ok = obj_kernels.parse_faces(a, starts, ends, np.arange(len(ends)),
                                                len(expected))  # fmt: skip
    assert ok and slashes == text.count(b"/")
    assert np.array_equal(ints, expected)
    for odd in (b"f 1 2 +3\n", b"f 1 2 3f\n", b"f 1 2 1234567890123456789\n", b"f 1 2 3.\n",
                b"f 1 2-3 4\n"):  # fmt: skip
        b = np.frombuffer(odd, np.uint8)
        *_, ok = obj_kernels.parse_faces(b, np.array([0]), np.array([len(odd) - 1]),
                                         np.array([0]), 3)  # fmt: skip
        assert not ok, odd


def test_scan_matches_the_chunked_numpy_scan(monkeypatch):
    rng = np.random.default_rng(2)
    pieces = [b"v 1 2 3", b"v 1 2", b"vt 0 0", b"f 1 2 3", b"f 1 2", b"f 0/1 2 3", b"f 1 0 3",
              b"f\t1 2 3", b"v\t1", b"# f 0 1", b"", b"  ", b"f 10 20 30\r", b"o x", b"f 1 20 0",
              b"s off"]  # fmt: skip
    text = b"\n".join(pieces[i] for i in rng.integers(0, len(pieces), 5000)) + b"\n"
    monkeypatch.setattr(obj_checks, "_CHUNK", 1 << 10)  # many chunks
    numpy_scan = obj_checks.scan(text, jit=False)
    jit_scan = obj_checks.scan(text, jit=True)
    for key in ("first_short_vertex", "first_zero_index", "short_faces"):
        assert getattr(jit_scan, key) == getattr(numpy_scan, key), key
    assert numpy_scan.short_faces > 0 and numpy_scan.first_zero_index is not None
    assert np.array_equal(jit_scan.line_ends, numpy_scan.line_ends)
    assert jit_scan.line_tokens.dtype == numpy_scan.line_tokens.dtype
    assert np.array_equal(jit_scan.line_tokens, numpy_scan.line_tokens)
    a = np.frombuffer(text, np.uint8)
    ends = numpy_scan.line_ends
    starts = np.concatenate(([0], ends[:-1] + 1))
    assert np.array_equal(obj_kernels.line_kinds(a, ends, numpy_scan.line_tokens),
                          obj_reader._first_kinds(a, starts, numpy_scan.line_tokens))


def test_normals_cross_and_areas_match_numpy():
    rng = np.random.default_rng(4)
    v, f, _ = _sheet(20, rng)
    v[::9] = -0.0 * v[::9]  # signed zeros weld with zeros
    # UV-seam copies: each vertex twice, the faces spread over both copies
    copies = np.concatenate([v, v])
    faces = f + len(v) * (rng.random(f.shape) < 0.5)
    faces[::13] = faces[::13, [0, 0, 1]]  # zero-area faces
    cross = face_cross_kernel(copies, faces)
    numpy_normals = welded_vertex_normals(copies, faces, cross)
    assert welded_vertex_normals(copies, faces, cross, jit=True).tobytes() == \
        numpy_normals.tobytes()  # fmt: skip
    source = (v, np.concatenate([np.arange(len(v))] * 2))
    assert welded_vertex_normals(copies, faces, cross, source, jit=True).tobytes() == \
        welded_vertex_normals(copies, faces, cross, source).tobytes()  # fmt: skip
    area2 = np.linalg.norm(cross, axis=1)
    assert area_counts(cross) == (int((area2 > 0).sum()), int((area2 <= 0).sum()))
    assert area_counts(cross)[1] >= len(faces[::13])


_TOKENS = [b"nan", b"-inf", b"1e308", b"1e-320", b"0", b"-0", b"x", b"", b"1e", b"--1", b"0x10",
           b"3.5.1", b"+2", b".5", b"5.", b"-1", b"-999", b"26", b"10000000000000000000",
           b"1.5", b"1//", b"/1", b"1/999", b"2/2/2", b"12345678901234567"]  # fmt: skip


def test_damaged_files_load_alike(tmp_path, monkeypatch):
    """Damaged copies of a small OBJ (bytes flipped, lines cut, repeated, dropped, numbers and
    indices replaced by odd spellings): the numba path loads, warns and refuses each exactly
    as the numpy path does."""
    rng = np.random.default_rng(5)
    v, f, uv = _sheet(3, rng)
    lines = _obj(v, f, uv).encode().split(b"\n")
    outcomes = []
    for trial in range(60):
        damaged = list(lines)
        for _ in range(rng.integers(1, 4)):
            i = int(rng.integers(0, len(damaged)))
            kind = trial % 5
            if kind == 0:
                tokens = damaged[i].split(b" ")
                tokens[int(rng.integers(0, len(tokens)))] = _TOKENS[rng.integers(len(_TOKENS))]
                damaged[i] = b" ".join(tokens)
            elif kind == 1:
                damaged.insert(i, damaged[i])
            elif kind == 2:
                del damaged[i]
            elif kind == 3 and damaged[i]:
                at = int(rng.integers(0, len(damaged[i])))
                damaged[i] = damaged[i][:at] + bytes([rng.integers(0, 256)]) + damaged[i][at + 1:]
            else:
                damaged[i] = damaged[i][: int(rng.integers(0, len(damaged[i]) + 1))]
        path = tmp_path / "damaged.obj"
        path.write_bytes(b"\n".join(damaged))
        outcomes.append(isinstance(_same_both_ways(path, monkeypatch), CrackbakeError))
    assert 0 < sum(outcomes) < len(outcomes)  # some load, some are refused
