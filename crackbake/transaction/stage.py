"""Hashes of written files and the output folder as one transaction (:class:`OutputStage`)."""

from __future__ import annotations

import errno
import os
import stat
import warnings
from pathlib import Path

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.safe_open import open_regular
from crackbake.transaction.interrupt import deferred, raise_if_received
from crackbake.transaction.outdir import (
    MARKER,
    FolderLock,
    check_replaceable,
    remove_leftovers,
    remove_tree,
    sibling,
    swap_in,
    target_dir,
    warn_left,
)

PathLike = str | os.PathLike


def sha256_file(path: PathLike) -> str:
    """Hex SHA-256 of a file's bytes, read in chunks (no whole-file copy in memory)."""
    import hashlib  # 5 ms of start-up a run without digests need not pay

    with open_regular(path) as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


class OutputStage:
    """The output folder as a transaction: the whole set appears at once, or nothing changes.

    ::

        with OutputStage(out_dir) as stage:     # checks and locks out_dir: before any work
            ...                                 # the slow stages
            write_exr(stage.path("cracks.exr"), ...)
            records = stage.records()           # name, bytes, sha256 of what is staged
            write_manifest(stage.path("manifest.json"), records)
            stage.commit()

    Entering checks that ``out_dir`` is missing, empty or a crackbake output folder (see
    :func:`~crackbake.transaction.outdir.check_replaceable`), locks it against other runs, removes
    what killed runs left beside it and creates a hidden staging folder next to it (same
    parent, so same file system).  :meth:`commit` swaps the staging folder in with one rename
    and then deletes the previous set: the folder holds exactly this run's files, and SIGINT or
    SIGTERM (under :func:`~crackbake.transaction.interrupt.interruptible`) wait for the swap to
    end.  Leaving the block without commit (an exception or interrupt included) removes the
    staging folder, the lock file and any parent folder entering created; ``out_dir`` is
    untouched.

    Attributes
    ----------
    out_dir : Path
        The folder as given.
    final : Path
        Its absolute path, symlinks resolved (set on entering).
    had_previous : bool
        ``final`` held a previous set when the stage was entered.
    committed : bool
        The new set is in place.
    option : str
        How messages name the option that chose the folder (``-o``; ``--png`` for inspect).
    """

    def __init__(self, out_dir: PathLike, option: str = "-o") -> None:
        self.out_dir = Path(out_dir) if str(out_dir) else out_dir
        self.option = option
        self.final: Path | None = None
        self.had_previous = False
        self.committed = False
        self._staging: Path | None = None
        self._lock: FolderLock | None = None
        self._made: list[Path] = []
        self._hashes: dict[str, tuple[tuple[int, int], str]] = {}

    def __enter__(self) -> OutputStage:
        try:
            self._open()
        except BaseException:
            self._close()
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._close()

    def _open(self) -> None:
        opt = self.option
        final = target_dir(self.out_dir, opt)
        self.final = final
        check_replaceable(final, self.out_dir, opt)  # cheap refusals before touching anything
        self._made = _make_parents(final.parent, self.out_dir, opt)
        self._lock = FolderLock(final, self.out_dir, opt).acquire()
        remove_leftovers(final)
        self.had_previous = check_replaceable(final, self.out_dir, opt)  # again, under the lock
        try:
            self._staging = _new_folder(sibling(final, "staging-"))
            (self._staging / MARKER).write_bytes(b"")
        except OSError as exc:
            raise CrackbakeError(
                f"cannot write beside output folder '{self.out_dir}': {exc.strerror}; "
                f"choose a writable location with {opt}"
            ) from exc

    def _close(self) -> None:
        with deferred():
            self.discard()
            if self._lock is not None:
                self._lock.release()
                self._lock = None
            if not self.committed:
                for folder in reversed(self._made):  # parents this run created, if still empty
                    try:
                        folder.rmdir()
                    except OSError:
                        break
            self._made = []

    @property
    def staging_dir(self) -> Path:
        if self._staging is None or self.committed:
            raise CrackbakeError(
                "OutputStage is not open; use it as `with OutputStage(out_dir) as stage:` "
                "and stage files before commit()"
            )
        return self._staging

    def path(self, name: str) -> Path:
        """Temporary path in the staging folder for the final file ``out_dir / name``."""
        if (
            not isinstance(name, str)
            or not name
            or name in (".", "..", MARKER)
            or Path(name).name != name
            or "/" in name
            or "\\" in name
        ):
            raise CrackbakeError(
                f"output name {name!r} is not a plain file name; pass a name without folders"
            )
        return self.staging_dir / name

    def _staged(self) -> list[os.DirEntry]:
        with os.scandir(self.staging_dir) as it:
            return sorted(
                (e for e in it if e.is_file(follow_symlinks=False) and e.name != MARKER),
                key=lambda e: e.name,
            )

    def remember(self, path: PathLike, data: bytes | None = None) -> None:
        """Hash a file just staged, on the calling thread, for :meth:`records` to find cached:
        the write stage's encoders hash their own files beside each other's work instead of
        the run's thread hashing them all at the end (230 MB at a 1.5M-face asset).  ``data``:
        the bytes just written to it (hashed without reading the file back)."""
        path = Path(path)
        st = path.stat()
        if data is None:
            digest = sha256_file(path)
        else:
            import hashlib

            digest = hashlib.sha256(data).hexdigest()
        self._hashes[path.name] = ((st.st_size, st.st_mtime_ns), digest)

    def records(self) -> list[dict]:
        """``[{"name", "bytes", "sha256"}]`` of the files staged so far, sorted by name.

        Hashes are cached by (size, mtime), so calling again only hashes files that changed.
        """
        out = []
        for entry in self._staged():
            st = entry.stat(follow_symlinks=False)
            key = (st.st_size, st.st_mtime_ns)
            cached = self._hashes.get(entry.name)
            if cached is None or cached[0] != key:
                cached = (key, sha256_file(entry.path))
                self._hashes[entry.name] = cached
            out.append({"name": entry.name, "bytes": int(st.st_size), "sha256": cached[1]})
        return out

    def commit(self) -> list[Path]:
        """Swap the staged set in as ``out_dir`` with one rename; return the final file paths.

        Every file appears at once.  A run that received SIGINT/SIGTERM never commits, even if
        the signal's exception was lost on the way (see :func:`raise_if_received`).
        """
        raise_if_received()
        staging = self.staging_dir
        names = [e.name for e in self._staged()]
        with deferred():
            try:
                # The set is complete: once the marker is gone, the manifest marks it as ours.
                (staging / MARKER).unlink()
                # nothing foreign arrived meanwhile
                check_replaceable(self.final, self.out_dir, self.option)
                read_only = _read_only(self.final)
                old = swap_in(staging, self.final)
            except OSError as exc:
                raise CrackbakeError(
                    f"cannot move the new files into '{self.out_dir}': {exc.strerror}; "
                    "check the folder holding it is writable and run again"
                ) from exc
            self.committed = True
            self._staging = None
            if old is not None:
                if read_only:
                    warnings.warn(
                        f"output folder '{self.out_dir}' was read-only; crackbake replaces its "
                        "output folder as a whole, so its previous files are deleted and the "
                        f"new folder is writable (to keep a set, copy it or use another "
                        f"{self.option})",
                        CrackbakeWarning,
                        stacklevel=2,
                    )
                if not remove_tree(old):
                    warn_left(old)
        return [self.final / n for n in names]

    def discard(self) -> None:
        """Remove the staging folder and everything in it (``out_dir`` is not touched)."""
        if self._staging is not None:
            with deferred():
                remove_tree(self._staging)
                self._staging = None

    def interrupted_message(self) -> str:
        """What the output folder holds after an interrupt, as the end of a one-line message."""
        shown = self.out_dir
        if self.committed:
            return f"interrupted; the new outputs in {shown} are complete"
        if self.had_previous:
            return f"interrupted; the previous outputs in {shown} are unchanged"
        return "interrupted; no outputs were written"


def _read_only(folder: Path) -> bool:
    """The folder exists and its owner may not write to it (``chmod a-w``)."""
    try:
        return not os.stat(folder).st_mode & stat.S_IWUSR
    except OSError:
        return False


def _new_folder(prefix: Path) -> Path:
    """Create ``<prefix>XXXXXXXX`` (random) with the default permissions (umask applies).

    Not :func:`tempfile.mkdtemp`: its 0700 folder would become the output folder.
    """
    for _ in range(100):
        folder = prefix.parent / f"{prefix.name}{os.urandom(4).hex()}"
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        return folder
    raise FileExistsError(errno.EEXIST, "no free staging name", str(prefix))


def _make_parents(parent: Path, shown: PathLike, option: str = "-o") -> list[Path]:
    """Create ``parent`` and its missing ancestors; return the ones created, outermost first."""
    missing = []
    p = parent
    while not os.path.lexists(p):
        missing.append(p)
        p = p.parent
    if os.path.lexists(p) and not p.is_dir():
        raise CrackbakeError(
            f"cannot create output folder '{shown}': '{p}' is not a folder; choose another {option}"
        )
    made = []
    for folder in reversed(missing):
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            for m in reversed(made):
                try:
                    m.rmdir()
                except OSError:
                    break
            raise CrackbakeError(
                f"cannot create output folder '{shown}': {exc.strerror}; "
                f"choose a writable location with {option}"
            ) from exc
        made.append(folder)
    return made
