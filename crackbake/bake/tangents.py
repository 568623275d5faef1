"""MikkTSpace tangent frames for the output mesh, vectorised with numpy.

Normal maps are decoded by engines in the MikkTSpace frame (Blender, Unity, Unreal, Godot and the
glTF specification all use it), so maps baked in any other frame show seams and shading errors.
This is our own implementation of the rules of Morten Mikkelsen's reference code (as Blender 5
ships it), written for whole arrays instead of one triangle at a time:

1. **Welding.**  Corners with bit-identical position, normal and UV (as float32, the precision a
   GLB stores) are one welded vertex; triangles are adjacent across an edge only when both
   triangles see the same two welded vertices in opposite order.
2. **Triangles.**  A triangle whose positions coincide (two equal corners) is *degenerate* and
   takes no part.  Every other triangle has a tangent ``dP/du`` (normalised) and an orientation
   (UV area > 0 is orientation preserving, w = +1; mirrored UVs give w = -1).  A triangle with
   zero UV area (or zero ``dP/du`` / ``dP/dv``) is *group-with-any*: it contributes nothing and
   adopts the orientation of the first group reaching it.
3. **Groups.**  Around each welded vertex, triangles connected through shared edges and of equal
   orientation form one group; its tangent is the sum of the member tangents, each projected
   onto the vertex normal and weighted by the corner angle (also measured in the tangent
   plane), normalised.  Every corner of the group gets it.  Groups are formed in face order, so
   which group a zero-UV-area triangle joins (and which groups it then links) depends on the
   face order exactly as in MikkTSpace: that part is replayed step by step, over only the groups
   touching such triangles.
4. **Leftovers.**  Corners of degenerate triangles copy the frame of the first corner (in face
   order) with the same welded vertex; corners no group reached get MikkTSpace's default
   ``(1, 0, 0), w = -1``, here made orthogonal to the normal (the nearest valid frame).

Conventions: UVs with ``v`` up (OBJ/Blender), so ``B = w * cross(N, T)`` points towards +v.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from crackbake.bake.uv.uvmesh import UVMesh
from crackbake.errors import CrackbakeError

# MikkTSpace's "not zero": |x| > FLT_MIN (the smallest normal float32).
_TINY = float(np.finfo(np.float32).tiny)
_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


def corner_tangents(
    vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """MikkTSpace tangent and bitangent sign of every face corner.

    Parameters
    ----------
    vertices : (V, 3) float
        Positions, any unit.
    faces : (F, 3) int
        Triangles (corner order defines the winding).
    uv : (V, 2) float
        Texture coordinates, ``v`` up (OBJ/Blender).
    normals : (V, 3) float
        Unit vertex normals (the shading normals the map is decoded with).

    Returns
    -------
    (F, 3, 4) float64
        Per corner: ``xyz`` the unit tangent (direction of increasing ``u``, orthogonal to the
        corner's normal), ``w`` = +1 or -1 such that ``w * cross(N, T)`` points towards
        increasing ``v``.
    """
    p, n, t, faces = _checked(vertices, faces, uv, normals)
    if not len(faces):
        return np.zeros((0, 3, 4))
    weld = _weld(p, n, t)[faces]
    pc, nc, tc = p[faces], n[faces], t[faces]
    nondeg = ~(
        (pc[:, 0] == pc[:, 1]).all(1) | (pc[:, 0] == pc[:, 2]).all(1)
        | (pc[:, 1] == pc[:, 2]).all(1)
    )
    tangent, orient, good = _triangle_frames(pc, tc)
    good &= nondeg
    partner = _match_edges(weld, nondeg)
    label, group_orient = _corner_groups(partner, orient, good, nondeg)
    n_groups = len(group_orient)

    contrib = _corner_contributions(pc, nc, tangent) * good[:, None, None]
    flat = contrib.reshape(-1, 3)
    sums = np.stack([np.bincount(label, flat[:, k], n_groups) for k in range(3)], 1)
    has_good = np.bincount(label, np.repeat(good, 3).astype(np.float64), n_groups) > 0
    length = np.sqrt(_dot(sums, sums))
    group_t = sums / np.where(length > 0, length, 1.0)[:, None]

    out = np.empty((len(faces) * 3, 4))
    take = has_good[label] & np.repeat(nondeg, 3)
    # A group whose contributions cancel (Blender: a zero tangent) gets the fallback too.
    full = take & (length[label] > 0)
    out[full, :3] = group_t[label[full]]
    out[~full, :3] = _fallback(nc.reshape(-1, 3)[~full])
    out[:, 3] = -1.0
    out[take, 3] = np.where(group_orient[label[take]], 1.0, -1.0)
    _copy_to_degenerate(out, weld.reshape(-1), np.repeat(nondeg, 3))
    return out.reshape(-1, 3, 4)


def with_tangents(uvmesh: UVMesh) -> UVMesh:
    """The same mesh with MikkTSpace tangents per vertex, vertices split where needed.

    A vertex whose corners get different tangents (a UV seam's or a mirror seam's sides, or
    the sides of a hard tangent edge) is split: its first frame (in face order) keeps the vertex
    index, every other one becomes a new vertex appended after the existing ones.  Faces keep
    their count and order; ``vertices``, ``uv``, ``normals`` and ``vertex_map`` are extended with
    copies of the split vertex.

    Parameters
    ----------
    uvmesh : UVMesh
        The output mesh (its ``tangents``, if any, are recomputed).

    Returns
    -------
    UVMesh
        ``tangents`` (V', 4) float64 set; unused vertices get a frame orthogonal to their
        normal with w = -1.
    """
    faces = np.asarray(uvmesh.faces, dtype=np.int64)
    tan = corner_tangents(uvmesh.vertices, faces, uvmesh.uv, uvmesh.normals).reshape(-1, 4)
    n_vert = len(uvmesh.vertices)
    corner_vertex = faces.reshape(-1)
    variant, first = _exact_ids(np.column_stack([corner_vertex.astype(np.float64), tan]))
    var_vertex = corner_vertex[first]
    # Variants are numbered by first corner, so a vertex's first variant comes first.
    _, primary = np.unique(var_vertex, return_index=True)
    is_primary = np.zeros(len(first), dtype=bool)
    is_primary[primary] = True
    new_id = np.empty(len(first), dtype=np.int64)
    new_id[is_primary] = var_vertex[is_primary]
    new_id[~is_primary] = n_vert + np.arange(np.count_nonzero(~is_primary))
    source = np.concatenate([np.arange(n_vert), var_vertex[~is_primary]])

    normals = np.asarray(uvmesh.normals, dtype=np.float64)[source]
    tangents = np.empty((len(source), 4))
    unused = np.ones(len(source), dtype=bool)
    unused[new_id] = False
    tangents[unused, :3] = _fallback(normals[unused])
    tangents[unused, 3] = -1.0
    tangents[new_id] = tan[first]
    return dataclasses.replace(
        uvmesh,
        vertices=np.asarray(uvmesh.vertices, dtype=np.float64)[source],
        faces=new_id[variant].reshape(-1, 3),
        uv=np.asarray(uvmesh.uv, dtype=np.float64)[source],
        normals=normals,
        vertex_map=np.asarray(uvmesh.vertex_map, dtype=np.int64)[source],
        tangents=tangents,
    )


def _checked(vertices, faces, uv, normals):
    """Float32-rounded (as float64) positions, normals, UVs and int64 faces, validated."""
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
        raise CrackbakeError(
            f"tangents need (F, 3) integer faces, got {f.shape} {f.dtype}; triangulate the mesh"
        )
    out = []
    for name, arr, width in (("vertices", vertices, 3), ("normals", normals, 3), ("uv", uv, 2)):
        a = np.asarray(arr, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != width or (out and len(a) != len(out[0])):
            raise CrackbakeError(
                f"tangents got {name} of shape {a.shape}; expected ({len(out[0]) if out else 'V'}"
                f", {width}), one row per vertex"
            )
        if not np.isfinite(a).all():
            raise CrackbakeError(f"tangents got non-finite {name}; repair the mesh first")
        out.append(a.astype(np.float32).astype(np.float64) + 0.0)  # +0.0 folds -0 into 0
    if len(f) and (f.min() < 0 or f.max() >= len(out[0])):
        raise CrackbakeError(
            f"tangent faces index vertices outside 0..{len(out[0]) - 1}; faces do not match"
        )
    return out[0], out[1], out[2], f.astype(np.int64)


def _exact_ids(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ids of bit-identical rows, numbered by first occurrence, and each id's first row.

    Hashes the rows' bits to one uint64 and sorts that (much faster than sorting rows); a hash
    collision is detected and then the exact row sort is used.
    """
    r = np.ascontiguousarray(rows, dtype=np.float64) + 0.0
    bits = r.view(np.uint64)
    h = np.zeros(len(r), dtype=np.uint64)
    for k in range(r.shape[1]):
        h = (h ^ bits[:, k]) * np.uint64(0x9E3779B97F4A7C15)
        h ^= h >> np.uint64(29)
    _, first, inverse = np.unique(h, return_index=True, return_inverse=True)
    if not np.array_equal(r, r[first[inverse]]):
        _, first, inverse = np.unique(r, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inverse], first[order]


def _weld(p: np.ndarray, n: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(V,) welded-vertex id: equal for bit-identical position, normal and UV."""
    return _exact_ids(np.column_stack([p, n, t]))[0]


def _triangle_frames(pc: np.ndarray, tc: np.ndarray):
    """Per triangle: unit ``dP/du`` (F, 3), orientation preserving (F,), good (F,)."""
    d1, d2 = pc[:, 1] - pc[:, 0], pc[:, 2] - pc[:, 0]
    t21, t31 = tc[:, 1] - tc[:, 0], tc[:, 2] - tc[:, 0]
    area = t21[:, 0] * t31[:, 1] - t21[:, 1] * t31[:, 0]
    v_os = t31[:, 1, None] * d1 - t21[:, 1, None] * d2
    v_ot = -t31[:, 0, None] * d1 + t21[:, 0, None] * d2
    len_os2 = _dot(v_os, v_os)
    len_ot2 = _dot(v_ot, v_ot)
    orient = area > 0
    good = (np.abs(area) > _TINY) & (len_os2 > _TINY) & (len_ot2 > _TINY)
    scale = np.where(good, np.where(orient, 1.0, -1.0) / np.sqrt(np.where(good, len_os2, 1.0)), 0)
    return v_os * scale[:, None], orient, good


def _match_edges(weld: np.ndarray, nondeg: np.ndarray) -> np.ndarray:
    """(3F,) the edge (``3 * face + corner``) paired with each edge, or -1.

    Edge ``c`` of a face runs from corner ``c`` to the next one.  It pairs with an edge running
    the other way between the same two welded vertices; where more than two faces share an
    edge, the k-th edge one way (in face order) pairs with the k-th the other way, which is what
    MikkTSpace's greedy first-come pairing amounts to.
    """
    a = weld.reshape(-1)
    b = weld[:, _NEXT].reshape(-1)
    edges = np.flatnonzero(np.repeat(nondeg, 3))
    partner = np.full(len(a), -1, dtype=np.int64)
    if not len(edges):
        return partner
    lo = np.minimum(a[edges], b[edges])
    hi = np.maximum(a[edges], b[edges])
    key = lo * np.int64(weld.max(initial=0) + 1) + hi
    backwards = (a[edges] > b[edges]).astype(np.int64)
    order = np.argsort(key * 2 + backwards, kind="stable")
    s_key, s_back, s_edge = key[order], backwards[order], edges[order]
    starts = np.flatnonzero(np.r_[True, s_key[1:] != s_key[:-1]])
    sizes = np.diff(np.r_[starts, len(s_key)])
    n_fwd = np.add.reduceat(1 - s_back, starts)
    block_start = np.repeat(starts, sizes)
    block_fwd = np.repeat(n_fwd, sizes)
    pos = np.arange(len(s_key))
    rank = pos - block_start - block_fwd  # rank among the backward edges of the block
    ok = (s_back == 1) & (rank < block_fwd)
    mate = s_edge[(block_start + rank)[ok]]
    partner[s_edge[ok]] = mate
    partner[mate] = s_edge[ok]
    return partner


def _corner_groups(partner, orient, good, nondeg) -> tuple[np.ndarray, np.ndarray]:
    """(3F,) group label of each corner and (labels,) each group's orientation.

    Edge ``(f, c)`` paired with ``(g, d)`` links corner ``c`` of f with corner ``d + 1`` of g
    and corner ``c + 1`` of f with corner ``d`` of g (the same welded vertex).  Links between
    good faces of equal orientation give the groups directly (connected components).  Faces
    with zero UV area then join groups as MikkTSpace's sequential pass would have it
    (:func:`_join_group_with_any`); only the groups touching such faces take part in that.
    """
    e = np.flatnonzero(partner > np.arange(len(partner)))
    m = partner[e]
    nxt = lambda x: x - x % 3 + _NEXT[x % 3]  # noqa: E731 - the corner after corner x
    src, dst = np.concatenate([e, nxt(e)]), np.concatenate([nxt(m), m])
    good_c, orient_c = np.repeat(good, 3), np.repeat(orient, 3)
    plain = good_c[src] & good_c[dst] & (orient_c[src] == orient_c[dst])
    n = len(partner)
    graph = coo_matrix(
        (np.ones(np.count_nonzero(plain), dtype=np.int8), (src[plain], dst[plain])), shape=(n, n)
    ).tocsr()
    n_comp, label = connected_components(graph, directed=False)
    label = label.astype(np.int64)
    # Each component's orientation and first corner (where MikkTSpace starts its group).
    comp_orient = np.zeros(n_comp, dtype=bool)
    comp_orient[label] = orient_c
    start = np.full(n_comp, n, dtype=np.int64)
    np.minimum.at(start, label[good_c], np.flatnonzero(good_c))
    gwa_c = np.repeat(nondeg & ~good, 3)
    mixed = ~plain & (gwa_c[src] | gwa_c[dst])
    if mixed.any():
        root = _join_group_with_any(
            label[src[mixed]], label[dst[mixed]], n_comp, start, comp_orient, gwa_c, label
        )
        label = root[label]
    return label, comp_orient


def _join_group_with_any(a, b, n_comp, start, comp_orient, gwa_c, label) -> np.ndarray:
    """(components,) the group each component ends in once zero-UV-area corners are joined.

    ``a``-``b`` are links between components where at least one side is a zero-UV-area corner
    (each such corner is a component of its own).  MikkTSpace creates groups in corner order;
    each floods its vertex fan, and a zero-UV-area face takes the orientation of the first group
    reaching it, which decides which later groups it can connect.  That order dependence is
    replayed here, one step per component touching such a corner (a Python loop, but only over
    those few components and corners).
    """
    graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n_comp, n_comp))
    graph = (graph + graph.T).tocsr()
    indptr, indices = graph.indptr.tolist(), graph.indices.tolist()
    is_gwa = np.zeros(n_comp, dtype=bool)
    is_gwa[label[gwa_c]] = True
    tri_of = np.full(n_comp, -1, dtype=np.int64)
    tri_of[label[gwa_c]] = np.flatnonzero(gwa_c) // 3
    touched = np.unique(np.concatenate([a, b]))
    seeds = touched[~is_gwa[touched]]
    seeds = seeds[np.argsort(start[seeds], kind="stable")].tolist()
    is_gwa_l, tri_l, orient_l = is_gwa.tolist(), tri_of.tolist(), comp_orient.tolist()
    assigned = np.zeros(n_comp, dtype=bool)
    root = np.arange(n_comp)
    state: dict[int, bool] = {}  # zero-UV-area face -> orientation once a group reached it
    for seed in seeds:
        if assigned[seed]:
            continue
        assigned[seed] = True
        o = orient_l[seed]
        stack = [seed]
        while stack:
            x = stack.pop()
            for y in indices[indptr[x]:indptr[x + 1]]:
                if assigned[y]:
                    continue
                if is_gwa_l[y]:
                    if state.setdefault(tri_l[y], o) != o:
                        continue
                elif orient_l[y] != o:
                    continue
                assigned[y] = True
                root[y] = seed
                stack.append(y)
    for y in np.flatnonzero(assigned & is_gwa).tolist():
        comp_orient[y] = comp_orient[root[y]]
    return root


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis (of length 3); faster than einsum on (..., 3) arrays."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _project(n: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` projected onto the plane normal to ``n`` and normalised (zero stays zero)."""
    w = v - n * _dot(n, v)[..., None]
    length = np.sqrt(_dot(w, w))
    return w / np.where(length > 0, length, 1.0)[..., None]


def _corner_contributions(pc, nc, tangent) -> np.ndarray:
    """(F, 3, 3) each corner's share: the face tangent in the corner's tangent plane times the
    corner angle measured in that plane."""
    e1 = _project(nc, pc[:, _NEXT] - pc)
    e2 = _project(nc, pc[:, _PREV] - pc)
    angle = np.arccos(np.clip(_dot(e1, e2), -1.0, 1.0))
    return _project(nc, np.broadcast_to(tangent[:, None, :], pc.shape)) * angle[..., None]


def _fallback(n: np.ndarray) -> np.ndarray:
    """(N, 3) MikkTSpace's default tangent +X made orthogonal to ``n`` (+Y where n is +-X)."""
    n = np.asarray(n, dtype=np.float64)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    t = np.zeros_like(n)
    t[:, 0] = 1.0
    t -= n * n[:, :1]
    length = np.linalg.norm(t, axis=1)
    weak = length < 1e-6
    t[weak] = np.array([0.0, 1.0, 0.0]) - n[weak] * n[weak, 1:2]
    length = np.linalg.norm(t, axis=1)
    bad = length < 1e-6  # a zero or broken normal
    t[bad], length[bad] = [1.0, 0.0, 0.0], 1.0
    return t / length[:, None]


def _copy_to_degenerate(out: np.ndarray, weld: np.ndarray, nondeg: np.ndarray) -> None:
    """Corners of degenerate faces take the frame of the first corner of a kept face that has
    the same welded vertex (MikkTSpace's rule); others keep the default."""
    if nondeg.all():
        return
    kept = np.flatnonzero(nondeg)
    src = np.full(weld.max() + 1, -1, dtype=np.int64)
    ids, first = np.unique(weld[kept], return_index=True)
    src[ids] = kept[first]
    dst = np.flatnonzero(~nondeg)
    from_corner = src[weld[dst]]
    has = from_corner >= 0
    out[dst[has]] = out[from_corner[has]]
