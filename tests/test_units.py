"""Units must not matter (issue 18 §1): a scan-like mesh without UVs unwraps, cracks and bakes the
same at any uniform scale; every run reports its UV coverage; a poor unwrap warns."""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import cli_forks
import numpy as np
import pytest
from PIL import Image

from crackbake.bake import uv as U
from crackbake.bake.uv.shapes import relief_plane, scan_blob, write_obj
from crackbake.bake.uv.unwrap import COVERAGE_WARN, _warn_coverage
from crackbake.bake.uv.uvmesh import unwrapped_uvmesh, uv_area_coverage
from crackbake.errors import CrackbakeWarning

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CRACKBAKE_CACHE_DIR", str(tmp_path / "cache"))


def _run(mesh: Path, out: Path, impact: np.ndarray, cache: Path):
    env = dict(os.environ, PYTHONPATH=str(ROOT), CRACKBAKE_CACHE_DIR=str(cache))
    return cli_forks.run(
        [str(mesh), "--preset", "glass",
         "--impact", ",".join(repr(float(x)) for x in impact), "--sim-faces", "12000",
         "--res", "512", "--formats", "png", "-o", str(out)],
        env=env, timeout=300,
    )  # fmt: skip


def test_a_scan_without_uvs_bakes_the_same_at_any_scale(tmp_path):
    blob = scan_blob(4000, diagonal=0.15, seed=3)  # a 15 cm scan in metres
    impact = blob.vertices[int(np.argmax(blob.vertices[:, 2]))]
    results = {}
    for scale in (1e-3, 1.0, 1e3):
        mesh = write_obj(
            type(blob)(vertices=blob.vertices * scale, faces=blob.faces, uv=None,
                       normals=blob.normals),
            tmp_path / f"blob_{scale:g}.obj",
        )  # fmt: skip
        out = tmp_path / f"out_{scale:g}"
        res = _run(mesh, out, impact * scale, tmp_path / f"cache_{scale:g}")
        assert res.returncode == 0, res.stderr
        manifest = json.loads((out / "manifest.json").read_text())
        mask = np.asarray(Image.open(out / f"{mesh.stem}_mask.png"))
        results[scale] = (manifest, mask, res.stderr)
    ref_manifest, ref_mask, _ = results[1.0]
    ref_coverage = ref_manifest["uv"]["coverage"]
    assert ref_manifest["uv"]["method"] == "unwrapped"
    assert ref_coverage >= 0.5
    ref_texels = np.count_nonzero(ref_mask)
    assert ref_texels > 500  # a star, not specks
    for scale in (1e-3, 1e3):
        manifest, mask, stderr = results[scale]
        assert abs(manifest["uv"]["coverage"] - ref_coverage) < 1e-3
        assert abs(np.count_nonzero(mask) - ref_texels) <= 0.02 * ref_texels
        # Same UVs and the same network up to scale: the masks agree texel for texel but for
        # float rounding at 8-bit steps.
        diff = np.abs(mask.astype(int) - ref_mask.astype(int))
        assert np.count_nonzero(diff > 1) <= 1e-3 * diff.size
        assert f"{manifest['uv']['coverage']:.0%} of the texture used" in stderr
        assert "uses only" not in stderr


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_unwrap_charts_do_not_depend_on_units(scale):
    blob = scan_blob(3000, diagonal=0.15, seed=1)
    ref = U.unwrap(blob, 512, cache=False)
    scaled = type(blob)(vertices=blob.vertices * scale + 7.0 * scale, faces=blob.faces, uv=None,
                        normals=blob.normals, source="blob.obj")  # fmt: skip
    got = U.unwrap(scaled, 512, cache=False)
    assert np.array_equal(got.faces, ref.faces)
    assert np.allclose(got.uv, ref.uv, atol=1e-6)
    assert uv_area_coverage(got.uv, got.faces) >= 0.5


def test_a_flat_relief_fills_half_the_texture():
    relief = relief_plane(40, diagonal=0.3)
    got = U.unwrap(relief, 1024, cache=False)
    assert uv_area_coverage(got.uv, got.faces) >= 0.5


def test_an_unwrap_using_little_of_the_texture_warns():
    blob = scan_blob(500, diagonal=1.0)
    good = U.unwrap(blob, 256, cache=False)
    assert uv_area_coverage(good.uv, good.faces) > COVERAGE_WARN
    # The same charts shrunk into a corner: a poor layout the warning must name.
    poor = unwrapped_uvmesh(blob, good.vertex_map, good.faces, good.uv * 0.4, 0.0, 2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_coverage(good, "blob.obj", 256)
        _warn_coverage(poor, "blob.obj", 256)
    lines = [str(w.message) for w in caught if issubclass(w.category, CrackbakeWarning)]
    assert len(lines) == 1
    assert "uses only" in lines[0] and "--res" in lines[0] and "\n" not in lines[0]


def test_uv_area_coverage_counts_the_page_share():
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert uv_area_coverage(uv, np.array([[0, 1, 2]])) == pytest.approx(0.5)
    assert uv_area_coverage(uv, np.array([[0, 1, 2], [0, 2, 3]])) == pytest.approx(1.0)
    assert uv_area_coverage(uv * 0.5, np.array([[0, 1, 2], [0, 2, 3]])) == pytest.approx(0.25)
