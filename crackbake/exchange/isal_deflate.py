"""ISA-L's deflate, one call at a time: the same bytes for the same data in every run.

ISA-L (the ``isal`` package) deflates 2-3x faster than zlib-ng at a similar size, with the GIL
released.  But two of its calls running at once on different threads gave different (valid)
streams for the same input: writing the README run's 4096² crack master on two threads at
once, 30 times, gave 4 different files with the same pixels (in the runs themselves, 2 EXRs of
10 differed from a lone run's); one at a time, 15 of 15 were the same, and with this lock 30 of
30.  A zeroed margin round each chunk's buffer did not help, so it is not a read past our
buffers.  The other encoders (zlib-ng's, the kernels) still run beside the lock.
"""

from __future__ import annotations

import threading

try:
    from isal import isal_zlib as _isal
except ImportError:  # pragma: no cover - isal is a dependency
    _isal = None

#: Whether ISA-L is installed (else the callers use zlib-ng).
AVAILABLE = _isal is not None
_LOCK = threading.Lock()


def compress(data, level: int) -> bytes:
    """zlib stream of ``data`` (a buffer) at ISA-L's ``level`` (0-3), no other ISA-L call
    running meanwhile in this process."""
    with _LOCK:
        return _isal.compress(data, level)
