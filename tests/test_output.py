"""File hashes and the atomic output folder (crackbake.exchange.output)."""

from __future__ import annotations

import hashlib
import json
import os

import pytest

from crackbake.errors import CrackbakeError
from crackbake.exchange import (
    OutputStage,
    sha256_file,
)


def test_sha256_file(tmp_path):
    p = tmp_path / "x.bin"
    data = os.urandom(3_000_000)
    p.write_bytes(data)
    assert sha256_file(p) == hashlib.sha256(data).hexdigest()


def test_output_stage_commit(tmp_path):
    out = tmp_path / "rock_cracks"
    out.mkdir()
    (out / "mask.png").write_bytes(b"old")
    with OutputStage(out) as stage:
        stage.path("mask.png").write_bytes(b"new mask")
        stage.path("master.exr").write_bytes(b"exr" * 1000)
        staging = stage.staging_dir
        assert staging.parent == out and staging.name.startswith(".")
        # Nothing visible under final names before commit.
        assert (out / "mask.png").read_bytes() == b"old" and not (out / "master.exr").exists()
        records = stage.records()
        assert [r["name"] for r in records] == ["mask.png", "master.exr"]
        for r in records:
            data = (staging / r["name"]).read_bytes()
            assert r["bytes"] == len(data)
            assert r["sha256"] == hashlib.sha256(data).hexdigest()
        assert stage.records() == records  # cached, same answer
        stage.path("manifest.json").write_text(json.dumps({"files": records}))
        moved = stage.commit(last=("manifest.json",))
    assert [p.name for p in moved][-1] == "manifest.json"
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "mask.png", "master.exr"]
    assert (out / "mask.png").read_bytes() == b"new mask"
    assert not staging.exists()


def test_output_stage_exception_touches_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mask.png").write_bytes(b"old")
    with pytest.raises(RuntimeError, match="bake failed"):
        with OutputStage(out) as stage:
            stage.path("mask.png").write_bytes(b"new")
            stage.path("manifest.json").write_text("{}")
            staging = stage.staging_dir
            raise RuntimeError("bake failed")
    assert not staging.exists()
    assert [p.name for p in out.iterdir()] == ["mask.png"]
    assert (out / "mask.png").read_bytes() == b"old"

    # Leaving without commit behaves the same; a new folder is created on demand.
    fresh = tmp_path / "new" / "dir"
    with OutputStage(fresh) as stage:
        stage.path("a.exr").write_bytes(b"x")
    assert list(fresh.iterdir()) == []


def test_output_stage_rejects_paths_outside(tmp_path):
    with OutputStage(tmp_path / "o") as stage:
        for name in ("../x.png", "a/b.png", "", ".."):
            with pytest.raises(CrackbakeError):
                stage.path(name)
        stage.commit()
        with pytest.raises(CrackbakeError):
            stage.path("late.png")
