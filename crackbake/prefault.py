"""The run's heap faulted in on a thread of its own, before the stages on the main thread touch it.

Every page the run's thread touches for the first time costs a page fault and the zeroing of the
page.  perf of the README bake (4096², 2 cores) put 18 % of the main thread's samples in the
kernel's ``clear_page_erms``: about 100,000 first touches, 0.4 s of the run's own thread (the
stress field's temporaries, the solver's state, the stress bake, the preview's textures), and
more than the zeroing alone in a virtual machine, whose host backs each new page too.  Memory
that was touched once and freed is reused by malloc without a fault.

So the ``crackbake`` command, before it imports its modules, has glibc's malloc keep the main
thread's memory in its heap (``M_MMAP_MAX`` 0: no block of its own mapped and unmapped per large
array; ``M_TRIM_THRESHOLD``: freed memory stays for the next array), grows the heap by the
memory the run's thread is expected to touch (:func:`heap_bytes`), and has a thread fault it in
with ``madvise(MADV_POPULATE_WRITE)`` (Linux 5.14), which maps each page as a write would,
without writing: the pages malloc hands out meanwhile keep their contents.  The heap grown is
advised onto transparent huge pages first (``MADV_HUGEPAGE``, where the system allows them):
fewer faults, and a faster exit, which frees it a 2 MiB page at a time.  ctypes releases the
GIL around each call, so the faults are taken on another core while the run imports and solves.

Only on glibc, for a bake of ``--res`` 2048 or more, and never beyond a quarter of the memory
the run may use; not for a re-bake (``--cracks``: its thread touches little memory first, so the
thread would only take a core).  ``CRACKBAKE_PREFAULT=0`` turns it off.  Where the heap cannot
grow or the kernel refuses the advice, the run goes on taking its own faults, as before.
"""

from __future__ import annotations

import os
import threading

#: mallopt parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_MAX = -4
#: madvise advice (Linux 5.14): fault pages in writable without writing them.
MADV_POPULATE_WRITE = 23
#: madvise advice: back the range with transparent huge pages where the system allows them.
MADV_HUGEPAGE = 14
#: A transparent huge page (x86-64, arm64 with 4 KiB pages).
HUGE_PAGE = 2 << 20
#: The heap the run's thread touches (measured, README bake on spot: 0.41 GB at 2048², 0.62 GB
#: at 4096², with the main thread's arrays all in the heap): a base and a share per texel.
HEAP_BASE = 384 << 20
HEAP_PER_TEXEL = 16
#: The smallest ``--res`` prefaulted for: below it the run's own faults are few.
PREFAULT_RES = 2048
#: The largest share of the memory the run may use that is prefaulted.
MAX_SHARE = 0.25
#: Bytes faulted in per call: the call holds the process's memory map (read), so the run's own
#: mmap, munmap and brk wait for at most one chunk (about 2 ms here).
CHUNK = 2 << 20

_started: list[threading.Thread] = []


def heap_bytes(res: int) -> int:
    """Memory the run's thread is expected to touch for a bake at ``res``², bytes."""
    return HEAP_BASE + HEAP_PER_TEXEL * res * res


def _libc():
    import ctypes

    try:
        if not os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc"):
            return None
    except (ValueError, OSError):
        return None
    libc = ctypes.CDLL(None, use_errno=True)
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    libc.madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return libc


def start(res: int, environ: dict | None = None, limit: int | None = None) -> int:
    """Grow the main arena's heap for a bake at ``res``² and fault it in on a thread.

    Parameters
    ----------
    res : int
        The bake's ``--res``; below :data:`PREFAULT_RES` nothing is done.
    environ : dict, optional
        The environment (``CRACKBAKE_PREFAULT=0`` turns this off); ``os.environ`` by default.
    limit : int, optional
        The memory the run may use, bytes (default:
        :func:`crackbake.memory_limit.available_memory`);
        at most :data:`MAX_SHARE` of it is prefaulted.

    Returns
    -------
    int
        Bytes the thread faults in (0: nothing started, or started before in this process).
        Call from the main thread, before the run allocates: the heap grown is the main
        thread's arena.
    """
    env = os.environ if environ is None else environ
    if env.get("CRACKBAKE_PREFAULT", "1").strip() == "0" or res < PREFAULT_RES or _started:
        return 0  # off, small, or done once already (the heap would grow again)
    libc = _libc()
    if libc is None:
        return 0
    if limit is None:
        from crackbake.memory_limit import available_memory

        limit = available_memory()[0]
    size = min(heap_bytes(res), int(MAX_SHARE * limit)) & ~0xFFFFF
    if size <= 0:
        return 0
    # Heap memory from here on: a large array no longer gets (and gives back) a mapping of its
    # own, and freed memory is kept for the next one.
    if not (libc.mallopt(M_MMAP_MAX, 0) and libc.mallopt(M_TRIM_THRESHOLD, 2**31 - 1)):
        return 0
    block = libc.malloc(size)
    if not block:
        return 0
    libc.free(block)  # back into the heap's top, which malloc hands out from next
    _advise_huge(libc, block, size)  # before the faults: they then map huge pages
    thread = threading.Thread(target=_populate, args=(libc, block, size), daemon=True,
                              name="crackbake-prefault")  # fmt: skip
    thread.start()
    _started.append(thread)
    return size


def _advise_huge(libc, address: int, size: int) -> bool:
    """Ask for transparent huge pages over the whole 2 MiB pages of ``[address, address +
    size)``; True when the kernel took the advice.

    Where the command restarted on glibc's huge-page tunable (llvmpipe machines,
    :func:`crackbake.entry.huge_pages`), malloc gave this advice for its heap already.  A GPU
    machine does not restart: its heap was faulted in, and freed at the exit, 4 KiB at a time,
    and the README bake's start-up and exit took 51 ms longer with the prefault than without it
    (H200).  With the advice the whole process took 1.912 s against 2.008 s without it
    (H200, ``bench_process.py -n 8``, interleaved; docs/benchmarks.md).  Where the system
    has transparent huge pages off, the kernel refuses the advice and nothing changes.
    """
    lo = (address + HUGE_PAGE - 1) // HUGE_PAGE * HUGE_PAGE
    hi = (address + size) // HUGE_PAGE * HUGE_PAGE
    return hi > lo and libc.madvise(lo, hi - lo, MADV_HUGEPAGE) == 0


def _populate(libc, address: int, size: int) -> None:
    """Fault ``[address, address + size)`` in, chunk by chunk; stop at the first refusal (an
    older kernel, a range no longer mapped)."""
    page = os.sysconf("SC_PAGESIZE")
    lo = (address + page - 1) // page * page
    hi = (address + size) // page * page
    for at in range(lo, hi, CHUNK):
        if libc.madvise(at, min(CHUNK, hi - at), MADV_POPULATE_WRITE) != 0:
            return


def wait(timeout: float | None = None) -> None:
    """Wait for the thread (tests; a run never waits for it)."""
    for thread in _started:
        thread.join(timeout)
