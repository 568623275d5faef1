"""File hashes and the atomic output folder (crackbake.transaction.stage)."""

from __future__ import annotations

import hashlib
import json
import os

import pytest

from crackbake.errors import CrackbakeError
from crackbake.transaction import OutputStage, sha256_file
from crackbake.transaction.outdir import swap_in


def test_sha256_file(tmp_path):
    p = tmp_path / "x.bin"
    data = os.urandom(3_000_000)
    p.write_bytes(data)
    assert sha256_file(p) == hashlib.sha256(data).hexdigest()


def _previous_set(out, files=("mask.png", "stale.exr")):
    """A folder as an earlier crackbake run left it: files plus a manifest listing them."""
    out.mkdir(parents=True)
    for name in files:
        (out / name).write_bytes(b"old " + name.encode())
    doc = {"crackbake": "0.1.0", "files": [{"name": n} for n in files]}
    (out / "manifest.json").write_text(json.dumps(doc))


def _beside(out):
    """Names crackbake made beside ``out`` (staging, trash, lock)."""
    return sorted(p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}."))


def test_output_stage_commit_replaces_the_whole_set(tmp_path):
    out = tmp_path / "rock_cracks"
    _previous_set(out)
    with OutputStage(out) as stage:
        stage.path("mask.png").write_bytes(b"new mask")
        stage.path("master.exr").write_bytes(b"exr" * 1000)
        staging = stage.staging_dir
        # A hidden sibling (same file system), locked while the stage is open.
        assert staging.parent == tmp_path and staging.name.startswith(".rock_cracks.crackbake-")
        assert (tmp_path / ".rock_cracks.crackbake-lock").read_text().strip() == str(os.getpid())
        # Nothing visible in the folder before commit.
        assert (out / "mask.png").read_bytes() == b"old mask.png"
        records = stage.records()
        assert [r["name"] for r in records] == ["mask.png", "master.exr"]
        for r in records:
            data = (staging / r["name"]).read_bytes()
            assert r["bytes"] == len(data)
            assert r["sha256"] == hashlib.sha256(data).hexdigest()
        assert stage.records() == records  # cached, same answer
        stage.path("manifest.json").write_text(json.dumps({"crackbake": "x", "files": records}))
        moved = stage.commit()
        assert stage.committed
    assert sorted(p.name for p in moved) == ["manifest.json", "mask.png", "master.exr"]
    # Exactly this run's files: the previous run's stale.exr is gone, nothing hidden remains.
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "mask.png", "master.exr"]
    assert (out / "mask.png").read_bytes() == b"new mask"
    assert _beside(out) == []
    umask = os.umask(0o022)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o777 & ~umask  # an ordinary folder, not mkdtemp's 0700


@pytest.mark.parametrize("exchange", [True, False])
def test_swap_in_both_ways(tmp_path, exchange):
    final, staging = tmp_path / "out", tmp_path / ".out.crackbake-staging-abcd1234"
    final.mkdir()
    (final / "old").write_text("old")
    staging.mkdir()
    (staging / "new").write_text("new")
    old = swap_in(staging, final, exchange=exchange)
    assert [p.name for p in final.iterdir()] == ["new"]
    assert [p.name for p in old.iterdir()] == ["old"]
    if not exchange:
        assert old.name == ".out.crackbake-trash-abcd1234"


def test_output_stage_exception_touches_nothing(tmp_path):
    out = tmp_path / "out"
    _previous_set(out, ("mask.png",))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(RuntimeError, match="bake failed"):
        with OutputStage(out) as stage:
            stage.path("mask.png").write_bytes(b"new")
            stage.path("manifest.json").write_text("{}")
            staging = stage.staging_dir
            raise RuntimeError("bake failed")
    assert not staging.exists()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _beside(out) == []

    # A folder that did not exist: no folder, no created parents, no lock file left.
    fresh = tmp_path / "new" / "dir"
    with OutputStage(fresh) as stage:
        stage.path("a.exr").write_bytes(b"x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_output_stage_rejects_paths_outside(tmp_path):
    with OutputStage(tmp_path / "o") as stage:
        for name in ("../x.png", "a/b.png", "", "..", ".crackbake-staging"):
            with pytest.raises(CrackbakeError):
                stage.path(name)
        stage.commit()
        with pytest.raises(CrackbakeError):
            stage.path("late.png")
    assert list((tmp_path / "o").iterdir()) == []


def test_refuses_to_replace_what_is_not_ours(tmp_path, monkeypatch):
    home = tmp_path / "home"
    home.mkdir()
    (home / "thesis.tex").write_text("years of work")
    with pytest.raises(CrackbakeError, match="has no crackbake manifest.json") as err:
        OutputStage(home).__enter__()
    assert "\n" not in str(err.value)
    # A crackbake folder the user added a file to.
    out = tmp_path / "out"
    _previous_set(out)
    (out / "notes.txt").write_text("mine")
    with pytest.raises(CrackbakeError, match="holds 'notes.txt', which crackbake did not write"):
        OutputStage(out).__enter__()
    # A manifest that is not crackbake's does not count.
    other = tmp_path / "other"
    other.mkdir()
    (other / "manifest.json").write_text('{"name": "some web app"}')
    with pytest.raises(CrackbakeError, match="no crackbake manifest"):
        OutputStage(other).__enter__()
    afile = tmp_path / "file.png"
    afile.write_bytes(b"x")
    for path, message in (
        (afile, "exists and is not a folder"),
        ("/dev/null", "exists and is not a folder"),
        ("/proc", "is a mount point"),
        ("", "is empty"),
        ("/", "name a sub-folder"),
        (tmp_path, "is or holds the current folder"),
        (afile / "sub", "is not a folder"),
    ):
        monkeypatch.chdir(tmp_path / "home")
        with pytest.raises(CrackbakeError, match=message):
            OutputStage(path).__enter__()
    # Nothing was touched, and nothing was left beside any of them.
    assert (home / "thesis.tex").read_text() == "years of work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.png", "home", "other", "out"]


def test_symlinked_output_folder_is_replaced_through_the_link(tmp_path):
    real = tmp_path / "real"
    _previous_set(real, ("a.png",))
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    with OutputStage(link) as stage:
        stage.path("b.png").write_bytes(b"b")
        stage.commit()
    assert link.is_symlink() and [p.name for p in link.iterdir()] == ["b.png"]


def test_lock_refuses_a_second_stage_and_a_stale_lock_does_not_block(tmp_path):
    out = tmp_path / "out"
    with OutputStage(out):
        busy = f"in use by another crackbake run \\(pid {os.getpid()}\\)"
        with pytest.raises(CrackbakeError, match=busy):
            OutputStage(out).__enter__()
    assert not (tmp_path / ".out.crackbake-lock").exists()
    # A lock file a killed run left (nobody holds the flock) is taken over, then removed.
    (tmp_path / ".out.crackbake-lock").write_text("999999\n")
    with OutputStage(out) as stage:
        stage.commit()
    assert _beside(out) == []


def test_leftovers_of_killed_runs_are_removed(tmp_path):
    out = tmp_path / "out"
    _previous_set(out, ("a.png",))
    staging = tmp_path / ".out.crackbake-staging-k1ll3d00"  # killed while writing
    staging.mkdir()
    (staging / ".crackbake-staging").write_bytes(b"")
    (staging / "half.exr").write_bytes(b"x" * 100)
    trash = tmp_path / ".out.crackbake-trash-k1ll3d01"  # killed between the two renames
    trash.mkdir()
    (trash / "manifest.json").write_text(json.dumps({"crackbake": "0.1", "files": []}))
    empty = tmp_path / ".out.crackbake-staging-k1ll3d02"
    empty.mkdir()
    foreign = tmp_path / ".out.crackbake-staging-notours"  # prefix but no marker: kept
    foreign.mkdir()
    (foreign / "keep.txt").write_text("keep")
    with OutputStage(out) as stage:
        assert not staging.exists() and not trash.exists() and not empty.exists()
        stage.path("a.png").write_bytes(b"a")
        stage.commit()
    assert (foreign / "keep.txt").exists()
    assert _beside(out) == [foreign.name]


def test_a_signal_whose_exception_was_lost_still_stops_the_commit(tmp_path):
    """SIGTERM raised inside C code can be swallowed or turned into another error (seen: an
    ImportError from an extension's import); the stage must still refuse to commit."""
    import signal

    from crackbake.transaction.interrupt import Interrupt, interruptible, received

    out = tmp_path / "rock_cracks"
    _previous_set(out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with interruptible():
        with OutputStage(out) as stage:
            stage.path("mask.png").write_bytes(b"new mask")
            try:
                os.kill(os.getpid(), signal.SIGTERM)  # a real signal, handled in this thread
                for _ in range(1000):  # the handler runs between bytecodes
                    pass
            except Interrupt:
                pass  # what a C extension might do with it
            assert received() == signal.SIGTERM
            with pytest.raises(Interrupt):
                stage.commit()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _beside(out) == []


def test_a_signal_of_an_earlier_run_does_not_stop_a_later_commit(tmp_path):
    """The lost-signal guard is the run's own: once ``interruptible()`` has ended, a later
    stage committed outside it (a library caller's, the next test's) commits."""
    import signal

    from crackbake.transaction.interrupt import Interrupt, interruptible

    with interruptible():
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs between bytecodes
                pass
        except Interrupt:
            pass
    out = tmp_path / "later"
    with OutputStage(out) as stage:
        stage.path("mask.png").write_bytes(b"mask")
        stage.commit()
    assert (out / "mask.png").read_bytes() == b"mask"


def test_remembered_hashes_are_the_records_and_follow_a_rewrite(tmp_path):
    with OutputStage(tmp_path / "out") as stage:
        a, b = stage.path("a.bin"), stage.path("b.bin")
        a.write_bytes(b"first")
        stage.remember(a, b"first")  # the bytes just written
        b.write_bytes(b"second" * 1000)
        stage.remember(b)  # read back
        records = {r["name"]: r for r in stage.records()}
        assert records["a.bin"]["sha256"] == hashlib.sha256(b"first").hexdigest()
        assert records["b.bin"]["sha256"] == hashlib.sha256(b"second" * 1000).hexdigest()
        a.write_bytes(b"other")  # rewritten after: hashed again
        os.utime(a, ns=(1, 1))
        again = {r["name"]: r for r in stage.records()}
        assert again["a.bin"]["sha256"] == hashlib.sha256(b"other").hexdigest()
        stage.commit()
