"""crackbake.jit: numba's cache loads without its compiler's set-up, with the same kernels."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

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


def test_light_loads_take_numbas_lock_events_off_and_numba_still_compiles():
    # numba's two events around every LLVM call time the lock for compile metadata only
    from llvmlite.binding import ffi
    from numba import njit

    assert jit.light_cache_loads()
    assert not [cb for cb in ffi.lib._lock._cblist
                if getattr(cb[0], "__module__", None) == "numba.core.base"]

    @njit
    def twice(x):
        return 2 * x

    assert twice(21) == 42  # a compilation, not a cache load: its timers simply read nothing


# Preloads the kernel from the cache (no call), then calls it: what preload loaded, and
# whether the call compiled or loaded anything more.
_PRELOAD = """
import json
from crackbake.jit import light_cache_loads, preload
light_cache_loads()
from tiny_kernel import ramp
loaded = preload(ramp)
had = len(ramp.overloads)
out = ramp(5)
print(json.dumps({"loaded": loaded, "had": had, "out": out.tolist(),
                  "hits": sum(ramp.stats.cache_hits.values()),
                  "misses": sum(ramp.stats.cache_misses.values())}))
"""


def test_preload_loads_the_cached_signatures_without_compiling(tmp_path):
    (tmp_path / "tiny_kernel.py").write_text(textwrap.dedent(_KERNEL))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(REPO)]))

    def run() -> dict:
        r = subprocess.run([sys.executable, "-c", _PRELOAD], env=env, capture_output=True,
                           text=True, timeout=300)  # fmt: skip
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout.strip().splitlines()[-1])

    cold = run()  # nothing cached: preload compiles nothing, the call compiles (and caches)
    assert cold["loaded"] == 0 and cold["had"] == 0 and cold["misses"] == 1
    warm = run()  # cached: preload loads it, and the call finds it loaded
    assert warm["loaded"] == 1 and warm["had"] == 1
    assert warm["hits"] == 1 and warm["misses"] == 0
    assert cold["out"] == warm["out"] == [0.0, 0.5, 1.0, 1.5, 2.0]
    # a source edited since: its old entries are another source's, never loaded
    (tmp_path / "tiny_kernel.py").write_text(textwrap.dedent(_KERNEL).replace("0.5", "0.25"))
    edited = run()
    assert edited["loaded"] == 0 and edited["misses"] == 1
    assert edited["out"] == [0.0, 0.25, 0.5, 0.75, 1.0]
