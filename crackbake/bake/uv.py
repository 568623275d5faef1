"""The UVs the textures are baked for: the asset's own when usable, else an xatlas unwrap.

Most game assets come with good UVs, and xatlas is slow (about 45 s for 100k faces) and can
crash, so :func:`prepare_uvs` keeps the asset's UVs whenever :func:`check_uvs` finds them usable.
An unwrap runs in a child process (:mod:`crackbake.bake.xatlas_worker`) with a time limit, packs
every chart into ONE square page with square texels and a gutter, and is cached by mesh content.

Conventions: UVs are in [0, 1] with ``v`` pointing up (OBJ/Blender); texel ``(i, j)`` of a
``res`` x ``res`` page covers ``u`` in ``[i, i+1] / res`` and ``v`` in ``[j, j+1] / res`` (GL's
framebuffer rows, row 0 at the bottom).
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh

UV_MODES = ("auto", "keep", "unwrap")

# Kept UVs may stray this far outside [0, 1] (exporters round) and are clipped.
UV_TOLERANCE = 1e-6
# Twice the UV area below which a face counts as degenerate: far below one texel at 16384^2
# (3.7e-9), so only truly collapsed faces qualify.
DEGENERATE_AREA2 = 1e-12
# Above this overlap fraction kept UVs get a warning: mirrored/stacked islands repeat cracks.
OVERLAP_WARN_FRACTION = 0.01
# Kept UVs may have up to this fraction of faces straying outside [0, 1] by at most
# STRAY_MARGIN (Keenan Crane's spot has 10 of 5,856): they are kept, with a warning, rather than
# throwing away an artist's layout for a few texels.
STRAY_FACE_FRACTION = 0.01
STRAY_MARGIN = 0.25
# Resolution at which check_uvs measures overlap; 1024^2 resolves islands down to ~0.1 % of the
# page and costs well under a second even for 500k faces.
OVERLAP_RES = 1024
MIN_RES, MAX_RES = 16, 16384

# Bump whenever the worker's output or the fitting changes, so old cache files are not reused.
CACHE_FORMAT_VERSION = 2


@dataclass(frozen=True, eq=False)
class UVMesh:
    """The output mesh: the asset's faces (same count and order as ``Mesh.faces``), UVs used.

    Attributes
    ----------
    vertices : (V', 3) float64
        Positions, mesh units; ``vertices == mesh.vertices[vertex_map]`` exactly.
    faces : (F, 3) int64
        Same faces, same order and same corner order as the input ``Mesh.faces``.
    uv : (V', 2) float64
        In [0, 1], ``v`` up (OBJ/Blender convention), one square page.
    normals : (V', 3) float64
        Unit normals, ``mesh.normals[vertex_map]``.
    vertex_map : (V',) int64
        Index into the input ``Mesh.vertices`` for each output vertex.
    method : str
        ``"kept"`` (the asset's UVs) or ``"unwrapped"`` (xatlas).
    overlap_fraction : float
        Overlapping UV area / covered UV area, 0..1 (NaN when an unwrap could not measure it
        because no OpenGL context was available).
    padding_px : int
        Chart gutter in texels at the resolution unwrapped for (0 when kept).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    normals: np.ndarray
    vertex_map: np.ndarray
    method: str
    overlap_fraction: float
    padding_px: int


@dataclass(frozen=True)
class UVCheck:
    """Whether a mesh's own UVs can be baked into.

    Attributes
    ----------
    usable : bool
        UVs exist, are finite, lie in [0, 1] and not every face is degenerate in UV.
    reason : str
        ``""`` when usable, else a short why (no UVs / outside [0, 1] / UDIM tiles / degenerate).
    udim : bool
        The UVs are laid out in UDIM tiles (each face inside one integer tile, ``u`` in [0, 10)).
    overlap_fraction : float or None
        Overlapping / covered UV area for usable UVs, else ``None``.
    outside_fraction : float
        Fraction of faces reaching slightly outside [0, 1] in otherwise usable UVs (exporters
        and hand-made UVs often stray a little); their outside part gets no texels.
    """

    usable: bool
    reason: str
    udim: bool
    overlap_fraction: float | None
    outside_fraction: float = 0.0


def default_padding(res: int) -> int:
    """Chart gutter for a page of ``res`` texels: about ``res / 256``, at least 2 texels.

    Mip-mapping halves the gutter per level; res/256 keeps islands apart down to the 1/128-size
    mip and 2 texels keeps bilinear filtering clean at small sizes.
    """
    return max(2, int(round(res / 256)))


# --------------------------------------------------------------------------------------------
# overlap


def uv_overlap_fraction(uv: np.ndarray, faces: np.ndarray, res: int = 1024) -> float:
    """Fraction of the covered UV area that more than one face covers.

    The UV triangles are rasterised with OpenGL (EGL) into a ``res`` x ``res`` R32F target with
    additive blending, giving the number of faces over each texel centre.  GL's rasterisation
    rules give a texel centre on an edge shared by two faces to only one of them, so adjacent
    faces do not count as overlap.

    Parameters
    ----------
    uv : (V, 2) float
        Texture coordinates; the page is [0, 1]^2 (anything outside is clipped away).
    faces : (F, 3) int
        Triangles indexing ``uv``.
    res : int
        Raster resolution, texels per side.

    Returns
    -------
    float
        (#texels covered at least twice) / (#texels covered at least once); 0.0 when nothing is
        covered.

    Raises
    ------
    CrackbakeError
        When no headless OpenGL context can be created.
    """
    import moderngl

    from crackbake.bake.context import create_context, shader_source

    uv = np.ascontiguousarray(uv, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (V, 2), got {uv.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
    if len(faces) == 0 or len(uv) == 0:
        return 0.0
    if faces.min() < 0 or faces.max() >= len(uv):
        raise ValueError("faces index vertices that uv does not have")
    res = int(res)

    ctx = create_context()
    try:
        prog = ctx.program(
            vertex_shader=shader_source("uv_overlap.vert"),
            fragment_shader=shader_source("uv_overlap.frag"),
        )
        vbo = ctx.buffer(uv.tobytes())
        ibo = ctx.buffer(faces.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "2f", "in_uv")], index_buffer=ibo, index_element_size=4)
        target = ctx.texture((res, res), 1, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[target])
        fbo.use()
        ctx.viewport = (0, 0, res, res)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        # Mirrored islands are back-facing in UV; they must count too.
        ctx.disable(moderngl.CULL_FACE | moderngl.DEPTH_TEST)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        vao.render(moderngl.TRIANGLES)
        counts = np.empty((res, res), dtype=np.float32)
        fbo.read_into(counts, components=1, dtype="f4")
    finally:
        ctx.release()

    # Counts are small whole numbers in float32; compare at the half-way points.
    covered = int(np.count_nonzero(counts >= 0.5))
    if covered == 0:
        return 0.0
    return int(np.count_nonzero(counts >= 1.5)) / covered


# --------------------------------------------------------------------------------------------
# checking kept UVs


def _uv_area2(corners: np.ndarray) -> np.ndarray:
    """Twice the unsigned UV area per face, (F,), from corners (F, 3, 2)."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    return np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _is_udim(corners: np.ndarray) -> bool:
    """True when every face lies inside one integer UV tile of a UDIM layout, not all in 0-1."""
    if corners.size == 0:
        return False
    tile = np.floor(corners.mean(axis=1))  # (F, 2); a centroid is strictly inside its tile
    inside = (corners >= tile[:, None, :] - UV_TOLERANCE) & (
        corners <= tile[:, None, :] + 1.0 + UV_TOLERANCE
    )
    if not inside.all():
        return False
    tu, tv = tile[:, 0], tile[:, 1]
    # UDIM numbers tiles 1001 + u + 10 v: u in 0..9, v >= 0.
    if (tu < 0).any() or (tu > 9).any() or (tv < 0).any():
        return False
    return bool(((tu > 0) | (tv > 0)).any())


def check_uvs(mesh: Mesh) -> UVCheck:
    """Decide whether the mesh's own UVs can be baked into, and how much they overlap.

    Parameters
    ----------
    mesh : Mesh
        The asset mesh; only the UVs of vertices that faces use are looked at.

    Returns
    -------
    UVCheck
        ``overlap_fraction`` is measured (at 1024^2, see :func:`uv_overlap_fraction`) only when
        the UVs are usable.
    """
    if mesh.uv is None:
        return UVCheck(False, "the mesh has no UVs", False, None)
    uv = np.asarray(mesh.uv, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if uv.shape != (len(mesh.vertices), 2):
        return UVCheck(False, f"UV array has shape {uv.shape}, not one UV per vertex", False, None)
    if len(faces) == 0:
        return UVCheck(False, "the mesh has no faces", False, None)
    corners = uv[faces]
    if not np.isfinite(corners).all():
        return UVCheck(False, "UVs contain NaN or infinite values", False, None)
    lo, hi = corners.reshape(-1, 2).min(axis=0), corners.reshape(-1, 2).max(axis=0)
    outside_fraction = 0.0
    if (lo < -UV_TOLERANCE).any() or (hi > 1.0 + UV_TOLERANCE).any():
        if _is_udim(corners):
            tiles = np.unique(np.floor(corners.mean(axis=1)), axis=0)
            return UVCheck(False, f"UVs span {len(tiles)} UDIM tiles", True, None)
        stray = ((corners < -UV_TOLERANCE) | (corners > 1.0 + UV_TOLERANCE)).any(axis=(1, 2))
        outside_fraction = float(stray.mean())
        if (
            outside_fraction > STRAY_FACE_FRACTION
            or (lo < -STRAY_MARGIN).any()
            or (hi > 1.0 + STRAY_MARGIN).any()
        ):
            return UVCheck(
                False,
                f"UVs lie outside [0, 1] (u {lo[0]:.3g}..{hi[0]:.3g}, "
                f"v {lo[1]:.3g}..{hi[1]:.3g})",
                False,
                None,
            )
    if not (_uv_area2(corners) > DEGENERATE_AREA2).any():
        return UVCheck(False, "every face has zero UV area", False, None)
    overlap = uv_overlap_fraction(np.clip(uv, 0.0, 1.0), faces, OVERLAP_RES)
    return UVCheck(True, "", False, overlap, outside_fraction)


# --------------------------------------------------------------------------------------------
# unwrapping


def _mesh_label(mesh: Mesh) -> str:
    return Path(mesh.source).name if mesh.source else mesh.name


def _weld_for_unwrap(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices that share position and normal before handing the mesh to xatlas.

    Old UV seams (and STL triangle soup) would otherwise cut charts along every split; hard
    edges (same position, different normals) stay split, which makes them chart borders, as
    normal-map baking wants.

    Returns
    -------
    representative : (W,) int64
        An input vertex index for each welded vertex (same position and normal).
    welded_faces : (F, 3) int64
        The input faces, same order and corners, indexing the welded vertices.
    """
    key = np.concatenate([mesh.vertices, mesh.normals], axis=1)
    _, representative, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1).astype(np.int64)
    return representative.astype(np.int64), inverse[mesh.faces]


def _xatlas_version() -> str:
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
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "crackbake" / "unwrap"


def _cache_key(mesh: Mesh, res: int, padding: int) -> str:
    h = hashlib.sha256()
    h.update(f"crackbake-unwrap:{CACHE_FORMAT_VERSION}:xatlas-{_xatlas_version()}:".encode())
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


def _read_cache(path: Path, key: str, mesh: Mesh) -> UVMesh | None:
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
    return _uvmesh_from(mesh, vertex_map, faces, uv, overlap, padding)


def _write_cache(path: Path, key: str, result: UVMesh) -> None:
    tmp_name = None
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


def _uvmesh_from(
    mesh: Mesh,
    vertex_map: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    overlap: float,
    padding: int,
) -> UVMesh:
    return UVMesh(
        vertices=np.asarray(mesh.vertices, dtype=np.float64)[vertex_map],
        faces=faces,
        uv=uv,
        normals=np.asarray(mesh.normals, dtype=np.float64)[vertex_map],
        vertex_map=vertex_map,
        method="unwrapped",
        overlap_fraction=overlap,
        padding_px=int(padding),
    )


def _worker_error(returncode: int, stderr: str, label: str, n_faces: int) -> CrackbakeError:
    """The user-facing error for a worker that exited with ``returncode`` != 0."""
    if returncode < 0:
        sig = -returncode
        try:
            signame = f", {signal.Signals(sig).name}"
        except ValueError:
            signame = ""
        return CrackbakeError(
            f"xatlas crashed (signal {sig}{signame}) unwrapping {label} ({n_faces} faces); "
            "try --uv keep with your own UVs or remesh"
        )
    lines = [ln.strip() for ln in stderr.strip().splitlines() if ln.strip()]
    detail = lines[-1] if lines else f"exit status {returncode}"
    return CrackbakeError(
        f"xatlas failed unwrapping {label} ({n_faces} faces): {detail}; "
        "try --uv keep with your own UVs or remesh"
    )


def _run_worker(
    vertices: np.ndarray,
    faces: np.ndarray,
    res: int,
    padding: int,
    timeout: float,
    label: str,
) -> dict[str, np.ndarray]:
    n_faces = len(faces)
    with tempfile.TemporaryDirectory(prefix="crackbake-xatlas-") as tmp:
        inp, out = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(inp, vertices=vertices, faces=faces, res=np.int64(res), padding=np.int64(padding))
        env = os.environ.copy()
        # The child must import this very crackbake, installed or not.
        package_parent = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (package_parent, env.get("PYTHONPATH", "")) if p
        )
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "crackbake.bake.xatlas_worker", str(inp), str(out)],
                capture_output=True,
                text=True,
                timeout=timeout,
                env=env,
            )
        except subprocess.TimeoutExpired:
            raise CrackbakeError(
                f"xatlas did not finish within {timeout:g} s unwrapping {label} "
                f"({n_faces} faces); raise --unwrap-timeout, use --uv keep with your own UVs, "
                "or decimate the mesh"
            ) from None
        if proc.returncode != 0:
            raise _worker_error(proc.returncode, proc.stderr, label, n_faces)
        try:
            with np.load(out, allow_pickle=False) as data:
                result = {k: np.asarray(data[k]) for k in data.files}
        except Exception as exc:
            raise CrackbakeError(
                f"xatlas's worker wrote no readable result for {label} ({exc}); "
                "check free space in the temp folder"
            ) from exc
    return result


def unwrap(
    mesh: Mesh,
    res: int,
    padding: int | None = None,
    timeout: float = 300.0,
    cache: bool = True,
) -> UVMesh:
    """Unwrap the mesh with xatlas into one square ``res`` x ``res`` page.

    xatlas runs in a child process, so a crash or hang becomes a :class:`CrackbakeError`.  The
    charts are packed with a ``padding``-texel gutter (bilinear-safe) and square texels: UVs are
    texel positions / ``res`` on both axes.  Vertices sharing position and normal are welded
    first, so old UV seams do not cut the new charts.

    Parameters
    ----------
    mesh : Mesh
        The asset mesh (its own UVs, if any, are ignored).
    res : int
        Texture resolution the charts are packed for, texels per side.
    padding : int, optional
        Gutter between charts, texels at ``res``; default :func:`default_padding`.
    timeout : float
        Seconds xatlas may run before it is stopped.
    cache : bool
        Read and write the unwrap cache (see :func:`cache_dir`); ``False`` touches no files
        there.

    Returns
    -------
    UVMesh
        ``method == "unwrapped"``, faces in the input order.

    Raises
    ------
    CrackbakeError
        Bad resolution or padding, an empty mesh, or xatlas crashing, failing or timing out.
    """
    label = _mesh_label(mesh)
    res = int(res)
    if not MIN_RES <= res <= MAX_RES:
        raise CrackbakeError(
            f"texture resolution {res} is out of range; use {MIN_RES}..{MAX_RES} (e.g. 2048)"
        )
    padding = default_padding(res) if padding is None else int(padding)
    if not 0 <= padding <= res // 8:
        raise CrackbakeError(
            f"UV padding {padding} px does not suit a {res} px texture; use 0..{res // 8} px"
        )
    faces = np.asarray(mesh.faces, dtype=np.int64)
    n_vertices = len(mesh.vertices)
    if len(faces) == 0:
        raise CrackbakeError(f"{label}: the mesh has no faces; crackbake needs a triangle mesh")
    if faces.min() < 0 or faces.max() >= n_vertices:
        raise CrackbakeError(f"{label}: faces index missing vertices; repair the mesh first")
    if np.shape(mesh.normals) != (n_vertices, 3):
        raise CrackbakeError(f"{label}: normals do not match the vertices; reload the mesh")

    key = _cache_key(mesh, res, padding)
    path = cache_dir() / f"{key}.npz"
    if cache:
        hit = _read_cache(path, key, mesh)
        if hit is not None:
            return hit

    representative, welded_faces = _weld_for_unwrap(mesh)
    out = _run_worker(
        np.asarray(mesh.vertices, dtype=np.float64)[representative],
        welded_faces,
        res,
        padding,
        timeout,
        label,
    )
    vmapping = out["vmapping"].astype(np.int64)
    indices = out["indices"].astype(np.int64)
    uv = out["uv"].astype(np.float64)
    if indices.shape != faces.shape or (len(vmapping) and vmapping.max() >= len(representative)):
        raise CrackbakeError(
            f"xatlas returned a mesh that does not match {label}; "
            "try --uv keep with your own UVs or remesh"
        )
    vertex_map = representative[vmapping]

    try:
        overlap = uv_overlap_fraction(uv, indices, OVERLAP_RES)
    except CrackbakeError:
        # Measuring is a nicety here; the bake will report the missing GL context itself.
        overlap = float("nan")

    result = _uvmesh_from(mesh, vertex_map, indices, uv, overlap, padding)
    if cache:
        _write_cache(path, key, result)
    return result


# --------------------------------------------------------------------------------------------
# the entry point


def _kept(mesh: Mesh, check: UVCheck) -> UVMesh:
    label = _mesh_label(mesh)
    overlap = float(check.overlap_fraction or 0.0)
    if overlap > OVERLAP_WARN_FRACTION:
        warnings.warn(
            f"{label}: {overlap:.1%} of the UV area overlaps (stacked or mirrored islands), so "
            "cracks will show twice there; use --uv unwrap for unique UVs",
            CrackbakeWarning,
            stacklevel=3,
        )
    if check.outside_fraction > 0:
        n = int(round(check.outside_fraction * len(mesh.faces)))
        warnings.warn(
            f"{label}: {n} faces reach slightly outside the 0-1 UV square; their outside parts "
            "get no texels (use --uv unwrap to avoid it)",
            CrackbakeWarning,
            stacklevel=3,
        )
    # Not clipped: clipping would distort the straying faces; the bake simply gets no texels
    # outside the page and the GLB keeps the artist's UVs.
    uv = np.asarray(mesh.uv, dtype=np.float64)
    n_degenerate = int(np.count_nonzero(_uv_area2(uv[mesh.faces]) <= DEGENERATE_AREA2))
    if n_degenerate > OVERLAP_WARN_FRACTION * len(mesh.faces):
        warnings.warn(
            f"{label}: {n_degenerate} faces have zero UV area and get no texels; "
            "use --uv unwrap if cracks go missing there",
            CrackbakeWarning,
            stacklevel=3,
        )
    return UVMesh(
        vertices=np.asarray(mesh.vertices, dtype=np.float64),
        faces=np.asarray(mesh.faces, dtype=np.int64),
        uv=uv,
        normals=np.asarray(mesh.normals, dtype=np.float64),
        vertex_map=np.arange(len(mesh.vertices), dtype=np.int64),
        method="kept",
        overlap_fraction=overlap,
        padding_px=0,
    )


def prepare_uvs(
    mesh: Mesh,
    mode: str = "auto",
    res: int = 2048,
    padding: int | None = None,
    timeout: float = 300.0,
    cache: bool = True,
) -> UVMesh:
    """The UVs to bake into: keep the asset's, or unwrap with xatlas.

    Parameters
    ----------
    mesh : Mesh
        The asset mesh.
    mode : {"auto", "keep", "unwrap"}
        ``"keep"`` uses the mesh's UVs (error when unusable), ``"unwrap"`` always runs xatlas,
        ``"auto"`` keeps usable UVs and unwraps otherwise (warning why when the mesh had UVs).
    res : int
        Texture resolution an unwrap packs for, texels per side.
    padding : int, optional
        Unwrap gutter in texels; default :func:`default_padding`.
    timeout : float
        Seconds xatlas may run.
    cache : bool
        Use the unwrap cache.

    Returns
    -------
    UVMesh

    Raises
    ------
    CrackbakeError
        Unknown mode, unusable UVs in ``"keep"`` mode, or a failed unwrap.

    Warns
    -----
    CrackbakeWarning
        Kept UVs overlapping by more than 1 %, or ``"auto"`` falling back to an unwrap.
    """
    if mode not in UV_MODES:
        raise CrackbakeError(f"unknown UV mode '{mode}'; use one of {', '.join(UV_MODES)}")
    if mode == "unwrap":
        return unwrap(mesh, res, padding=padding, timeout=timeout, cache=cache)

    label = _mesh_label(mesh)
    check = check_uvs(mesh)
    if check.usable:
        return _kept(mesh, check)
    if mode == "keep":
        if check.udim:
            raise CrackbakeError(
                f"{label}: UDIM tiles are not supported yet; move the UVs into the 0-1 tile "
                "or use --uv unwrap"
            )
        raise CrackbakeError(f"{label}: cannot keep the UVs: {check.reason}; use --uv unwrap")
    if mesh.uv is not None:
        warnings.warn(
            f"{label}: {check.reason}; unwrapping with xatlas instead",
            CrackbakeWarning,
            stacklevel=2,
        )
    return unwrap(mesh, res, padding=padding, timeout=timeout, cache=cache)
