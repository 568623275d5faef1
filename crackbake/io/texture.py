"""The asset's own base-colour texture: OBJ ``map_Kd`` or glTF/GLB ``baseColorTexture``.

The output files composite the cracks over it, so the result keeps the asset's look.  Only the
small text of the file is parsed (OBJ ``mtllib``/``usemtl`` lines, the glTF JSON): the geometry
is never read twice.  The texture is returned resampled to the bake's square page with row 0 the
top of the image, which is ``v = 1`` in both OBJ and glTF (glTF's ``v`` runs down from the top
of the image, trimesh flips it to ``v`` up on load), so texels line up with the baked maps.
"""

from __future__ import annotations

import base64
import io
import json
import struct
import urllib.parse
import warnings
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeWarning

# map_Kd options and how many values follow each (the file name comes after them).
_MTL_OPTIONS = {
    "-blendu": 1, "-blendv": 1, "-boost": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3,
    "-texres": 1, "-clamp": 1, "-bm": 1, "-imfchan": 1, "-type": 1, "-cc": 1,
}  # fmt: skip


def base_color_texture(mesh_path: str | Path, res: int) -> np.ndarray | None:
    """The asset's base-colour texture at ``res`` x ``res``, or ``None`` when it has none.

    Parameters
    ----------
    mesh_path : str or Path
        The mesh file (OBJ with an MTL ``map_Kd``, glTF or GLB with a ``baseColorTexture``).
    res : int
        Edge of the returned page in texels (the bake resolution).

    Returns
    -------
    (res, res, 3) uint8 or None
        sRGB colour, row 0 = top (``v = 1``).  ``None`` (with a :class:`CrackbakeWarning` when
        a texture was named but cannot be used: missing file, several different textures on
        one mesh) for meshes without one.
    """
    path = Path(mesh_path)
    suffix = path.suffix.lower()
    if not path.is_file():  # meshes built in memory name a source that is not a file
        return None
    try:
        if suffix == ".obj":
            found = _obj_texture(path)
        elif suffix in (".gltf", ".glb"):
            found = _gltf_texture(path)
        else:
            return None
    except (OSError, ValueError, KeyError, IndexError, TypeError, struct.error) as exc:
        _warn(f"{path.name}: its base-colour texture could not be read ({exc}); using grey")
        return None
    if found is None:
        return None
    return _resampled(found, res, path)


def _warn(message: str) -> None:
    warnings.warn(message, CrackbakeWarning, stacklevel=4)


#: Largest base-colour texture read, pixels (11585² as 8-bit RGB is 400 MB).  The bake's page is at
#: most 16384², but a texture that large is rare and a header can claim any size (a 74-byte PNG
#: declared 20000²), so bigger ones give grey with a warning naming the size.
TEXTURE_PIXELS_MAX = 2**27


def _resampled(source: bytes | Path, res: int, mesh_path: Path) -> np.ndarray | None:
    from PIL import Image, UnidentifiedImageError

    name = source.name if isinstance(source, Path) else "embedded image"
    try:
        with warnings.catch_warnings():  # the size check below replaces Pillow's bomb warning
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            img = Image.open(io.BytesIO(source) if isinstance(source, bytes) else source)
        w, h = img.size
        if w * h > TEXTURE_PIXELS_MAX:
            _warn(f"{mesh_path.name}: base-colour texture {name} is {w}x{h}, over the "
                  f"{TEXTURE_PIXELS_MAX:,} pixels crackbake reads; using grey (shrink the "
                  "texture to the bake's --res)")
            return None
        img.draft("RGB", (res, res))  # JPEG decodes at 1/2..1/8 scale when that suffices
        img.load()
    except (OSError, ValueError, SyntaxError, EOFError, MemoryError,
            Image.DecompressionBombError, UnidentifiedImageError) as exc:
        _warn(f"{mesh_path.name}: base-colour texture {name} is unreadable ({exc}); using grey")
        return None
    if img.mode not in ("RGB", "RGBA", "L", "LA", "P"):
        img = img.convert("RGBA")  # 16-bit and float images: Pillow scales them to 8 bit here
    img = img.convert("RGB")
    if img.size != (res, res):
        # Lanczos keeps texture detail when upsampling and filters aliasing when shrinking.
        img = img.resize((res, res), Image.Resampling.LANCZOS)
    return np.asarray(img, dtype=np.uint8)


def _obj_texture(path: Path) -> Path | None:
    data = path.read_bytes()
    libs = _directive(data, b"mtllib")
    used = set(_directive(data, b"usemtl"))
    maps: dict[str, Path] = {}
    for lib in libs:
        mtl = path.parent / lib
        if not mtl.is_file():
            continue
        maps.update(_mtl_maps(mtl))
    files = {maps[m] for m in (used or set(maps)) if m in maps}
    return _one(files, path)


def _directive(data: bytes, word: bytes) -> list[str]:
    """The values of the OBJ lines ``word value`` (leading blanks allowed), in file order.

    Jumps between occurrences of ``word`` with ``bytes.find`` (memchr speed): a multi-line
    regex over a 1.5M-face OBJ took 0.8 s per directive.
    """
    out = []
    pos = data.find(word)
    while pos >= 0:
        start = pos
        while start > 0 and data[start - 1] in b" \t":
            start -= 1
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        line = data[pos + len(word):end]
        if (start == 0 or data[start - 1] in b"\r\n") and line[:1] in (b" ", b"\t"):
            value = line.decode("utf-8", errors="replace").strip(" \t\r")
            if value:
                out.append(value)
        pos = data.find(word, end)
    return out


def _mtl_maps(mtl: Path) -> dict[str, Path]:
    """Material name -> its ``map_Kd`` file, from one MTL file."""
    out: dict[str, Path] = {}
    current = None
    for line in mtl.read_text("utf-8", errors="replace").splitlines():
        parts = line.strip().split()
        if not parts:
            continue
        key = parts[0].lower()
        if key == "newmtl" and len(parts) > 1:
            current = " ".join(parts[1:])
        elif key == "map_kd" and current is not None and len(parts) > 1:
            args = parts[1:]
            while args and args[0].lower() in _MTL_OPTIONS:
                args = args[1 + _MTL_OPTIONS[args[0].lower()] :]
            if args:
                out[current] = (mtl.parent / " ".join(args).replace("\\", "/")).resolve()
    return out


def _one(files: set, path: Path):
    """The single texture of a mesh; warn and give None when its materials use several."""
    if len(files) > 1:
        _warn(
            f"{path.name}: its materials use {len(files)} different base-colour textures; the "
            "outputs use one neutral grey (bake a single-material mesh to keep its colours)"
        )
        return None
    if not files:
        return None
    found = next(iter(files))
    if isinstance(found, Path) and not found.is_file():
        _warn(f"{path.name}: base-colour texture {found.name} not found; using grey")
        return None
    return found


def _gltf_texture(path: Path) -> bytes | Path | None:
    data = path.read_bytes()
    binary = None
    if path.suffix.lower() == ".glb":
        _magic, _version, _length = struct.unpack_from("<III", data, 0)
        jlen, _ = struct.unpack_from("<II", data, 12)
        doc = json.loads(data[20 : 20 + jlen])
        if len(data) > 28 + jlen:
            blen, _ = struct.unpack_from("<II", data, 20 + jlen)
            binary = data[28 + jlen : 28 + jlen + blen]
    else:
        doc = json.loads(data)
    used = {
        prim["material"]
        for mesh in doc.get("meshes", [])
        for prim in mesh.get("primitives", [])
        if "material" in prim
    }
    images = set()
    for m in sorted(used):
        ref = doc["materials"][m].get("pbrMetallicRoughness", {}).get("baseColorTexture")
        if ref is not None:
            images.add(doc["textures"][ref["index"]].get("source"))
    images.discard(None)
    chosen = _one(images, path)
    if chosen is None:
        return None
    return _gltf_image(doc, chosen, path, binary)


def _gltf_image(doc: dict, index: int, path: Path, binary: bytes | None) -> bytes | Path:
    image = doc["images"][index]
    if "bufferView" in image:
        view = doc["bufferViews"][image["bufferView"]]
        start = view.get("byteOffset", 0)
        buffer = doc["buffers"][view["buffer"]]
        blob = binary if "uri" not in buffer else _uri_bytes(buffer["uri"], path)
        return bytes(blob[start : start + view["byteLength"]])
    uri = image["uri"]
    if uri.startswith("data:"):
        return _uri_bytes(uri, path)
    return path.parent / urllib.parse.unquote(uri)


def _uri_bytes(uri: str, path: Path) -> bytes:
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    return (path.parent / urllib.parse.unquote(uri)).read_bytes()
