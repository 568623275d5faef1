"""Opening the files a user (or a mesh) names without trusting what they are.

Every reader of a user-named file goes through here: the mesh, a ``cracks.json`` sidecar, a
weight map, an EXR to inspect, and the textures, materials and buffers a mesh names.  A FIFO
blocks the open (or the read) forever, and a device such as ``/dev/zero`` never ends; both are
refused before anything is read, also behind a symlink.  Reads are bounded by the size the file
had when it was opened, so a file that grows while it is read cannot exhaust memory either.

Paths a mesh names (OBJ ``mtllib``/``map_Kd``, glTF image and buffer URIs) must also stay
inside the mesh's folder (:func:`inside`): an asset from outside must not make crackbake read
(and embed into its outputs) a file elsewhere on the machine.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from crackbake.errors import CrackbakeError

PathLike = str | os.PathLike

__all__ = [
    "NotRegularFile", "check_regular", "inside", "kind", "open_regular", "read_bytes", "read_text",
]


def kind(mode: int) -> str:
    """What a non-regular ``st_mode`` is, as an error message names it."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


class NotRegularFile(CrackbakeError):
    """A FIFO, device or socket where a file was expected; ``label`` names it, ``what`` says
    what it is (``"a FIFO (named pipe)"``...)."""

    def __init__(self, label: str, what: str) -> None:
        super().__init__(
            f"{label}: is {what}, not a regular file (pipes and devices can block or never "
            "end); pass a regular file"
        )
        self.label, self.what = label, what


def _refuse(path: PathLike, mode: int, label: str | None) -> NotRegularFile:
    return NotRegularFile(label or os.fspath(path), kind(mode))


def check_regular(path: PathLike, label: str | None = None) -> os.stat_result:
    """``os.stat(path)`` (symlinks followed), refusing anything but a regular file or folder.

    Folders are left to the caller (each says in its own words what to pass instead); missing
    files raise the usual :class:`OSError` (``FileNotFoundError``...).

    Parameters
    ----------
    path : str or os.PathLike
    label : str, optional
        How the message names the file (default: the path).

    Raises
    ------
    CrackbakeError
        A FIFO, device or socket.
    """
    st = os.stat(path)
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        raise _refuse(path, st.st_mode, label)
    return st


def _open_fd(path: PathLike, label: str | None) -> tuple[int, os.stat_result]:
    # O_NONBLOCK: a FIFO put at the path after a check cannot block the open; fstat then says
    # what was really opened.  It changes nothing for regular files.
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), os.fspath(path))
        if not stat.S_ISREG(st.st_mode):
            raise _refuse(path, st.st_mode, label)
    except BaseException:
        os.close(fd)
        raise
    return fd, st


def open_regular(path: PathLike, label: str | None = None):
    """The regular file ``path`` opened for binary reading (a context manager).

    Raises
    ------
    CrackbakeError
        A FIFO, device or socket (checked on the opened file, so no swap after a check fools it).
    OSError
        Missing, unreadable, or a folder (``IsADirectoryError``).
    """
    fd, _ = _open_fd(path, label)
    return os.fdopen(fd, "rb")


def read_bytes(path: PathLike, label: str | None = None, limit: int | None = None) -> bytes:
    """The bytes of the regular file ``path``, at most its size when opened.

    Parameters
    ----------
    path : str or os.PathLike
    label : str, optional
        How messages name the file.
    limit : int, optional
        Largest size in bytes accepted; a bigger file is refused before it is read.

    Raises
    ------
    CrackbakeError
        A FIFO, device or socket, or a file over ``limit``.
    OSError
        Missing, unreadable, or a folder (``IsADirectoryError``).
    """
    fd, st = _open_fd(path, label)
    with os.fdopen(fd, "rb") as fh:
        if limit is not None and st.st_size > limit:
            raise CrackbakeError(
                f"{label or path}: {st.st_size} bytes is more than the {limit} bytes "
                "crackbake reads from such a file; check it is the file you meant"
            )
        return fh.read(st.st_size)


def read_text(path: PathLike, label: str | None = None, limit: int | None = None) -> str:
    """:func:`read_bytes` decoded as UTF-8 (undecodable bytes replaced)."""
    return read_bytes(path, label, limit).decode("utf-8", errors="replace")


def inside(folder: PathLike, name: str) -> Path | None:
    """``folder / name`` with symlinks resolved, or None when it leaves ``folder``.

    An absolute ``name``, ``..`` steps or a symlink out of the folder all count as leaving it.
    """
    root = Path(os.path.realpath(folder))
    target = Path(os.path.realpath(root / name))
    return target if target.is_relative_to(root) else None
