"""What crackbake's child processes (the xatlas unwrap, the closest-point worker) share: dying
with their parent.  Imports nothing slow, so a worker calls it before its own imports."""

from __future__ import annotations

import os
import sys

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_env: str) -> None:
    """SIGKILL this process when its parent exits (Linux); exit now if it already has.

    The parent's pid comes from the environment variable ``parent_env`` (set by the parent);
    comparing it with ``getppid()`` after the ``prctl`` call closes the race where the parent
    died before the request was made.
    """
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass
    parent = os.environ.get(parent_env)
    if parent and parent.isdigit() and os.getppid() != int(parent):
        os._exit(3)
