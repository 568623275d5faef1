"""The bake's mesh cache: what a bake derives from the asset alone, stored by content, so an
artist's next re-bake of the same asset (``--cracks``, new impacts, another look) skips it.

Two results are kept, each a pure function of inputs the key hashes in full:

- the gutter fill plan (:class:`crackbake.bake.dilation.FillPlan`) of the bake's islands: keyed
  by the islands themselves (the faces' coverage ``inside``, packed bits) and the fill limit.
  Any change of the UVs, the faces, ``--res`` or ``--tile`` that moves one covered texel gives
  another key; one that moves none gives the same plan, which is then the right one.  The file
  holds the islands too, compared on reading.  Spot at 4096²: planned in about 0.7 CPU-s
  (serial), read in 0.05 (a 70 MB file).
- the MikkTSpace tangent frames (:func:`crackbake.bake.tangents.with_tangents`): keyed by the
  output mesh's positions, faces, UVs and normals (bytes as float64/int64).
- the preview's and the USD's guessed up axis (:func:`crackbake.bake.preview.up_axis`: a
  convex hull, whose scipy.spatial import is 0.3 s a re-bake has no other use for): keyed by
  the vertices, the faces and whether the source is glTF.
- the check of an asset's own UVs (:func:`crackbake.bake.uv.check.check_uvs`: range, strays,
  their wrapped copies, overlap measured with GL): keyed by the UVs, the faces, the vertex count
  and the renderer (vendor, renderer and version strings), whose rasterisation it counts.
- the simulation mesh (:func:`crackbake.simulate.simmesh.build_simmesh`), with the warnings
  its build gave and, for a dense asset, its decimated proxy and the welded asset surface the
  proxy's closest points are found on (whose AABB tree a read builds only when first asked):
  keyed by the asset's positions and faces, the build's arguments (edge length or face count,
  seed, jitter, proxy limit, refined balls) and the versions of numpy, numba and Triangle.  An
  artist who moves the impact re-solves on the same sim mesh (the README bake: 0.4-0.5 s of its
  2-core wall; a 1.5M-face asset: 5.5-7 s).

Each key also hashes the source of the modules that compute the result, so an edited kernel
never meets an old answer.  The files live beside the cached unwraps
(:func:`crackbake.bake.uv.cache.cache_dir`) as ``<kind>-<key>.npys`` (``gutter``,
``tangents``, ``up``, ``uvcheck``, ``simmesh``; .npy records in a row: read straight into the
arrays, without a zip's CRC and copies), and together take at most :data:`MAX_BYTES`, the least
recently used removed first (a hit refreshes a file's time).  A failure to write is logged,
never raised: the cache is an optimisation.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from functools import cache
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

#: Bump whenever a stored layout changes: older files are not read.
MESH_CACHE_VERSION = 1

#: Most bytes the cached plans and frames take together (a 4096² plan of spot is 70 MB).
MAX_BYTES = 1 << 30

_SUFFIX = ".npys"
_KINDS = ("gutter", "tangents", "uvcheck", "up", "simmesh")


@cache
def _sources(*modules: str) -> bytes:
    """SHA-256 of the named modules' source files and of ``shaders/*.glsl`` names given as
    ``"shaders/NAME"`` (part of every key)."""
    import importlib.util

    h = hashlib.sha256()
    for name in modules:
        if name.startswith("shaders/"):
            from crackbake.bake.context import shader_source

            h.update(shader_source(name.removeprefix("shaders/")).encode())
        else:
            h.update(Path(importlib.util.find_spec(name).origin).read_bytes())
    return h.digest()


def _hasher(kind: str, *modules: str):
    h = hashlib.sha256()
    h.update(f"crackbake-{kind}:{MESH_CACHE_VERSION}:".encode())
    h.update(_sources(*modules))
    return h


def _path(kind: str, key: str) -> Path:
    from crackbake.bake.uv.cache import cache_dir

    return cache_dir() / f"{kind}-{key}{_SUFFIX}"


def _load(kind: str, key: str, count: int) -> list[np.ndarray] | None:
    """The ``count`` arrays stored under ``key`` after it, or None (missing, unreadable, another
    key); a hit refreshes the file's time."""
    path = _path(kind, key)
    try:
        with open(path, "rb") as fh:
            if str(np.load(fh, allow_pickle=False)) != key:
                return None
            arrays = [np.load(fh, allow_pickle=False) for _ in range(count)]
    except FileNotFoundError:
        return None
    except Exception:  # a truncated or foreign file: computed again and overwritten
        return None
    try:
        os.utime(path)  # recently used: kept longest
    except OSError:
        pass
    return arrays


def _store(kind: str, key: str, arrays: list[np.ndarray]) -> None:
    """Write ``arrays`` under ``key`` atomically, then trim the cache; a failure is logged and
    leaves no partial file."""
    from crackbake.bake.uv.cache import _missing_home

    size = sum(a.nbytes for a in arrays)
    if size > MAX_BYTES // 2:
        logger.debug("%s of %d bytes not cached (over half the cache)", kind, size)
        return
    if _missing_home() is not None:  # the unwrap cache says so, as a warning
        return
    path = _path(kind, key)
    tmp_name = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=_SUFFIX)
        with os.fdopen(fd, "wb") as fh:
            for a in (np.array(key), *arrays):
                np.save(fh, a, allow_pickle=False)
        os.chmod(tmp_name, 0o644)
        os.replace(tmp_name, path)  # readers never see a half-written file
        tmp_name = None
        trim(path.parent, keep=path)
    except OSError as exc:
        logger.debug("could not write the %s cache in %s: %s", kind, path.parent, exc)
    finally:
        if tmp_name is not None:
            try:
                os.unlink(tmp_name)
            except OSError:
                pass


#: Seconds after which a ``.tmp-*`` file of this cache is a killed writer's, removed by
#: :func:`trim` (a live write takes well under a second).
STALE_TMP_S = 3600.0


def trim(folder: Path, keep: Path | None = None, max_bytes: int = MAX_BYTES) -> None:
    """Remove the least recently used plans and frames in ``folder`` until they total at most
    ``max_bytes`` (``keep``, the one just written, stays), and temporary files that a killed
    run left (older than :data:`STALE_TMP_S`)."""
    import time

    for p in folder.glob(f".tmp-*{_SUFFIX}"):
        try:
            if time.time() - p.stat().st_mtime > STALE_TMP_S:
                p.unlink()
        except OSError:
            pass
    entries = []
    for kind in _KINDS:
        for p in folder.glob(f"{kind}-*{_SUFFIX}"):
            try:
                st = p.stat()
            except OSError:  # removed by another run meanwhile
                continue
            entries.append((st.st_mtime, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries, key=lambda e: e[0]):
        if total <= max_bytes:
            break
        if keep is not None and p == keep:
            continue
        try:
            p.unlink()
        except OSError:
            pass
        total -= size


# --- the gutter fill plan -------------------------------------------------------------------


def plan_key(inside: np.ndarray, limit: int | None) -> str:
    """Hex SHA-256 of what a fill plan depends on: the islands ``inside`` ((H, W) bool), the
    fill ``limit`` (texels; None: unbounded) and the planning code."""
    h = _hasher("gutter", "crackbake.bake.dilation")
    h.update(f"{inside.shape}:limit={limit}:".encode())
    h.update(np.packbits(inside, axis=None).tobytes())
    return h.hexdigest()


def read_plan(key: str, inside: np.ndarray, limit: int | None):
    """The cached :class:`~crackbake.bake.dilation.FillPlan` of ``inside`` and ``limit``, or
    None when missing, unreadable or not theirs (other islands, indices out of range, counts
    that do not add up: the fill kernels do not check their indices)."""
    from crackbake.bake.dilation import FillPlan

    arrays = _load("gutter", key, 4)
    if arrays is None or not np.array_equal(arrays[0], np.packbits(inside, axis=None)):
        return None
    plan = FillPlan(*arrays[1:])
    n = inside.size
    if (
        any(a.dtype != np.int32 or a.ndim != 1 for a in arrays[1:])
        or len(plan.targets) != len(plan.sources)
        or len(plan.targets) + len(plan.far) != n - int(np.count_nonzero(inside))
        or any(len(a) and (a.min() < 0 or a.max() >= n) for a in arrays[1:])
    ):
        return None
    return plan


def write_plan(key: str, inside: np.ndarray, plan) -> None:
    """Store a fill plan of ``inside`` under ``key`` (:func:`plan_key`)."""
    _store("gutter", key, [np.packbits(inside, axis=None), plan.targets, plan.sources, plan.far])


# --- the tangent frames ---------------------------------------------------------------------

_TANGENT_MODULES = ("crackbake.bake.tangents", "crackbake.bake.tangent_kernels",
                    "crackbake.grouping")  # fmt: skip


def tangents_key(vertices, faces, uv, normals) -> str:
    """Hex SHA-256 of what the tangent frames depend on: the output mesh's arrays and code."""
    h = _hasher("tangents", *_TANGENT_MODULES)
    for name, arr, dtype in (("vertices", vertices, np.float64), ("faces", faces, np.int64),
                             ("uv", uv, np.float64), ("normals", normals, np.float64)):  # fmt: skip
        a = np.ascontiguousarray(arr, dtype=dtype)
        h.update(f"{name}{a.shape}:".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def read_tangents(key: str, n_vertices: int, faces_shape: tuple[int, ...]):
    """``(faces, source, tangents)`` of :func:`~crackbake.bake.tangents.with_tangents` for the
    mesh keyed ``key``, or None (missing, unreadable, or shapes or indices that do not fit)."""
    arrays = _load("tangents", key, 3)
    if arrays is None:
        return None
    faces, source, tangents = arrays
    if (
        faces.shape != faces_shape or faces.dtype != np.int64
        or source.ndim != 1 or source.dtype != np.int64
        or tangents.shape != (len(source), 4) or tangents.dtype != np.float64
        or (faces.size and (faces.min() < 0 or faces.max() >= len(source)))
        or (source.size and (source.min() < 0 or source.max() >= n_vertices))
    ):  # fmt: skip
        return None
    return faces, source, tangents


def write_tangents(key: str, faces: np.ndarray, source: np.ndarray, tangents: np.ndarray) -> None:
    """Store the frames of the mesh keyed ``key`` (:func:`tangents_key`)."""
    _store("tangents", key, [np.asarray(faces, np.int64), np.asarray(source, np.int64),
                             np.asarray(tangents, np.float64)])  # fmt: skip


# --- the check of kept UVs ------------------------------------------------------------------

_CHECK_MODULES = ("crackbake.bake.uv.check", "crackbake.bake.uv.overlap",
                  "shaders/uv_overlap.vert", "shaders/uv_overlap.frag", "shaders/uv_wrap.vert",
                  "shaders/uv_wrap.frag")  # fmt: skip


def uvcheck_key(uv, faces, n_vertices: int, renderer: dict) -> str:
    """Hex SHA-256 of what :func:`~crackbake.bake.uv.check.check_uvs` depends on: the UVs,
    the faces, the vertex count, the GL renderer (``renderer_info``) and the code."""
    import json

    h = _hasher("uvcheck", *_CHECK_MODULES)
    h.update(f"{n_vertices}:{json.dumps(renderer, sort_keys=True)}:".encode())
    for name, arr, dtype in (("uv", uv, np.float64), ("faces", faces, np.int64)):
        a = np.ascontiguousarray(arr, dtype=dtype)
        h.update(f"{name}{a.shape}:".encode())
        h.update(a.tobytes())
    return h.hexdigest()


_CHECK_SCALARS = ("usable", "reason", "udim", "overlap_fraction", "outside_fraction",
                  "lost_fraction", "lost_faces")  # fmt: skip


def read_uvcheck(key: str, n_faces: int):
    """The cached :class:`~crackbake.bake.uv.check.UVCheck` keyed ``key``, or None (missing,
    unreadable, or copies of faces the mesh lacks)."""
    import json

    from crackbake.bake.uv.check import UVCheck

    arrays = _load("uvcheck", key, 3)
    if arrays is None:
        return None
    try:
        scalars = json.loads(str(arrays[0]))
        values = {k: scalars[k] for k in _CHECK_SCALARS}
        has_tiles = bool(scalars["has_tiles"])
    except (ValueError, KeyError, TypeError):
        return None
    wraps, tiles = arrays[1], arrays[2]
    if (
        wraps.dtype != np.int64 or wraps.ndim != 2 or wraps.shape[1] != 3
        or (len(wraps) and (wraps[:, 0].min() < 0 or wraps[:, 0].max() >= n_faces))
        or tiles.dtype != np.int64 or tiles.ndim != 2 or tiles.shape[1] != 2
    ):  # fmt: skip
        return None
    return UVCheck(**values, wraps=wraps, tiles=tiles if has_tiles else None)


def write_uvcheck(key: str, check) -> None:
    """Store a :class:`~crackbake.bake.uv.check.UVCheck` under ``key`` (:func:`uvcheck_key`)."""
    import json

    scalars = {k: getattr(check, k) for k in _CHECK_SCALARS}
    scalars["has_tiles"] = check.tiles is not None
    try:
        text = json.dumps(scalars)
    except (TypeError, ValueError):  # a value JSON cannot hold exactly: not cached
        return
    tiles = np.zeros((0, 2), np.int64) if check.tiles is None else check.tiles
    _store("uvcheck", key, [np.array(text), np.asarray(check.wraps, np.int64),
                            np.asarray(tiles, np.int64)])  # fmt: skip


# --- the guessed up axis --------------------------------------------------------------------

_UP_MODULES = ("crackbake.bake.preview", "crackbake.geometry_kernels")


def up_key(vertices, faces, gltf: bool) -> str:
    """Hex SHA-256 of what :func:`~crackbake.bake.preview.up_axis` depends on: the vertices,
    the faces, whether the source is glTF (always +Y) and the code."""
    h = _hasher("up", *_UP_MODULES)
    h.update(f"gltf={gltf}:".encode())
    for name, arr, dtype in (("vertices", vertices, np.float64), ("faces", faces, np.int64)):
        a = np.ascontiguousarray(arr, dtype=dtype)
        h.update(f"{name}{a.shape}:".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def read_up(key: str) -> np.ndarray | None:
    """The cached up axis keyed ``key`` ((3,) float64, +Y or +Z), or None."""
    arrays = _load("up", key, 1)
    if arrays is None:
        return None
    up = arrays[0]
    if up.shape != (3,) or up.dtype != np.float64 or not (
        np.array_equal(up, [0.0, 1.0, 0.0]) or np.array_equal(up, [0.0, 0.0, 1.0])
    ):
        return None
    return up


def write_up(key: str, up: np.ndarray) -> None:
    """Store the up axis of the mesh keyed ``key`` (:func:`up_key`)."""
    _store("up", key, [np.asarray(up, np.float64)])


# --- the simulation mesh --------------------------------------------------------------------

_SIMMESH_MODULES = ("crackbake.simulate.simmesh.build", "crackbake.simulate.simmesh.layout",
                    "crackbake.simulate.simmesh.manifold",
                    "crackbake.simulate.simmesh.manifold_kernels",
                    "crackbake.simulate.simmesh.triangulate", "crackbake.simulate.simmesh.proxy",
                    "crackbake.simulate.simmesh.collapse",
                    "crackbake.simulate.simmesh.collapse_kernels", "crackbake.geometry",
                    "crackbake.geometry_kernels")  # fmt: skip
_SIMMESH_ARRAYS = ("vertices", "faces", "asset_face", "node_face", "node_bary", "boundary")
#: The sim mesh file's layout (in its key): 2 added the derived arrays
#: (:data:`crackbake.geometry.DERIVED_ARRAYS`) and their reach.
SIMMESH_LAYOUT = 2


@cache
def _versions() -> str:
    """The versions of the libraries a sim mesh's numbers come from: numpy's, numba's and
    Triangle's ``__version__`` (a solving run has imported them or soon will), libigl's from
    its installed distribution's folder name (importing it takes 0.35 s, the package
    metadata 15-65 ms a package)."""
    import importlib.util

    import numba
    import triangle

    found = [f"{m.__name__}={getattr(m, '__version__', '?')}" for m in (np, numba, triangle)]
    igl = "?"
    try:
        spec = importlib.util.find_spec("igl")
        if spec is not None and spec.origin:
            site = Path(spec.origin).resolve().parent.parent
            names = sorted(p.name for p in site.glob("libigl-*.dist-info"))
            igl = names[-1].removeprefix("libigl-").removesuffix(".dist-info") if names else "?"
    except (ImportError, OSError, ValueError):
        pass
    return ",".join([*found, f"igl={igl}"])


def simmesh_key(vertices, faces, settings: dict, local=None) -> str:
    """Hex SHA-256 of what a sim mesh refined in the asset's faces depends on: the asset's
    positions and faces, the build's ``settings`` (JSON-able scalars), the refined balls
    ``local`` (:class:`~crackbake.simulate.simmesh.Local` or None), the code and the
    libraries' versions."""
    import json

    h = _hasher("simmesh", *_SIMMESH_MODULES)
    h.update(f"{SIMMESH_LAYOUT}:{_versions()}:{json.dumps(settings, sort_keys=True)}:".encode())
    parts = [("vertices", vertices, np.float64), ("faces", faces, np.int64)]
    if local is not None:
        parts += [("centres", local.centres, np.float64), ("radii", local.radii, np.float64),
                  ("edges", local.edges, np.float64)]  # fmt: skip
    for name, arr, dtype in parts:
        a = np.ascontiguousarray(arr, dtype=dtype)
        h.update(f"{name}{a.shape}:".encode())
        h.update(a.tobytes())
    return h.hexdigest()


_PROXY_ARRAYS = ("proxy_vertices", "proxy_faces", "proxy_rows", "surface_vertices",
                 "surface_faces")  # fmt: skip


def read_simmesh(key: str, n_asset_faces: int):
    """``(arrays, edge_length, warnings, proxy, derived)`` of the sim mesh keyed ``key``: its
    six arrays by name, its edge length, the warnings its build gave (category, message,
    filename, line), for a mesh refined in a proxy the proxy's arrays by name (its vertices,
    faces and asset rows, and the welded asset surface its closest points are found on), else
    None, and ``(arrays, reach)`` of :func:`crackbake.geometry.mesh_derived`; or None (missing,
    unreadable, or arrays that do not fit together or the asset)."""
    import json

    from crackbake.errors import CrackbakeWarning
    from crackbake.geometry import DERIVED_ARRAYS

    first = len(_SIMMESH_ARRAYS) + len(_PROXY_ARRAYS)
    loaded = _load("simmesh", key, first + len(DERIVED_ARRAYS) + 1)
    if loaded is None:
        return None
    arrays = dict(zip(_SIMMESH_ARRAYS, loaded, strict=False))
    parts = dict(zip(_PROXY_ARRAYS, loaded[len(_SIMMESH_ARRAYS):], strict=False))
    e, uses, shells, centroids = loaded[first:first + len(DERIVED_ARRAYS)]
    try:
        extra = json.loads(str(loaded[-1]))
        edge_length = float(extra["edge_length"])
        has_proxy = bool(extra["proxy"])
        reach = float(extra["reach"])
        said = []
        for category, message, filename, line in extra["warnings"]:
            kind = {"CrackbakeWarning": CrackbakeWarning}.get(category)
            if kind is None:
                return None
            said.append((kind, str(message), str(filename), int(line)))
    except (ValueError, KeyError, TypeError):
        return None

    def mesh_ok(v, f) -> bool:
        return (v.dtype == np.float64 and v.ndim == 2 and v.shape[1] == 3
                and f.dtype == np.int64 and f.ndim == 2 and f.shape[1] == 3
                and not (f.size and (f.min() < 0 or f.max() >= len(v))))  # fmt: skip

    def rows_ok(a, n: int) -> bool:
        return a.dtype == np.int64 and a.shape == (n,) and not (
            len(a) and (a.min() < 0 or a.max() >= n_asset_faces))

    v, f = arrays["vertices"], arrays["faces"]
    n = len(v)
    if not (
        mesh_ok(v, f) and rows_ok(arrays["asset_face"], len(f))
        and rows_ok(arrays["node_face"], n)
        and arrays["node_bary"].dtype == np.float64 and arrays["node_bary"].shape == (n, 3)
        and arrays["boundary"].dtype == np.bool_ and arrays["boundary"].shape == (n,)
        and e.dtype == np.int64 and e.ndim == 2 and e.shape[1:] == (2,)
        and not (e.size and (e.min() < 0 or e.max() >= n))
        and uses.dtype == np.int64 and uses.shape == (len(e),)
        and shells.dtype == np.int32 and shells.shape == (n,)
        and centroids.dtype == np.float64 and centroids.shape == (len(f), 3)
        and np.isfinite(reach)
    ):  # fmt: skip
        return None
    derived = ([e, uses, shells, centroids], reach)
    if not has_proxy:
        return arrays, edge_length, said, None, derived
    sf = parts["surface_faces"]
    if not (
        mesh_ok(parts["proxy_vertices"], parts["proxy_faces"]) and len(parts["proxy_faces"])
        and mesh_ok(parts["surface_vertices"], sf) and len(sf)
        and rows_ok(parts["proxy_rows"], len(sf))
    ):  # fmt: skip
        return None
    return arrays, edge_length, said, parts, derived


def write_simmesh(key: str, sim, said: list, derived: tuple[list, float]) -> None:
    """Store the sim mesh ``sim`` (with its proxy's arrays and surface when it has one), its
    build's warnings ``said`` (``warnings.WarningMessage``) and its ``derived`` arrays and
    reach (:func:`crackbake.geometry.mesh_derived`) under ``key`` (:func:`simmesh_key`);
    nothing is stored when a warning is not crackbake's own."""
    import json

    rows = []
    for w in said:
        if w.category.__name__ != "CrackbakeWarning":
            return
        rows.append([w.category.__name__, str(w.message), str(w.filename), int(w.lineno)])
    proxy = sim.proxy
    if proxy is None:
        none3 = np.zeros((0, 3))
        parts = [none3, none3.astype(np.int64), np.zeros(0, np.int64), none3,
                 none3.astype(np.int64)]  # fmt: skip
    else:
        parts = [np.asarray(proxy.vertices, np.float64), np.asarray(proxy.faces, np.int64),
                 np.asarray(proxy.rows, np.int64), proxy.surface.vertices,
                 proxy.surface.faces]  # fmt: skip
    text = json.dumps({"edge_length": float(sim.edge_length), "warnings": rows,
                       "proxy": proxy is not None, "reach": float(derived[1])})  # fmt: skip
    _store("simmesh", key, [np.asarray(getattr(sim, name)) for name in _SIMMESH_ARRAYS]
           + parts + list(derived[0]) + [np.array(text)])  # fmt: skip
