"""Writing the bake's outputs: EXR masters, PNGs, the GLB, hashes and atomic output folders.

Image arrays are ``(H, W)`` or ``(H, W, C)`` with row 0 the top of the image, which is UV
``v = 1`` (OBJ/Blender convention); they are written as they are, never flipped.  Data maps are
linear, never sRGB.

EXR files are written with the OpenEXR Python bindings, which take one 2-D array per channel in
its own pixel type.  OpenImageIO needs one interleaved buffer (an extra 700 MB and ~0.5 s at
4096² x 11 channels) and was 2-2.5x slower on the mixed half/float bake with its default two
threads (see ``benchmarks/bench_exr.py``); it is kept as the independent reader in the tests.
8-bit PNGs are quantised in numpy and encoded by Pillow (faster than OIIO), 16-bit PNGs by
OpenImageIO.  The GLB is written by hand with :mod:`json` and :mod:`struct` so every accessor,
material and sampler field is ours to set.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import struct
import tempfile
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning

PathLike = str | os.PathLike

# ---------------------------------------------------------------------------------------------
# EXR

LOSSLESS_COMPRESSIONS = ("none", "zip", "zips", "piz", "rle", "zstd")
LOSSY_COMPRESSIONS = ("dwaa", "dwab", "b44", "b44a", "pxr24")

# Header attributes the EXR format itself owns; a custom attribute with one of these names would
# silently replace (or corrupt) the file's own.
_RESERVED_ATTRIBUTES = frozenset(
    {
        "channels", "compression", "dataWindow", "displayWindow", "lineOrder",
        "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth", "type", "tiles",
        "name", "version", "chunkCount", "maxSamplesPerPixel",
    }
)  # fmt: skip

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


def _openexr_compression(name: str):
    import OpenEXR

    key = str(name).lower()
    if key in LOSSY_COMPRESSIONS:
        raise CrackbakeError(
            f"EXR compression '{name}' is lossy and would change data values; "
            f"use one of {', '.join(LOSSLESS_COMPRESSIONS)} (zip is the default)"
        )
    table = {
        "none": OpenEXR.NO_COMPRESSION,
        "zip": OpenEXR.ZIP_COMPRESSION,
        "zips": OpenEXR.ZIPS_COMPRESSION,
        "piz": OpenEXR.PIZ_COMPRESSION,
        "rle": OpenEXR.RLE_COMPRESSION,
        "zstd": OpenEXR.ZSTD_COMPRESSION,
    }
    if key not in table:
        raise CrackbakeError(
            f"unknown EXR compression '{name}'; use one of {', '.join(LOSSLESS_COMPRESSIONS)}"
        )
    return table[key]


def _compression_name(value) -> str:
    # The bindings spell it ZIP_COMPRESSION; give back the name write_exr accepts.
    text = getattr(value, "name", str(value)).removesuffix("_COMPRESSION").lower()
    return "none" if text == "no" else text


def _header_value(name: str, value):
    if isinstance(value, bool) or not isinstance(
        value, str | int | float | np.integer | np.floating
    ):
        raise CrackbakeError(
            f"EXR attribute '{name}' has type {type(value).__name__}; "
            "pass a str, int or float (write other values as a JSON string)"
        )
    if isinstance(value, int | np.integer):
        if not _INT32_MIN <= int(value) <= _INT32_MAX:
            # The bindings silently store 0 for ints beyond 32 bits.
            raise CrackbakeError(
                f"EXR attribute '{name}' = {value} does not fit a 32-bit int; pass it as a string"
            )
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    return value


def write_exr(
    path: PathLike,
    channels: dict[str, np.ndarray],
    attributes: dict[str, str | int | float] | None = None,
    compression: str = "zip",
) -> None:
    """Write a single-part scanline EXR with named channels and custom header attributes.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; its folder must exist.
    channels : dict of str to (H, W) ndarray
        Channel name (e.g. ``"crack.mask"``, ``"normal.X"``) to pixels, row 0 = top of the image
        (UV ``v = 1``).  The dtype picks the EXR pixel type: float16 -> HALF, float32 -> FLOAT,
        uint32 -> UINT.  Arrays are not converted (converting big planes costs seconds); other
        dtypes are refused.
    attributes : dict of str to str, int or float, optional
        Extra header attributes, e.g. ``{"crackbake:version": "0.1.0"}``.  Ints are stored as
        32-bit ints and floats as 32-bit floats (the bindings have no double attribute); pass a
        string where more precision matters.
    compression : str
        One of ``none``, ``zip`` (default), ``zips``, ``piz``, ``rle``, ``zstd``.  The lossy
        methods (``dwaa``, ``dwab``, ``b44``, ``b44a``, ``pxr24``) are refused: they alter data.

    Raises
    ------
    CrackbakeError
        For empty or mismatched channels, unsupported dtypes, bad attributes, lossy or unknown
        compression, or when the file cannot be written.
    """
    import OpenEXR

    if not channels:
        raise CrackbakeError("write_exr got no channels; pass at least one (H, W) array")
    planes: dict[str, np.ndarray] = {}
    shape = None
    for name, arr in channels.items():
        arr = np.asarray(arr)
        if not isinstance(name, str) or not name:
            raise CrackbakeError(f"EXR channel name {name!r} is invalid; use a non-empty string")
        if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
            raise CrackbakeError(
                f"EXR channel '{name}' has shape {arr.shape}; pass one (H, W) array per channel"
            )
        if arr.dtype not in (np.float16, np.float32, np.uint32):
            raise CrackbakeError(
                f"EXR channel '{name}' has dtype {arr.dtype}; "
                "cast it to float16 (half), float32 (float) or uint32 (uint)"
            )
        if shape is None:
            shape = arr.shape
        elif arr.shape != shape:
            raise CrackbakeError(
                f"EXR channel '{name}' is {arr.shape[1]}x{arr.shape[0]} but the others are "
                f"{shape[1]}x{shape[0]}; bake every channel at the same resolution"
            )
        # The bindings size the data window from the array and read its buffer as C-ordered.
        planes[name] = np.ascontiguousarray(arr)

    header = {"compression": _openexr_compression(compression), "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        if not isinstance(key, str) or not key or key in _RESERVED_ATTRIBUTES:
            raise CrackbakeError(
                f"EXR attribute name {key!r} is reserved or invalid; "
                "use a prefixed name such as 'crackbake:version'"
            )
        header[key] = _header_value(key, value)

    try:
        # File() replaces the dict's values with Channel objects; `planes` is our own copy.
        # Thread count is left at the library default: more threads did not speed up this
        # write (measured on 2 and 16 cores).
        OpenEXR.File(header, planes).write(os.fspath(path))
    except (RuntimeError, ValueError, OSError) as exc:
        raise CrackbakeError(
            f"cannot write EXR '{path}': {str(exc).splitlines()[0] if str(exc) else exc}; "
            "check that the folder exists, is writable and has space"
        ) from exc


def read_exr(path: PathLike) -> tuple[dict[str, np.ndarray], dict]:
    """Read every channel of a (single-part or first-part) EXR with the OpenEXR bindings.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    channels : dict of str to (H, W) ndarray
        By name (files list channels sorted, not in write order); dtype float16, float32 or
        uint32 as stored.  Row 0 is the top of the image.
    header : dict
        The header as the bindings give it, except ``"compression"``, which is the lower-case
        name :func:`write_exr` accepts (``"zip"``, ``"none"``, ...).
    """
    import OpenEXR

    try:
        with OpenEXR.File(os.fspath(path), separate_channels=True) as f:
            part = f.parts[0]
            channels = {name: np.asarray(ch.pixels) for name, ch in part.channels.items()}
            header = dict(part.header)
    except (RuntimeError, ValueError, OSError) as exc:
        raise CrackbakeError(
            f"cannot read EXR '{path}': {str(exc).splitlines()[0] if str(exc) else exc}; "
            "check the path and that the file is a complete OpenEXR image"
        ) from exc
    if "compression" in header:
        header["compression"] = _compression_name(header["compression"])
    return channels, header


# ---------------------------------------------------------------------------------------------
# PNG

_OUT_OF_RANGE_TOLERANCE = 1e-3


def _checked_float(image: np.ndarray, bits: int, path: PathLike) -> np.ndarray:
    """Float32 ``image``; NaN and values clearly outside [0, 1] replaced/clipped with a warning."""
    if image.dtype.kind != "f":
        raise CrackbakeError(
            f"PNG '{path}': got {image.dtype} for a {bits}-bit PNG; pass floats in [0, 1] "
            f"or {'uint8' if bits == 8 else 'uint16'} values"
        )
    if image.dtype != np.float32:
        image = image.astype(np.float32)
    lo, hi = float(image.min()), float(image.max())
    # NaN makes min/max NaN, so this comparison also catches it.
    if not (lo >= -_OUT_OF_RANGE_TOLERANCE and hi <= 1.0 + _OUT_OF_RANGE_TOLERANCE):
        bad = int(np.count_nonzero(~((image >= 0.0) & (image <= 1.0))))
        warnings.warn(
            f"{Path(path).name}: {bad} values outside [0, 1] (min {lo:.4g}, max {hi:.4g}) were "
            "clipped; remap the data (e.g. n*0.5+0.5 for normals) before writing",
            CrackbakeWarning,
            stacklevel=4,
        )
        image = np.nan_to_num(image, nan=0.0)
    # Values still outside are clamped by the quantisation (ours for 8 bit, OIIO's for 16 bit),
    # which saves a full-image copy on the common in-range path.
    return image


def _to_uint8(image: np.ndarray, path: PathLike) -> np.ndarray:
    if image.dtype == np.uint8:
        return image
    q = _checked_float(image, 8, path) * np.float32(255.0)
    q += np.float32(0.5)  # round half up, as OIIO does for 16 bit
    np.clip(q, 0.0, 255.0, out=q)
    return q.astype(np.uint8)


def write_png(
    path: PathLike, image: np.ndarray, bits: int = 8, compression_level: int | None = None
) -> None:
    """Write a linear (no sRGB transform) 8- or 16-bit PNG.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; its folder must exist.
    image : (H, W) or (H, W, C) ndarray, C in 1..4
        Floats in [0, 1], row 0 = top of the image.  Values outside are clipped, with a
        :class:`~crackbake.io.mesh.CrackbakeWarning` when any was outside by more than 1e-3 (NaN
        is written as 0, also with the warning).  Already-quantised ``uint8`` (``bits=8``) or
        ``uint16`` (``bits=16``) arrays are written unchanged.  (H, W) and (H, W, 1) give a
        one-channel grey PNG.
    bits : {8, 16}
        8 bit is quantised in numpy and encoded by Pillow (measured faster than OIIO); 16 bit is
        written by OpenImageIO (Pillow cannot write 16-bit RGB).
    compression_level : int, optional
        zlib level 0..9; 6 when ``None``.  Level 1 is ~1.3x faster for a larger file.
    """
    if bits not in (8, 16):
        raise CrackbakeError(f"PNG bit depth {bits} is not supported; use 8 or 16")
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if not (image.ndim == 2 or (image.ndim == 3 and 1 <= image.shape[2] <= 4)) or 0 in image.shape:
        raise CrackbakeError(
            f"PNG '{path}': image shape {image.shape} is not (H, W) or (H, W, C) with C in 1..4"
        )
    if compression_level is not None and not 0 <= int(compression_level) <= 9:
        raise CrackbakeError(f"PNG compression level {compression_level} is invalid; use 0..9")
    target = os.fspath(path)
    if bits == 8:
        _write_png8_pillow(target, _to_uint8(image, path), compression_level)
    else:
        if image.dtype != np.uint16:
            image = _checked_float(image, 16, path)
        _write_png16_oiio(target, image, compression_level)


def _write_png8_pillow(target: str, pixels: np.ndarray, level: int | None) -> None:
    from PIL import Image

    nchan = 1 if pixels.ndim == 2 else pixels.shape[2]
    mode = {1: "L", 2: "LA", 3: "RGB", 4: "RGBA"}[nchan]
    try:
        Image.fromarray(np.ascontiguousarray(pixels), mode).save(
            target, format="PNG", compress_level=6 if level is None else int(level)
        )
    except OSError as exc:
        raise CrackbakeError(
            f"cannot write PNG '{target}': {exc.strerror or exc}; "
            "check that the folder exists and is writable"
        ) from exc


def _write_png16_oiio(target: str, pixels: np.ndarray, level: int | None) -> None:
    import OpenImageIO as oiio

    if pixels.ndim == 2:
        # OIIO's Python write_image misreads 2-D arrays (measured): give it (H, W, 1).
        pixels = pixels[:, :, None]
    pixels = np.ascontiguousarray(pixels)
    h, w, nchan = pixels.shape
    spec = oiio.ImageSpec(w, h, nchan, "uint16")
    if level is not None:
        spec.attribute("png:compressionLevel", int(level))
    out = oiio.ImageOutput.create(target)
    ok = out is not None and out.open(target, spec) and out.write_image(pixels)
    error = "" if ok else (out.geterror() if out is not None else oiio.geterror())
    if out is not None:
        ok = out.close() and ok
    if not ok:
        raise CrackbakeError(
            f"cannot write PNG '{target}': {error.strip().splitlines()[0] if error else 'failed'}; "
            "check that the folder exists and is writable"
        )


def _png_bytes(image: np.ndarray, what: str) -> bytes:
    """Encode an (H, W, C) uint8 texture for embedding (Pillow writes to memory directly)."""
    from PIL import Image

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise CrackbakeError(
            f"GLB {what} texture must be (H, W, 3) or (H, W, 4) uint8, got {image.shape} "
            f"{image.dtype}; quantise it to 8 bits first"
        )
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image), "RGB" if image.shape[2] == 3 else "RGBA").save(
        buf, format="PNG", compress_level=6
    )
    return buf.getvalue()


# ---------------------------------------------------------------------------------------------
# GLB

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
    base_color : (H, W, 3) or (H, W, 4) uint8
        sRGB base colour, row 0 = top; embedded as PNG.
    name : str
        Mesh, node and material name.
    extra_textures : dict, optional
        More (H, W, 3|4) uint8 maps, embedded as PNG, keyed by material slot: ``"normal"``
        (tangent-space, OpenGL Y+, linear), ``"occlusion"`` (R channel, linear) and
        ``"metallic_roughness"`` (G = roughness, B = metallic, linear; the factors become 1).
    tangents : (V, 4) float, optional
        MikkTSpace tangents, xyz unit and w = +-1 the bitangent sign; written as TANGENT.

    Notes
    -----
    Material: metallic 0, roughness 0.8 (unless a metallic-roughness map is given), one sampler
    with linear filtering, trilinear mipmaps and REPEAT wrapping (glTF's default).
    """
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

    def add_texture(image: np.ndarray, what: str) -> int:
        images.append({"bufferView": b.view(_png_bytes(image, what)), "mimeType": "image/png"})
        textures.append({"sampler": 0, "source": len(images) - 1})
        return len(textures) - 1

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

    from crackbake import __version__

    binary = b.binary()
    gltf = {
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
        "buffers": [{"byteLength": len(binary)}],
    }
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


# ---------------------------------------------------------------------------------------------
# Hashes and atomic output folders


def sha256_file(path: PathLike) -> str:
    """Hex SHA-256 of a file's bytes, read in chunks (no whole-file copy in memory)."""
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


_STAGE_PREFIX = ".crackbake-staging-"


class OutputStage:
    """Atomic writes into an output folder.

    ::

        with OutputStage(out_dir) as stage:
            write_exr(stage.path("cracks.exr"), ...)
            records = stage.records()           # name, bytes, sha256 of what is staged
            write_manifest(stage.path("manifest.json"), records)
            stage.commit(last=("manifest.json",))

    Files are written into a hidden staging folder inside ``out_dir`` (same filesystem, so the
    final :func:`os.replace` is atomic per file).  :meth:`commit` moves every file in the staging
    folder onto its final name, the names in ``last`` after all others, so a manifest present in
    ``out_dir`` means the files it lists are complete.  Leaving the block without commit (an
    exception included) removes the staging folder and touches no final name.

    A hard kill (SIGKILL, power loss) can leave a ``.crackbake-staging-*`` folder behind; it is
    safe to delete.
    """

    def __init__(self, out_dir: PathLike) -> None:
        self.out_dir = Path(out_dir)
        self._staging: Path | None = None
        self._committed = False
        self._hashes: dict[str, tuple[tuple[int, int], str]] = {}

    def __enter__(self) -> OutputStage:
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            self._staging = Path(tempfile.mkdtemp(prefix=_STAGE_PREFIX, dir=self.out_dir))
        except OSError as exc:
            raise CrackbakeError(
                f"cannot create output folder '{self.out_dir}': {exc.strerror}; "
                "choose a writable location with --out"
            ) from exc
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.discard()

    @property
    def staging_dir(self) -> Path:
        if self._staging is None or self._committed:
            raise CrackbakeError(
                "OutputStage is not open; use it as `with OutputStage(out_dir) as stage:` "
                "and stage files before commit()"
            )
        return self._staging

    def path(self, name: str) -> Path:
        """Temporary path in the staging folder for the final file ``out_dir / name``."""
        if (
            not isinstance(name, str)
            or not name
            or name in (".", "..")
            or Path(name).name != name
            or "/" in name
            or "\\" in name
        ):
            raise CrackbakeError(
                f"output name {name!r} is not a plain file name; pass a name without folders"
            )
        return self.staging_dir / name

    def _staged(self) -> list[os.DirEntry]:
        with os.scandir(self.staging_dir) as it:
            return sorted((e for e in it if e.is_file(follow_symlinks=False)), key=lambda e: e.name)

    def records(self) -> list[dict]:
        """``[{"name", "bytes", "sha256"}]`` of the files staged so far, sorted by name.

        Hashes are cached by (size, mtime), so calling again only hashes files that changed.
        """
        out = []
        for entry in self._staged():
            st = entry.stat(follow_symlinks=False)
            key = (st.st_size, st.st_mtime_ns)
            cached = self._hashes.get(entry.name)
            if cached is None or cached[0] != key:
                cached = (key, sha256_file(entry.path))
                self._hashes[entry.name] = cached
            out.append({"name": entry.name, "bytes": int(st.st_size), "sha256": cached[1]})
        return out

    def commit(self, last: Iterable[str] = ("manifest.json",)) -> list[Path]:
        """Move every staged file onto its final name (``last`` ones last); return final paths.

        Names in ``last`` that were never staged are skipped.
        """
        entries = self._staged()
        last = [n for n in last if any(e.name == n for e in entries)]
        order = [e.name for e in entries if e.name not in last] + last
        moved = []
        try:
            for name in order:
                final = self.out_dir / name
                os.replace(self.staging_dir / name, final)
                moved.append(final)
        except OSError as exc:
            raise CrackbakeError(
                f"cannot move '{name}' into '{self.out_dir}': {exc.strerror}; "
                "remove or rename what is in the way and run again"
            ) from exc
        self.discard()
        self._committed = True
        return moved

    def discard(self) -> None:
        """Remove the staging folder and everything in it (no final name is touched)."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None
