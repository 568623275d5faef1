"""The run's heap faulted in on a thread (crackbake.prefault).

Each check runs in a fresh interpreter: the module changes how glibc's malloc serves the whole
process, which must not leak into the test session.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from crackbake.prefault import HEAP_BASE, PREFAULT_RES, heap_bytes

ROOT = Path(__file__).resolve().parents[1]
GLIBC = os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc")


def _run(code: str, env: dict | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=300)


#: Main-thread minor faults of touching a fresh 64 MiB array, after start(res) (0: not called).
_TOUCH = """
import sys, threading
import numpy as np
from crackbake import prefault

def faults():
    stat = open(f"/proc/self/task/{threading.get_native_id()}/stat").read()
    return int(stat.rsplit(")", 1)[1].split()[7])

np._core.multiarray._set_madvise_hugepage(False)  # count 4 KiB pages, as the GPU hosts fault
res = int(sys.argv[1])
size = prefault.start(res, limit=64 << 30) if res else 0
early = np.full(1 << 20, 7.0)  # handed out while the thread faults its pages in
prefault.wait()
before = faults()
a = np.ones(8 << 20)  # 64 MiB
print(size, faults() - before, int(a.sum()), bool((early == 7.0).all()))
"""


def test_the_model_grows_with_the_resolution():
    assert heap_bytes(2048) > HEAP_BASE
    assert heap_bytes(4096) - heap_bytes(2048) == 3 * (heap_bytes(2048) - HEAP_BASE)


@pytest.mark.skipif(not GLIBC, reason="the heap's settings are glibc's")
def test_the_heap_is_faulted_in_ahead_and_keeps_what_it_holds():
    """After the thread, a 64 MiB array costs the run's thread (almost) no fault, where it
    costs a fault per page without it; memory handed out while the thread ran keeps its
    contents (MADV_POPULATE_WRITE maps pages without writing them)."""
    code = _TOUCH.replace("sys.argv[1]", "'4096'")
    size, faults, total, kept = _run(code).stdout.split()
    assert int(size) == heap_bytes(4096) & ~0xFFFFF
    assert int(total) == 8 << 20 and kept == "True"
    without = _run(_TOUCH.replace("sys.argv[1]", "'0'")).stdout.split()
    assert int(without[1]) > 10_000  # one per 4 KiB page of the array
    assert int(faults) < 200, (faults, without)


@pytest.mark.skipif(not GLIBC, reason="the heap's settings are glibc's")
def test_small_bakes_a_switch_and_a_tight_limit_are_respected():
    r = _run("from crackbake import prefault\n"
             f"print(prefault.start({PREFAULT_RES // 2}, limit=64 << 30),"
             " prefault.start(4096, environ={'CRACKBAKE_PREFAULT': '0'}, limit=64 << 30),"
             " prefault.start(4096, limit=1 << 30), prefault.start(4096, limit=64 << 30))")
    small, off, capped, again = map(int, r.stdout.split())
    assert small == 0 and off == 0
    assert 0 < capped <= (1 << 30) // 4
    assert again == 0  # once per process


def test_the_command_prefaults_bakes_not_re_bakes():
    from crackbake.entry import _rebakes

    assert not _rebakes(["mesh.obj", "--res", "4096"])
    assert _rebakes(["mesh.obj", "--cracks", "cracks.json"])
    assert _rebakes(["mesh.obj", "--cracks=cracks.json"])


def _outputs(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())
            if p.name != "manifest.json"}  # its timings differ run to run


@pytest.mark.slow
def test_a_bake_writes_the_same_files_with_and_without_it(tmp_path):
    """The README's bake at 2048² (where the command prefaults) with the heap prefaulted and
    without: every file the same, byte for byte."""
    mesh = ROOT / "examples" / "spot.obj"
    outs = {}
    for flag in ("1", "0"):
        out = tmp_path / f"prefault{flag}"
        r = subprocess.run([sys.executable, "-m", "crackbake", str(mesh), "--preset", "glass",
                            "--impact", "0.334,0.044,0.287", "--res", "2048", "-q", "-o",
                            str(out)], capture_output=True, text=True, timeout=300,
                           env={**os.environ, "PYTHONPATH": str(ROOT),
                                "CRACKBAKE_PREFAULT": flag})  # fmt: skip
        assert r.returncode == 0, r.stderr[-800:]
        outs[flag] = _outputs(out)
    assert outs["1"] == outs["0"] and len(outs["1"]) >= 12


def _thp_mode() -> str:
    try:
        text = Path("/sys/kernel/mm/transparent_hugepage/enabled").read_text()
    except OSError:
        return "never"
    return text.split("[", 1)[1].split("]", 1)[0] if "[" in text else "never"


@pytest.mark.skipif(not GLIBC or _thp_mode() == "never",
                    reason="glibc's heap on a system with transparent huge pages")
def test_the_heap_is_faulted_in_on_huge_pages_without_the_restart():
    """Without glibc's huge-page tunable (a GPU machine does not restart on it), the heap the
    thread faults in is still backed by 2 MiB pages: the advice is the module's own."""
    code = """
import sys
from crackbake import prefault
size = prefault.start(4096, limit=64 << 30)
prefault.wait()
huge = 0
for line in open("/proc/self/smaps"):
    if line.startswith("AnonHugePages:"):
        huge += int(line.split()[1]) << 10
print(size, huge)
"""
    env = {"GLIBC_TUNABLES": "glibc.malloc.hugetlb=0"}
    size, huge = map(int, _run(code, env).stdout.split())
    assert size == heap_bytes(4096) & ~0xFFFFF
    # all but the partial 2 MiB pages at its ends (the kernel may fall back to small pages
    # where it has no free huge one: most of the heap is enough)
    assert huge >= size // 2, (size, huge)
