"""The peak-memory estimate and the check that refuses runs before they can be killed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from crackbake.errors import CrackbakeError
from crackbake.memory import (
    GIB,
    MemoryEstimate,
    available_memory,
    cgroup_limit,
    check_memory,
    estimate_peak,
    run_sizes,
)
from crackbake.params import DECAL_RES_DEFAULT, TILE_DEFAULT, Impact, RunParams

REPO = Path(__file__).resolve().parents[1]


def test_estimate_grows_with_every_size():
    base = estimate_peak(faces=10_000, sim_faces=100_000, res=1024, stress_res=1024)
    for change in ({"faces": 1_000_000}, {"sim_faces": 1_000_000}, {"res": 4096},
                   {"stress_res": 4096}):
        bigger = estimate_peak(**{"faces": 10_000, "sim_faces": 100_000, "res": 1024,
                                  "stress_res": 1024, **change})
        assert bigger.rss > base.rss, change
    assert base.rss == sum(base.parts.values())
    assert estimate_peak(faces=0, sim_faces=0, res=64).parts["stress"] == 0


def test_banded_bake_grows_slower_than_the_texels():
    """Above the tile the GL targets stop growing: 4x the texels, less than 4x the bake."""
    a = estimate_peak(faces=0, sim_faces=0, res=4096).parts["bake"]
    b = estimate_peak(faces=0, sim_faces=0, res=8192).parts["bake"]
    assert 2 * a < b < 4 * a


def test_the_issue_runs_are_refused_where_they_died():
    """Issue 19's runs: --stress-res 16384 was killed at 21.5 GB on a 24 GB machine; --res 8192
    ended in MemoryError under a 2-3 GB cap, --res 16384 under 10 GB."""
    stress = estimate_peak(faces=5856, sim_faces=100_000, res=2048, stress_res=16384)
    assert stress.rss > 18 * GIB and stress.largest == "stress"
    assert estimate_peak(faces=5856, sim_faces=100_000, res=8192).rss > 3 * GIB
    assert estimate_peak(faces=5856, sim_faces=100_000, res=16384).rss > 10 * GIB
    assert estimate_peak(faces=5856, sim_faces=20_000_000, res=2048).largest == "sim"


def test_check_names_estimate_limit_and_option():
    est = estimate_peak(faces=5856, sim_faces=100_000, res=16384)
    with pytest.raises(CrackbakeError) as info:
        check_memory(est, max_memory=10)
    text = str(info.value)
    assert f"needs about {est.rss / GIB:.1f} GiB" in text
    assert "--max-memory allows 10.0 GiB; lower --res, or raise --max-memory" in text
    check_memory(est, max_memory=est.rss / GIB + 0.1)  # the override lets it run
    check_memory(MemoryEstimate(rss=GIB, parts={"base": GIB}))  # 1 GiB fits any test machine


def test_run_sizes_follow_the_options(tmp_path):
    p = RunParams(mesh=Path("m.obj"), res=4096, sim_faces=300_000)
    sizes = run_sizes(p, faces=5000)
    assert sizes == {"faces": 5000, "sim_faces": 300_000, "res": 4096, "stress_res": 1024,
                     "tile": TILE_DEFAULT, "decal_res": None, "frames": 0, "unwrap_faces": 0}
    # An asset finer than wanted is its own sim mesh; far finer gets a proxy of the wanted size.
    assert run_sizes(p, faces=500_000)["sim_faces"] == 500_000
    assert run_sizes(p, faces=5_000_000)["sim_faces"] == 300_000
    # A re-bake solves nothing and writes no stress maps.
    rebake = run_sizes(RunParams(mesh=Path("m.obj"), cracks=Path("c.json")), faces=5000)
    assert rebake["sim_faces"] == 0 and rebake["stress_res"] is None
    assert run_sizes(RunParams(mesh=Path("m"), formats=("exr",)), faces=1)["stress_res"] is None


def test_a_rebake_sizes_its_run_without_the_sim_mesh_modules():
    """``--cracks`` solves nothing: sizing its run imports none of the sim-mesh modules
    (proxy, triangulation, decimation; issue 25's re-bake floor), a solving run does."""
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "from crackbake.memory import run_sizes\n"
        "from crackbake.params import RunParams\n"
        "run_sizes(RunParams(mesh=Path('m.obj'), cracks=Path(sys.argv[1])), faces=5000)\n"
        "print('crackbake.simulate.simmesh' in sys.modules)\n"
        "run_sizes(RunParams(mesh=Path('m.obj')), faces=5000)\n"
        "print('crackbake.simulate.simmesh' in sys.modules)\n"
    )
    r = subprocess.run([sys.executable, "-c", code, "c.json"], capture_output=True, text=True,
                       timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True"]


def test_available_memory_reads_the_address_space_cap():
    """Under ``RLIMIT_AS`` (``ulimit -v``, ``prlimit --as``) the cap is the limit, compared with
    the address space (the resident estimate plus the libraries' reservations)."""
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30));"
            "from crackbake.memory import available_memory; print(available_memory())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=120, check=True)
    limit, source, address = eval(out.stdout)  # noqa: S307 - our own repr of a tuple
    assert limit == 3 * 2**30 and "ulimit -v" in source and address is True
    limit, _, _ = available_memory()
    assert 0 < limit <= os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _cgroup_tree(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


@pytest.mark.parametrize("layout, membership, limit, source", [
    # cgroup v2: a systemd slice with MemoryMax under an unlimited parent
    ({"memory.max": "max\n", "user.slice/memory.max": "max\n",
      "user.slice/run-1.scope/memory.max": "3221225472\n"},
     "0::/user.slice/run-1.scope\n", 3 * 2**30, "user.slice/run-1.scope/memory.max"),
    # v2: the parent's limit is smaller than the group's own
    ({"a/memory.max": "1073741824\n", "a/b/memory.max": "max\n"},
     "0::/a/b\n", 2**30, "a/memory.max"),
    # cgroup v1 in a sub-group (this is how a job scheduler's process group looks)
    ({"memory/memory.limit_in_bytes": "9223372036854771712\n",
      "memory/jobs/42/memory.limit_in_bytes": "2147483648\n"},
     "4:memory:/jobs/42\n0::/\n", 2 * 2**30, "memory/jobs/42/memory.limit_in_bytes"),
    # v1 with no limit anywhere
    ({"memory/memory.limit_in_bytes": "9223372036854771712\n"},
     "4:memory:/\n0::/\n", None, None),
])
def test_cgroup_limit_reads_the_process_group_and_its_parents(tmp_path, layout, membership,
                                                              limit, source):
    root = tmp_path / "cgroup"
    _cgroup_tree(root, layout)
    (tmp_path / "self").write_text(membership)
    found = cgroup_limit(root, tmp_path / "self")
    if limit is None:
        assert found is None
        return
    assert found[0] == limit and found[1].endswith(source)
    got, said, address = available_memory(root, tmp_path / "self")
    assert got == min(limit, os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    assert "cgroup" in said and address is False



def test_a_decal_adds_its_texels_and_names_its_option():
    plain = estimate_peak(faces=5856, sim_faces=100_000, res=1024)
    decal = estimate_peak(faces=5856, sim_faces=100_000, res=1024, decal_res=8192)
    # measured: --decal-res 4096 adds 1.84 GB to spot's run; 8192 has 4x the texels
    assert decal.rss - plain.rss > 4 * 1.6 * GIB
    assert decal.largest == "decal"
    p = RunParams(mesh=Path("m.obj"), impacts=(Impact((0, 0, 0)),), decal=0.5, res=2048)
    assert run_sizes(p, faces=10)["decal_res"] == min(2048, DECAL_RES_DEFAULT)
    with pytest.raises(CrackbakeError, match="--decal-res"):
        check_memory(decal, max_memory=4.0)


def test_frames_add_one_term_whatever_their_count():
    plain = estimate_peak(faces=5856, sim_faces=100_000, res=4096)
    eight = estimate_peak(faces=5856, sim_faces=100_000, res=4096, frames=8)
    many = estimate_peak(faces=5856, sim_faces=100_000, res=4096, frames=500)
    assert eight.rss > plain.rss and many.rss == eight.rss
    p = RunParams(mesh=Path("m.obj"), frames=12, res=2048)
    assert run_sizes(p, faces=10)["frames"] == 12


def test_the_xatlas_child_adds_to_the_unwrap_not_to_the_later_stages():
    """xatlas runs in a child while the run waits, before the solver and the bake: the peak is
    the larger of the stages' sum and (base + mesh + child), never all of them at once."""
    from crackbake.memory import ADDRESS_OVERHEAD, XATLAS_BASE, XATLAS_PER_FACE

    sizes = {"faces": 100_000, "sim_faces": 100_000, "res": 4096}
    kept = estimate_peak(**sizes)
    unwrapped = estimate_peak(**sizes, unwrap_faces=100_000)
    child = XATLAS_BASE + XATLAS_PER_FACE * 100_000
    assert unwrapped.parts["xatlas"] == int(child)
    assert unwrapped.rss == kept.rss  # the bake's peak is later and larger than the unwrap's
    assert unwrapped.largest == kept.largest == "bake"

    # A re-bake of a big scan at a small size: the unwrap is the peak.
    big = estimate_peak(faces=3_000_000, sim_faces=0, res=256, unwrap_faces=3_000_000)
    p = big.parts
    assert big.rss == p["base"] + p["mesh"] + p["xatlas"] > big.stages
    assert big.largest == "xatlas"
    # Address space is each process's own: the larger of the two, plus the libraries.
    assert big.address_space == int(max(big.stages, p["xatlas"]) + ADDRESS_OVERHEAD)
    with pytest.raises(CrackbakeError) as info:
        check_memory(big, max_memory=big.rss / GIB - 0.5)
    text = str(info.value)
    assert "decimate it" in text and "--uv keep" in text
    assert "xatlas" in text and "bake" not in text


def test_run_sizes_count_the_unwrap_when_there_is_one():
    from crackbake.io.mesh import Mesh

    def mesh(uv):
        v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
        return Mesh(vertices=v, faces=np.array([[0, 1, 2]]), uv=uv, normals=None,
                    source="t.obj", name="t")

    with_uv, without = mesh(np.array([[0.0, 0], [1, 0], [0, 1]])), mesh(None)
    auto = RunParams(mesh=Path("m.obj"))
    assert run_sizes(auto, with_uv)["unwrap_faces"] == 0
    assert run_sizes(auto, without)["unwrap_faces"] == 1
    assert run_sizes(RunParams(mesh=Path("m.obj"), uv="unwrap"), with_uv)["unwrap_faces"] == 1
    assert run_sizes(RunParams(mesh=Path("m.obj"), uv="unwrap"), faces=7)["unwrap_faces"] == 7
    assert run_sizes(RunParams(mesh=Path("m.obj"), uv="keep"), without)["unwrap_faces"] == 0


@pytest.mark.slow
def test_the_xatlas_term_holds_a_real_worker():
    """A real unwrap of a 40k-face scan-like mesh in a fresh process: its one child's peak RSS
    (the xatlas worker) lies under the model's xatlas term, and not far under it."""
    from crackbake.memory import XATLAS_BASE, XATLAS_PER_FACE

    code = (
        "import resource, warnings\n"
        "from crackbake.bake.uv import unwrap\n"
        "from crackbake.bake.uv.shapes import scan_blob\n"
        "m = scan_blob(40000, 0.15)\n"
        "warnings.simplefilter('ignore')\n"
        "unwrap(m, 1024, cache=False, timeout=600)\n"
        "print(len(m.faces), resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=900, check=True)  # fmt: skip
    faces, kib = (int(x) for x in out.stdout.split())
    measured, model = kib * 1024, XATLAS_BASE + XATLAS_PER_FACE * faces
    assert 0.6 * model < measured < model, (measured / 2**20, model / 2**20)
