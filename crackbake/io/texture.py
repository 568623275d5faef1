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
import os
import struct
import urllib.parse
import warnings
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.safe_open import NotRegularFile, inside, read_bytes, read_text

# Largest MTL file read (they hold a few lines per material).
MTL_MAX_BYTES = 64 << 20

# map_Kd options and how many values follow each (the file name comes after them).
_MTL_OPTIONS = {
    "-blendu": 1, "-blendv": 1, "-boost": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3,
    "-texres": 1, "-clamp": 1, "-bm": 1, "-imfchan": 1, "-type": 1, "-cc": 1,
}  # fmt: skip


def base_color_texture(
    mesh_path: str | Path, res: int, allow_outside: bool = False
) -> np.ndarray | None:
    """The asset's base-colour texture at ``res`` x ``res``, or ``None`` when it has none.

    Parameters
    ----------
    mesh_path : str or Path
        The mesh file (OBJ with an MTL ``map_Kd``, glTF or GLB with a ``baseColorTexture``).
    res : int
        Edge of the returned page in texels (the bake resolution).
    allow_outside : bool
        Read material libraries and textures outside the mesh's folder (``../``, absolute
        paths, symlinks out of it).  By default they are refused with a warning naming the
        path, and the outputs use grey: an asset from elsewhere must not make crackbake read
        (and embed) any file on the machine.

    Returns
    -------
    (res, res, 3) uint8 or None
        sRGB colour, row 0 = top (``v = 1``).  ``None`` (with a :class:`CrackbakeWarning` when
        a texture was named but cannot be used: missing file, outside the mesh's folder, not a
        regular file, several different textures on one mesh) for meshes without one.
    """
    path = Path(mesh_path)
    suffix = path.suffix.lower()
    if not path.is_file():  # meshes built in memory name a source that is not a file
        return None
    try:
        if suffix == ".obj":
            found = _obj_texture(path, allow_outside)
        elif suffix in (".gltf", ".glb"):
            found = _gltf_texture(path, allow_outside)
        else:
            return None
        name = found.name if isinstance(found, Path) else "embedded image"
        if isinstance(found, Path):
            found = read_bytes(found, f"{path.name}: its base-colour texture {found}")
    except _Outside as exc:
        where = "" if exc.target == exc.name else f" ({exc.target})"
        _warn(
            f"{path.name}: {exc.what} '{exc.name}'{where} lies outside the mesh's folder, so it "
            "was not read; using grey for the base colour (move it beside the mesh, or pass "
            "--allow-outside-textures to read it)"
        )
        return None
    except NotRegularFile as exc:  # a FIFO or device named as a texture or material library
        _warn(f"{exc.label} is {exc.what}, not a regular file, so it was not read; using grey "
              "for the base colour")
        return None
    except CrackbakeError as exc:  # e.g. an MTL file too big to be one
        _warn(f"{exc}; using grey for the base colour")
        return None
    except (OSError, ValueError, KeyError, IndexError, TypeError, struct.error) as exc:
        _warn(f"{path.name}: its base-colour texture could not be read ({exc}); using grey")
        return None
    if found is None:
        return None
    return _resampled(found, res, path, name)


def _warn(message: str) -> None:
    warnings.warn(message, CrackbakeWarning, stacklevel=4)


class _Outside(Exception):
    """A path the mesh names that leads out of its folder (``target``: where it leads)."""

    def __init__(self, name: str, target: str, what: str) -> None:
        super().__init__(name)
        self.name, self.target, self.what = name, target, what


def _named(
    mesh_path: Path, base: Path, name: str, allow_outside: bool, what: str = "base-colour texture"
) -> Path:
    """The file ``name`` (as the mesh, or its MTL in ``base``, spells it), made absolute.

    Raises
    ------
    _Outside
        It leads out of the mesh's folder (and ``allow_outside`` is off).
    """
    target = Path(os.path.abspath(base / name))
    if not allow_outside and inside(mesh_path.parent, target) is None:
        raise _Outside(name, os.path.realpath(target), what)
    return target


#: Largest base-colour texture read, pixels (11585² as 8-bit RGB is 400 MB).  The bake's page is at
#: most 16384², but a texture that large is rare and a header can claim any size (a 74-byte PNG
#: declared 20000²), so bigger ones give grey with a warning naming the size.
TEXTURE_PIXELS_MAX = 2**27


def _resampled(blob: bytes, res: int, mesh_path: Path, name: str) -> np.ndarray | None:
    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():  # the size check below replaces Pillow's bomb warning
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            img = Image.open(io.BytesIO(blob))
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


def _obj_texture(path: Path, allow_outside: bool) -> Path | None:
    data = read_bytes(path)
    libs = _directive(data, b"mtllib")
    used = set(_directive(data, b"usemtl"))
    maps: dict[str, tuple[Path, str]] = {}
    for lib in libs:
        # the MTL is read, so it is checked first
        mtl = _named(path, path.parent, lib, allow_outside, "material library")
        if not os.path.exists(mtl):
            continue
        for material, name in _mtl_maps(mtl, path).items():
            maps[material] = (mtl.parent, name)
    files = {
        Path(os.path.abspath(maps[m][0] / maps[m][1])): maps[m]
        for m in (used or set(maps)) if m in maps
    }  # fmt: skip
    chosen = _one(set(files), path)
    if chosen is None:
        return None
    return _existing(_named(path, *files[chosen], allow_outside), path)


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


def _mtl_maps(mtl: Path, mesh_path: Path) -> dict[str, str]:
    """Material name -> its ``map_Kd`` file name as written, from one MTL file."""
    out: dict[str, str] = {}
    current = None
    text = read_text(mtl, f"{mesh_path.name}: its material library {mtl}", MTL_MAX_BYTES)
    for line in text.splitlines():
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
                out[current] = " ".join(args).replace("\\", "/")
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
    return next(iter(files))


def _existing(found: Path, path: Path) -> Path | None:
    """``found``, or None with a warning when there is no such file."""
    if not os.path.exists(found):
        _warn(f"{path.name}: base-colour texture {found.name} not found; using grey")
        return None
    return found


def _gltf_texture(path: Path, allow_outside: bool) -> bytes | Path | None:
    data = read_bytes(path)
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
    return _gltf_image(doc, chosen, path, binary, allow_outside)


def _gltf_image(
    doc: dict, index: int, path: Path, binary: bytes | None, allow_outside: bool
) -> bytes | Path:
    image = doc["images"][index]
    if "bufferView" in image:
        view = doc["bufferViews"][image["bufferView"]]
        start = view.get("byteOffset", 0)
        buffer = doc["buffers"][view["buffer"]]
        blob = binary if "uri" not in buffer else _uri_bytes(buffer["uri"], path, allow_outside)
        return bytes(blob[start : start + view["byteLength"]])
    uri = image["uri"]
    if uri.startswith("data:"):
        return _uri_bytes(uri, path, allow_outside)
    return _existing(_named(path, path.parent, urllib.parse.unquote(uri), allow_outside), path)


def _uri_bytes(uri: str, path: Path, allow_outside: bool) -> bytes:
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    name = urllib.parse.unquote(uri)
    found = _named(path, path.parent, name, allow_outside, "buffer")
    return read_bytes(found, f"{path.name}: buffer {name}")
