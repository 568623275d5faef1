"""Small geometry helpers shared by every stage: normals, areas, barycentrics, edges.

Plain functions over numpy arrays, in the spirit of ``trimesh.triangles``.  Vertices are
``(V, 3)`` float64 in mesh units, faces ``(F, 3)`` int64 indices, counter-clockwise seen from
the front.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable

import numpy as np


def face_cross(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Edge cross products ``(b - a) x (c - a)`` per face, (F, 3): twice the area times the
    unit normal.

    Raises ``IndexError`` (as numpy indexing would) when a face indexes outside ``vertices``.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise IndexError(f"faces index vertices outside 0..{len(v) - 1}")
    # numba is imported with its first use: a run refused while reading its mesh file does
    # not pay the import (crackbake.io.mesh imports this module).
    from crackbake.geometry_kernels import face_cross_kernel

    return face_cross_kernel(v, f)


def face_cross_numpy(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """:func:`face_cross` with numpy, bit for bit: for the mesh load, which runs before any
    numba kernel (numba's import and first call cost more than this at 1.5M faces)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise IndexError(f"faces index vertices outside 0..{len(v) - 1}")
    a = v[f[:, 0]]
    u = v[f[:, 1]] - a
    w = v[f[:, 2]] - a
    out = np.empty((len(f), 3))
    # the kernel's operations in its order (no fused multiply-add either way)
    np.subtract(u[:, 1] * w[:, 2], u[:, 2] * w[:, 1], out=out[:, 0])
    np.subtract(u[:, 2] * w[:, 0], u[:, 0] * w[:, 2], out=out[:, 1])
    np.subtract(u[:, 0] * w[:, 1], u[:, 1] * w[:, 0], out=out[:, 2])
    return out


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas, (F,), mesh units squared."""
    return 0.5 * np.linalg.norm(face_cross(vertices, faces), axis=1)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit face normals, (F, 3); zero for degenerate faces."""
    n = face_cross(vertices, faces)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def corner_mean(corners: np.ndarray) -> np.ndarray:
    """``corners.mean(axis=1)`` of (K, 3, ...) float64 corners (a face's three), bit for bit,
    in about a third of the time: numpy's mean is a generic reduction, slow over an axis of 3.

    numpy sums from 0 (``((0 + a) + b) + c``), which differs from ``(a + b) + c`` only in the
    sign of a zero sum; adding 0.0 gives that zero numpy's sign, then both divide by 3.
    """
    c = np.asarray(corners)
    if c.dtype != np.float64:  # numpy's own rules (float32 sums in float32 and so on)
        return c.mean(axis=1)
    out = c[:, 0] + c[:, 1]
    out += c[:, 2]
    out += 0.0
    out /= 3.0
    return out


def unit_rows(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``v`` (N, 3) scaled to unit length (zero rows stay zero) and their lengths (N,)."""
    length = np.linalg.norm(v, axis=1)
    return v / np.where(length > 0, length, 1.0)[:, None], length


def vertex_normals(
    vertices: np.ndarray, faces: np.ndarray, cross: np.ndarray | None = None
) -> np.ndarray:
    """Area-weighted unit vertex normals, (V, 3); zero at vertices no face uses.

    Vertices are not welded here: call :func:`weld_by_position` first where UV-seam copies of
    a position must share one normal.  ``cross``: the faces' :func:`face_cross` when the
    caller has it.
    """
    if cross is None:
        cross = face_cross(vertices, faces)  # 2 A n
    return _summed_normals(len(vertices), faces, cross)


def _summed_normals(n: int, faces: np.ndarray, cross: np.ndarray) -> np.ndarray:
    idx = faces.reshape(-1)
    acc = np.empty((n, 3))
    for a in range(3):
        acc[:, a] = np.bincount(idx, weights=np.repeat(cross[:, a], 3), minlength=n)
    return unit_rows(acc)[0]


def weld_by_position(
    vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge vertices with identical positions (the copies made by UV seams).

    Returns
    -------
    welded_vertices : (W, 3) float64
    welded_faces : (F, 3) int64
        Same faces, same order, indexing ``welded_vertices``.
    inverse : (V,) int64
        ``welded_vertices[inverse] == vertices``.
    """
    v = np.asarray(vertices)
    if not len(v):
        return v.reshape(0, 3).astype(np.float64), np.asarray(faces), np.zeros(0, np.int64)
    # np.unique(axis=0)'s result (rows sorted by x, y, z), from a lexsort of the columns:
    # 3.5x faster than its sort of structured rows at 750k vertices.
    order = np.lexsort(v.T[::-1])
    ordered = v[order]
    first = np.empty(len(v), bool)
    first[0] = True
    np.any(ordered[1:] != ordered[:-1], axis=1, out=first[1:])
    inverse = np.empty(len(v), np.int64)
    inverse[order] = np.cumsum(first) - 1
    return ordered[first], inverse[faces], inverse


def position_groups(positions: np.ndarray) -> np.ndarray:
    """A group number per row of ``positions`` (P, 3) float64, equal for equal positions (as
    :func:`weld_by_position` merges them), numbered in no particular order.

    Sorts one 64-bit hash of each row instead of lexsorting three float columns (8x faster
    at 375k rows); rows that share a hash but differ (a collision) fall back to the lexsort.
    """
    if len(positions) < 2:
        return np.zeros(len(positions), dtype=np.int64)
    bits = np.ascontiguousarray(positions + 0.0, dtype=np.float64).view(np.uint64)  # -0 -> +0
    key = bits[:, 0] * np.uint64(0x9E3779B97F4A7C15)
    key ^= (bits[:, 1] + np.uint64(0x632BE59BD9B4E019)) * np.uint64(0xBF58476D1CE4E5B9)
    key ^= (bits[:, 2] + np.uint64(0x8CB92BA72F3D8DD7)) * np.uint64(0x94D049BB133111EB)
    key ^= key >> np.uint64(29)
    n_bits = (len(key) - 1).bit_length()
    # the row number below the hash's top bits: one plain sort gives the order
    packed = (key >> np.uint64(n_bits)) << np.uint64(n_bits) | np.arange(len(key), dtype=np.uint64)
    packed.sort()
    order = (packed & np.uint64((1 << n_bits) - 1)).astype(np.int64)
    top = packed >> np.uint64(n_bits)
    same = top[1:] == top[:-1]
    rows = bits[order]
    if (same & (rows[1:] != rows[:-1]).any(axis=1)).any():  # a collision: exact lexsort
        return weld_by_position(positions, np.zeros((0, 3), np.int64))[2]
    group = np.empty(len(key), dtype=np.int64)
    group[order] = np.cumsum(np.concatenate(([True], ~same))) - 1
    return group


def barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points ``p`` (K, D) in triangles ``tri`` (K, 3, D), D = 2 or 3.

    A least-squares solve in each triangle's plane: points off the plane are projected onto
    it, points outside the triangle get coordinates outside [0, 1] (no clamping), degenerate
    triangles give (1, 0, 0).  Returns (K, 3), rows summing to 1.
    """
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    d = p - tri[:, 0]
    d11 = np.einsum("ij,ij->i", e1, e1)
    d12 = np.einsum("ij,ij->i", e1, e2)
    d22 = np.einsum("ij,ij->i", e2, e2)
    p1 = np.einsum("ij,ij->i", d, e1)
    p2 = np.einsum("ij,ij->i", d, e2)
    det = d11 * d22 - d12 * d12
    det = np.where(det != 0, det, 1.0)
    b1 = (d22 * p1 - d12 * p2) / det
    b2 = (d11 * p2 - d12 * p1) / det
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1)


def closest_on_triangles(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closest point to ``p`` on each triangle ``(a, b, c)``, each (K, 3) (``p`` may be (3,)).

    Returns
    -------
    points : (K, 3)
    bary : (K, 3)
        Barycentric coordinates of ``points``, each in [0, 1].
    """
    ab, ac, ap = b - a, c - a, p - a
    d00 = np.einsum("ka,ka->k", ab, ab)
    d01 = np.einsum("ka,ka->k", ab, ac)
    d11 = np.einsum("ka,ka->k", ac, ac)
    d20 = np.einsum("ka,ka->k", ap, ab)
    d21 = np.einsum("ka,ka->k", ap, ac)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-300 * np.maximum(d00 * d11, 1e-300)
    safe = np.where(ok, den, 1.0)
    v = (d11 * d20 - d01 * d21) / safe
    w = (d00 * d21 - d01 * d20) / safe
    u = 1.0 - v - w
    inside = ok & (u >= 0) & (v >= 0) & (w >= 0)
    bary = np.stack([u, v, w], axis=1)
    best = a + v[:, None] * ab + w[:, None] * ac
    best_d = np.where(inside, np.einsum("ka,ka->k", best - p, best - p), np.inf)
    # Projection outside the triangle: the closest point lies on one of its edges.
    for i, (s, e) in enumerate(((a, b), (b, c), (c, a))):
        se = e - s
        ll = np.einsum("ka,ka->k", se, se)
        t = np.clip(np.einsum("ka,ka->k", p - s, se) / np.where(ll > 0, ll, 1.0), 0.0, 1.0)
        q = s + t[:, None] * se
        dq = np.einsum("ka,ka->k", q - p, q - p)
        better = dq < best_d
        if better.any():
            bb = np.zeros((better.sum(), 3))
            bb[:, i] = 1.0 - t[better]
            bb[:, (i + 1) % 3] = t[better]
            bary[better] = bb
            best[better] = q[better]
            best_d = np.where(better, dq, best_d)
    return best, bary


class SurfaceIndex:
    """Closest points on one triangle mesh: libigl's AABB tree, built once, queried many times.

    Parameters
    ----------
    vertices : (V, 3) float64
        Mesh units.
    faces : (F, 3) int64
        At least one face.
    lazy : bool
        Build the tree at the first query instead of now (a sim mesh read from the mesh cache:
        its proxy's surface is asked only where cracks move onto the asset).
    ahead : bool
        Build it now in a child process (:meth:`start_worker`).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, lazy: bool = False,
                 ahead: bool = False) -> None:  # fmt: skip
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        if not len(self.faces):
            raise ValueError("a surface index needs at least one face")
        self._tree = None
        self._worker = None
        if ahead:
            self.start_worker()
        elif not lazy:
            self._build()

    def __getstate__(self) -> dict:
        # A copy in another process (a pickled result: a batch worker's, multiprocessing's)
        # builds its tree at its first query: libigl's tree does not pickle, and a worker
        # belongs to the process that started it.
        state = dict(self.__dict__)
        state["_tree"] = state["_worker"] = None
        return state

    def start_worker(self) -> None:
        """Build the tree from now on in a child process (:mod:`crackbake.closest_worker`),
        which answers the next query: the build holds the GIL for seconds at a million faces,
        so on a thread it would stall the caller instead of running beside it.  Later queries,
        or one the worker failed, use a tree built here.  Nothing to do once a tree or a
        worker exists."""
        if self._tree is None and self._worker is None:
            self._worker = _TreeWorker.start(self.vertices, self.faces)

    def _build(self) -> None:
        import igl  # only the simulation proxy and its stress bake need it

        tree = igl.AABB()
        tree.init(self.vertices, self.faces)
        self._tree = tree

    def stop_worker(self) -> None:
        """Stop the worker (:meth:`start_worker`) if no query has used it (a run that grew no
        cracks)."""
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.stop()

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The closest surface point to each of ``points`` (K, 3).

        Returns
        -------
        face : (K,) int64
            Row of ``faces`` holding the closest point (ties go to one of them, always the same).
        bary : (K, 3) float64
            Its barycentric coordinates in that face, each in [0, 1], rows summing to 1.
        position : (K, 3) float64
            The closest point, mesh units.
        """
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(p):
            return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))
        answer = None
        if self._worker is not None:  # the first query: the worker's tree, built meanwhile
            worker, self._worker = self._worker, None
            answer = worker.query(p)
        if answer is None:
            if self._tree is None:
                self._build()
            _, face, position = self._tree.squared_distance(self.vertices, self.faces, p)
        else:
            face, position = answer
        face = np.asarray(face, dtype=np.int64)
        bary = np.clip(barycentric(self.vertices[self.faces[face]], position), 0.0, None)
        bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
        return face, bary, np.asarray(position, dtype=np.float64)


class _TreeWorker:
    """A :mod:`crackbake.closest_worker` process building a surface's tree (see
    :class:`SurfaceIndex`'s ``ahead``); killed when dropped or at the exit, it dies with us."""

    def __init__(self, proc, feeding) -> None:
        import weakref

        self.proc, self.feeding = proc, feeding
        self._stop = weakref.finalize(self, _stop_tree_worker, proc)

    @classmethod
    def start(cls, vertices: np.ndarray, faces: np.ndarray) -> _TreeWorker | None:
        """The worker, fed the surface on a thread; None where it cannot start."""
        import os
        import subprocess
        import sys
        import threading

        from crackbake.closest_worker import PARENT_ENV, send

        try:
            proc = subprocess.Popen(
                [sys.executable, "-m", "crackbake.closest_worker"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                env=dict(os.environ, **{PARENT_ENV: str(os.getpid())}),
                start_new_session=True,  # own process group: Ctrl-C reaches us, we stop it
            )  # fmt: skip
        except OSError:
            return None

        def feed() -> None:
            try:
                send(proc.stdin, vertices)
                send(proc.stdin, faces)
                proc.stdin.flush()
            except (OSError, ValueError):  # it died or was stopped: the query finds out
                pass

        feeding = threading.Thread(target=feed, name="crackbake-closest-feed", daemon=True)
        feeding.start()
        return cls(proc, feeding)

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """libigl's closest faces (K,) and positions (K, 3) of ``points`` (K, 3), or None where
        the worker failed; the worker is gone after."""
        from crackbake.closest_worker import receive, send

        try:
            self.feeding.join()
            send(self.proc.stdin, points)
            self.proc.stdin.close()
            face = receive(self.proc.stdout)
            position = receive(self.proc.stdout)
            ok = (self.proc.wait() == 0 and face.shape == (len(points),)
                  and position.shape == (len(points), 3))  # fmt: skip
        except (OSError, ValueError):  # a broken pipe, a truncated or garbled answer
            ok = False
        finally:
            self.stop()
        return (face, position) if ok else None

    def stop(self) -> None:
        """Kill the worker if it still runs and reap it; idempotent."""
        self._stop()


def _stop_tree_worker(proc) -> None:
    import os
    import signal

    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    for pipe in (proc.stdin, proc.stdout):
        try:
            pipe.close()
        except (OSError, ValueError):
            pass
    proc.wait()


def edges(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (E, 2), sorted, low index first, and how many faces use each (E,)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    # One int64 key per edge: a 1-D unique is far faster than np.unique(axis=0).
    key = e[:, 0] * np.int64(n_vertices) + e[:, 1]
    uniq, counts = np.unique(key, return_counts=True)
    return np.stack([uniq // n_vertices, uniq % n_vertices], axis=1), counts


#: How many results :func:`memo` keeps (the newest): a run asks about one or two sim meshes
#: (edges, shells, centroids) and, per impact, a fast-marching patch and its distance.
MEMO_SIZE = 16
_memo: OrderedDict = OrderedDict()
_memo_lock = threading.Lock()


def content_key(*arrays: np.ndarray) -> bytes:
    """A digest of the arrays' dtypes, shapes and bytes (SHA-256: with the CPU's SHA
    instructions about 1 GB/s, 3x BLAKE2b here): equal keys, equal contents.  About 2.5 ms for
    a 100k-face mesh's faces."""
    import hashlib  # where used: 5 ms of every run's start-up

    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(memoryview(a).cast("B"))
    return h.digest()


def memo(name: str, compute: Callable[[], tuple], *key) -> tuple:
    """``compute()``'s arrays, remembered by ``name`` and ``key`` (arrays by their contents,
    :func:`content_key`; other parts as they are) for the :data:`MEMO_SIZE` newest keys.

    The stress field, the impacts' star check and the solver's set-up all ask for the same
    sim mesh's edges, shells and face centroids; each is computed once.  The arrays come back
    read-only, shared by every caller: copy one to change it.
    """
    full = _memo_key(name, key)
    out = recall(full)
    if out is None:
        out = compute()
        remember(full, out)
    return out


def _memo_key(name: str, key: tuple) -> tuple:
    return (name, *(content_key(k) if isinstance(k, np.ndarray) else k for k in key))


def recall(full: tuple) -> tuple | None:
    """What :func:`remember` kept under ``full`` (a name and hashable parts), or None."""
    with _memo_lock:
        if full in _memo:
            _memo.move_to_end(full)
            return _memo[full]
    return None


def remember(full: tuple, out: tuple) -> None:
    """Keep ``out`` (its arrays made read-only) under ``full``, for :func:`recall`; the
    :data:`MEMO_SIZE` newest are kept, as :func:`memo`'s."""
    for a in out:
        if isinstance(a, np.ndarray):
            a.flags.writeable = False
    with _memo_lock:
        _memo[full] = out
        while len(_memo) > MEMO_SIZE:
            _memo.popitem(last=False)


def forget() -> None:
    """Drop everything :func:`memo` keeps (a run's sim mesh arrays and fast-marching patch:
    tens of MB on a 1M-face sim mesh), so a long-lived process (the Blender add-on, a batch)
    holds none of them between runs."""
    with _memo_lock:
        _memo.clear()


def shared_edges(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`edges`, computed once per face array (by content, :func:`memo`); read-only."""
    return memo("edges", lambda: edges(faces, n_vertices), faces, int(n_vertices))


def shared_shells(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Connected piece (shell) of each of ``n_vertices`` nodes over the faces' edges, (N,)
    int32, computed once per face array (:func:`memo`): the stress field (twice), the star
    check and the solver's mates ask."""
    def compute():
        from crackbake.nearest import components

        return (components(n_vertices, shared_edges(faces, n_vertices)[0]),)

    return memo("shells", compute, faces, int(n_vertices))[0]


def shared_centroids(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, float]:
    """Face centroids (M, 3) and the largest centroid-to-corner distance, computed once per
    mesh (:func:`memo`): the stress field and the star check snap on the same sim mesh."""

    def compute():
        tri = vertices[faces]
        centroid = corner_mean(tri)
        off = tri - centroid[:, None]
        return centroid, float(np.sqrt(np.einsum("eka,eka->ek", off, off)).max())

    return memo("centroids", compute, vertices, faces)


#: What :func:`mesh_derived` gives, in order (arrays; the centroids' reach is a float apart).
DERIVED_ARRAYS = ("edges", "edge_uses", "shells", "centroids")


def mesh_derived(vertices: np.ndarray, faces: np.ndarray) -> tuple[list[np.ndarray], float]:
    """A sim mesh's :data:`DERIVED_ARRAYS` and its centroids' reach, from (and into) the
    memo: what :func:`remember_derived` puts back for a sim mesh read from the cache.
    ``vertices`` (N, 3) float64, ``faces`` (M, 3) int64."""
    e, uses = shared_edges(faces, len(vertices))
    shells = shared_shells(faces, len(vertices))
    centroids, reach = shared_centroids(vertices, faces)
    return [e, uses, shells, centroids], reach


def remember_derived(vertices: np.ndarray, faces: np.ndarray, derived: list[np.ndarray],
                     reach: float) -> None:
    """Put :func:`mesh_derived`'s arrays of this mesh into the memo, as the calls that compute
    them would have: their first callers in a run (the stress field, the star check, the
    solver's set-up: 0.05 CPU-s of the README bake on 2 cores) then find them."""
    e, uses, shells, centroids = derived
    n = int(len(vertices))
    fk, vk = content_key(faces), content_key(vertices)
    remember(("edges", fk, n), (e, uses))
    remember(("shells", fk, n), (shells,))
    remember(("centroids", vk, fk), (centroids, float(reach)))


def boundary_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Per-vertex flag (V,) bool: the vertex lies on an edge used by exactly one face."""
    e, counts = edges(faces, n_vertices)
    flag = np.zeros(n_vertices, bool)
    flag[e[counts == 1].ravel()] = True
    return flag


def welded_vertex_normals(
    vertices: np.ndarray,
    faces: np.ndarray,
    cross: np.ndarray | None = None,
    source: tuple[np.ndarray, np.ndarray] | None = None,
    jit: bool = False,
) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3) accumulated over positions: vertices that share
    a position (UV-seam copies) get the same normal, so shading is smooth across UV seams.
    The asset mesh's normals when its file has none.

    ``cross``: the faces' :func:`face_cross` when the caller has it (welding moves no
    position, so it holds for the welded faces too).  ``source``: ``(positions, index)`` with
    ``vertices == positions[index]`` (an OBJ's ``v`` lines and each vertex's line): welding
    the fewer ``positions`` groups the vertices alike, so the sums, taken in face order,
    are the same bit for bit.  ``jit``: group the positions with a hash table and sum the
    corners in one numba pass (the same sums, in the same order; for large meshes, where
    numba's import costs less than the sort and the ``bincount`` passes)."""
    if jit:
        return _welded_vertex_normals_jit(vertices, faces, cross, source)
    if source is None:
        wv, wf, inverse = weld_by_position(vertices, faces)
        return vertex_normals(wv, wf, cross)[inverse]
    positions, index = source
    by_position = position_groups(positions)
    inverse = by_position[index]
    if cross is None:
        cross = face_cross(vertices, faces)
    return _summed_normals(int(by_position.max()) + 1, inverse[faces], cross)[inverse]


def _welded_vertex_normals_jit(vertices, faces, cross, source) -> np.ndarray:
    from crackbake.geometry_kernels import summed_normals
    from crackbake.grouping import exact_ids

    positions, index = source if source is not None else (vertices, None)
    # bits compared as position_groups compares them (-0.0 folded into 0.0)
    bits = np.ascontiguousarray(positions + 0.0, dtype=np.float64).view(np.uint64)
    groups, first = exact_ids(bits)
    if index is not None:
        groups = groups[index]
    if cross is None:
        cross = face_cross(vertices, faces)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    return unit_rows(summed_normals(len(first), groups, f, np.ascontiguousarray(cross)))[0][groups]
