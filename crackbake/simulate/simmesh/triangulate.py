"""Triangulating the simulation mesh: every asset face that gets points is meshed on its own
plane by one constrained-Delaunay call (Shewchuk's Triangle) for all faces, laid out side by side
in 2-D."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackbake.geometry import barycentric, corner_mean
from crackbake.simulate.simmesh.layout import min_angle_2d


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


def boundary_polygons(
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


def triangulate(corners, b_face, b_xy, segments, l_face, l_xy, quality_on_edges: bool):
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
    tri_face = locate(corner_mean(out_xy[out_tri]))
    return out_xy, out_tri, tri_face, translate, locate, np.asarray(out["segments"])


@dataclass(frozen=True, eq=False)
class FaceSet:
    """The welded asset faces to refine and their interior points (what meshing reads).

    Attributes
    ----------
    wf : (R, 3) int64
        Welded faces (zero-area ones dropped).
    face_edge : (R, 3) int64
        Welded edge of each side (side ``i`` runs from corner ``i`` to ``i + 1``).
    forward : (R, 3) bool
        The side runs along its edge's ``lo -> hi`` direction.
    corners : (R, 3, 2) float64
        Corners in each face's own 2-D frame, target lengths.
    l_face, l_xy : (P,) int64, (P, 2) float64
        Interior lattice points: face row and 2-D position.
    e_len : (E,) float64
        Welded edge lengths, mesh units.
    h : float
        Target edge length, mesh units.
    n_v : int
        Welded asset vertices (node ids below ``n_v``).
    """

    wf: np.ndarray
    face_edge: np.ndarray
    forward: np.ndarray
    corners: np.ndarray
    l_face: np.ndarray
    l_xy: np.ndarray
    e_len: np.ndarray
    h: float
    n_v: int

    @property
    def e_base(self) -> int:
        """First node id of the edge points (after asset vertices and lattice points)."""
        return self.n_v + len(self.l_face)


@dataclass(eq=False)
class Refined:
    """Result of :func:`refine_faces`.

    Node ids: asset vertices, then lattice points, then edge points (append only, so ids stay
    valid when points are added); Triangle's own interior points get negative ids ``-1 - k``.
    """

    pt_edge: np.ndarray  # (Q,) welded edge of each edge point
    t_edge: np.ndarray  # (Q,) parameter along lo -> hi
    refined: np.ndarray  # (R,) bool: face was meshed (its own triangles replaced)
    st_face: list  # Triangle's interior points: face rows ...
    st_bary: list  # ... and barycentrics in that face
    tri_ids: np.ndarray  # (T, 3) node ids of the sim triangles of refined faces
    tri_owner: np.ndarray  # (T,) face row of each


def refine_faces(fs: FaceSet, pt_edge: np.ndarray, t_edge: np.ndarray, todo: np.ndarray) -> Refined:
    """Triangulate every face in ``todo``, splitting asset edges where quality needs it.

    Where the no-points-on-edges rule keeps Triangle from reaching 20 degrees, let it split
    those faces' edges freely, adopt the new edge points for both faces of the edge, and mesh
    again just the faces that changed (at most 8 rounds).
    """
    n_f = len(fs.wf)
    asset_min_angle = min_angle_2d(fs.corners)
    out = Refined(pt_edge, t_edge, np.zeros(n_f, dtype=bool), [], [],
                  np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64))
    n_st = 0
    for attempt in range(8):
        if not len(todo):
            break
        out.refined[todo] = True
        order = np.lexsort((out.t_edge, out.pt_edge))
        sorted_pts = (out.pt_edge[order], out.t_edge[order], fs.e_base + order)
        in_todo = np.full(n_f, -1)
        in_todo[todo] = np.arange(len(todo))
        out_xy, out_tri, tri_face, n_new = _mesh_rows(fs, todo, in_todo, sorted_pts, n_st, out)
        n_st += n_new
        bad = np.unique(tri_face[(min_angle_2d(out_xy[out_tri]) < 20.0)
                                 & (asset_min_angle[todo[tri_face]] >= 20.0)])
        if not len(bad) or attempt == 7:
            break
        e_new, t_new = _edge_splits(fs, todo[bad], sorted_pts)
        if not len(e_new):
            break
        e_new, t_new = _without_duplicates(fs, out.pt_edge, out.t_edge, e_new, t_new)
        if not len(e_new):
            break
        out.pt_edge = np.concatenate([out.pt_edge, e_new])
        out.t_edge = np.concatenate([out.t_edge, t_new])
        changed = np.zeros(len(fs.e_len), dtype=bool)
        changed[e_new] = True
        todo = np.flatnonzero(changed[fs.face_edge].any(axis=1))
    return out


def _mesh_rows(fs: FaceSet, todo, in_todo, sorted_pts, n_st: int, out: Refined):
    """Mesh the faces ``todo`` without points on their edges; replace their triangles in
    ``out`` and record Triangle's interior points.  Returns the 2-D output points, triangles,
    the row of ``todo`` of each triangle and how many interior points Triangle added."""
    s_edge, s_t, s_id = sorted_pts
    l_sel = np.flatnonzero(in_todo[fs.l_face] >= 0)
    b_face, b_gid, b_xy, segments = boundary_polygons(
        fs.wf[todo], fs.face_edge[todo], fs.forward[todo], fs.corners[todo], s_edge, s_t, s_id)
    out_xy, out_tri, tri_face, translate, _, _ = triangulate(
        fs.corners[todo], b_face, b_xy, segments, in_todo[fs.l_face[l_sel]], fs.l_xy[l_sel],
        False)
    n_in = len(b_xy) + len(l_sel)
    n_new = len(out_xy) - n_in
    new_face = np.zeros(n_new, dtype=np.int64)  # rows of todo
    if n_new:
        flat = out_tri.ravel()
        is_new = flat >= n_in
        new_face[flat[is_new] - n_in] = np.repeat(tri_face, 3)[is_new]
    out.st_face.append(todo[new_face])
    out.st_bary.append(barycentric(fs.corners[todo[new_face]], out_xy[n_in:] - translate[new_face]))
    gid = np.concatenate([b_gid, fs.n_v + l_sel, -1 - (n_st + np.arange(n_new))])
    faces_new = gid[out_tri]
    # Triangle emits counter-clockwise triangles and the 2-D frames keep the asset
    # orientation; flip any that come out otherwise, defensively.
    p = out_xy[out_tri]
    signed = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
              - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    faces_new[signed < 0] = faces_new[signed < 0][:, [0, 2, 1]]
    stale = out.refined[out.tri_owner] & (in_todo[out.tri_owner] >= 0)
    out.tri_ids = np.concatenate([out.tri_ids[~stale], faces_new])
    out.tri_owner = np.concatenate([out.tri_owner[~stale], todo[tri_face]])
    return out_xy, out_tri, tri_face, n_new


def _edge_splits(fs: FaceSet, fix: np.ndarray, sorted_pts) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the faces ``fix`` letting Triangle split their edges; the new edge points as
    (welded edge, parameter along lo -> hi)."""
    s_edge, s_t, s_id = sorted_pts
    n_f = len(fs.wf)
    corners = fs.corners
    in_fix = np.full(n_f, -1)
    in_fix[fix] = np.arange(len(fix))
    f_sel = in_fix[fs.l_face] >= 0
    fb_face, _, fb_xy, f_segments = boundary_polygons(
        fs.wf[fix], fs.face_edge[fix], fs.forward[fix], corners[fix], s_edge, s_t, s_id)
    f_xy, _, _, f_translate, f_locate, f_seg_out = triangulate(
        corners[fix], fb_face, fb_xy, f_segments, in_fix[fs.l_face[f_sel]], fs.l_xy[f_sel], True)
    f_in = len(fb_xy) + int(f_sel.sum())
    new = np.unique(f_seg_out[f_seg_out >= f_in])
    if not len(new):
        return np.zeros(0, dtype=np.int64), np.zeros(0)
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
    e_new = fs.face_edge[fix[pf], side]
    t_new = np.where(fs.forward[fix[pf], side], t_side, 1.0 - t_side)
    return e_new, t_new


def _without_duplicates(fs: FaceSet, pt_edge, t_edge, e_new, t_new):
    """New edge points less those within 1e-6 h of an existing (or another new) one: both
    faces of an edge may split it at the same spot, and duplicate points crash Triangle."""
    all_e = np.concatenate([pt_edge, e_new])
    all_t = np.concatenate([t_edge, t_new])
    fresh = np.r_[np.zeros(len(pt_edge), dtype=bool), np.ones(len(e_new), dtype=bool)]
    order = np.lexsort((all_t, all_e))
    close = (all_e[order][1:] == all_e[order][:-1]) & (
        np.diff(all_t[order]) * fs.e_len[all_e[order][1:]] < 1e-6 * fs.h)
    drop = np.zeros(len(all_e), dtype=bool)
    pair_hi, pair_lo = order[1:][close], order[:-1][close]
    drop[np.where(fresh[pair_hi], pair_hi, pair_lo)] = True
    keep_new = ~drop[len(pt_edge):]
    return e_new[keep_new], t_new[keep_new]
