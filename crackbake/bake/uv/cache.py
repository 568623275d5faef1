"""The unwrap cache: xatlas results stored by mesh content, so a re-run skips the unwrap."""

from __future__ import annotations

import hashlib
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

from crackbake.bake.uv.uvmesh import UVMesh, unwrapped_uvmesh
from crackbake.errors import CrackbakeWarning
from crackbake.io.mesh import Mesh

# Bump whenever the worker's output or the fitting changes, so old cache files are not reused.
CACHE_FORMAT_VERSION = 4


def xatlas_version() -> str:
    """The installed xatlas version (part of the cache key)."""
    # importlib.metadata (with email) is ~35 ms of imports that only an unwrap needs.
    from importlib import metadata

    try:
        return metadata.version("xatlas")
    except metadata.PackageNotFoundError:
        return "unknown"


def cache_dir() -> Path:
    """Folder of cached unwraps.

    ``$CRACKBAKE_CACHE_DIR``, else ``$XDG_CACHE_HOME/crackbake/unwrap``, else
    ``~/.cache/crackbake/unwrap``.
    """
    if os.environ.get("CRACKBAKE_CACHE_DIR"):
        return Path(os.environ["CRACKBAKE_CACHE_DIR"])
    try:
        home = Path.home()
    except RuntimeError:  # no $HOME and no passwd entry: _missing_home keeps the cache off
        home = Path("~")
    base = os.environ.get("XDG_CACHE_HOME") or str(home / ".cache")
    return Path(base) / "crackbake" / "unwrap"


def _missing_home() -> Path | None:
    """The user's home (or ``$XDG_CACHE_HOME``'s parent) when it does not exist: the cache then
    stays off rather than create a home folder (``mkdir -p`` would make ``$HOME`` itself)."""
    if os.environ.get("CRACKBAKE_CACHE_DIR"):
        return None  # named explicitly: created as asked
    xdg = os.environ.get("XDG_CACHE_HOME")
    try:
        home = Path(xdg).parent if xdg else Path.home()
    except RuntimeError:  # no $HOME and no passwd entry
        return Path("~")
    return None if home.is_dir() else home


def cache_key(mesh: Mesh, res: int, padding: int) -> str:
    """Hex SHA-256 of everything an unwrap depends on (format, xatlas version, inputs)."""
    h = hashlib.sha256()
    h.update(f"crackbake-unwrap:{CACHE_FORMAT_VERSION}:xatlas-{xatlas_version()}:".encode())
    h.update(f"res={res}:padding={padding}:".encode())
    # Normals decide the weld (hard edges stay split), so they are part of the input.
    for name, arr, dtype in (
        ("vertices", mesh.vertices, np.float64),
        ("faces", mesh.faces, np.int64),
        ("normals", mesh.normals, np.float64),
    ):
        a = np.ascontiguousarray(arr, dtype=dtype)
        h.update(f"{name}{a.shape}:".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def read_cache(path: Path, key: str, mesh: Mesh) -> UVMesh | None:
    """The cached unwrap, or None when missing, unreadable or not matching this mesh."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["key"]) != key:
                return None
            vertex_map = np.asarray(data["vertex_map"], dtype=np.int64)
            faces = np.asarray(data["faces"], dtype=np.int64)
            uv = np.asarray(data["uv"], dtype=np.float64)
            overlap = float(data["overlap_fraction"])
            padding = int(data["padding_px"])
    except Exception:  # a truncated or foreign file: recompute and overwrite it
        return None
    n_in = len(mesh.vertices)
    if (
        vertex_map.ndim != 1
        or faces.shape != mesh.faces.shape
        or uv.shape != (len(vertex_map), 2)
        or (len(vertex_map) and (vertex_map.min() < 0 or vertex_map.max() >= n_in))
        or (faces.size and (faces.min() < 0 or faces.max() >= len(vertex_map)))
        or not np.isfinite(uv).all()
    ):
        return None
    return unwrapped_uvmesh(mesh, vertex_map, faces, uv, overlap, padding)


def write_cache(path: Path, key: str, result: UVMesh) -> None:
    """Store an unwrap atomically; a failure only warns (the cache is an optimisation)."""
    tmp_name = None
    home = _missing_home()
    if home is not None:
        warnings.warn(
            f"no unwrap cache written: the home folder {home} does not exist (crackbake does not "
            "create it); set CRACKBAKE_CACHE_DIR to a folder to cache unwraps",
            CrackbakeWarning,
            stacklevel=3,
        )
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
        with os.fdopen(fd, "wb") as fh:
            np.savez(
                fh,
                key=np.array(key),
                vertex_map=result.vertex_map,
                faces=result.faces,
                uv=result.uv,
                overlap_fraction=np.float64(result.overlap_fraction),
                padding_px=np.int64(result.padding_px),
            )
        # mkstemp makes the file private (0600); cache entries are ordinary files.
        os.chmod(tmp_name, 0o644)
        # Readers never see a half-written file: the rename is atomic within one folder.
        os.replace(tmp_name, path)
        tmp_name = None
    except OSError as exc:
        warnings.warn(
            f"could not write the unwrap cache in {path.parent} ({exc}); "
            "set CRACKBAKE_CACHE_DIR to a writable folder",
            CrackbakeWarning,
            stacklevel=3,
        )
    finally:
        if tmp_name is not None:
            try:
                os.unlink(tmp_name)
            except OSError:
                pass
