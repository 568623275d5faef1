"""numba's start-up in a fresh process: kernels loaded from the cache without the compiler's set-up.

Every ``crackbake`` process loads its kernels from numba's disk cache (about 40 of them in a
bake).  Before its first load numba refreshes its target context (``BaseContext.refresh``):
it imports and registers every lowering and typing implementation it has (numba.np, numba.typed,
numba.cpython..., scipy.linalg through its BLAS check) and compiles the NRT runtime.  A
compilation needs those registries; a load from the cache needs only the runtime (its machine
code calls NRT and the helper library, registered with LLVM when the runtime initialises).
:func:`light_cache_loads` makes numba's cache load the runtime only; a kernel that is not in
the cache still compiles as before (numba's compiler refreshes the context itself).  About
0.2-0.3 CPU-s of numba's 1 CPU-s start-up, on the critical path of every run, re-bake and
batch job (docs/benchmarks.md).  It also takes numba's ``numba:llvm_lock`` events off
llvmlite's lock: numba broadcasts two events around each of the thousands of LLVM calls a load
makes, only to time the lock for a compilation's metadata (nothing here reads it), about a
fifth of a load's CPU time.

The start-up's own kernels are not loaded ahead on a thread: the start-up is imports and loads
that hold the GIL, so a thread gained little (docs/benchmarks.md).  The stages after the solver
are another matter: :func:`preload` loads their kernels on the solver's warm-up thread while the
solver's loop runs without the GIL (:func:`crackbake.simulate.warm.start`).
"""

from __future__ import annotations

import os


def light_cache_loads() -> bool:
    """Make numba's cache loads set up its runtime only, not the compiler; True when in place.

    Idempotent.  Leaves numba as it is (False) where its cache class lacks the methods this
    relies on (another numba version): only the start-up is slower then.
    """
    from numba.core import caching
    from numba.core.runtime import nrt

    cache = caching.Cache
    if getattr(cache.load_overload, "_crackbake_light", False):
        return True
    if not all(hasattr(cache, name) for name in ("_load_overload",
                                                 "_guard_against_spurious_io_errors")):
        return False

    def load_overload(self, sig, target_context):
        # numba's own load_overload calls target_context.refresh() here (every registry)
        nrt.rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)

    load_overload._crackbake_light = True
    cache.load_overload = load_overload
    _drop_llvm_lock_events()
    return True


def _drop_llvm_lock_events() -> None:
    """Unregister numba's ``numba:llvm_lock`` event callbacks from llvmlite's LLVM lock (called
    around every LLVM call; their timings feed only numba's compile metadata).  Left as they
    are where llvmlite keeps its callbacks elsewhere (another version)."""
    try:
        from llvmlite.binding import ffi

        for acquire, release in list(ffi.lib._lock._cblist):
            if getattr(acquire, "__module__", None) == "numba.core.base":
                ffi.unregister_lock_callback(acquire, release)
    except Exception:  # noqa: BLE001 - only a saving; numba works with them
        pass


def preload(dispatcher) -> int:
    """Load ``dispatcher``'s machine code from numba's disk cache for every signature the cache
    holds for this source and this machine, without calling it; how many were loaded.

    For a thread that loads a later stage's kernels while the run's own thread computes: a
    kernel's first call otherwise loads it there, under numba's global compiler lock, so the
    write stage's encoders waited on each other's loads (0.4 s of them, serialised).  Never
    compiles: an entry whose key is another source's or another machine's, or whose data file
    is gone, is skipped (its first call compiles it as before).  Nothing is raised: this is only
    a head start, and it relies on numba's cache internals (another numba version loads
    nothing here).
    """
    count = 0
    try:
        cache = dispatcher._cache
        files = cache._cache_file
        codegen = dispatcher.targetctx.codegen()
        for key, name in files._load_index().items():
            sig = key[0]
            if (tuple(sig) in dispatcher.overloads or cache._index_key(sig, codegen) != key
                    or not os.path.exists(files._data_path(name))):
                continue
            dispatcher.compile(sig)
            count += 1
    except Exception:  # noqa: BLE001
        pass
    return count
