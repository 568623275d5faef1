"""Fuzzing: mutated OBJ, ``cracks.json`` and MTL files through the whole library run (load,
solve or read the sidecar, bake, write).

Every mutated file must either run (exit 0) or be refused with a :class:`CrackbakeError` (exit
2): any other exception is a bug that would reach a user as "internal error".  The run is the one
the CLI makes (``pipeline.run``), in-process for speed, on a 32-triangle plate with a 64 px bake.
Hypothesis is derandomised, so every run tries the same files.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crackbake.errors import CrackbakeError
from crackbake.params import RunParams
from tests.test_bad_inputs import PLATE

# More for a deeper hunt: CRACKBAKE_FUZZ_EXAMPLES=3000 pytest tests/test_fuzz.py
EXAMPLES = int(os.environ.get("CRACKBAKE_FUZZ_EXAMPLES", "320"))
BASE = PLATE.encode()
LINES = BASE.split(b"\n")

_numbers = st.sampled_from([b"nan", b"inf", b"-inf", b"1e308", b"-1e308", b"1e-320", b"0",
                            b"-0", b"x", b"", b"1e", b"--1", b"0x10", b"3.5.1"])
_indices = st.sampled_from([b"0", b"-1", b"-999", b"26", b"1000000000000", b"1.5", b"a",
                            b"1//", b"/1", b"1/999", b"", b"-0"])


@st.composite
def mutation(draw, data: bytes) -> bytes:
    """One damage done to an OBJ's bytes."""
    kind = draw(st.sampled_from(["flip", "truncate", "duplicate", "delete", "index", "number",
                                 "insert", "bom", "swap", "crlf"]))
    lines = data.split(b"\n")
    if kind == "flip" and data:
        at = draw(st.integers(0, len(data) - 1))
        return data[:at] + bytes([draw(st.integers(0, 255))]) + data[at + 1:]
    if kind == "truncate":
        return data[: draw(st.integers(0, len(data)))]
    if kind in ("duplicate", "delete", "swap", "index", "number") and lines:
        i = draw(st.integers(0, len(lines) - 1))
        if kind == "duplicate":
            lines.insert(i, lines[i])
        elif kind == "delete":
            del lines[i]
        elif kind == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        else:
            tokens = lines[i].split(b" ")
            if len(tokens) > 1:
                k = draw(st.integers(1, len(tokens) - 1))
                tokens[k] = draw(_indices if kind == "index" else _numbers)
            lines[i] = b" ".join(tokens)
        return b"\n".join(lines)
    if kind == "insert":
        i = draw(st.integers(0, len(lines)))
        lines.insert(i, draw(st.binary(max_size=24)))
        return b"\n".join(lines)
    if kind == "bom":
        return b"\xef\xbb\xbf" + data
    if kind == "crlf":
        return data.replace(b"\n", b"\r\n")
    return data


@st.composite
def mutated_obj(draw) -> bytes:
    data = BASE
    for _ in range(draw(st.integers(1, 3))):
        data = draw(mutation(data))
    return data


def _fuzz(tmp_path, examples: int) -> list[str]:
    """Run ``examples`` mutated OBJs; return "ok" or "refused" per file."""
    from crackbake.pipeline import run

    seen: list[str] = []

    @settings(max_examples=examples, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(mutated_obj())
    def one(data: bytes) -> None:
        path = tmp_path / "fuzz.obj"
        path.write_bytes(data)
        out = tmp_path / "out"
        params = RunParams(mesh=path, out=out, shrink=1.0, res=64, sim_faces=100,
                           formats=("exr",), uv="keep", cache=False)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                run(params)
            seen.append("ok")
        except CrackbakeError as exc:  # exit code 2: the only failure allowed
            text = str(exc)
            assert "\n" not in text and "np." not in text, text
            seen.append("refused")
        finally:
            shutil.rmtree(out, ignore_errors=True)

    one()
    print(f"fuzz: {len(seen)} files, {seen.count('ok')} ran, {seen.count('refused')} refused")
    return seen


@pytest.mark.slow  # about 25-40 s on two busy cores
def test_mutated_objs_run_or_fail_cleanly(tmp_path):
    seen = _fuzz(tmp_path, EXAMPLES)
    assert len(seen) >= min(300, EXAMPLES)
    # The mutations must reach both outcomes, or the test proves nothing.
    assert seen.count("ok") >= 30 and seen.count("refused") >= 30, (
        seen.count("ok"), seen.count("refused"))


def test_mutated_objs_quick(tmp_path):
    """The first 40 files of the same search, for the quick suite."""
    seen = _fuzz(tmp_path, 40)
    assert len(seen) >= 40 and "ok" in seen and "refused" in seen


@pytest.mark.parametrize("data", [BASE, b"\xef\xbb\xbf" + BASE, BASE.replace(b"\n", b"\r\n")],
                         ids=["plain", "bom", "crlf"])
def test_fuzz_base_runs(tmp_path, data):
    """The unmutated plate (and its harmless variants) runs: refusals above are real."""
    from crackbake.pipeline import run

    path = tmp_path / "plate.obj"
    path.write_bytes(data)
    result = run(RunParams(mesh=path, out=tmp_path / "o", shrink=1.0, res=64, sim_faces=100,
                           formats=("exr",), uv="keep", cache=False))
    assert result.manifest["cracks"]["cracks"] > 0
    assert len(LINES) > 50


# --- sidecars and MTL files (issue 19) ------------------------------------------------------

_VALUES = st.sampled_from([
    2**70, -1, 2**24, -(2**63), 10**400, 1e300, -1e300, 1e308, 5e-324, float("nan"),
    float("inf"), None, True, False, "x", "", [], {}, [[[[1]]]], 0, -0.0, 1.5, [0, 0],
    [1e300, 0, 0], {"point": [0, 0, 0]}, json.loads("[" * 60 + "]" * 60),
])


def _paths(value, prefix=()) -> list[tuple]:
    """Every key/index path into a JSON value (containers and leaves)."""
    out = [prefix] if prefix else []
    if len(prefix) > 6:  # the sidecar nests 5 deep; below that only the fuzz's own values
        return out
    if isinstance(value, dict):
        for k, v in value.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value[:4]):  # a few points per array are enough
            out += _paths(v, (*prefix, i))
    return out


@st.composite
def mutated_sidecar(draw, base: dict) -> bytes:
    """A valid sidecar with one to three values replaced, keys dropped or text damaged."""
    data = json.loads(json.dumps(base))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(data)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = data
        for key in path[:-1]:
            parent = parent[key]
        if draw(st.booleans()) and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = copy.deepcopy(draw(_VALUES))  # never share a mutable value
    try:
        text = json.dumps(data).encode()
    except ValueError:  # a 400-digit integer past Python's str limit: write it by hand
        text = json.dumps(data, default=str).encode()
    if draw(st.integers(0, 4)) == 0:
        text = draw(mutation(text))
    return text


@st.composite
def mutated_mtl(draw) -> tuple[bytes, bytes]:
    """An OBJ naming an MTL (``mtllib``/``usemtl`` lines maybe damaged) and the MTL's bytes,
    whose ``map_Kd`` names a good, truncated, bomb, missing or odd texture path."""
    texture = draw(st.sampled_from([b"ok.png", b"cut.png", b"bomb.png", b"none.png", b".",
                                    b"../ok.png", b"-s 1 1 1 ok.png", b"", b"ok.png extra",
                                    b"\xff\xfe.png", b"/dev/null", b"sub/ok.png"]))
    mtl = b"newmtl m\nKd 1 1 1\nmap_Kd " + texture + b"\n"
    if draw(st.booleans()):
        mtl = draw(mutation(mtl))
    head = draw(st.sampled_from([b"mtllib a.mtl\nusemtl m\n", b"mtllib a.mtl\n",
                                 b"mtllib missing.mtl\nusemtl m\n", b"mtllib a.mtl\nusemtl q\n",
                                 b"mtllib a.mtl a.mtl\nusemtl m\nusemtl m\n"]))
    return head + BASE, mtl


def _run_or_refuse(params, seen: list[str]) -> None:
    from crackbake.pipeline import run

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run(params)
        seen.append("ok")
    except CrackbakeError as exc:  # exit code 2: the only failure allowed
        text = str(exc)
        assert "\n" not in text and "np." not in text, text
        seen.append("refused")
    finally:
        shutil.rmtree(params.out, ignore_errors=True)


def _fuzz_sidecars(tmp_path: Path, examples: int) -> list[str]:
    from tests.test_bad_inputs import _sidecar

    plate = tmp_path / "plate.obj"
    plate.write_bytes(BASE)
    base = _sidecar(plate)
    seen: list[str] = []

    @settings(max_examples=examples, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(mutated_sidecar(base))
    def one(text: bytes) -> None:
        (tmp_path / "c.json").write_bytes(text)
        _run_or_refuse(RunParams(mesh=plate, out=tmp_path / "out", cracks=tmp_path / "c.json",
                                 res=64, formats=("exr", "png"), uv="keep", cache=False), seen)

    one()
    print(f"sidecar fuzz: {len(seen)} files, {seen.count('ok')} ran, "
          f"{seen.count('refused')} refused")
    return seen


def _fuzz_mtls(tmp_path: Path, examples: int) -> list[str]:
    from PIL import Image

    from tests.test_bad_inputs import png_header_only

    Image.fromarray(np.full((32, 32, 3), 90, np.uint8)).save(tmp_path / "ok.png")
    (tmp_path / "sub").mkdir()
    shutil.copy(tmp_path / "ok.png", tmp_path / "sub" / "ok.png")
    data = (tmp_path / "ok.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    (tmp_path / "bomb.png").write_bytes(png_header_only(20_000, 20_000))
    seen: list[str] = []

    @settings(max_examples=examples, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(mutated_mtl())
    def one(files: tuple[bytes, bytes]) -> None:
        obj, mtl = files
        (tmp_path / "m.obj").write_bytes(obj)
        (tmp_path / "a.mtl").write_bytes(mtl)
        _run_or_refuse(RunParams(mesh=tmp_path / "m.obj", out=tmp_path / "out", shrink=1.0,
                                 res=64, sim_faces=100, formats=("png",), uv="keep",
                                 cache=False), seen)

    one()
    print(f"mtl fuzz: {len(seen)} files, {seen.count('ok')} ran, {seen.count('refused')} refused")
    return seen


def test_mutated_sidecars_quick(tmp_path):
    seen = _fuzz_sidecars(tmp_path, 30)
    assert len(seen) >= 30 and "ok" in seen and "refused" in seen


@pytest.mark.slow
def test_mutated_sidecars_run_or_fail_cleanly(tmp_path):
    seen = _fuzz_sidecars(tmp_path, max(200, EXAMPLES // 2))
    assert seen.count("ok") >= 10 and seen.count("refused") >= 100, (
        seen.count("ok"), seen.count("refused"))


def test_mutated_mtls_quick(tmp_path):
    """Every broken material still runs (a texture is optional) or is refused in one line."""
    seen = _fuzz_mtls(tmp_path, 20)
    assert len(seen) >= 20 and "ok" in seen


@pytest.mark.slow
def test_mutated_mtls_run_or_fail_cleanly(tmp_path):
    seen = _fuzz_mtls(tmp_path, max(120, EXAMPLES // 3))
    assert seen.count("ok") >= 60, (seen.count("ok"), seen.count("refused"))
