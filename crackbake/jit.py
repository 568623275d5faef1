"""numba's start-up in a fresh process: cache loads without the compiler's set-up, begun early.

Every ``crackbake`` process loads its kernels from numba's disk cache (about 40 of them in a
bake).  Before its first load numba refreshes its target context (``BaseContext.refresh``):
it imports and registers every lowering and typing implementation it has (numba.np, numba.typed,
numba.cpython..., scipy.linalg through its BLAS check) and compiles the NRT runtime.  A
compilation needs those registries; a load from the cache needs only the runtime (its machine
code calls NRT and the helper library, registered with LLVM when the runtime initialises).
:func:`light_cache_loads` makes numba's cache load the runtime only; a kernel that is not in
the cache still compiles as before (numba's compiler refreshes the context itself).  About
0.2-0.3 CPU-s of numba's 1 CPU-s start-up, on the critical path of every run, re-bake and
batch job (docs/benchmarks.md).

:func:`start` then loads the first stage's kernels (the tangent frames) on a thread as soon as
the mesh is read, while the main thread opens the GL context and checks the UVs: LLVM's share
of each load runs beside them (llvmlite's calls release the GIL).
"""

from __future__ import annotations

import threading


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
    return True


def warm_first_kernels() -> None:
    """Light cache loads, then the tangent frames' kernels loaded (or compiled)."""
    light_cache_loads()
    from crackbake.bake.tangents import warm

    warm()


def start() -> threading.Thread:
    """:func:`warm_first_kernels` on a daemon thread, started; join it or let it run out."""
    thread = threading.Thread(target=_quiet, name="crackbake-jit-warm", daemon=True)
    thread.start()
    return thread


def _quiet() -> None:
    # Only a head start: a failure here is the real stage's to report, with its own inputs.
    try:
        warm_first_kernels()
    except Exception:  # noqa: BLE001
        pass
