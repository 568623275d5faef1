"""Child-process entry point running xatlas: ``python -m crackbake.bake.xatlas_worker [IN OUT]``.

xatlas can segfault (regular closed meshes, upstream jpcy/xatlas#146) or run for minutes, and
either would take the calling process with it; :func:`crackbake.bake.uv.unwrap` therefore runs this
module in a child process with a time limit.  It imports only numpy and xatlas so the child
starts fast.

The child dies with its parent: on Linux it asks the kernel for SIGKILL when the parent exits
(``prctl(PR_SET_PDEATHSIG)``) before importing anything slow, and exits at once when the parent
is already gone.  Without file arguments it reads the input ``.npz`` from stdin and writes the
output ``.npz`` to stdout, so an unwrap leaves no temporary files anywhere, however it ends.

Input arrays (``in.npz``): ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64, ``res`` and
``padding`` (0-d ints).

Output arrays (``out.npz``): ``vmapping`` (V',) int64 into the input vertices, ``indices``
(F, 3) int64 (same face order and corner order as the input), ``uv`` (V', 2) float64 texel
position / ``res`` on both axes (one square page, square texels), ``width`` and ``height`` (the
page xatlas packed into, texels), ``atlas_count``, ``chart_count``, ``utilization``,
``texels_per_unit`` (in the normalised frame, see :func:`normalised`), ``attempts`` (packing
runs) and ``tried`` (the (width, height, atlas_count) of every packing run at the search
resolution, (attempts, 3) int64).

Progress goes to stderr as ``progress: <text>`` lines (chart batches, packing tries), which
:func:`crackbake.bake.uv.unwrap.run_worker` relays to the UV stage's display as they come.
"""

from __future__ import annotations

import os
import sys

# Environment variable naming the parent's pid, set by crackbake.bake.uv.unwrap.run_worker.
PARENT_ENV = "CRACKBAKE_XATLAS_PARENT"


def die_with_parent() -> None:
    """SIGKILL this process when its parent exits (Linux); exit now if it already has
    (:func:`crackbake.child.die_with_parent` with :data:`PARENT_ENV`)."""
    from crackbake.child import die_with_parent as die

    die(PARENT_ENV)


if __name__ == "__main__":
    die_with_parent()

import io  # noqa: E402  (after die_with_parent: the slow imports below run already guarded)

import numpy as np  # noqa: E402
import xatlas  # noqa: E402

# Meshes up to this many faces unwrap in seconds as one xatlas mesh, and a flat one packs far
# better as one chart (0.68 of the page) than cut into a few (0.38).
LIMIT_ABOVE = 20000
# Larger meshes are cut into patches of at most PATCH_FACES faces (each a separate xatlas mesh,
# so xatlas grows their charts on all cores), and a patch bounds its charts' size.  Chart growing
# costs xatlas far more than linear time in a chart's size (a 100k-face scan: 13 CPU s in
# patches of 2k faces, 22 s in patches of 4k; a 20k-face blob: 19 s as 51 charts), while
# larger charts need less gutter per texel.  Capping the charts' area within larger patches
# instead (xatlas's max_chart_area) left ragged chart borders and many crumbs: 36 % of the
# page on a 270k-face scan, against 52 % now.  Patches go to xatlas BATCH_FACES faces at a
# time, one progress line per call.
PATCH_FACES = 4096
BATCH_FACES = 32768
# Charts of at most this many faces are crumbs (see attach_crumbs), given back in at most
# CRUMB_ROUNDS passes.
CRUMB_FACES = 5
CRUMB_ROUNDS = 4
# Majority-vote rounds smoothing the patch borders (see patches()).
SMOOTH_ROUNDS = 8
# Share of the page the first packing try aims to fill (the chart area over the page area).
# xatlas fits about 0.5-0.7 of the page with charts of real meshes; tries shrink the scale by SHRINK
# until everything fits one page, then bisect between the last miss and the fit.
TARGET_FILL = 0.7
TARGET_FILL_MANY = 0.55
MAX_ATTEMPTS = 14
SHRINK = 0.93
REFINE_STEPS = 4
SEARCH_RES = 1024
PROBES = 4
PROBE_STEP = 0.015


# The frame xatlas works in: the mesh centred, its bounding-box diagonal 1 and its median face at
# least this area.  xatlas takes float32 positions and counts a face whose area is below
# FLT_EPSILON (1.2e-7) as degenerate (zero UV area): a 15 cm scan of 270k faces in metres has 96 %
# of its faces there.  In this frame a face is that small only on a mesh of millions of faces,
# and the floor scales those up further (float32 keeps 7 digits, plenty at any size here).
MEDIAN_AREA_MIN = 1e-5


def normalised(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``vertices`` (V, 3) moved into the frame xatlas unwraps in (see :data:`MEDIAN_AREA_MIN`).

    A uniform scale and a translation: charts, and so UVs, are the same for a mesh at any size
    and place.  Returned as float64; an empty or single-point mesh is only centred.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if len(v) == 0:
        return v
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = v - 0.5 * (lo + hi)
    diagonal = float(np.linalg.norm(hi - lo))
    if not np.isfinite(diagonal) or diagonal <= 0.0:
        return v
    v = v / diagonal
    if len(faces):
        median = float(np.median(face_areas(v, faces)))
        if 0.0 < median < MEDIAN_AREA_MIN:
            v = v * np.sqrt(MEDIAN_AREA_MIN / median)
    return v


def _pack_options(res: int, padding: int, texels_per_unit: float):
    pack = xatlas.PackOptions()
    pack.resolution = int(res)
    pack.padding = int(padding)
    pack.bilinear = True
    # bruteForce ran for minutes on 20k faces at 4096 (measured); never use it.
    pack.bruteForce = False
    pack.blockAlign = False  # aligning charts to 4x4 blocks wastes page for no bake benefit
    pack.rotate_charts = True
    pack.texels_per_unit = float(texels_per_unit)
    return pack


def _chart_options():
    return xatlas.ChartOptions()


def _progress(message: str) -> None:
    """One progress line on stderr; the parent shows it as the UV stage's detail."""
    print(f"progress: {message}", file=sys.stderr, flush=True)


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area per face, (F,)."""
    c = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)


def patches(vertices: np.ndarray, faces: np.ndarray, limit: int = PATCH_FACES) -> list[np.ndarray]:
    """Face indices of spatial patches of about ``limit`` faces, cut along the longest axis.

    Recursive halving of the face centroids at their median: patches are compact blobs, so
    their borders (which become chart borders) are short.  A plane cuts a triangle mesh along
    a zigzag, and where the surface runs along the plane (a bump, a fold) into a scatter of
    single faces; each tooth and speck would become a chart of its own, or a hole in one, and
    cost a gutter.  So the borders are smoothed (:func:`smooth_labels`): a face joins the patch
    that two of its neighbours are in.  Deterministic; sorted face indices per patch.
    """
    centroids = vertices[faces].mean(axis=1)
    label = np.zeros(len(faces), dtype=np.int64)
    n_parts, todo = 0, [np.arange(len(faces))]
    while todo:
        idx = todo.pop()
        if len(idx) <= limit:
            label[idx] = n_parts
            n_parts += 1
            continue
        c = centroids[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = idx[np.argsort(c[:, axis], kind="stable")]
        half = len(order) // 2
        todo += [order[half:], order[:half]]
    if n_parts > 1:
        label = smooth_labels(label, face_neighbours(faces))
    order = np.argsort(label, kind="stable")
    cuts = np.flatnonzero(np.diff(label[order])) + 1
    return [part for part in np.split(order, cuts) if len(part)]


def face_neighbours(faces: np.ndarray) -> np.ndarray:
    """(F, 3) int64: the face across each edge (edge k runs from corner k to k + 1), -1 where the
    edge is a border or shared by more than two faces."""
    n = len(faces)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    key = edges[:, 0] * (int(faces.max(initial=0)) + 1) + edges[:, 1]
    order = np.argsort(key, kind="stable")
    k = key[order]
    pair = np.flatnonzero(k[1:] == k[:-1])
    # Only edges with exactly two faces: a third face on the same key is left unpaired.
    lone = np.ones(len(pair), dtype=bool)
    if len(pair) > 1:
        lone &= np.r_[True, pair[1:] != pair[:-1] + 1] & np.r_[pair[:-1] + 1 != pair[1:], True]
    a, b = order[pair[lone]], order[pair[lone] + 1]
    nb = np.full(3 * n, -1, dtype=np.int64)
    nb[a], nb[b] = b % n, a % n
    return nb.reshape(3, n).T.copy()


def smooth_labels(
    label: np.ndarray, neighbours: np.ndarray, rounds: int = SMOOTH_ROUNDS
) -> np.ndarray:
    """Patch labels (F,) after ``rounds`` of majority votes: a face two or three of whose
    ``neighbours`` (F, 3) share another label takes it.  Removes single-face teeth and specks
    along the cuts; a straight border is left as it is."""
    label = label.copy()
    for _ in range(rounds):
        near = np.where(neighbours >= 0, label[np.maximum(neighbours, 0)], -1)
        vote = np.where((near[:, 0] == near[:, 1]) | (near[:, 0] == near[:, 2]), near[:, 0],
                        near[:, 1])  # fmt: skip
        move = ((near == vote[:, None]).sum(axis=1) >= 2) & (vote >= 0) & (vote != label)
        if not move.any():
            break
        label[move] = vote[move]
    return label


def _chart_patches(vertices, faces, patch_faces):
    """Charts of every patch: (vertex index (C,), faces (F, 3) into it, uv (C, 2)) in the
    normalised frame's units, face order as ``faces``; xatlas's own packing is thrown away."""
    parts = patches(vertices, faces, patch_faces)
    batches, size = [], BATCH_FACES
    for part in parts:
        if size + len(part) > BATCH_FACES:
            batches.append([])
            size = 0
        batches[-1].append(part)
        size += len(part)
    # xatlas packs each batch too; packing it coarsely costs next to nothing.
    tpu = 256.0 / np.sqrt(max(face_areas(vertices, faces).sum() / len(batches), 1e-30))
    vmap, uv, out_faces = [], [], np.empty_like(faces)
    n_uv, done, shift = 0, 0, 0.0
    for b, batch in enumerate(batches):
        atlas = xatlas.Atlas()
        locals_ = []
        for face_idx in batch:
            used, local = np.unique(faces[face_idx], return_inverse=True)
            locals_.append((face_idx, used))
            atlas.add_mesh(vertices[used].astype(np.float32),
                           local.reshape(-1, 3).astype(np.uint32))  # fmt: skip
        atlas.generate(_chart_options(), _pack_options(0, 0, tpu))
        for m, (face_idx, used) in enumerate(locals_):
            vm, ix, uvm = atlas[m]
            vmap.append(used[vm.astype(np.int64)])
            # Batches are packed on their own pages: moved apart so no two charts share UVs.
            uv.append(uvm.astype(np.float64) * np.array([atlas.width, atlas.height]) / tpu
                      + np.array([shift, 0.0]))  # fmt: skip
            out_faces[face_idx] = ix.astype(np.int64) + n_uv
            n_uv += len(vm)
        shift += (atlas.width + 16) / tpu
        done += sum(len(f) for f in batch)
        _progress(f"charts {done * 100 // len(faces)}% ({b + 1}/{len(batches)} batches)")
    return np.concatenate(vmap), out_faces, np.concatenate(uv)


def _charts_of(indices: np.ndarray, n_uv: int) -> np.ndarray:
    """Chart (connected UV island) of every face, (F,) int64: faces sharing a UV vertex."""
    from scipy.sparse import coo_matrix  # only here: the worker starts without scipy
    from scipy.sparse.csgraph import connected_components

    n = len(indices)
    # Face-vertex incidence; faces linked through a shared vertex are one island.
    rows = np.repeat(np.arange(n), 3)
    inc = coo_matrix((np.ones(3 * n), (rows, indices.ravel())), shape=(n, n_uv)).tocsr()
    _, label = connected_components(inc @ inc.T, directed=False)
    return label.astype(np.int64)


def _corner_angles(t: np.ndarray) -> np.ndarray:
    """Interior angles (F, 3) of UV triangles ``t`` (F, 3, 2) at their three corners."""
    out = np.empty(t.shape[:2])
    for k in range(3):
        a, b = t[:, (k + 1) % 3] - t[:, k], t[:, (k + 2) % 3] - t[:, k]
        cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        out[:, k] = np.abs(np.arctan2(cross, np.einsum("ij,ij->i", a, b)))
    return out


def attach_crumbs(
    vmap: np.ndarray, indices: np.ndarray, uv: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Give xatlas's crumbs (charts of at most :data:`CRUMB_FACES` faces) back to a neighbour.

    xatlas leaves single faces out of the charts it grows (holes and notches along their
    borders) and makes each a chart of its own; every such crumb costs a whole gutter ring in
    the page (on a 270k-face scan a thousand crumbs, 0.6 % of the faces, cost 7 % of the page).
    A crumb face two or three of whose edges border one large chart has all three corners in
    that chart already: it takes those corners' UVs, which fills the hole or notch exactly.  It
    is kept only when it keeps the chart's orientation and no corner's angles then sum past a
    full turn (so it overlaps no face around its corners).

    ``vmap`` (V',) welded vertex of each UV vertex, ``indices`` (F, 3) into ``uv`` (V', 2),
    ``faces`` (F, 3) the welded faces (same order).  Returns the three arrays with the attached
    faces re-indexed and unused UV vertices dropped.
    """
    indices = indices.copy()
    neighbours = face_neighbours(faces)
    n_vertices = int(vmap.max(initial=-1)) + 1
    for _ in range(CRUMB_ROUNDS):
        chart = _charts_of(indices, len(uv))
        size = np.bincount(chart)
        crumb = size[chart] <= CRUMB_FACES
        if not crumb.any():
            break
        near = np.where(neighbours >= 0, chart[np.maximum(neighbours, 0)], -1)
        vote = np.where((near[:, 0] == near[:, 1]) | (near[:, 0] == near[:, 2]), near[:, 0],
                        near[:, 1])  # fmt: skip
        cand = np.flatnonzero(crumb & (vote >= 0) & ((near == vote[:, None]).sum(axis=1) >= 2))
        cand = cand[size[vote[cand]] > CRUMB_FACES]
        if not len(cand):
            break
        # The UV vertex of (chart, welded vertex), for the large charts' vertices.
        big = np.zeros(len(uv), dtype=bool)
        big[indices[~crumb].ravel()] = True
        owner = np.full(len(uv), -1, dtype=np.int64)
        owner[indices.ravel()] = np.repeat(chart, 3)
        ids = np.flatnonzero(big)
        keys = owner[ids] * n_vertices + vmap[ids]
        order = np.argsort(keys, kind="stable")
        keys, ids = keys[order], ids[order]
        want = vote[cand][:, None] * n_vertices + faces[cand]
        pos = np.minimum(np.searchsorted(keys, want), len(keys) - 1)
        found = (keys[pos] == want).all(axis=1)
        cand, corners = cand[found], ids[pos[found]]
        # Orientation of each large chart (xatlas mirrors some charts): sign of its UV area.
        t = uv[indices]
        signed = (t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (
            t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0])  # fmt: skip
        chart_sign = np.sign(np.bincount(chart, signed, minlength=len(size)))
        tc = uv[corners]
        s_new = (tc[:, 1, 0] - tc[:, 0, 0]) * (tc[:, 2, 1] - tc[:, 0, 1]) - (
            tc[:, 1, 1] - tc[:, 0, 1]) * (tc[:, 2, 0] - tc[:, 0, 0])  # fmt: skip
        scale = np.median(np.abs(signed)) if len(signed) else 1.0
        ok = (s_new * chart_sign[vote[cand]] > 1e-9 * scale)
        cand, corners = cand[ok], corners[ok]
        # Angle sums around the corners with every candidate in: a corner past a full turn
        # drops the candidates at it.
        trial = indices.copy()
        trial[cand] = corners
        keep = ~crumb
        keep[cand] = True
        ang = _corner_angles(uv[trial[keep]])
        total = np.bincount(trial[keep].ravel(), ang.ravel(), minlength=len(uv))
        full = total > 2.0 * np.pi * (1.0 + 1e-6)
        ok = ~full[corners].any(axis=1)
        if not ok.any():
            break
        indices[cand[ok]] = corners[ok]
    used, inverse = np.unique(indices, return_inverse=True)
    return vmap[used], inverse.reshape(-1, 3).astype(np.int64), uv[used]


def _pack(uv_units, indices, res, padding, scale):
    """Pack the charts (UV islands of ``uv_units``) at ``scale`` texels per unit."""
    atlas = xatlas.Atlas()
    atlas.add_uv_mesh((uv_units * scale).astype(np.float32), indices.astype(np.uint32))
    atlas.generate(xatlas.ChartOptions(), _pack_options(res, padding, 1.0))
    return atlas


def fit_one_page(
    vertices: np.ndarray, faces: np.ndarray, res: int, padding: int
) -> dict[str, np.ndarray]:
    """Unwrap and pack into one ``res`` x ``res`` page with square texels, as large as fits.

    The mesh is unwrapped in a normalised frame (:func:`normalised`), cut into patches whose
    charts xatlas computes (the slow part) once; the charts are then *repacked* only (UV
    islands, no chart computation), first at the scale where their area fills
    :data:`TARGET_FILL` of the page, shrinking by :data:`SHRINK` until everything fits one
    page, then bisecting towards the largest scale that fits.
    """
    faces = np.asarray(faces, dtype=np.int64)
    v = normalised(vertices, faces)
    limited = len(faces) > LIMIT_ABOVE
    _progress(f"charts of {len(faces)} faces")
    vmap, ix, uv_units = _chart_patches(v, faces, PATCH_FACES if limited else len(faces))
    vmap, ix, uv_units = attach_crumbs(vmap, ix, uv_units, faces)
    n_charts = 0
    chart_area = max(float(face_areas(np.pad(uv_units, ((0, 0), (0, 1))), ix).sum()), 1e-30)

    tried: list[tuple[int, int, int]] = []
    best, miss = None, None
    # Many charts (a capped mesh) fill less of the page: start lower.
    scale = res * np.sqrt((TARGET_FILL_MANY if limited else TARGET_FILL) / chart_area)

    # Packing costs xatlas time in proportion to the page's texels, so the search packs at
    # most SEARCH_RES texels wide, with the gutter rounded up, and the layout found is scaled
    # up: xatlas rasterises charts conservatively, so at the full size every chart stays inside
    # its footprint and the gutters are at least `padding` wide.
    search = min(res, SEARCH_RES)
    up = res / search
    pad_search = int(np.ceil(padding / up))

    def attempt(scale):
        packed = _pack(uv_units, ix, search, pad_search, scale / up)
        w, h, pages = int(packed.width), int(packed.height), int(packed.atlas_count)
        tried.append((w, h, pages))
        _progress(f"packing {res}px, try {len(tried)}")
        if pages == 1 and max(w, h) <= search:
            vm2, ix2, uv2 = packed[0]
            fit = (vmap[vm2.astype(np.int64)], ix2.astype(np.int64),
                   uv2.astype(np.float64) * np.array([w, h]) * up,
                   round(w * up), round(h * up), int(packed.chart_count))  # fmt: skip
            return fit
        return None

    # Shrink until everything fits one page; when the first try fits, grow until it does not.
    first = attempt(scale)
    if first is None:
        miss = scale
        while len(tried) < 2 * MAX_ATTEMPTS and best is None:
            # Past MAX_ATTEMPTS the page is far too small for the first guess (a tiny --res
            # with many charts, whose gutters dominate): halve the scale instead.
            scale *= SHRINK if len(tried) < MAX_ATTEMPTS else 0.5
            fit = attempt(scale)
            best = None if fit is None else (scale, fit)
    else:
        best = (scale, first)
        while len(tried) < MAX_ATTEMPTS and miss is None:
            scale /= SHRINK
            fit = attempt(scale)
            if fit is None:
                miss = scale
            else:
                best = (scale, fit)
    if best is None:
        raise RuntimeError(
            f"could not fit the charts into one {res}x{res} page after {len(tried)} tries "
            f"(last: {tried[-1][0]}x{tried[-1][1]}, {tried[-1][2]} pages)"
        )
    if miss is not None:
        lo, hi = best[0], miss
        for _ in range(REFINE_STEPS):
            mid = np.sqrt(lo * hi)
            fit = attempt(mid)
            if fit is None:
                hi = mid
            else:
                lo, best = mid, (mid, fit)
    # Whether charts fit is not monotonic in the scale (xatlas places them greedily), so a few
    # scales just above the bracket often fit too.
    top = best[0]
    for k in range(1, PROBES + 1):
        fit = attempt(top * (1.0 + PROBE_STEP * k))
        if fit is not None:
            best = (top * (1.0 + PROBE_STEP * k), fit)
    scale, (vmapping, indices, texels, width, height, n_charts) = best
    # Texel positions / res on both axes keep texels square.  The y axis is kept as is (no
    # flip): xatlas's texel y counts rows from 0 like GL's framebuffer rows (row 0 = v 0,
    # bottom) and its charts come in both orientations anyway, so reading y as v-up (OBJ) is as
    # valid as any and keeps chart texel alignment.
    uv = texels / res
    return {
        "vmapping": vmapping,
        "indices": indices,
        "uv": np.clip(uv, 0.0, 1.0),
        "width": np.int64(width),
        "height": np.int64(height),
        "atlas_count": np.int64(1),
        "chart_count": np.int64(n_charts),
        "utilization": np.float64(_utilization(uv, indices)),
        "texels_per_unit": np.float64(scale),
        "attempts": np.int64(len(tried)),
        "tried": np.asarray(tried, dtype=np.int64),
    }


def _utilization(uv: np.ndarray, faces: np.ndarray) -> float:
    """Fraction of the page covered by charts (sum of UV triangle areas)."""
    c = uv[faces]
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    return float(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (0, 2):
        print("usage: python -m crackbake.bake.xatlas_worker [in.npz out.npz]", file=sys.stderr)
        return 2
    if args:
        source, sink = open(args[0], "rb"), open(args[1], "wb")
    else:
        # stdout carries the result: anything else printing there (a library) goes to stderr.
        sink = os.fdopen(os.dup(1), "wb")
        os.dup2(2, 1)
        source = io.BytesIO(sys.stdin.buffer.read())  # np.load needs a seekable file
    with source, np.load(source, allow_pickle=False) as data:
        vertices = np.ascontiguousarray(data["vertices"], dtype=np.float64)
        faces = np.ascontiguousarray(data["faces"], dtype=np.int64)
        res = int(data["res"])
        padding = int(data["padding"])
    result = fit_one_page(vertices, faces, res, padding)
    with sink:
        np.savez(sink, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
