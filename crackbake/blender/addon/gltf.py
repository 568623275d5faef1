"""The UVs of the GLB crackbake writes (``--uv unwrap``): its one primitive's TEXCOORD_0 and
triangles, in the input's face order (crackbake keeps it)."""

from __future__ import annotations

import json
import struct

import numpy as np

_COMPONENTS = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def read_uv_triangles(path: str) -> tuple[np.ndarray, np.ndarray]:
    """``(uv, faces)``: (N, 2) float UVs with v up (Blender's and crackbake's convention; glTF
    stores 1 - v) and (M, 3) vertex indices of the GLB's mesh."""
    with open(path, "rb") as fh:
        data = fh.read()
    magic, _version, _length = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF":
        raise ValueError(f"{path} is not a GLB")
    json_len, json_type = struct.unpack_from("<I4s", data, 12)
    doc = json.loads(data[20:20 + json_len])
    bin_start = 20 + json_len + 8
    blob = data[bin_start:]
    prim = doc["meshes"][0]["primitives"][0]

    def accessor(index: int) -> np.ndarray:
        acc = doc["accessors"][index]
        view = doc["bufferViews"][acc["bufferView"]]
        width = _WIDTH[acc["type"]]
        offset = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        values = np.frombuffer(blob, _COMPONENTS[acc["componentType"]], acc["count"] * width,
                               offset)
        return values.reshape(acc["count"], width)

    uv = accessor(prim["attributes"]["TEXCOORD_0"]).astype(np.float64)
    faces = accessor(prim["indices"]).reshape(-1, 3).astype(np.int64)
    uv[:, 1] = 1.0 - uv[:, 1]
    return uv, faces
