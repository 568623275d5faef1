"""The write stage begun early (crackbake.exchange.bundle.Writer): the same files as a write
after the stress bake, every job joined before the stage is committed or discarded."""

from __future__ import annotations

import hashlib
import os
import sys
import threading

import pytest
from conftest import tiny_network
from maps_factory import plate_uvmesh, synthetic_maps

from crackbake.exchange.bundle import Writer, write_outputs
from crackbake.params import RunParams
from crackbake.transaction.stage import OutputStage

FORMATS = ("exr", "png", "glb", "preview")


def _digests(folder) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()}


def test_work_between_start_and_finish_changes_no_byte(tmp_path):
    mesh, uvm = plate_uvmesh()
    maps = synthetic_maps()
    params = RunParams(mesh=mesh.source, formats=FORMATS)
    with OutputStage(tmp_path / "whole") as stage:
        write_outputs(stage, "rock", params, mesh, uvm, tiny_network(), maps)
        stage.commit()
    with OutputStage(tmp_path / "early") as stage:
        with Writer(stage, "rock", params, mesh, uvm, tiny_network(), maps) as writer:
            threading.Event().wait(0.05)  # the stress bake's place: the encoders run meanwhile
            writer.finish()
        stage.commit()
    whole, early = _digests(tmp_path / "whole"), _digests(tmp_path / "early")
    assert "rock_cracks.exr" in whole and "preview.png" in whole and "cracks.json" in whole
    assert early == whole


def test_an_error_between_start_and_finish_waits_for_every_job(tmp_path, monkeypatch):
    """The stress bake fails while the encoders run: the error comes out only once no job is
    left writing into the stage, and the output folder is not created."""
    import crackbake.exchange.bundle as bundle

    mesh, uvm = plate_uvmesh()
    maps = synthetic_maps()
    params = RunParams(mesh=mesh.source, formats=FORMATS)
    release, ended = threading.Event(), []
    slow_exr = bundle._write_exr

    def held_exr(*args, **kwargs):  # a real EXR write that ends only once the error is raised
        release.wait(10)
        slow_exr(*args, **kwargs)
        ended.append(True)

    monkeypatch.setattr(bundle, "_write_exr", held_exr)
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="stress bake failed"):
        with OutputStage(out) as stage:
            with Writer(stage, "rock", params, mesh, uvm, tiny_network(), maps) as writer:
                threading.Timer(0.2, release.set).start()
                raise RuntimeError("stress bake failed")
            writer.finish()
    assert ended == [True]  # the EXR job had finished when the error reached the caller
    assert not out.exists()


def test_a_failed_job_is_raised_by_finish(tmp_path, monkeypatch):
    import crackbake.exchange.bundle as bundle

    mesh, uvm = plate_uvmesh()
    params = RunParams(mesh=mesh.source, formats=FORMATS)

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(bundle, "_write_exr", broken)
    with OutputStage(tmp_path / "out") as stage:
        with pytest.raises(OSError, match="disk full"):
            with Writer(stage, "rock", params, mesh, uvm, tiny_network(), synthetic_maps()) as w:
                w.finish()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice is Linux's")
def test_encoders_run_below_the_main_thread_and_their_chunk_threads_too(tmp_path):
    """The stress bake's GL draws keep the main thread's priority while the encoders run."""
    from concurrent.futures import ThreadPoolExecutor

    from crackbake.exchange.bundle import ENCODER_NICE

    def nice() -> int:
        return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    def chunk_thread() -> int:  # as exrzip's chunk pool starts its threads from an encoder
        with ThreadPoolExecutor(1) as inner:
            return inner.submit(nice).result()

    mesh, uvm = plate_uvmesh()
    params = RunParams(mesh=mesh.source, formats=("exr",))
    before = nice()
    with OutputStage(tmp_path / "out") as stage:
        with Writer(stage, "rock", params, mesh, uvm, tiny_network(), synthetic_maps()) as w:
            assert w.pool.submit(nice).result() == min(19, before + ENCODER_NICE)
            assert w.pool.submit(chunk_thread).result() == min(19, before + ENCODER_NICE)
            w.finish()
    assert nice() == before
