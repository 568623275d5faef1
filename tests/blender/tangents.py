"""Blender's MikkTSpace tangents of a GLB against the ones crackbake wrote into it.

Usage (under a Python with ``bpy``)::

    python tests/blender/tangents.py MESH.glb EXPECTED.npz [DUMP.npz]

``EXPECTED.npz`` holds ``positions`` (F, 3, 3), ``normals`` (F, 3, 3) and ``tangents`` (F, 3, 4):
crackbake's corners in face order, glTF axes (y up), ``v`` up.  The GLB is imported with
Blender's own glTF importer (which turns y-up into z-up and flips ``v`` back),
``Mesh.calc_tangents`` runs MikkTSpace on the imported corner normals and UVs, and each Blender
loop is matched to our corner by face order and position (any cyclic corner shift).

Prints one JSON object: angle differences (degrees) and sign agreement over all corners and
over all but the *explained* disagreements: corners off by more than 0.5 deg whose imported
normal is not the one we wrote (more than 0.1 deg off, or not bit-identical across corners we
wrote as one vertex).  Blender stores custom normals per corner fan and cannot hold one on a
zero-area face, and MikkTSpace welds by normal, so such corners get other tangents for a reason
outside MikkTSpace.  ``DUMP.npz`` (optional) receives Blender's per-corner arrays.
"""

from __future__ import annotations

import json
import sys

import bpy
import numpy as np


def _import_mesh(path: str):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)
    objects = [o for o in bpy.data.objects if o.type == "MESH"]
    if len(objects) != 1:
        raise SystemExit(f"expected one mesh object in {path}, got {len(objects)}")
    return objects[0]


def _loops(obj) -> dict[str, np.ndarray]:
    """Per-loop positions, tangents, signs, normals and UVs, in glTF axes (y up)."""
    me = obj.data
    me.calc_tangents(uvmap=me.uv_layers.active.name)
    n_loop, n_poly = len(me.loops), len(me.polygons)
    sizes = np.zeros(n_poly, dtype=np.int32)
    me.polygons.foreach_get("loop_total", sizes)
    if not (sizes == 3).all():
        raise SystemExit("the imported mesh is not all triangles")
    starts = np.zeros(n_poly, dtype=np.int32)
    me.polygons.foreach_get("loop_start", starts)
    co = np.zeros(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    vidx = np.zeros(n_loop, dtype=np.int32)
    me.loops.foreach_get("vertex_index", vidx)
    tan = np.zeros(n_loop * 3, dtype=np.float32)
    me.loops.foreach_get("tangent", tan)
    sign = np.zeros(n_loop, dtype=np.float32)
    me.loops.foreach_get("bitangent_sign", sign)
    nrm = np.zeros(n_loop * 3, dtype=np.float32)
    me.corner_normals.foreach_get("vector", nrm)
    uv = np.zeros(n_loop * 2, dtype=np.float32)
    me.uv_layers.active.data.foreach_get("uv", uv)
    world = np.array(obj.matrix_world, dtype=np.float64)
    # Blender z-up (X, Y, Z) is glTF y-up (X, Z, -Y).
    to_gltf = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]) @ world[:3, :3]
    loop = (starts[:, None] + np.arange(3)).reshape(-1)
    pos = co.reshape(-1, 3)[vidx[loop]] @ world[:3, :3].T + world[:3, 3]
    pos = pos @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T
    return {
        "positions": pos.reshape(-1, 3, 3),
        "tangents": (tan.reshape(-1, 3)[loop] @ to_gltf.T).reshape(-1, 3, 3),
        "signs": sign[loop].reshape(-1, 3),
        "normals": (nrm.reshape(-1, 3)[loop] @ to_gltf.T).reshape(-1, 3, 3),
        "uv": uv.reshape(-1, 2)[loop].reshape(-1, 3, 2),
    }


def _match(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """(F,) cyclic shift s with theirs[f, (c + s) % 3] == ours[f, c], -1 where none fits."""
    shift = np.full(len(ours), -1)
    scale = max(float(np.abs(ours).max()), 1e-12)
    for s in (2, 1, 0):  # 0 last, so it wins when several fit
        err = np.abs(np.roll(theirs, -s, axis=1) - ours).max(axis=(1, 2))
        shift[err <= 1e-5 * scale] = s
    return shift


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) angle between rows of ``a`` and ``b`` in degrees (90 where one is zero)."""
    norm = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    cos = np.einsum("ij,ij->i", a, b) / np.maximum(norm, 1e-30)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _welds_alike(pos, nrm, uv, b_nrm) -> np.ndarray:
    """(N,) True where Blender's corner normal is bit-identical across every corner we weld
    this one with (same written position, normal and UV), so MikkTSpace welds alike."""
    key = np.column_stack([pos, nrm]).astype(np.float32)
    key = np.column_stack([key, uv.astype(np.float32)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    b = b_nrm.astype(np.float32)
    same = (b == b[first[inverse.reshape(-1)]]).all(axis=1)
    bad_group = np.zeros(len(first), dtype=bool)
    bad_group[inverse.reshape(-1)[~same]] = True
    return ~bad_group[inverse.reshape(-1)]


def _stats(angle: np.ndarray, same_sign: np.ndarray) -> dict:
    """Corner count, max/mean angle, share within 0.5 and 1 degree, share of equal signs."""
    if not len(angle):
        return {"corners": 0}
    return {
        "corners": int(len(angle)),
        "max_angle_deg": float(angle.max()),
        "mean_angle_deg": float(angle.mean()),
        "within_0_5_deg": float(np.mean(angle <= 0.5)),
        "within_1_deg": float(np.mean(angle <= 1.0)),
        "sign_agreement": float(np.mean(same_sign)),
    }


def main() -> None:
    glb, expected = sys.argv[1], sys.argv[2]
    ours = np.load(expected)
    blend = _loops(_import_mesh(glb))
    if len(blend["positions"]) != len(ours["positions"]):
        raise SystemExit(
            f"Blender has {len(blend['positions'])} faces, we wrote {len(ours['positions'])}"
        )
    shift = _match(ours["positions"], blend["positions"])
    ok = shift >= 0
    idx = (np.arange(3)[None, :] + shift[:, None]) % 3
    rows = np.arange(len(shift))[:, None]
    b_tan = blend["tangents"][rows, idx][ok].reshape(-1, 3)
    b_sign = blend["signs"][rows, idx][ok].reshape(-1)
    o_tan = ours["tangents"][ok][..., :3].reshape(-1, 3)
    o_sign = ours["tangents"][ok][..., 3].reshape(-1)
    b_len = np.linalg.norm(b_tan, axis=1)
    angle = _angle_deg(o_tan, b_tan)
    normal_err = _angle_deg(ours["normals"][ok].reshape(-1, 3),
                            blend["normals"][rows, idx][ok].reshape(-1, 3))
    unwelded = (normal_err > 0.1) | ~_welds_alike(
        ours["positions"][ok].reshape(-1, 3), ours["normals"][ok].reshape(-1, 3),
        blend["uv"][rows, idx][ok].reshape(-1, 2), blend["normals"][rows, idx][ok].reshape(-1, 3))
    # A disagreement is "explained" where Blender's MikkTSpace got other input than the file
    # holds; the others are ours to answer for.
    explained = unwelded & (angle > 0.5)
    worst = np.argsort(-angle)[:8]
    corner_face = np.repeat(np.flatnonzero(ok), 3)
    result = {
        "faces": int(len(shift)),
        "faces_matched": int(ok.sum()),
        "blender_zero_tangents": int(np.count_nonzero(b_len < 1e-6)),
        "all": _stats(angle, o_sign == b_sign),
        "unexplained": _stats(angle[~explained], (o_sign == b_sign)[~explained]),
        "explained_faces": sorted({int(corner_face[i]) for i in np.flatnonzero(explained)}),
        "max_normal_error_deg": float(normal_err.max()) if len(normal_err) else 0.0,
        "worst": [
            {"face": int(corner_face[i]), "corner": int(i % 3), "angle_deg": float(angle[i]),
             "ours": o_tan[i].round(5).tolist(), "blender": b_tan[i].round(5).tolist(),
             "sign_ours": float(o_sign[i]), "sign_blender": float(b_sign[i]),
             "normal_error_deg": float(normal_err[i]), "explained": bool(explained[i])}
            for i in worst if angle[i] > 0.5
        ],
    }
    if len(sys.argv) > 3:
        np.savez(sys.argv[3], shift=shift, **blend)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
