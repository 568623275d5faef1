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

from crackbake.bake import tangent_kernels as kern
from crackbake.bake.uv.uvmesh import UVMesh
from crackbake.errors import CrackbakeError
from crackbake.grouping import first_ids

# MikkTSpace's "not zero": |x| > FLT_MIN (the smallest normal float32).
_TINY = float(np.finfo(np.float32).tiny)
_NEXT = np.array([1, 2, 0])


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
    tangent, orient, good, nondeg = kern.face_frames(p, t, faces, _TINY)
    partner = _match_edges(weld, nondeg)
    label, group_orient = _corner_groups(partner, orient, good, nondeg)
    sums, has_good = kern.group_sums(p, n, faces, tangent, good, label, len(group_orient))
    out = kern.assemble(n, faces, label, sums, has_good, group_orient, nondeg)
    _copy_to_degenerate(out, weld.reshape(-1), np.repeat(nondeg, 3))
    return out.reshape(-1, 3, 4)


def with_tangents(uvmesh: UVMesh, cache: bool = False) -> UVMesh:
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
    cache : bool
        Read the frames from the mesh cache (:mod:`crackbake.bake.mesh_cache`, keyed by the
        content of the mesh's arrays) when it holds them, else store them there.

    Returns
    -------
    UVMesh
        ``tangents`` (V', 4) float64 set; unused vertices get a frame orthogonal to their
        normal with w = -1.
    """
    faces = np.asarray(uvmesh.faces, dtype=np.int64)
    key = hit = None
    if cache:
        from crackbake.bake.mesh_cache import read_tangents, tangents_key

        key = tangents_key(uvmesh.vertices, faces, uvmesh.uv, uvmesh.normals)
        hit = read_tangents(key, len(uvmesh.vertices), faces.shape)
    if hit is not None:
        new_faces, source, tangents = hit
        normals = np.asarray(uvmesh.normals, dtype=np.float64)[source]
    else:
        tan = corner_tangents(uvmesh.vertices, faces, uvmesh.uv, uvmesh.normals).reshape(-1, 4)
        new_vertex, source, first = kern.split_vertices(faces.reshape(-1), tan,
                                                        len(uvmesh.vertices))  # fmt: skip
        normals = np.asarray(uvmesh.normals, dtype=np.float64)[source]
        tangents = np.empty((len(source), 4))
        unused = first < 0
        tangents[unused, :3] = kern.fallback_rows(np.ascontiguousarray(normals[unused]))
        tangents[unused, 3] = -1.0
        tangents[~unused] = tan[first[~unused]]
        new_faces = new_vertex.reshape(-1, 3)
        if key is not None:
            from crackbake.bake.mesh_cache import write_tangents

            write_tangents(key, new_faces, source, tangents)
    return dataclasses.replace(
        uvmesh,
        vertices=np.asarray(uvmesh.vertices, dtype=np.float64)[source],
        faces=new_faces,
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


def _weld(p: np.ndarray, n: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(V,) welded-vertex id: equal for bit-identical position, normal and UV."""
    rows = np.ascontiguousarray(np.column_stack([p, n, t]), dtype=np.float64) + 0.0
    return first_ids(rows)[0]


def _match_edges(weld: np.ndarray, nondeg: np.ndarray) -> np.ndarray:
    """(3F,) the edge (``3 * face + corner``) paired with each edge, or -1.

    Edge ``c`` of a face runs from corner ``c`` to the next one.  It pairs with an edge running
    the other way between the same two welded vertices; where more than two faces share an
    edge, the k-th edge one way (in face order) pairs with the k-th the other way, which is what
    MikkTSpace's greedy first-come pairing amounts to.
    """
    return kern.match_edges(np.ascontiguousarray(weld, dtype=np.int64), nondeg)


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
    # Components, each with its first good corner (where MikkTSpace starts its group).
    label, n_comp, start = kern.components(len(partner), src[plain], dst[plain], good_c)
    comp_orient = np.zeros(n_comp, dtype=bool)
    comp_orient[label] = orient_c
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
    # Imported here, not with the module: only meshes with zero-UV-area faces get this far, and
    # scipy.sparse is 0.1-0.3 s of imports the UV stage (and a --cracks re-bake) need not pay.
    from scipy.sparse import coo_matrix

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
