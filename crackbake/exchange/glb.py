"""Binary glTF 2.0 (GLB): the output mesh with its UVs, normals, tangents and maps bound.

Written by hand with :mod:`json` and :mod:`struct` so every accessor, material and sampler field
is ours to set.  Embedded textures are PNGs encoded in memory by Pillow.
"""

from __future__ import annotations

import json
import os
import struct

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.exchange.pngenc import png_bytes

PathLike = str | os.PathLike

_GLB_MAGIC = 0x46546C67  # "glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT = 5126
_UNSIGNED_INT = 5125
_LINEAR = 9729
_LINEAR_MIPMAP_LINEAR = 9987
_REPEAT = 10497
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

# extra_textures key -> how the material binds it
_EXTRA_TEXTURE_SLOTS = ("normal", "occlusion", "metallic_roughness")


class _GlbBuilder:
    """Accumulates 4-byte-aligned buffer views and accessors for one binary buffer."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.offset = 0
        self.buffer_views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        view = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.buffer_views.append(view)
        pad = (-len(data)) % 4
        self.blobs.append(data + b"\0" * pad)
        self.offset += len(data) + pad
        return len(self.buffer_views) - 1

    def accessor(self, array: np.ndarray, kind: str, target: int, minmax: bool = False) -> int:
        component = _UNSIGNED_INT if array.dtype == np.uint32 else _FLOAT
        acc = {
            "bufferView": self.view(np.ascontiguousarray(array).tobytes(), target),
            "componentType": component,
            "count": int(array.shape[0]),
            "type": kind,
        }
        if minmax:
            # Must be the stored (float32) values, or validators flag them.
            acc["min"] = [float(x) for x in array.min(axis=0)]
            acc["max"] = [float(x) for x in array.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def binary(self) -> bytes:
        return b"".join(self.blobs)


def _vertex_array(name: str, arr, n: int | None, width: int) -> np.ndarray:
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != width or (n is not None and a.shape[0] != n):
        want = f"({n if n is not None else 'V'}, {width})"
        raise CrackbakeError(f"GLB {name} has shape {a.shape}, expected {want}; one row per vertex")
    if not np.all(np.isfinite(a)):
        raise CrackbakeError(f"GLB {name} contains NaN or inf; fix the mesh before exporting")
    return a


def _png_bytes(image: np.ndarray | bytes, what: str) -> bytes:
    """PNG bytes of an (H, W, C) uint8 texture, or ``image`` itself when already PNG bytes."""
    if isinstance(image, bytes | bytearray | memoryview):
        data = bytes(image)
        if not data.startswith(_PNG_SIGNATURE):
            raise CrackbakeError(f"GLB {what} texture bytes are not a PNG; pass PNG bytes")
        return data
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise CrackbakeError(
            f"GLB {what} texture must be (H, W, 3) or (H, W, 4) uint8, got {image.shape} "
            f"{image.dtype}; quantise it to 8 bits first"
        )
    return png_bytes(image, srgb=what == "base colour")


def write_glb(
    path: PathLike,
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    normals: np.ndarray,
    base_color: np.ndarray,
    name: str = "crackbake",
    extra_textures: dict[str, np.ndarray] | None = None,
    tangents: np.ndarray | None = None,
    material_extras: dict | None = None,
) -> None:
    """Write the output mesh and its maps as one binary glTF 2.0 file.

    Parameters
    ----------
    path : str or os.PathLike
    vertices : (V, 3) float
        Positions, mesh units (written as float32).
    faces : (F, 3) int
        Counter-clockwise triangles (written as uint32 indices).
    uv : (V, 2) float
        Texture coordinates with ``v`` up (OBJ/Blender); written as ``(u, 1 - v)``, glTF's
        convention, so image row 0 (top) lands at ``v = 1`` as everywhere in crackbake.
    normals : (V, 3) float
        Vertex normals; renormalised (zero ones become +Z, glTF requires unit length).
    base_color : (H, W, 3) or (H, W, 4) uint8, or PNG bytes
        sRGB base colour, row 0 = top; embedded as PNG (bytes are embedded as they are).
    name : str
        Mesh, node and material name.
    extra_textures : dict, optional
        More (H, W, 3|4) uint8 maps or PNG bytes, keyed by material slot: ``"normal"``
        (tangent-space, OpenGL Y+, linear), ``"occlusion"`` (R channel, linear) and
        ``"metallic_roughness"`` (G = roughness, B = metallic, linear; the factors become 1).
        Passing the same object for ``"occlusion"`` and ``"metallic_roughness"`` (an ORM map)
        embeds it once and binds it to both.
    tangents : (V, 4) float, optional
        MikkTSpace tangents, xyz unit and w = +-1 the bitangent sign; written as TANGENT.
    material_extras : dict, optional
        JSON-ready application data stored as the material's ``extras`` (crackbake writes
        ``{"crackbake_look": {...}}``: how the cracks were composited, so a tool can tell bright
        glass lines from dark grooves without decoding the textures).

    Notes
    -----
    Material: metallic 0, roughness 0.8 (unless a metallic-roughness map is given), one sampler
    with linear filtering, trilinear mipmaps and REPEAT wrapping (glTF's default).
    """
    v, f, t, nrm, tan = _checked_mesh(vertices, faces, uv, normals, tangents)
    extra = dict(extra_textures or {})
    unknown = sorted(set(extra) - set(_EXTRA_TEXTURE_SLOTS))
    if unknown:
        raise CrackbakeError(
            f"GLB extra texture(s) {', '.join(unknown)} not supported; "
            f"use {', '.join(_EXTRA_TEXTURE_SLOTS)}"
        )

    b = _GlbBuilder()
    attributes = {
        "POSITION": b.accessor(v.astype(np.float32), "VEC3", _ARRAY_BUFFER, minmax=True),
        "NORMAL": b.accessor(nrm.astype(np.float32), "VEC3", _ARRAY_BUFFER),
        "TEXCOORD_0": b.accessor(
            np.column_stack([t[:, 0], 1.0 - t[:, 1]]).astype(np.float32), "VEC2", _ARRAY_BUFFER
        ),
    }
    if tan is not None:
        attributes["TANGENT"] = b.accessor(tan.astype(np.float32), "VEC4", _ARRAY_BUFFER)
    indices = b.accessor(f.astype(np.uint32).reshape(-1), "SCALAR", _ELEMENT_ARRAY_BUFFER)
    images: list[dict] = []
    textures: list[dict] = []
    material = _material(b, images, textures, name, base_color, extra)
    if material_extras:
        material["extras"] = dict(material_extras)
    binary = b.binary()
    gltf = _gltf_document(name, attributes, indices, material, images, textures, b, len(binary))
    _write_chunks(path, gltf, binary)


def _checked_mesh(vertices, faces, uv, normals, tangents):
    """Validated float64 positions, faces, UVs, unit normals and tangents (or None)."""
    v = _vertex_array("vertices", vertices, None, 3)
    n_vert = v.shape[0]
    if n_vert == 0:
        raise CrackbakeError("GLB export got a mesh with no vertices; check the input mesh")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0 or f.dtype.kind not in "iu":
        raise CrackbakeError(f"GLB faces have shape {f.shape} {f.dtype}; expected (F, 3) integers")
    if f.min() < 0 or f.max() >= n_vert:
        raise CrackbakeError(
            f"GLB faces index vertices outside 0..{n_vert - 1}; the faces do not match the vertices"
        )
    t = _vertex_array("uv", uv, n_vert, 2)
    nrm = _vertex_array("normals", normals, n_vert, 3)
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(length > 1e-12, nrm / np.where(length > 1e-12, length, 1.0), [0.0, 0.0, 1.0])
    tan = None if tangents is None else _vertex_array("tangents", tangents, n_vert, 4)
    return v, f, t, nrm, tan


def _material(
    b: _GlbBuilder,
    images: list[dict],
    textures: list[dict],
    name: str,
    base_color: np.ndarray,
    extra: dict[str, np.ndarray],
) -> dict:
    """The PBR material; embeds its textures, appending to ``images`` and ``textures``."""

    added: dict[int, int] = {}

    def add_texture(image: np.ndarray | bytes, what: str) -> int:
        # The same object given for two slots (an ORM map for occlusion and
        # metallic-roughness, as glTF allows) is embedded once and shared.
        if id(image) not in added:
            images.append({"bufferView": b.view(_png_bytes(image, what)), "mimeType": "image/png"})
            textures.append({"sampler": 0, "source": len(images) - 1})
            added[id(image)] = len(textures) - 1
        return added[id(image)]

    pbr: dict = {
        "baseColorTexture": {"index": add_texture(base_color, "base colour")},
        "metallicFactor": 0.0,
        "roughnessFactor": 0.8,
    }
    material: dict = {"name": name, "pbrMetallicRoughness": pbr}
    if "metallic_roughness" in extra:
        pbr["metallicRoughnessTexture"] = {
            "index": add_texture(extra["metallic_roughness"], "metallic_roughness")
        }
        pbr["metallicFactor"] = 1.0
        pbr["roughnessFactor"] = 1.0
    if "normal" in extra:
        material["normalTexture"] = {"index": add_texture(extra["normal"], "normal")}
    if "occlusion" in extra:
        material["occlusionTexture"] = {"index": add_texture(extra["occlusion"], "occlusion")}
    return material


def _gltf_document(
    name: str,
    attributes: dict,
    indices: int,
    material: dict,
    images: list[dict],
    textures: list[dict],
    b: _GlbBuilder,
    byte_length: int,
) -> dict:
    """The glTF JSON: one scene, one node, one mesh with one primitive, one sampler."""
    from crackbake import __version__

    return {
        "asset": {"version": "2.0", "generator": f"crackbake {__version__}"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": name}],
        "meshes": [
            {
                "name": name,
                "primitives": [
                    {"attributes": attributes, "indices": indices, "material": 0, "mode": 4}
                ],
            }
        ],
        "materials": [material],
        "samplers": [
            {
                "magFilter": _LINEAR,
                "minFilter": _LINEAR_MIPMAP_LINEAR,
                "wrapS": _REPEAT,
                "wrapT": _REPEAT,
            }
        ],
        "images": images,
        "textures": textures,
        "accessors": b.accessors,
        "bufferViews": b.buffer_views,
        "buffers": [{"byteLength": byte_length}],
    }


def _write_chunks(path: PathLike, gltf: dict, binary: bytes) -> None:
    """Header, JSON chunk (space-padded) and BIN chunk."""
    json_bytes = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    json_bytes += b" " * ((-len(json_bytes)) % 4)  # the spec pads JSON with spaces
    total = 12 + 8 + len(json_bytes) + 8 + len(binary)
    try:
        with open(path, "wb") as fh:
            fh.write(struct.pack("<III", _GLB_MAGIC, 2, total))
            fh.write(struct.pack("<II", len(json_bytes), _CHUNK_JSON))
            fh.write(json_bytes)
            fh.write(struct.pack("<II", len(binary), _CHUNK_BIN))
            fh.write(binary)
    except OSError as exc:
        raise CrackbakeError(
            f"cannot write GLB '{path}': {exc.strerror}; check the folder exists and is writable"
        ) from exc
