"""xatlas unwraps, run in a child process (:mod:`crackbake.bake.xatlas_worker`) with a time limit.

xatlas is slow (10-25 s of CPU for 100k faces) and can crash, so it never runs in this
process; an unwrap packs every chart into ONE square page with square texels and a gutter, and
is cached by mesh content (:mod:`crackbake.bake.uv.cache`).  Its progress lines are logged
(logger ``crackbake.bake.uv.unwrap``) and show as the UV stage's detail on the live display.
"""

from __future__ import annotations

import io
import logging
import os
import signal
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np

from crackbake.bake.uv.cache import cache_dir, cache_key, read_cache, write_cache
from crackbake.bake.uv.check import OVERLAP_RES
from crackbake.bake.uv.overlap import uv_overlap_fraction
from crackbake.bake.uv.uvmesh import (
    UVMesh,
    mesh_label,
    unwrapped_uvmesh,
    uv_area_coverage,
)
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh
from crackbake.params import default_padding

# Tells the worker our pid (crackbake.bake.xatlas_worker.PARENT_ENV; not imported from there so
# this process never loads xatlas).
PARENT_ENV = "CRACKBAKE_XATLAS_PARENT"
logger = logging.getLogger(__name__)
# The worker's stderr lines starting so are progress (shown as the UV stage's detail).
PROGRESS_PREFIX = "progress: "
# An unwrap using less of the texture than this gets a warning: its cracks get few texels.
COVERAGE_WARN = 0.30


def weld_for_unwrap(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
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


def worker_error(returncode: int, stderr: str, label: str, n_faces: int) -> CrackbakeError:
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


def run_worker(
    vertices: np.ndarray,
    faces: np.ndarray,
    res: int,
    padding: int,
    timeout: float,
    label: str,
) -> dict[str, np.ndarray]:
    """Run :mod:`crackbake.bake.xatlas_worker` on (vertices, faces); its output arrays.

    The arrays travel through the child's stdin and stdout, so no temporary file exists at any
    time.  The child runs in its own process group, which is killed on a timeout, an error or
    an interrupt (SIGINT/SIGTERM arriving here); if this process is killed outright, the
    kernel kills the child (``PR_SET_PDEATHSIG``, Linux).
    """
    n_faces = len(faces)
    buf = io.BytesIO()
    np.savez(buf, vertices=vertices, faces=faces, res=np.int64(res), padding=np.int64(padding))
    env = os.environ.copy()
    # The child must import this very crackbake, installed or not.
    package_parent = str(Path(__file__).resolve().parents[3])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package_parent, env.get("PYTHONPATH", "")) if p)
    env[PARENT_ENV] = str(os.getpid())
    # A first try that runs far longer than an unwrap of its size does is taken for a stall and
    # tried once more with the time left: a 128-face unwrap once never returned here (the
    # full suite, 300 s), and the same call then took 0.1 s.
    first = min(timeout, max(STALL_MIN_S, STALL_S_PER_FACE * n_faces))
    try:
        proc, stdout, stderr = _run_once(buf.getvalue(), env, first)
    except subprocess.TimeoutExpired:
        if first >= timeout:
            raise _timed_out(timeout, label, n_faces) from None
        logger.info("xatlas made no result in %.0f s for %d faces: starting it again",
                    first, n_faces)
        try:
            proc, stdout, stderr = _run_once(buf.getvalue(), env, timeout - first)
        except subprocess.TimeoutExpired:
            raise _timed_out(timeout, label, n_faces) from None
    if proc.returncode != 0:
        raise worker_error(proc.returncode, stderr, label, n_faces)
    try:
        with np.load(io.BytesIO(stdout), allow_pickle=False) as data:
            return {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError, KeyError, EOFError) as exc:
        raise CrackbakeError(
            f"xatlas's worker sent no readable result for {label} ({exc}); "
            "try --uv keep with your own UVs or remesh"
        ) from exc


#: The first try's time limit (:func:`run_worker`): this many seconds a face, at least
#: :data:`STALL_MIN_S` (an unwrap here: 128 faces 0.1 s, 100k faces 60-90 s).
STALL_S_PER_FACE = 0.01
STALL_MIN_S = 30.0


def _timed_out(timeout: float, label: str, n_faces: int) -> CrackbakeError:
    return CrackbakeError(
        f"xatlas did not finish within {timeout:g} s unwrapping {label} "
        f"({n_faces} faces); raise --unwrap-timeout, use --uv keep with your own UVs, "
        "or decimate the mesh"
    )


def _run_once(payload: bytes, env: dict, limit: float):
    """One run of the worker on ``payload`` (the input ``.npz``) within ``limit`` seconds:
    (the finished process, its stdout bytes, its non-progress stderr lines); raises
    :class:`subprocess.TimeoutExpired` (the child killed) when it runs longer."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "crackbake.bake.xatlas_worker"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        start_new_session=True,  # own process group: Ctrl-C reaches us, we stop the child
    )
    # Three pipes at once: feeding stdin while draining stdout and stderr (progress lines shown
    # as they come) so neither side blocks on a full pipe.
    out_chunks: list[bytes] = []
    err_lines: list[str] = []
    pumps = [
        threading.Thread(target=_feed, args=(proc.stdin, payload), daemon=True),
        threading.Thread(target=_drain, args=(proc.stdout, out_chunks), daemon=True),
        threading.Thread(target=_relay, args=(proc.stderr, err_lines), daemon=True),
    ]
    for pump in pumps:
        pump.start()
    try:
        proc.wait(timeout=limit)
    finally:
        stop_worker(proc, pumps)
    return proc, b"".join(out_chunks), "\n".join(err_lines)


def _feed(pipe, data: bytes) -> None:
    try:
        with pipe:
            pipe.write(data)
    except (BrokenPipeError, OSError, ValueError):  # the child died or was stopped
        pass


def _drain(pipe, chunks: list[bytes]) -> None:
    try:
        chunks.append(pipe.read())
    except (OSError, ValueError):
        pass


def _relay(pipe, lines: list[str]) -> None:
    """Log the worker's progress lines as they come; keep the others for an error message."""
    try:
        for raw in pipe:
            line = raw.decode("utf-8", "replace").rstrip()
            if line.startswith(PROGRESS_PREFIX):
                logger.info("%s", line[len(PROGRESS_PREFIX):])
            elif line:
                lines.append(line)
    except (OSError, ValueError):
        pass


def stop_worker(proc: subprocess.Popen, pumps: list[threading.Thread] = ()) -> None:
    """Kill ``proc``'s process group if it is still running, end the pipe threads, reap it."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    for pump in pumps:  # the pipes reach EOF once the group is gone
        pump.join(timeout=5.0)
    for pipe in (proc.stdin, proc.stdout, proc.stderr):
        if pipe is not None:
            pipe.close()
    proc.wait()


def unwrap(
    mesh: Mesh,
    res: int,
    padding: int | None = None,
    timeout: float = 300.0,
    cache: bool = True,
    ctx=None,
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
    ctx : moderngl.Context, optional
        The run's GL context for measuring the overlap; a temporary one when not given.

    Returns
    -------
    UVMesh
        ``method == "unwrapped"``, faces in the input order.

    Raises
    ------
    CrackbakeError
        Padding too wide for ``res``, an empty mesh, or xatlas crashing, failing or timing out.
    """
    label = mesh_label(mesh)
    res = int(res)
    padding = _checked_padding(mesh, label, res, padding)
    key = cache_key(mesh, res, padding)
    path = cache_dir() / f"{key}.npz"
    if cache:
        hit = read_cache(path, key, mesh)
        if hit is not None:
            _warn_coverage(hit, label, res)
            return hit

    vertex_map, indices, uv = _xatlas(mesh, label, res, padding, timeout)
    try:
        overlap = uv_overlap_fraction(uv, indices, OVERLAP_RES, ctx=ctx)
    except CrackbakeError:
        # Measuring is a nicety here; the bake will report the missing GL context itself.
        overlap = float("nan")

    result = unwrapped_uvmesh(mesh, vertex_map, indices, uv, overlap, padding)
    if cache:
        write_cache(path, key, result)
    _warn_coverage(result, label, res)
    return result


def _warn_coverage(result: UVMesh, label: str, res: int) -> None:
    """One line when the unwrap leaves most of the texture empty (cracks get few texels)."""
    coverage = uv_area_coverage(result.uv, result.faces)
    if coverage < COVERAGE_WARN:
        warnings.warn(
            f"{label}: the unwrap uses only {coverage:.0%} of the {res}px texture, so cracks get "
            "few texels; raise --res, lower --padding, or bring UVs of your own (--uv keep)",
            CrackbakeWarning,
            stacklevel=4,
        )


def _checked_padding(mesh: Mesh, label: str, res: int, padding: int | None) -> int:
    """The gutter in texels (default :func:`default_padding`), after checking the mesh."""
    if res < 1:
        # RunParams validates the user's --res; this guards direct library calls.
        raise ValueError(f"res must be a positive texel count, got {res}")
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
    return padding


def _xatlas(
    mesh: Mesh, label: str, res: int, padding: int, timeout: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the worker on the welded mesh: (vertex_map (V',), faces (F, 3), uv (V', 2))."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    representative, welded_faces = weld_for_unwrap(mesh)
    out = run_worker(
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

    return vertex_map, indices, uv
