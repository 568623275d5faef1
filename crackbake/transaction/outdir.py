"""The output folder as a transaction: checks, the lock, leftovers and the one-rename swap.

A run writes its whole set into a hidden sibling of the output folder and swaps it in at the
end, so the folder always holds exactly one complete run's files.  Every name this module makes
lives beside the output folder ``<parent>/<name>``:

``.<name>.crackbake-lock``
    Lock file (``fcntl.flock``) held for the whole run; it holds the owner's pid and is removed
    when the run ends.  A lock left by a killed process is not held, so it does not block.
``.<name>.crackbake-staging-XXXXXXXX/``
    The new set while it is written; holds :data:`MARKER` until the swap.
``.<name>.crackbake-trash-XXXXXXXX/``
    The previous set between the two renames of the fallback swap.

A run killed with SIGKILL can leave staging and trash folders and the lock file behind; the next
run into the same folder removes them (:func:`remove_leftovers`).
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
import warnings
from pathlib import Path

from crackbake.errors import CrackbakeError, CrackbakeWarning

# Present in a staging folder until its set is complete; marks it as ours for clean-up.
MARKER = ".crackbake-staging"
MANIFEST = "manifest.json"
# Staging folders inside the output folder, made by crackbake before 0.2 (safe to replace).
_LEGACY_STAGING = ".crackbake-staging-"


def target_dir(out_dir: str | os.PathLike, option: str = "-o") -> Path:
    """Absolute output folder with symlinks resolved (a link to a folder means that folder).

    ``option`` is how messages name the option that sets the folder (``-o``, ``--png``).

    Raises
    ------
    CrackbakeError
        An empty path, the file system root, or a folder holding the current directory.
    """
    if not str(out_dir).strip():
        raise CrackbakeError(f"the output folder '' is empty; name a folder with {option}")
    final = Path(os.path.realpath(os.path.abspath(os.fspath(out_dir))))
    if final.name in ("", ".", ".."):
        raise CrackbakeError(
            f"cannot use '{out_dir}' as the output folder; name a sub-folder with {option}"
        )
    cwd = Path(os.path.realpath(os.getcwd()))
    if cwd == final or final in cwd.parents:
        raise CrackbakeError(
            f"output folder '{out_dir}' is or holds the current folder, and crackbake replaces "
            f"its output folder as a whole; choose another folder with {option}"
        )
    return final


def sibling(final: Path, kind: str) -> Path:
    """``<parent>/.<name>.crackbake-<kind>`` (``kind``: ``lock``, ``staging-``, ``trash-``)."""
    return final.parent / f".{final.name}.crackbake-{kind}"


def check_replaceable(
    final: Path, shown: str | os.PathLike | None = None, option: str = "-o"
) -> bool:
    """Refuse an output path crackbake must not replace; True when a previous set is there.

    The folder may be missing, empty, or a crackbake output folder: a ``manifest.json`` written
    by crackbake and nothing that manifest does not list.  Anything else (a file, a device, a
    mount point, a folder of the user's own files) is refused, so ``-o ~`` never deletes a home
    folder.

    Raises
    ------
    CrackbakeError
        One line naming the path (as ``shown``, default ``final``) and what to do.
    """
    shown = final if shown is None else shown
    if not os.path.lexists(final):
        return False
    if not final.is_dir():
        raise CrackbakeError(
            f"output '{shown}' exists and is not a folder; choose a folder with {option}"
        )
    if os.path.ismount(final):
        raise CrackbakeError(
            f"output folder '{shown}' is a mount point, which cannot be replaced as a whole; "
            f"choose a folder inside it with {option}"
        )
    try:
        entries = sorted(os.listdir(final))
    except OSError as exc:
        raise CrackbakeError(
            f"cannot read output folder '{shown}': {exc.strerror}; choose another folder "
            f"with {option}"
        ) from exc
    if not entries:
        return False
    listed = _manifest_files(final / MANIFEST)
    if listed is None:
        raise CrackbakeError(
            f"output folder '{shown}' is not empty and has no crackbake manifest.json; crackbake "
            f"replaces its output folder as a whole, so choose a new or empty folder with {option}"
        )
    foreign = [
        e for e in entries
        if e != MANIFEST and e not in listed
        and not (e.startswith(_LEGACY_STAGING) and _is_ours(final / e))
    ]  # fmt: skip
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise CrackbakeError(
            f"output folder '{shown}' holds '{foreign[0]}'{more}, which crackbake did not write, "
            "and the folder is replaced as a whole; move them out or choose another folder with "
            f"{option}"
        )
    # crackbake writes files only: a folder under an output's name holds the user's own files
    folders = [e for e in entries if e in listed and os.path.isdir(final / e)
               and not os.path.islink(final / e)]  # fmt: skip
    if folders:
        raise CrackbakeError(
            f"output folder '{shown}' holds a folder '{folders[0]}' where crackbake wrote a "
            "file, and the folder is replaced as a whole; move it out or choose another folder "
            f"with {option}"
        )
    return True


def _manifest_files(path: Path) -> set[str] | None:
    """Names a crackbake ``manifest.json`` lists, or None when ``path`` is not one."""
    import json  # json, ctypes, shutil: imported where used, off every run's start-up

    try:
        if not path.is_file() or path.stat().st_size > 64 << 20:
            return None
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or "crackbake" not in doc:
        return None
    files = doc.get("files")
    if not isinstance(files, list):
        return None
    return {f["name"] for f in files if isinstance(f, dict) and isinstance(f.get("name"), str)}


def _is_ours(folder: Path) -> bool:
    """A leftover staging/trash folder: empty, marked, or holding a crackbake manifest."""
    try:
        names = os.listdir(folder)
    except OSError:
        return False
    return not names or MARKER in names or _manifest_files(folder / MANIFEST) is not None


def remove_leftovers(final: Path) -> list[Path]:
    """Remove staging and trash folders a killed run left beside ``final``; return them.

    Only call while holding the folder's lock: then no live run owns them.  Folders with the
    prefix but neither the marker nor a crackbake manifest are left alone.
    """
    removed = []
    prefixes = (sibling(final, "staging-").name, sibling(final, "trash-").name)
    try:
        candidates = [e for e in os.scandir(final.parent) if e.name.startswith(prefixes)]
    except OSError:
        return removed
    for entry in candidates:
        path = Path(entry.path)
        if entry.is_dir(follow_symlinks=False) and _is_ours(path):
            if remove_tree(path):
                removed.append(path)
            else:
                warn_left(path)
    return removed


def remove_tree(path: Path) -> bool:
    """Remove a folder crackbake made (a staged or replaced set); True when it is gone.

    A previous output folder the user made read-only still swaps out (renaming needs only the
    parent writable) but its files cannot be deleted: such folders inside the tree are made
    writable first (never through a symlink).
    """
    import shutil

    shutil.rmtree(path, ignore_errors=True)
    if not os.path.lexists(path):
        return True
    _make_writable(path)
    for root, dirs, _ in os.walk(path):  # top-down: each folder is opened before its children
        for d in dirs:
            _make_writable(os.path.join(root, d))
    shutil.rmtree(path, ignore_errors=True)
    return not os.path.lexists(path)


def _make_writable(folder: str | os.PathLike) -> None:
    try:
        st = os.lstat(folder)
        if stat.S_ISDIR(st.st_mode):
            os.chmod(folder, stat.S_IMODE(st.st_mode) | stat.S_IRWXU)
    except OSError:
        pass


def warn_left(path: Path) -> None:
    """Warn that the crackbake folder ``path`` could not be removed."""
    warnings.warn(
        f"could not remove '{path}', a copy of an earlier output set; delete it by hand (the "
        "next run into this folder tries again)",
        CrackbakeWarning,
        stacklevel=3,
    )


class FolderLock:
    """An exclusive ``flock`` on ``.<name>.crackbake-lock`` beside the output folder.

    The lock is tied to the open file, so the kernel drops it when its process dies, however it
    dies: a lock file left by a killed run does not block the next.  :meth:`release` removes
    the file while still holding the lock; :meth:`acquire` re-checks that the file it locked is
    still the one on disk, so a run never holds a lock on a removed file.
    """

    def __init__(
        self, final: Path, shown: str | os.PathLike | None = None, option: str = "-o"
    ) -> None:
        self.path = sibling(final, "lock")
        self.shown = final if shown is None else shown
        self.option = option
        self._fd: int | None = None

    def acquire(self) -> FolderLock:
        for _ in range(20):
            fd = self._open()
            if fd is None:
                continue  # removed between our two opens: create it again
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = _read_pid(fd)
                os.close(fd)
                raise CrackbakeError(
                    f"output folder '{self.shown}' is in use by another crackbake run "
                    f"(pid {pid}); wait for it to finish or choose another folder with "
                    f"{self.option}"
                ) from None
            try:
                same = os.path.samestat(os.fstat(fd), os.lstat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                self._fd = fd
                return self
            os.close(fd)  # the owner removed it while we waited: lock the new file
        raise CrackbakeError(f"cannot lock output folder '{self.shown}'; try again")

    def _open(self) -> int | None:
        """The lock file opened read-write: created now, or one a crackbake run left.

        Never through a symlink (``O_NOFOLLOW``; ``O_EXCL`` does not follow a dangling one
        either) and never a file crackbake did not make: only a regular file with one link
        that holds nothing but a pid is reused.  None when it vanished between the two opens.
        """
        flags = os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
        try:
            return os.open(self.path, flags | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            pass
        except OSError as exc:
            raise CrackbakeError(
                f"cannot lock output folder '{self.shown}': {exc.strerror} creating "
                f"'{self.path}'; the folder holding it must be writable, or choose another "
                f"{self.option}"
            ) from exc
        try:
            fd = os.open(self.path, flags)
        except FileNotFoundError:
            return None
        except OSError as exc:
            what = {errno.ELOOP: "a symbolic link", errno.EISDIR: "a folder"}.get(exc.errno)
            raise self._foreign(what or exc.strerror) from exc
        st = os.fstat(fd)
        why = None
        if not stat.S_ISREG(st.st_mode):
            why = "not a regular file"
        elif st.st_nlink != 1:
            why = f"a file with {st.st_nlink} hard links"
        elif st.st_size > 32 or (st.st_size and not _read_pid(fd, "").isdigit()):
            why = "a file that holds something other than a pid"
        if why is not None:
            os.close(fd)
            raise self._foreign(why)
        return fd

    def _foreign(self, what: str) -> CrackbakeError:
        return CrackbakeError(
            f"cannot lock output folder '{self.shown}': '{self.path}' is {what}, not a lock "
            f"file crackbake made, and crackbake will not write to it; remove it or choose "
            f"another folder with {self.option}"
        )

    def release(self) -> None:
        if self._fd is None:
            return
        try:
            os.unlink(self.path)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def _read_pid(fd: int, unknown: str = "unknown") -> str:
    try:
        text = os.pread(fd, 33, 0).decode("ascii", "replace").strip()
    except OSError:
        text = ""
    return text if text.isdigit() else unknown


_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _renameat2_exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically with ``renameat2(RENAME_EXCHANGE)``; False when unsupported."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(b))


def swap_in(staging: Path, final: Path, exchange: bool = True) -> Path | None:
    """Put the folder ``staging`` at ``final`` in one rename; return where the old set went.

    With a previous folder at ``final`` the two are exchanged atomically where the kernel and
    file system support ``renameat2(RENAME_EXCHANGE)`` (the old set ends up at ``staging``);
    elsewhere the old folder is first renamed to a trash sibling, then ``staging`` to
    ``final`` (also with ``exchange=False``).  The caller removes the returned folder.
    """
    if not os.path.lexists(final):
        os.rename(staging, final)
        return None
    if exchange and _renameat2_exchange(staging, final):
        return staging
    trash = final.parent / f"{sibling(final, 'trash-').name}{staging.name[-8:]}"
    os.rename(final, trash)
    try:
        os.rename(staging, final)
    except OSError:
        os.rename(trash, final)  # put the previous set back
        raise
    return trash
