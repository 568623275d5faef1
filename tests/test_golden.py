"""Golden runs: the crack networks and baked masks of fixed inputs and seeds, recorded once.

A restructuring must not change behaviour; these runs are its proof.  Each case runs the
``crackbake`` command in-process (the most stable public surface) and compares:

* the **crack network** (``cracks.json``: every id, point count and face exactly; every point,
  time, width and depth to ``NET_RTOL`` of the field's scale): the solver runs on the CPU in
  64-bit floats and is deterministic on one machine, but another CPU or another numpy/scipy
  release may round a sum in its last bits (plate_thesis moved by that between two machines of
  this project with the same code), and such a change leaves every crack where it was; a
  failure names the first crack that differs;
* the **baked mask** (the decoded 8-bit ``_mask.png``) **with a tolerance**: it is drawn by
  the GPU, and another driver than the recording one (see ``recorded_with`` in
  ``golden.json``) may round a coverage or an edge texel differently.  On the recording
  renderer the mask is also bit-identical (``mask_sha256``); elsewhere at most
  ``MASK_TEXELS`` of the texels may differ by more than ``MASK_LEVELS`` levels, and none by
  more than ``MASK_MAX``.

The recorded data: ``tests/golden/golden.json`` (summary figures, digests and the renderer and
dependency versions of the recording) and ``tests/golden/<case>.npz`` (the network's arrays and
the mask).  Re-record only on a deliberate change of behaviour:
``CRACKBAKE_RECORD_GOLDEN=1 pytest tests/test_golden.py`` (and say why in the commit).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from crackbake.cli import main
from crackbake.precompile import plate_obj

ROOT = Path(__file__).resolve().parents[1]
GOLDEN_DIR = ROOT / "tests" / "golden"
GOLDEN = GOLDEN_DIR / "golden.json"
RECORD = os.environ.get("CRACKBAKE_RECORD_GOLDEN") == "1"

# Mask tolerance on a renderer other than the recording one (see the module docstring).
MASK_LEVELS = 2  # 8-bit levels a texel may move without counting as different
MASK_TEXELS = 0.005  # share of the texels that may differ by more than MASK_LEVELS
MASK_MAX = 96  # largest difference of any texel, levels
# Network tolerance: a share of each float field's largest magnitude (last-bit rounding of
# sums between CPUs and library releases is ~1e-15 of it; a behaviour change moves points by
# a sim edge, ~1e-3).
NET_RTOL = 1e-7

FIELDS = ("points", "faces", "time", "width", "depth")
VERSIONS = ("numpy", "numba", "scipy", "moderngl", "triangle", "trimesh", "potpourri3d",
            "libigl", "xatlas", "pillow")


def _plate_obj(path: Path, n: int = 4) -> Path:
    """A 1 x 1 plate of n x n quads (2 n^2 triangles) with UVs equal to (x, y)."""
    return plate_obj(path, n, uv_margin=0.0)


CASES = {
    "plate_glass": ["--preset", "glass", "--impact", "0.5,0.5,0:0.25", "--sim-faces", "40000",
                    "--seed", "3"],
    "plate_shrink": ["--preset", "mud", "--sim-faces", "30000", "--seed", "5"],
    "plate_thesis": ["--preset", "glass", "--method", "thesis", "--impact", "0.4,0.55,0:0.3",
                     "--sim-faces", "30000", "--seed", "2"],
    "spot_glass": ["--preset", "glass", "--impact", "0.334,0.044,0.287", "--sim-faces",
                   "100000", "--seed", "0"],
}


def _digest(cracks: list[dict]) -> dict:
    """Exact fingerprint of the polylines plus readable summary figures."""
    blob = json.dumps(
        [[c["points"], c["faces"], c["time"], c["width"], c["depth"]] for c in cracks],
        separators=(",", ":"),
    ).encode()
    length = 0.0
    for c in cracks:
        p = np.asarray(c["points"], float)
        length += float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
    return {
        "cracks": len(cracks),
        "points": sum(len(c["points"]) for c in cracks),
        "length": round(length, 9),
        "sha256": hashlib.sha256(blob).hexdigest(),
    }


def _mask_sha(mask: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(mask).tobytes() + str(mask.shape).encode()
                          ).hexdigest()


def _arrays(cracks: list[dict], mask: np.ndarray) -> dict[str, np.ndarray]:
    """The network as flat arrays (``offsets`` splits them per crack) and the mask."""
    out = {"ids": np.array([c["id"] for c in cracks], np.int64),
           "offsets": np.cumsum([0] + [len(c["points"]) for c in cracks]).astype(np.int64),
           "mask": mask}
    for f in FIELDS:
        parts = [np.asarray(c[f], np.float64 if f != "faces" else np.int64) for c in cracks]
        out[f] = np.concatenate(parts) if parts else np.zeros(0)
    return out


def _run(case: str, tmp_path: Path) -> tuple[dict, dict, dict]:
    """Run ``case``: its summary record, its arrays and the manifest's renderer."""
    mesh = ROOT / "examples" / "spot.obj" if case.startswith("spot") else _plate_obj(
        tmp_path / "plate.obj")
    out = tmp_path / "out"
    args = [str(mesh), *CASES[case], "--res", "512", "--formats", "png", "-o", str(out), "-q"]
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    side = json.loads((out / "cracks.json").read_text())
    mask = np.asarray(Image.open(out / f"{mesh.stem}_mask.png"))
    record = _digest(side["cracks"])
    record["mask_sha256"] = _mask_sha(mask)
    record["mask_mean"] = round(float(mask.mean()), 6)
    renderer = json.loads((out / "manifest.json").read_text())["renderer"]
    return record, _arrays(side["cracks"], mask), renderer


def _recorded_with(renderer: dict) -> dict:
    """The renderer and the versions a recording was made with."""
    versions = {"python": platform.python_version(), "platform": sys.platform}
    for name in ("crackbake", *VERSIONS):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {"renderer": renderer, "versions": versions}


def first_network_difference(got: dict, want: dict) -> str | None:
    """None when the two networks agree (ids, counts and faces exactly, floats to
    ``NET_RTOL`` of each field's largest magnitude), else the first crack that differs.

    ``got`` and ``want`` are :func:`_arrays` dictionaries; the message names the crack (index
    and id), the first point and field that differ, and both values.
    """
    if len(got["ids"]) != len(want["ids"]):
        head = f"{len(got['ids'])} cracks, golden {len(want['ids'])}; "
    else:
        head = ""
    tol = {f: NET_RTOL * max(float(np.abs(want[f]).max(initial=0.0)), 1e-300)
           for f in FIELDS if f != "faces"}
    for k in range(min(len(got["ids"]), len(want["ids"]))):
        ga, gb = got["offsets"][k : k + 2]
        wa, wb = want["offsets"][k : k + 2]
        where = f"crack {k} (id {got['ids'][k]}, golden id {want['ids'][k]})"
        if got["ids"][k] != want["ids"][k]:
            return head + f"{where}: ids differ"
        if gb - ga != wb - wa:
            return head + f"{where}: {gb - ga} points, golden {wb - wa}"
        for f in FIELDS:
            g, w = got[f][ga:gb], want[f][wa:wb]
            off = (g != w) if f == "faces" else (np.abs(g - w) > tol[f])
            if off.any():
                i = int(np.flatnonzero(off.reshape(len(g), -1).any(axis=1))[0])
                return head + f"{where}: {f}[{i}] = {g[i].tolist()}, golden {w[i].tolist()}"
    if head:
        return head + "the first cracks are equal"
    return None


def mask_difference(got: np.ndarray, want: np.ndarray) -> dict:
    """Texels differing by more than MASK_LEVELS (share), the largest difference (levels)."""
    assert got.shape == want.shape, (got.shape, want.shape)
    d = np.abs(got.astype(np.int16) - want.astype(np.int16))
    return {"share": float((d > MASK_LEVELS).mean()), "max": int(d.max()),
            "texels": int((d > 0).sum())}


def test_first_network_difference_names_the_crack():
    cracks = [{"id": i, "points": [[0.0, 0.0, float(i)], [1.0, 0.0, float(i)]], "faces": [0, 1],
               "time": [0.0, 1.0], "width": [0.1, 0.0], "depth": [0.05, 0.0]} for i in (4, 9)]
    mask = np.zeros((4, 4), np.uint8)
    want = _arrays(cracks, mask)
    assert first_network_difference(_arrays(cracks, mask), want) is None
    cracks[1]["width"][1] = 1e-17  # last-bit rounding: within the tolerance
    assert first_network_difference(_arrays(cracks, mask), want) is None
    cracks[1]["width"][1] = 1e-4
    msg = first_network_difference(_arrays(cracks, mask), want)
    assert msg == "crack 1 (id 9, golden id 9): width[1] = 0.0001, golden 0.0"
    assert "1 cracks, golden 2" in first_network_difference(_arrays(cracks[:1], mask), want)


def test_mask_difference_counts_texels():
    want = np.zeros((10, 10), np.uint8)
    got = want.copy()
    got[0, :3] = (2, 3, 200)
    assert mask_difference(got, want) == {"share": 0.02, "max": 200, "texels": 3}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_golden_run(case, tmp_path):
    got, arrays, renderer = _run(case, tmp_path)
    golden = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    if RECORD:
        golden[case] = got
        golden["recorded_with"] = _recorded_with(renderer)
        GOLDEN.write_text(json.dumps(golden, indent=2, sort_keys=True) + "\n")
        np.savez_compressed(GOLDEN_DIR / f"{case}.npz", **arrays)
        pytest.skip("recorded")
    assert case in golden, f"no golden record for {case}: record with CRACKBAKE_RECORD_GOLDEN=1"
    want = golden[case]
    npz = GOLDEN_DIR / f"{case}.npz"
    stored = None
    if npz.exists():
        with np.load(npz) as z:
            stored = {k: z[k] for k in z.files}
        diff = first_network_difference(arrays, stored)
        assert diff is None, f"{case}: the crack network changed: {diff}"
    # With the arrays the counts suffice (the tolerance above); without them only the digest.
    summary = ("cracks", "points") if stored is not None else ("cracks", "points", "sha256")
    assert {k: got[k] for k in summary} == {k: want[k] for k in summary}, (
        f"{case}: the crack network changed"
        + ("" if stored is not None else f" (no {npz.name} to name the first differing crack)"))

    if got["mask_sha256"] == want["mask_sha256"]:
        return
    assert stored is not None, f"{case}: the mask changed (no {npz.name} to measure by how much)"
    rec = golden.get("recorded_with", {})
    m = mask_difference(arrays["mask"], stored["mask"])
    note = (f"{case}: mask differs from the golden on {m['texels']} texels "
            f"({100 * m['share']:.3f} % by more than {MASK_LEVELS} levels, max {m['max']}); "
            f"renderer {renderer.get('renderer')!r}, recorded on "
            f"{rec.get('renderer', {}).get('renderer')!r}")
    assert m["share"] <= MASK_TEXELS and m["max"] <= MASK_MAX, note
    # On the recording renderer the mask is bit-identical, so any difference is a change.
    assert renderer != rec.get("renderer"), note
