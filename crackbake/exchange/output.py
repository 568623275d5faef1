"""Hashes of written files and the atomic output folder."""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from crackbake.errors import CrackbakeError

PathLike = str | os.PathLike


def sha256_file(path: PathLike) -> str:
    """Hex SHA-256 of a file's bytes, read in chunks (no whole-file copy in memory)."""
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


_STAGE_PREFIX = ".crackbake-staging-"


class OutputStage:
    """Atomic writes into an output folder.

    ::

        with OutputStage(out_dir) as stage:
            write_exr(stage.path("cracks.exr"), ...)
            records = stage.records()           # name, bytes, sha256 of what is staged
            write_manifest(stage.path("manifest.json"), records)
            stage.commit(last=("manifest.json",))

    Files are written into a hidden staging folder inside ``out_dir`` (same filesystem, so the
    final :func:`os.replace` is atomic per file).  :meth:`commit` moves every file in the staging
    folder onto its final name, the names in ``last`` after all others, so a manifest present in
    ``out_dir`` means the files it lists are complete.  Leaving the block without commit (an
    exception included) removes the staging folder and touches no final name.

    A hard kill (SIGKILL, power loss) can leave a ``.crackbake-staging-*`` folder behind; it is
    safe to delete.
    """

    def __init__(self, out_dir: PathLike) -> None:
        self.out_dir = Path(out_dir)
        self._staging: Path | None = None
        self._committed = False
        self._hashes: dict[str, tuple[tuple[int, int], str]] = {}

    def __enter__(self) -> OutputStage:
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            self._staging = Path(tempfile.mkdtemp(prefix=_STAGE_PREFIX, dir=self.out_dir))
        except OSError as exc:
            raise CrackbakeError(
                f"cannot create output folder '{self.out_dir}': {exc.strerror}; "
                "choose a writable location with --out"
            ) from exc
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.discard()

    @property
    def staging_dir(self) -> Path:
        if self._staging is None or self._committed:
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
            or name in (".", "..")
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
            return sorted((e for e in it if e.is_file(follow_symlinks=False)), key=lambda e: e.name)

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

    def commit(self, last: Iterable[str] = ("manifest.json",)) -> list[Path]:
        """Move every staged file onto its final name (``last`` ones last); return final paths.

        Names in ``last`` that were never staged are skipped.
        """
        entries = self._staged()
        last = [n for n in last if any(e.name == n for e in entries)]
        order = [e.name for e in entries if e.name not in last] + last
        moved = []
        try:
            for name in order:
                final = self.out_dir / name
                os.replace(self.staging_dir / name, final)
                moved.append(final)
        except OSError as exc:
            raise CrackbakeError(
                f"cannot move '{name}' into '{self.out_dir}': {exc.strerror}; "
                "remove or rename what is in the way and run again"
            ) from exc
        self.discard()
        self._committed = True
        return moved

    def discard(self) -> None:
        """Remove the staging folder and everything in it (no final name is touched)."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None
