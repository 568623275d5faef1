"""The evaluated mesh (modifiers applied) as a binary PLY crackbake reads: object-space
positions, the chosen UV map as ``s t``, and a vertex group as the ``weight`` property
(``--weight-attribute weight``)."""

from __future__ import annotations

import numpy as np

WEIGHT_ATTRIBUTE = "weight"
UNWRAP_UV = "crackbake"  # the UV map a new unwrap is stored in


def uv_values(layer) -> tuple:
    """A UV map's per-corner values and their field for ``foreach_get``/``foreach_set``:
    Blender 3.5+'s ``layer.uv[i].vector``, 3.4's ``layer.data[i].uv``."""
    return (layer.uv, "vector") if hasattr(layer, "uv") else (layer.data, "uv")


class ExportError(Exception):
    """The object cannot be exported (no faces, no UV map); the message says the fix."""


def mesh_arrays(obj, depsgraph, uv_name: str | None = "", group: str = "") -> dict:
    """Vertices (N, 3) float64, faces (M, 3) int32, uv (N, 2) float32 and optional weight (N,)
    of ``obj``'s evaluated mesh in object space, a vertex per distinct (vertex, UV) corner so
    UV seams stay seams.  ``uv_name`` None: no UVs (crackbake unwraps; uv is zero)."""
    evaluated = obj.evaluated_get(depsgraph)
    me = evaluated.to_mesh()
    try:
        me.calc_loop_triangles()
        if not len(me.loop_triangles):
            raise ExportError(f"'{obj.name}' has no faces to crack")
        layer = me.uv_layers.get(uv_name) if uv_name else me.uv_layers.active
        if layer is None and uv_name is not None:
            raise ExportError(f"'{obj.name}' has no UV map{' ' + repr(uv_name) if uv_name else ''};"
                              " add one (UV > Unwrap) or pick another")
        n_loops, n_verts = len(me.loops), len(me.vertices)
        tri = np.empty(len(me.loop_triangles) * 3, np.int32)
        me.loop_triangles.foreach_get("loops", tri)
        loop_vert = np.empty(n_loops, np.int32)
        me.loops.foreach_get("vertex_index", loop_vert)
        co = np.empty(n_verts * 3, np.float32)
        me.vertices.foreach_get("co", co)
        uv = np.zeros(n_loops * 2, np.float32)
        if uv_name is not None:
            values, field = uv_values(layer)
            values.foreach_get(field, uv)
        uv = uv.reshape(-1, 2)
        weight = None
        if group:
            vg = evaluated.vertex_groups.get(group)
            if vg is None:
                raise ExportError(f"'{obj.name}' has no vertex group '{group}'")
            weight = np.zeros(n_verts, np.float32)
            gi = vg.index
            for v in me.vertices:  # vertex groups have no bulk accessor
                for g in v.groups:
                    if g.group == gi:
                        weight[v.index] = g.weight
    finally:
        evaluated.to_mesh_clear()
    # exact bit patterns: two corners share an output vertex only when their UVs are equal
    key = np.column_stack([loop_vert, uv.view(np.int32)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    out = {
        "vertices": co.reshape(-1, 3)[loop_vert[first]].astype(np.float64),
        "faces": inverse[tri].reshape(-1, 3).astype(np.int32),
        "uv": uv[first],
        "triangles": len(tri) // 3,
    }
    if weight is not None:
        out["weight"] = weight[loop_vert[first]]
    return out


def write_ply(path: str, arrays: dict) -> None:
    """A binary little-endian PLY of :func:`mesh_arrays`' result."""
    v, f, uv = arrays["vertices"], arrays["faces"], arrays["uv"]
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("s", "<f4"), ("t", "<f4")]
    if "weight" in arrays:
        fields.append((WEIGHT_ATTRIBUTE, "<f4"))
    rows = np.empty(len(v), dtype=fields)
    rows["x"], rows["y"], rows["z"] = v[:, 0], v[:, 1], v[:, 2]
    rows["s"], rows["t"] = uv[:, 0], uv[:, 1]
    if "weight" in arrays:
        rows[WEIGHT_ATTRIBUTE] = arrays["weight"]
    faces = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"], faces["i"] = 3, f
    names = {"<f8": "double", "<f4": "float"}
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(v)}"]
    header += [f"property {names[t]} {n}" for n, t in fields]
    header += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        fh.write(rows.tobytes())
        fh.write(faces.tobytes())


def store_unwrap(mesh, uv: np.ndarray, faces: np.ndarray, name: str = "crackbake") -> None:
    """Write crackbake's unwrap (``uv`` (N, 2), ``faces`` (M, 3) in the mesh's loop-triangle
    order) into the UV map ``name`` of ``mesh`` (made when missing)."""
    mesh.calc_loop_triangles()
    tri = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", tri)
    if len(tri) != faces.size:
        raise ExportError(f"the unwrap has {len(faces)} triangles, the mesh "
                          f"{len(tri) // 3}; bake again")
    loop_uv = np.zeros((len(mesh.loops), 2), np.float32)
    loop_uv[tri] = uv[faces.reshape(-1)]  # a loop in two triangles takes its last corner's UV
    layer = mesh.uv_layers.get(name) or mesh.uv_layers.new(name=name)
    values, field = uv_values(layer)
    values.foreach_set(field, loop_uv.ravel())
    mesh.update()
