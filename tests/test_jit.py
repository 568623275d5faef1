"""crackbake.jit: numba's cache loads without its compiler's set-up, and the first stage's kernels
loaded on a thread, with the same results."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np

from crackbake import jit

REPO = Path(__file__).resolve().parents[1]

# A module with one cached kernel that allocates (NRT) and returns an array.
_KERNEL = """
import numpy as np
from numba import njit

@njit(cache=True)
def ramp(n):
    out = np.empty(n, np.float64)
    for i in range(n):
        out[i] = 0.5 * i
    return out
"""

# Loads the kernel in a fresh process, light or not, and says whether numba's registries (what
# a compilation needs) were loaded, and whether the load was a cache hit.
_LOAD = """
import json, sys
from numba.core import cpu
refreshed = []
original = cpu.CPUContext.load_additional_registries
def counting(self):
    refreshed.append(1)
    return original(self)
cpu.CPUContext.load_additional_registries = counting
light = sys.argv[1] == "light"
if light:
    from crackbake.jit import light_cache_loads
    assert light_cache_loads()
from tiny_kernel import ramp
out = ramp(5)
print(json.dumps({"out": out.tolist(), "refreshed": bool(refreshed),
                  "hits": sum(ramp.stats.cache_hits.values())}))
"""


def _load(tmp_path: Path, mode: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(REPO)]))
    r = subprocess.run([sys.executable, "-c", _LOAD, mode], env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_a_light_load_skips_the_registries_and_gives_the_same_kernel(tmp_path):
    (tmp_path / "tiny_kernel.py").write_text(textwrap.dedent(_KERNEL))
    first = _load(tmp_path, "light")  # nothing cached: compiles, so the registries load
    assert first["hits"] == 0 and first["refreshed"]
    plain = _load(tmp_path, "plain")  # numba's own load refreshes them
    assert plain["hits"] == 1 and plain["refreshed"]
    light = _load(tmp_path, "light")
    assert light["hits"] == 1 and not light["refreshed"]
    assert first["out"] == plain["out"] == light["out"] == [0.0, 0.5, 1.0, 1.5, 2.0]


def test_light_cache_loads_is_idempotent():
    from numba.core import caching

    assert jit.light_cache_loads()
    patched = caching.Cache.load_overload
    assert jit.light_cache_loads()
    assert caching.Cache.load_overload is patched


def test_warm_loads_every_kernel_the_tangent_stage_calls_on_a_real_mesh():
    """After the warm-up, the tangents of spot (its own UVs, a seam, wrapped faces) need no
    new kernel signature: the real stage only finds them loaded."""
    from crackbake.bake import tangent_kernels
    from crackbake.bake.context import create_context
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs
    from crackbake.grouping import exact_ids
    from crackbake.io.mesh import load_mesh

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning from the thread would land in a run's list
        jit.warm_first_kernels()
    kernels = [exact_ids] + [getattr(tangent_kernels, n) for n in dir(tangent_kernels)
                             if hasattr(getattr(tangent_kernels, n), "signatures")]
    warmed = {k.__name__: set(k.signatures) for k in kernels}
    assert sum(map(len, warmed.values())) >= 8  # the stage's kernels really were loaded

    ctx = create_context()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # spot's faces past the UV square
            uvmesh = prepare_uvs(load_mesh(REPO / "examples" / "spot.obj"), mode="auto",
                                 res=512, padding=None, timeout=60, cache=False, ctx=ctx)
    finally:
        ctx.release()
    out = with_tangents(uvmesh)
    assert out.tangents is not None and np.isfinite(out.tangents).all()
    assert {k.__name__: set(k.signatures) for k in kernels} == warmed


def test_start_runs_a_daemon_thread_that_ends():
    thread = jit.start()
    assert thread.daemon and thread.name == "crackbake-jit-warm"
    thread.join(120)
    assert not thread.is_alive()
