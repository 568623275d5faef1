"""The simulation mesh: a conforming refinement inside each asset triangle.

The crack solver must not see the asset's triangulation (long thin game-asset triangles, or
millions of scan faces), so it runs on a mesh of well-shaped, slightly irregular triangles at a
target edge length (DESIGN.md §2).  It is built per asset face:

* asset edges are split into nearly equal pieces, about one target length each for big faces
  and fewer where the asset faces are small, so the point density (and face count) does not
  depend on how finely the asset is triangulated; the points are computed once per (welded)
  edge, so both faces of an edge share them exactly and the result is welded across UV seams;
* interior points come from a triangular lattice with a random orientation and offset per face,
  clipped to the face shrunk by a margin and jittered, so no global direction is preferred;
* each face is triangulated on its own plane by a constrained Delaunay triangulation with a
  20 degree quality bound (Shewchuk's Triangle) that may add interior points but never points on
  the face's edges (which would break the sharing).  All faces go to Triangle in one call, laid
  out side by side in 2-D, because one call per face costs ~100 us of overhead each;
* faces that get no point (asset already finer than the target) are kept as they are.

Every sim triangle lies inside exactly one asset triangle, so every sim node maps exactly to
(asset face, barycentric) and every sim triangle maps affinely into the asset's UV space.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.io.mesh import Mesh, weld_by_position

#: Refuse sim meshes estimated above this many faces (memory and solver time explode).
MAX_SIM_FACES = 20_000_000

# Area of an equilateral triangle of unit side: a triangular lattice of spacing h holds
# two such triangles (scaled by h^2) per point.
_EQUILATERAL = np.sqrt(3.0) / 4.0
# With the per-face point budget below, face counts land within ~1% of the request on spot,
# plates and tori of any resolution coarser than the target, so no correction is applied.

# Interior lattice points keep this distance (in target lengths) from the face's edges, so the
# triangles between an edge and the first lattice row are not slivers.  At sqrt(3)/4 the band
# it empties on both sides of an edge holds, on average, as many lattice points as the edge
# gets (one per target length), so the point density is the same near edges as inside.
_MARGIN = np.sqrt(3.0) / 4.0
_DENSITY = 2.0 / np.sqrt(3.0)  # lattice points per unit area, in target lengths
_ROW = np.sqrt(3.0) / 2.0  # lattice row spacing, target lengths


@dataclass(frozen=True, eq=False)
class SimMesh:
    """Simulation mesh with an exact map back to the asset mesh.

    Attributes
    ----------
    vertices : (N, 3) float64
        Welded node positions, mesh units.
    faces : (M, 3) int64
        Triangles indexing ``vertices``, oriented like the asset face each lies in.
    asset_face : (M,) int64
        Index into ``Mesh.faces`` (the asset/output mesh) of the face holding each sim face.
    node_face : (N,) int64
        One asset face holding each node.
    node_bary : (N, 3) float64
        Barycentric coordinates of each node in ``node_face``;
        ``(node_bary[:, :, None] * mesh.vertices[mesh.faces[node_face]]).sum(1) == vertices``
        up to rounding.
    boundary : (N,) bool
        Node lies on an open boundary of the welded asset surface.
    edge_length : float
        Target edge length used, mesh units.
    """

    vertices: np.ndarray
    faces: np.ndarray
    asset_face: np.ndarray
    node_face: np.ndarray
    node_bary: np.ndarray
    boundary: np.ndarray
    edge_length: float


def _total_area(mesh: Mesh) -> float:
    tri = mesh.vertices[mesh.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return 0.5 * float(np.linalg.norm(cross, axis=1).sum())


def target_edge_length(mesh: Mesh, target_faces: int = 100_000) -> float:
    """Edge length giving about ``target_faces`` near-equilateral sim faces over the surface.

    Parameters
    ----------
    mesh : Mesh
        Asset mesh.
    target_faces : int
        Wanted number of simulation faces (at least 100).

    Returns
    -------
    float
        Target edge length, mesh units.
    """
    if target_faces < 100:
        raise CrackbakeError(
            f"--sim-faces {target_faces} is too small for a crack simulation; use at least 100"
        )
    area = _total_area(mesh)
    if not area > 0:
        raise CrackbakeError("the mesh has zero surface area; crackbake needs a surface")
    return float(np.sqrt(area / (_EQUILATERAL * target_faces)))


def asset_barycentric(mesh: Mesh, asset_faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points in given asset faces.

    Points off the face's plane are projected onto it first; points outside the triangle get
    coordinates outside [0, 1] (no clamping).

    Parameters
    ----------
    mesh : Mesh
        Asset mesh.
    asset_faces : (K,) int64
        Index into ``mesh.faces`` for each point.
    points : (K, 3) float64
        Positions, mesh units.

    Returns
    -------
    (K, 3) float64
        Barycentric coordinates summing to 1.
    """
    tri = mesh.vertices[mesh.faces[np.asarray(asset_faces, dtype=np.int64)]]
    return _barycentric(tri, np.asarray(points, dtype=np.float64))


def _barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    # Least-squares solve in the plane of (a, b, c): works for 3-D and 2-D alike.
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


def _face_frames_2d(tri: np.ndarray, h: float) -> np.ndarray:
    """Corners of each face in its own plane, in target lengths: (R, 3, 2), counter-clockwise.

    Corner 0 at the origin, corner 1 on the +x axis, corner 2 above it.
    """
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    len1 = np.linalg.norm(e1, axis=1)
    u = e1 / len1[:, None]
    cx = np.einsum("ij,ij->i", e2, u)
    perp = e2 - cx[:, None] * u
    cy = np.linalg.norm(perp, axis=1)
    out = np.zeros((len(tri), 3, 2))
    out[:, 1, 0] = len1 / h
    out[:, 2, 0] = cx / h
    out[:, 2, 1] = cy / h
    return out


def _lattice_points(
    corners: np.ndarray, rng: np.random.Generator, jitter: float
) -> tuple[np.ndarray, np.ndarray]:
    """Jittered triangular-lattice points inside each face, at least ``_MARGIN`` from its edges.

    Parameters
    ----------
    corners : (R, 3, 2) float64
        Face corners in target lengths (:func:`_face_frames_2d`).

    Returns
    -------
    owner : (P,) int64
        Row of ``corners`` each point lies in.
    xy : (P, 2) float64
        Point positions in that face's 2-D frame, target lengths.
    """
    n_faces = len(corners)
    # Shrink each face by the margin: the inset triangle is the face scaled about its incentre
    # by (r - m) / r, r the inradius.
    a = np.linalg.norm(corners[:, 2] - corners[:, 1], axis=1)
    b = np.linalg.norm(corners[:, 0] - corners[:, 2], axis=1)
    c = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    perim = a + b + c
    incentre = (a[:, None] * corners[:, 0] + b[:, None] * corners[:, 1]
                + c[:, None] * corners[:, 2]) / perim[:, None]
    twice_area = corners[:, 1, 0] * corners[:, 2, 1]  # corner 0 at origin, 1 on the x axis
    inradius = twice_area / perim
    scale = np.clip(1.0 - _MARGIN / np.maximum(inradius, 1e-300), 0.0, None)
    inset = incentre[:, None] + (corners - incentre[:, None]) * scale[:, None, None]

    # Random lattice orientation and offset per face: no preferred direction on the surface.
    theta = rng.uniform(0.0, np.pi / 3.0, n_faces)
    offset = rng.uniform(0.0, 1.0, (n_faces, 2)) * [1.0, 2.0 * _ROW]
    cos, sin = np.cos(theta), np.sin(theta)
    # Rotate the inset face by -theta so the lattice rows are horizontal.
    qx = cos[:, None] * inset[..., 0] + sin[:, None] * inset[..., 1]
    qy = -sin[:, None] * inset[..., 0] + cos[:, None] * inset[..., 1]

    has = scale > 0
    k_lo = np.ceil((qy.min(axis=1) - offset[:, 1]) / _ROW).astype(np.int64)
    k_hi = np.floor((qy.max(axis=1) - offset[:, 1]) / _ROW).astype(np.int64)
    n_rows = np.where(has, np.maximum(k_hi - k_lo + 1, 0), 0)
    row_face = np.repeat(np.arange(n_faces), n_rows)
    row_start = np.cumsum(n_rows) - n_rows
    k = k_lo[row_face] + np.arange(len(row_face)) - row_start[row_face]
    y = offset[row_face, 1] + k * _ROW

    # x-interval of the (convex) inset triangle on the scanline y.
    lo = np.full(len(y), np.inf)
    hi = np.full(len(y), -np.inf)
    for i in range(3):
        j = (i + 1) % 3
        x0, y0 = qx[row_face, i], qy[row_face, i]
        x1, y1 = qx[row_face, j], qy[row_face, j]
        dy = y1 - y0
        hit = ((y - y0) * (y - y1) <= 0) & (dy != 0)
        x = x0 + (y - y0) * (x1 - x0) / np.where(dy != 0, dy, 1.0)
        lo = np.where(hit, np.minimum(lo, x), lo)
        hi = np.where(hit, np.maximum(hi, x), hi)
    shift = offset[row_face, 0] + 0.5 * (k & 1)
    ok = np.isfinite(lo)
    i_lo = np.where(ok, np.ceil(lo - shift), 0).astype(np.int64)
    i_hi = np.where(ok, np.floor(hi - shift), -1).astype(np.int64)
    n_pts = np.maximum(i_hi - i_lo + 1, 0)
    pt_row = np.repeat(np.arange(len(y)), n_pts)
    pt_start = np.cumsum(n_pts) - n_pts
    px = shift[pt_row] + i_lo[pt_row] + np.arange(len(pt_row)) - pt_start[pt_row]
    py = y[pt_row]
    owner = row_face[pt_row]

    # Jitter inside a disc of radius `jitter` (< margin, so points stay inside the face).
    r = jitter * np.sqrt(rng.uniform(0.0, 1.0, len(px)))
    phi = rng.uniform(0.0, 2.0 * np.pi, len(px))
    px = px + r * np.cos(phi)
    py = py + r * np.sin(phi)
    cs, sn = cos[owner], sin[owner]
    xy = np.stack([cs * px - sn * py, sn * px + cs * py], axis=1)
    return owner, xy


def _layout(corners: np.ndarray, gap: float = 1.0):
    """Place the 2-D faces side by side in shelves so one Triangle call meshes them all.

    Returns the per-face translation (R, 2) and a function mapping 2-D points back to the
    face whose bounding box holds them.
    """
    xmin = corners[..., 0].min(axis=1)
    width = corners[..., 0].max(axis=1) - xmin
    height = corners[:, 2, 1]
    row_width = max(float(width.max()) + gap,
                    float(np.sqrt(((width + gap) * (height + gap)).sum())))
    step = width + gap
    before = np.cumsum(step) - step
    row = np.floor(before / row_width).astype(np.int64)
    first = np.searchsorted(row, row)  # index of the first face in each face's row
    x0 = before - before[first]
    n_rows = int(row[-1]) + 1
    row_height = np.zeros(n_rows)
    np.maximum.at(row_height, row, height + gap)
    row_y0 = np.cumsum(row_height) - row_height
    translate = np.stack([x0 - xmin, row_y0[row]], axis=1)
    stride = row_width + float(width.max()) + 4.0 * gap
    face_key = row * stride + x0

    def locate(points: np.ndarray) -> np.ndarray:
        prow = np.searchsorted(row_y0, points[:, 1], side="right") - 1
        return np.searchsorted(face_key, prow * stride + points[:, 0], side="right") - 1

    return translate, locate


def _boundary_polygons(
    faces: np.ndarray,
    face_edge: np.ndarray,
    forward: np.ndarray,
    corners: np.ndarray,
    pt_edge: np.ndarray,
    t_edge: np.ndarray,
    pt_id: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Boundary polygons (corners and shared edge points, in face order) of a set of faces.

    ``faces``, ``face_edge``, ``forward`` and ``corners`` are rows for the faces to mesh;
    ``pt_edge`` / ``t_edge`` are all edge points sorted by (edge, t) and ``pt_id`` their node
    ids.  Returns, per polygon vertex, its face (row), node id and 2-D position, and the
    closed-loop segments.
    """
    n_faces = len(faces)
    n_mid = np.bincount(pt_edge, minlength=int(face_edge.max()) + 1)
    e_start = np.cumsum(n_mid) - n_mid
    side_edge = face_edge.ravel()  # (3R,) face-major
    side_fwd = forward.ravel()
    side_mid = n_mid[side_edge]
    side_len = 1 + side_mid
    n_b = int(side_len.sum())
    b_side = np.repeat(np.arange(3 * n_faces), side_len)
    b_k = np.arange(n_b) - (np.cumsum(side_len) - side_len)[b_side]
    b_face = b_side // 3
    b_s = b_side % 3
    on_edge = b_k > 0
    fwd = side_fwd[b_side]
    j = np.where(fwd, b_k - 1, side_mid[b_side] - b_k)
    pidx = np.where(on_edge, e_start[side_edge[b_side]] + j, 0)
    b_gid = np.where(on_edge, pt_id[pidx] if len(pt_id) else 0, faces[b_face, b_s])
    t_glob = t_edge[pidx] if len(t_edge) else np.zeros(n_b)
    t_side = np.where(on_edge, np.where(fwd, t_glob, 1.0 - t_glob), 0.0)
    c0 = corners[b_face, b_s]
    c1 = corners[b_face, (b_s + 1) % 3]
    b_xy = c0 + t_side[:, None] * (c1 - c0)
    face_len = side_len.reshape(n_faces, 3).sum(axis=1)
    face_start = np.cumsum(face_len) - face_len
    nxt = np.arange(1, n_b + 1)
    nxt[face_start + face_len - 1] = face_start
    segments = np.stack([np.arange(n_b), nxt], axis=1)
    return b_face, b_gid, b_xy, segments


def _triangulate(corners, b_face, b_xy, segments, l_face, l_xy, quality_on_edges: bool):
    """One Triangle call meshing every given face, laid out side by side in 2-D.

    Returns output 2-D points (input points first, in order), triangles, the face (row of
    ``corners``) of each triangle and the layout translation, plus the output segments.
    """
    import triangle

    translate, locate = _layout(corners)
    pts = np.concatenate([b_xy + translate[b_face], l_xy + translate[l_face]])
    # p: PSLG (the gaps between faces are eaten as concavities); q20: 20 degree quality;
    # YY: no Steiner points on segments, which are shared with the neighbour face (a single Y
    # crashed Triangle 1.6 on some inputs; every segment here is a boundary, so they mean the
    # same); S: cap on
    # added points, a guard against runaway refinement; Q: quiet.
    opts = f"pQq20S{max(len(pts), 1000)}" + ("" if quality_on_edges else "YY")
    out = triangle.triangulate({"vertices": pts, "segments": segments}, opts)
    out_xy = np.asarray(out["vertices"], dtype=np.float64)
    out_tri = np.asarray(out["triangles"], dtype=np.int64).reshape(-1, 3)
    tri_face = locate(out_xy[out_tri].mean(axis=1))
    return out_xy, out_tri, tri_face, translate, locate, np.asarray(out["segments"])


def _min_angle_2d(p: np.ndarray) -> np.ndarray:
    """Smallest angle (degrees) of 2-D triangles (K, 3, 2)."""
    e = p[:, [1, 2, 0]] - p  # e[:, i] runs from corner i to corner i+1
    length = np.linalg.norm(e, axis=2)
    # Angle at corner i+1 between -e[i] and e[i+1].
    cos = -np.einsum("kij,kij->ki", e, e[:, [1, 2, 0]]) / np.maximum(
        length * length[:, [1, 2, 0]], 1e-300)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).min(axis=1)


def build_simmesh(
    mesh: Mesh,
    detail: float | None = None,
    target_faces: int | None = 100_000,
    seed: int = 0,
    jitter: float = 0.15,
) -> SimMesh:
    """Build the simulation mesh: a conforming, welded refinement inside each asset face.

    Parameters
    ----------
    mesh : Mesh
        Asset mesh (UV seams are welded away here).
    detail : float, optional
        Target edge length, mesh units (``--detail``).  Takes precedence over ``target_faces``.
    target_faces : int, optional
        Wanted number of sim faces over the whole surface (``--sim-faces``), used when
        ``detail`` is None; None means the default 100,000.
    seed : int
        Seed for the lattice orientation and jitter; same seed, same mesh.
    jitter : float
        Random displacement of interior points, as a fraction of the edge length (0 to 0.45);
        edge points move half as much, along their edge.

    Returns
    -------
    SimMesh

    Raises
    ------
    CrackbakeError
        ``detail`` <= 0, ``target_faces`` < 100, an estimated sim mesh above 20M faces, a bad
        jitter, or a mesh without area.
    """
    if detail is not None:
        if not np.isfinite(detail) or detail <= 0:
            raise CrackbakeError(
                f"--detail {detail} must be a positive edge length in mesh units; "
                f"try about {mesh.diagonal / 300:.4g} for this mesh"
            )
        h = float(detail)
    else:
        h = target_edge_length(mesh, 100_000 if target_faces is None else int(target_faces))
    if not 0.0 <= jitter <= 0.45:
        raise CrackbakeError(f"jitter {jitter} is out of range; use a value from 0 to 0.45")
    area = _total_area(mesh)
    if not area > 0:
        raise CrackbakeError("the mesh has zero surface area; crackbake needs a surface")
    estimate = area / (_EQUILATERAL * h * h)
    if estimate > MAX_SIM_FACES:
        suggest = np.sqrt(area / (_EQUILATERAL * MAX_SIM_FACES))
        raise CrackbakeError(
            f"the simulation mesh would have about {estimate:,.0f} faces (limit "
            f"{MAX_SIM_FACES:,}); use --detail {suggest:.4g} or larger, or fewer --sim-faces"
        )
    rng = np.random.default_rng(seed)

    wv, wf_all, _ = weld_by_position(mesh.vertices, mesh.faces)
    n_v = len(wv)
    tri_all = wv[wf_all]
    edge_len_all = np.linalg.norm(tri_all[:, [1, 2, 0]] - tri_all, axis=2)
    cross = np.cross(tri_all[:, 1] - tri_all[:, 0], tri_all[:, 2] - tri_all[:, 0])
    twice_area = np.linalg.norm(cross, axis=1)
    # Zero-area faces carry no material and would give Triangle a collinear boundary: drop them.
    keep = np.flatnonzero(twice_area > 1e-12 * edge_len_all.max(axis=1) ** 2)
    wf = wf_all[keep]
    n_f = len(wf)
    corners3 = wv[wf]

    # Welded edges: (lo, hi) vertex pairs, shared by every face using them.
    b_idx = wf[:, [1, 2, 0]]
    lo = np.minimum(wf, b_idx)
    hi = np.maximum(wf, b_idx)
    uniq, face_edge = np.unique((lo * n_v + hi).ravel(), return_inverse=True)
    face_edge = face_edge.reshape(n_f, 3)
    forward = wf == lo  # the face's side runs lo -> hi
    ev0, ev1 = uniq // n_v, uniq % n_v
    n_e = len(uniq)
    e_len = np.linalg.norm(wv[ev1] - wv[ev0], axis=1)
    face_count = np.bincount(face_edge.ravel(), minlength=n_e)
    corners = _face_frames_2d(corners3, h)

    # How many points each edge gets.  Each face should end up with the lattice's point density;
    # what its inset lattice does not supply (all of it for small faces) goes on its edges, in
    # proportion to their lengths, and an edge takes the mean of its faces' requests.  For big
    # faces this is about one point per target length; for faces of a few target lengths it is
    # fewer, so dense asset meshes do not get denser sim meshes (edge points alone would).
    side_len = np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2)
    perim = side_len.sum(axis=1)
    f_area = 0.5 * corners[:, 1, 0] * corners[:, 2, 1]
    inset = f_area * np.clip(1.0 - _MARGIN * perim / (2.0 * f_area), 0.0, None) ** 2
    budget = np.clip(_DENSITY * (f_area - inset) - 0.5, 0.0, None)  # 0.5: corner share
    request = 2.0 * budget[:, None] * side_len / perim[:, None]
    want = np.bincount(face_edge.ravel(), request.ravel(), minlength=n_e) / face_count
    # Stochastic rounding keeps the expected count right whatever the asset's edge lengths;
    # below half a point an edge stays whole, so an asset finer than the target is kept as is.
    n_mid = np.where(want < 0.5, 0, np.floor(want + rng.uniform(0.0, 1.0, n_e))).astype(np.int64)
    n_seg = n_mid + 1

    # Edge points, by parameter t along lo -> hi, lightly jittered along the edge.
    pt_edge = np.repeat(np.arange(n_e), n_mid)
    pt_k = np.arange(len(pt_edge)) - (np.cumsum(n_mid) - n_mid)[pt_edge] + 1
    t_edge = (pt_k + 0.5 * jitter * rng.uniform(-1.0, 1.0, len(pt_edge))) / n_seg[pt_edge]

    # Interior points of every face (none where the inradius is below the margin).
    l_face, l_xy = _lattice_points(corners, rng, jitter)
    has_lattice = np.bincount(l_face, minlength=n_f) > 0
    asset_min_angle = _min_angle_2d(corners)

    n_lat = len(l_face)
    l_bary = _barycentric(corners[l_face], l_xy)

    # Node ids while meshing: asset vertices, then lattice points, then edge points (append
    # only, so ids stay valid when points are added); Triangle's own interior points get
    # negative ids -1 - k until the end.
    e_base = n_v + n_lat
    st_face: list[np.ndarray] = []  # Triangle's interior points: face and barycentrics
    st_bary: list[np.ndarray] = []
    n_st = 0
    tri_ids = np.zeros((0, 3), dtype=np.int64)  # sim triangles of refined faces
    tri_owner = np.zeros(0, dtype=np.int64)

    # Triangulate every face that gets points.  Where the no-points-on-edges rule keeps
    # Triangle from reaching 20 degrees, let it split those faces' edges freely, adopt the new
    # edge points for both faces of the edge, and mesh again just the faces that changed.
    has_pts = np.zeros(n_e, dtype=bool)
    has_pts[pt_edge] = True
    todo = np.flatnonzero(has_pts[face_edge].any(axis=1) | has_lattice)
    refined = np.zeros(n_f, dtype=bool)
    for attempt in range(8):
        if not len(todo):
            break
        refined[todo] = True
        order = np.lexsort((t_edge, pt_edge))
        s_edge, s_t, s_id = pt_edge[order], t_edge[order], e_base + order
        in_todo = np.full(n_f, -1)
        in_todo[todo] = np.arange(len(todo))
        l_sel = np.flatnonzero(in_todo[l_face] >= 0)
        b_face, b_gid, b_xy, segments = _boundary_polygons(
            wf[todo], face_edge[todo], forward[todo], corners[todo], s_edge, s_t, s_id)
        out_xy, out_tri, tri_face, translate, _, _ = _triangulate(
            corners[todo], b_face, b_xy, segments, in_todo[l_face[l_sel]], l_xy[l_sel], False)
        n_in = len(b_xy) + len(l_sel)
        n_new = len(out_xy) - n_in
        new_face = np.zeros(n_new, dtype=np.int64)  # rows of todo
        if n_new:
            flat = out_tri.ravel()
            is_new = flat >= n_in
            new_face[flat[is_new] - n_in] = np.repeat(tri_face, 3)[is_new]
        st_face.append(todo[new_face])
        st_bary.append(_barycentric(corners[todo[new_face]], out_xy[n_in:] - translate[new_face]))
        gid = np.concatenate([b_gid, n_v + l_sel, -1 - (n_st + np.arange(n_new))])
        n_st += n_new
        faces_new = gid[out_tri]
        # Triangle emits counter-clockwise triangles and the 2-D frames keep the asset
        # orientation; flip any that come out otherwise, defensively.
        p = out_xy[out_tri]
        signed = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
        faces_new[signed < 0] = faces_new[signed < 0][:, [0, 2, 1]]
        stale = refined[tri_owner] & (in_todo[tri_owner] >= 0)
        tri_ids = np.concatenate([tri_ids[~stale], faces_new])
        tri_owner = np.concatenate([tri_owner[~stale], todo[tri_face]])

        bad = np.unique(tri_face[(_min_angle_2d(out_xy[out_tri]) < 20.0)
                                 & (asset_min_angle[todo[tri_face]] >= 20.0)])
        if not len(bad) or attempt == 7:
            break
        fix = todo[bad]
        in_fix = np.full(n_f, -1)
        in_fix[fix] = np.arange(len(fix))
        f_sel = in_fix[l_face] >= 0
        fb_face, _, fb_xy, f_segments = _boundary_polygons(
            wf[fix], face_edge[fix], forward[fix], corners[fix], s_edge, s_t, s_id)
        f_xy, _, _, f_translate, f_locate, f_seg_out = _triangulate(
            corners[fix], fb_face, fb_xy, f_segments, in_fix[l_face[f_sel]], l_xy[f_sel], True)
        f_in = len(fb_xy) + int(f_sel.sum())
        new = np.unique(f_seg_out[f_seg_out >= f_in])
        if not len(new):
            break
        # Which side of which face each new boundary point lies on, and where along it.
        pf = f_locate(f_xy[new])
        q = f_xy[new] - f_translate[pf]
        c0 = corners[fix[pf]]
        d = c0[:, [1, 2, 0]] - c0
        rel = q[:, None] - c0
        dist = np.abs(d[..., 0] * rel[..., 1] - d[..., 1] * rel[..., 0]) / np.linalg.norm(d, axis=2)
        side = dist.argmin(axis=1)
        rows = np.arange(len(new))
        t_side = np.einsum("ij,ij->i", rel[rows, side], d[rows, side]) / np.einsum(
            "ij,ij->i", d[rows, side], d[rows, side])
        e_new = face_edge[fix[pf], side]
        t_new = np.where(forward[fix[pf], side], t_side, 1.0 - t_side)
        # Both faces of an edge may split it at the same spot; duplicate points crash Triangle.
        all_e = np.concatenate([pt_edge, e_new])
        all_t = np.concatenate([t_edge, t_new])
        fresh = np.r_[np.zeros(len(pt_edge), dtype=bool), np.ones(len(e_new), dtype=bool)]
        order = np.lexsort((all_t, all_e))
        close = (all_e[order][1:] == all_e[order][:-1]) & (
            np.diff(all_t[order]) * e_len[all_e[order][1:]] < 1e-6 * h)
        drop = np.zeros(len(all_e), dtype=bool)
        pair_hi, pair_lo = order[1:][close], order[:-1][close]
        drop[np.where(fresh[pair_hi], pair_hi, pair_lo)] = True
        keep_new = ~drop[len(pt_edge):]
        e_new, t_new = e_new[keep_new], t_new[keep_new]
        if not len(e_new):
            break
        pt_edge = np.concatenate([pt_edge, e_new])
        t_edge = np.concatenate([t_edge, t_new])
        changed = np.zeros(n_e, dtype=bool)
        changed[e_new] = True
        todo = np.flatnonzero(changed[face_edge].any(axis=1))

    n_edge_pts = len(pt_edge)
    edge_xyz = (1.0 - t_edge)[:, None] * wv[ev0[pt_edge]] + t_edge[:, None] * wv[ev1[pt_edge]]
    st_face_a = np.concatenate(st_face) if st_face else np.zeros(0, dtype=np.int64)
    st_bary_a = np.concatenate(st_bary) if st_bary else np.zeros((0, 3))
    tri_ids = np.where(tri_ids < 0, e_base + n_edge_pts - 1 - tri_ids, tri_ids)
    kept = np.flatnonzero(~refined)
    faces = np.concatenate([wf[kept], tri_ids]).astype(np.int64)
    owner = np.concatenate([kept, tri_owner]).astype(np.int64)
    inner_face = np.concatenate([l_face, st_face_a])
    inner_bary = np.concatenate([l_bary, st_bary_a])
    inner_xyz = np.einsum("ij,ijk->ik", inner_bary, corners3[inner_face])
    vertices = np.concatenate([wv, inner_xyz[:n_lat], edge_xyz, inner_xyz[n_lat:]])

    # Exact map back: asset vertices by a corner of some face, edge points by a face of the edge.
    node_face = np.zeros(len(vertices), dtype=np.int64)
    node_bary = np.zeros((len(vertices), 3))
    flat = wf.ravel()
    node_ids, corner = np.unique(flat, return_index=True)  # first corner using each vertex
    node_face[node_ids] = corner // 3
    node_bary[node_ids, corner % 3] = 1.0
    ids = np.r_[n_v + np.arange(n_lat), e_base + n_edge_pts + np.arange(len(st_face_a))]
    node_face[ids] = inner_face
    node_bary[ids] = inner_bary
    if n_edge_pts:
        side = np.zeros(n_e, dtype=np.int64)
        e_ids, e_side = np.unique(face_edge.ravel(), return_index=True)  # first face side
        side[e_ids] = e_side
        s_of_pt = side[pt_edge]
        s = s_of_pt % 3
        t_s = np.where(forward.ravel()[s_of_pt], t_edge, 1.0 - t_edge)
        ids = e_base + np.arange(n_edge_pts)
        node_face[ids] = s_of_pt // 3
        node_bary[ids, s] = 1.0 - t_s
        node_bary[ids, (s + 1) % 3] = t_s

    boundary = np.zeros(len(vertices), dtype=bool)
    open_e = np.flatnonzero(face_count == 1)
    boundary[ev0[open_e]] = True
    boundary[ev1[open_e]] = True
    boundary[e_base + np.flatnonzero(face_count[pt_edge] == 1)] = True

    # Drop nodes no face uses (loose asset vertices, corners of dropped zero-area faces,
    # lattice points of faces kept whole, points of faces meshed again).
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    if not used.all():
        remap = np.cumsum(used) - 1
        faces = remap[faces]
        vertices, node_face, node_bary, boundary = (
            vertices[used], node_face[used], node_bary[used], boundary[used])

    return SimMesh(
        vertices=vertices,
        faces=faces,
        asset_face=keep[owner],
        node_face=keep[node_face],
        node_bary=node_bary,
        boundary=boundary,
        edge_length=h,
    )
