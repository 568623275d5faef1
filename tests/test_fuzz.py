"""Fuzzing: mutated OBJ files through the whole library run (load, solve, bake, write).

Every mutated file must either run (exit 0) or be refused with a :class:`CrackbakeError` (exit
2): any other exception is a bug that would reach a user as "internal error".  The run is the one
the CLI makes (``pipeline.run``), in-process for speed, on a 32-triangle plate with a 64 px bake.
Hypothesis is derandomised, so every run tries the same files.
"""

from __future__ import annotations

import os
import shutil
import warnings

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
