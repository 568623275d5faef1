"""The memory this process may use: the cgroup's limit, ``RLIMIT_AS`` or the physical memory.

Apart from :mod:`crackbake.memory` (the run's peak estimated, and the check against this) so
that the command can ask before it imports numpy (:mod:`crackbake.prefault` sizes its heap by
it); only the standard library is imported here.
"""

from __future__ import annotations

import os
import resource
from pathlib import Path

GIB = 2**30
#: Address space beyond the resident set (shared libraries, LLVM, thread stacks, GL driver
#: reservations): ``VmPeak - VmHWM`` was 1.07..1.33 GiB over the measured runs.  ``RLIMIT_AS``
#: limits address space, so a cap is compared with ``rss + ADDRESS_OVERHEAD``.
ADDRESS_OVERHEAD = 1.3 * GIB

def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def cgroup_limit(root: str | os.PathLike = "/sys/fs/cgroup",
                 membership: str | os.PathLike = "/proc/self/cgroup") -> tuple[int, str] | None:
    """The memory limit of this process's cgroup: bytes and the file it was read from.

    The smallest limit from the process's own group up to the mount point (a parent's limit
    caps its children; a ``systemd-run -p MemoryMax=`` slice or a container sets one): cgroup v2's
    ``memory.max`` under the ``0::<path>`` line of ``membership``, and cgroup v1's
    ``memory/<path>/memory.limit_in_bytes`` under its ``memory`` line (v1 writes "no limit" as
    a huge number, v2 as ``max``).  None when no limit is set.

    Parameters
    ----------
    root : path
        Where the cgroup file system is mounted.
    membership : path
        The process's cgroup membership file.
    """
    root = Path(root)
    try:
        lines = Path(membership).read_text().splitlines()
    except OSError:
        lines = []
    groups = {"0::": "/", "memory": None}
    for line in lines:
        _, controllers, path = (line.split(":", 2) + ["", ""])[:3]
        if line.startswith("0::"):
            groups["0::"] = path
        elif "memory" in controllers.split(","):
            groups["memory"] = path
    # (mount, own group, limit file, "no limit" from): v2 unified, then the v1 memory controller
    places = [(root, groups["0::"], "memory.max", 2**62)]
    places.append((root / "memory", groups["memory"] or "/", "memory.limit_in_bytes", 2**60))
    found: list[tuple[int, str]] = []
    for mount, own, name, unlimited in places:
        top = mount.resolve()
        folder = (mount / own.lstrip("/")).resolve()
        while True:  # up to the mount point: a parent's limit caps its children
            value = _read_int(str(folder / name))
            if value is not None and value < unlimited:
                found.append((value, str(folder / name)))
            if folder == top or top not in folder.parents:
                break
            folder = folder.parent
    return min(found) if found else None


def available_memory(cgroup_root: str | os.PathLike = "/sys/fs/cgroup",
                     membership: str | os.PathLike = "/proc/self/cgroup") -> tuple[int, str, bool]:
    """The memory this process may use: bytes, where the figure comes from, and whether it
    limits address space (``RLIMIT_AS``) rather than resident memory.

    The smallest of the cgroup limit (:func:`cgroup_limit`), ``RLIMIT_AS`` and the physical
    memory.  ``cgroup_root`` and ``membership`` are where :func:`cgroup_limit` reads.
    """
    found: list[tuple[int, str, bool]] = []
    limit = cgroup_limit(cgroup_root, membership)
    if limit is not None:
        found.append((limit[0], f"the cgroup limit ({limit[1]})", False))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        found.append((soft, "the address-space limit (ulimit -v)", True))
    try:
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        found.append((physical, "the physical memory", False))
    except (ValueError, OSError):
        pass
    if not found:
        return 2**62, "no known limit", False
    return min(found, key=lambda f: f[0] - (ADDRESS_OVERHEAD if f[2] else 0))
