"""The asset's own base-colour texture: OBJ ``map_Kd`` or glTF/GLB ``baseColorTexture``.

The output files composite the cracks over it, so the result keeps the asset's look.  Only the
small text of the file is parsed (OBJ ``mtllib``/``usemtl`` lines, the glTF JSON): the geometry
is never read twice.  The texture is returned resampled to the bake's square page with row 0 the
top of the image, which is ``v = 1`` in both OBJ and glTF (glTF's ``v`` runs down from the top
of the image, trimesh flips it to ``v`` up on load), so texels line up with the baked maps.
On UDIM tiles (:func:`base_color_tiles`) each tile reads its own file of the set the MTL names.
"""

from __future__ import annotations

import base64
import io
import json
import os
import re
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

    def find():
        if suffix == ".obj":
            return _obj_texture(path, allow_outside)
        if suffix in (".gltf", ".glb"):
            return _gltf_texture(path, allow_outside)
        return None

    found = _guarded(path, lambda: _read(find(), path))
    if found is None:
        return None
    return _resampled(*found, res, path)


def base_color_tiles(
    mesh_path: str | Path, numbers: list[int], res: int, allow_outside: bool = False
) -> list[np.ndarray | None] | None:
    """The asset's base colour per UDIM tile, each at ``res`` x ``res``, or ``None`` when it
    has none.

    An OBJ's ``map_Kd`` names a UDIM set as ``name.<UDIM>.png`` (also ``<udim>`` or
    ``%(UDIM)d``), or as one tile of it (``name.1001.png``, ``name_1001.png``; several
    materials naming ``name.1001.png``, ``name.1002.png``, ... are the same set): each tile
    reads its own file.  A single image (no tile number; any glTF, which has no UDIM) lies
    under every tile, as renderers repeat it on each (one warning says so).

    Parameters
    ----------
    mesh_path : str or Path
        The mesh file.
    numbers : list of int
        The used tiles' UDIM numbers (``UdimMaps.numbers``).
    res : int
        Texels per tile edge.
    allow_outside : bool
        As :func:`base_color_texture`.

    Returns
    -------
    list of (res, res, 3) uint8 or None, or None
        One entry per tile (``None`` for a tile whose file is missing: grey, one warning for
        them all); ``None`` when the asset names no usable texture.
    """
    path = Path(mesh_path)
    suffix = path.suffix.lower()
    if not path.is_file():
        return None
    if suffix == ".obj":
        files = _guarded(path, lambda: _obj_texture_files(path, allow_outside))
        if not files:
            return None
        names = [name for _, name in files.values()]
        base = next(iter(files.values()))[0]
        template = _udim_template(names)
        tokened = any(t in names[0] for t in UDIM_TOKENS)
        if template is not None and len(names) == 1 and not tokened and not any(
                os.path.exists(base / template.replace("<UDIM>", str(n))) for n in numbers):
            template = None  # photo_2048.png: a number, but no tile of it exists: one image
        if template is not None:
            return _guarded(path, lambda: _tiles(path, base, template, numbers, res,
                                                 allow_outside))  # fmt: skip
        chosen = _one(set(files), path)  # several files that are not one set: grey, warned
        if chosen is None:
            return None
        found = _guarded(path, lambda: _read(
            _existing(_named(path, *files[chosen], allow_outside), path), path))
    elif suffix in (".gltf", ".glb"):
        found = _guarded(path, lambda: _read(_gltf_texture(path, allow_outside), path))
    else:
        return None
    if found is None:
        return None
    texture = _resampled(*found, res, path)
    if texture is None:
        return None
    fix = ("glTF has no UDIM: an OBJ whose MTL names <name>.<UDIM>.png gives one texture per "
           "tile" if suffix != ".obj" else "name the tiles <name>.<UDIM>.png, or "
           "<name>.1001.png, ..., in the MTL for one texture per tile")
    _warn(f"{path.name}: its base-colour texture {found[1]} is one image on a UDIM layout: it is "
          f"composited under every tile, as renderers repeat it on each ({fix})")
    return [texture] * len(numbers)


#: The tokens a texture name may hold for the tile number (Mari, Blender, USD, MaterialX:
#: ``<UDIM>``; Houdini, RenderMan: ``%(UDIM)d``).
UDIM_TOKENS = ("<UDIM>", "<udim>", "%(UDIM)d")
#: One tile of a UDIM set: ``name.1001.png`` or ``name_1001.png``.
_TILE_NUMBER = re.compile(r"^(.*[._])(\d{4})(\.[^./]+)$")


def _udim_template(names: list[str]) -> str | None:
    """The set the MTL's ``map_Kd`` names spell, with ``<UDIM>`` for the tile number, or None
    when they are not one UDIM set."""
    if len(names) == 1:
        for token in UDIM_TOKENS:
            if token in names[0]:
                return names[0].replace(token, "<UDIM>")
    found = {_TILE_NUMBER.match(n) for n in names}
    if None in found:
        return None
    templates = {f"{m.group(1)}<UDIM>{m.group(3)}" for m in found if int(m.group(2)) >= 1001}
    return next(iter(templates)) if len(templates) == 1 and len(found) == len(names) else None


def _tiles(path: Path, base: Path, template: str, numbers, res: int, allow_outside: bool):
    """Each tile's file of the set ``template`` (``<UDIM>`` for the number), read and
    resampled; missing tiles are None, with one warning naming them."""
    out, missing = [], []
    for number in numbers:
        name = template.replace("<UDIM>", str(number))
        target = _named(path, base, name, allow_outside)
        if not os.path.exists(target):
            missing.append(number)
            out.append(None)
            continue
        blob = read_bytes(target, f"{path.name}: its base-colour texture {target}")
        out.append(_resampled(blob, target.name, res, path))
    if missing:
        shown = ", ".join(map(str, missing))
        _warn(f"{path.name}: its base-colour set {Path(template).name} has no file for tile"
              f"{'s' if len(missing) > 1 else ''} {shown}; grey there (add "
              f"{Path(template.replace('<UDIM>', str(missing[0]))).name} beside the others)")
    return out if any(t is not None for t in out) else None


def _read(found, path: Path):
    """(bytes, name) of a texture found as a path or embedded bytes, or None."""
    if found is None:
        return None
    if isinstance(found, Path):
        return read_bytes(found, f"{path.name}: its base-colour texture {found}"), found.name
    return found, "embedded image"


def _guarded(path: Path, thunk):
    """``thunk()``, or None with one warning when the texture cannot be read safely."""
    try:
        return thunk()
    except _Outside as exc:
        where = "" if exc.target == exc.name else f" ({exc.target})"
        _warn(
            f"{path.name}: {exc.what} '{exc.name}'{where} lies outside the mesh's folder, so it "
            "was not read; using grey for the base colour (move it beside the mesh, or pass "
            "--allow-outside-textures to read it)"
        )
    except NotRegularFile as exc:  # a FIFO or device named as a texture or material library
        _warn(f"{exc.label} is {exc.what}, not a regular file, so it was not read; using grey "
              "for the base colour")
    except CrackbakeError as exc:  # e.g. an MTL file too big to be one
        _warn(f"{exc}; using grey for the base colour")
    except (OSError, ValueError, KeyError, IndexError, TypeError, struct.error) as exc:
        _warn(f"{path.name}: its base-colour texture could not be read ({exc}); using grey")
    return None


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


def _resampled(blob: bytes, name: str, res: int, mesh_path: Path) -> np.ndarray | None:
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
    files = _obj_texture_files(path, allow_outside)
    chosen = _one(set(files), path)
    if chosen is None:
        return None
    return _existing(_named(path, *files[chosen], allow_outside), path)


def _obj_texture_files(path: Path, allow_outside: bool) -> dict[Path, tuple[Path, str]]:
    """The ``map_Kd`` files of the OBJ's used materials: absolute path -> (folder, name as
    written)."""
    data = read_bytes(path)
    libs = _directive(data, b"mtllib")
    if not libs:  # no material library, no texture: the usemtl scan (0.1 s at 107 MB) is moot
        return {}
    used = set(_directive(data, b"usemtl"))
    maps: dict[str, tuple[Path, str]] = {}
    for lib in libs:
        # the MTL is read, so it is checked first
        mtl = _named(path, path.parent, lib, allow_outside, "material library")
        if not os.path.exists(mtl):
            continue
        for material, name in _mtl_maps(mtl, path).items():
            maps[material] = (mtl.parent, name)
    return {
        Path(os.path.abspath(maps[m][0] / maps[m][1])): maps[m]
        for m in (used or set(maps)) if m in maps
    }  # fmt: skip


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
