"""numba's kernel cache on each node of a batch: a folder on the node's own disk, seeded from
the kernels precompiled into the package.

By default numba caches compiled kernels in ``__pycache__`` beside their sources.  On a cluster
the package is often installed once on storage every node mounts, and the nodes then write the
same index files over the network file system, where numba's own safety (each file written to a
unique temporary name, then renamed over the target) needs an atomic rename the file system may
not give, and where nodes with different CPUs overwrite each other's entries.  So each job's
worker points ``NUMBA_CACHE_DIR`` at a folder on its node's local temporary disk, one per node
(not per worker: every job is a fresh process, and a per-worker cache would compile every kernel
for every job).  The workers of one node share it safely: numba's rename is atomic on a local
disk, and an index entry lost to two writers at once only costs one recompile.

The folder is seeded with the package's own cache files (what ``make setup``'s precompile
wrote), copied the same way, so the first job on a fresh node does not spend minutes compiling.
A ``NUMBA_CACHE_DIR`` the user set is left as it is.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def node_cache_dir() -> Path:
    """The node-local cache folder: ``<tmp>/crackbake-numba-<uid>`` (``TMPDIR`` or /tmp)."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return Path(tempfile.gettempdir()) / f"crackbake-numba-{uid}"


def use_node_cache(env: dict | None = None) -> str:
    """Set ``NUMBA_CACHE_DIR`` to this node's cache folder (seeded) before numba is imported;
    returns the folder numba will use.  Call it in the worker, first thing in the job."""
    env = os.environ if env is None else env
    if env.get("NUMBA_CACHE_DIR"):
        return env["NUMBA_CACHE_DIR"]
    target = node_cache_dir()
    env["NUMBA_CACHE_DIR"] = str(target)
    try:
        seed(target)
    except OSError:  # an unwritable temporary folder: numba falls back to compiling
        pass
    return str(target)


def seed(target: Path, package: Path | None = None) -> int:
    """Copy the package's cached kernels (``*.nbi`` indexes, ``*.nbc`` object code) into
    ``target`` where numba's user-provided locator looks for them; returns the files copied.

    A file already there and at least as new is kept.  Each copy is written under a temporary
    name and renamed into place, as numba writes, so a worker reading meanwhile sees the old
    file or the new one, never half of one.
    """
    from numba.core.caching import UserProvidedCacheLocator

    if package is None:
        package = Path(__file__).resolve().parents[1]
    copied = 0
    for src in package.rglob("__pycache__/*.nb[ic]"):
        # numba names a source folder's cache by its path: the sub-folder for any file in it
        sub = UserProvidedCacheLocator.get_suitable_cache_subpath(str(src.parent.parent / "_"))
        dest = target / sub / src.name
        try:
            if dest.stat().st_mtime >= src.stat().st_mtime:
                continue
        except FileNotFoundError:
            pass
        dest.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{src.name}.", dir=dest.parent)
        os.close(fd)
        try:
            shutil.copy2(src, tmp)
            os.replace(tmp, dest)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        copied += 1
    return copied
