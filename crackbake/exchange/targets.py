"""Engine profiles (``--target``): which PNGs a run writes, their names, packing and bit depths.

One table, :data:`TARGETS`: each profile lists its files as (name pattern, content, bits); the
contents are packed here from the baked maps by :func:`pack`.  Channel layouts follow what each
engine's standard material reads:

- glTF / Godot ``orm``: R occlusion, G roughness, B metallic (glTF's occlusion and
  metallicRoughness textures may share one image; Godot's ORM material reads the same layout).
- Unity HDRP ``mask_map``: R metallic, G occlusion, B detail mask, A smoothness.
- Unity built-in/URP ``metallic_smoothness``: R metallic, A smoothness; occlusion its own map.
- Unreal ``orm``: the same R/G/B layout, the usual packed-mask convention of its materials.
- ``data`` (every target): R mask, G width / width scale, B depth / depth scale, A crack time,
  16 bit; the scales are in the manifest (:func:`describe`), for custom crack shaders.

Normal maps are tangent space, ``n * 0.5 + 0.5``; ``gl`` = +Y (OpenGL: glTF, Unity, Godot,
Blender), ``dx`` = -Y (DirectX: Unreal).  Without a baked normal map (no tangents) the normal
file is flat (0.5, 0.5, 1) and the occlusion is 1 (open).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from crackbake.errors import CrackbakeWarning
from crackbake.exchange.materials import ROUGHNESS_CRACK, ROUGHNESS_SURFACE, half_lut
from crackbake.exchange.packing import (
    SRC_A,
    SRC_B,
    SRC_CONST,
    data16,
    data16_bands,
    data16_rows,
    half_max,
    lut_planes,
    normal_q,
    quantise_float,
    take_half,
)
from crackbake.params import NORMAL_Y
from crackbake.params import TARGETS as TARGET_NAMES

#: What each packed content holds, channel by channel (also written into the manifest).
CONTENTS: dict[str, str] = {
    "base_color": "RGB sRGB base colour: the asset's texture (or grey) with the cracks over it",
    "normal": "RGB tangent-space normal, n * 0.5 + 0.5 (Y convention in the manifest)",
    "orm": "R occlusion (1 = open), G roughness, B metallic",
    "mask_map": "R metallic, G occlusion, B detail mask (1), A smoothness (1 - roughness)",
    "metallic_smoothness": "R metallic, G 0, B 0, A smoothness (1 - roughness)",
    "occlusion": "grey occlusion, 1 = open",
    "roughness": "grey roughness",
    "mask": "grey crack coverage 0..1",
    "depth": "grey crack depth / depth scale",
    "data": "R mask, G width / width scale, B depth / depth scale, A crack time 0..1",
}


@dataclass(frozen=True)
class MapFile:
    """One PNG of a profile: ``name`` with ``{stem}`` replaced, its content and bit depth."""

    name: str
    content: str
    bits: int = 8


@dataclass(frozen=True)
class Target:
    """An engine profile: its normal-map convention and the PNGs it writes."""

    name: str
    engine: str
    normal_y: str
    files: tuple[MapFile, ...]


def _t(name, engine, normal_y, *files) -> Target:
    return Target(name, engine, normal_y, tuple(MapFile(*f) for f in files))


#: The profiles.  ``base_color`` is sRGB; every other file is linear data.
TARGETS: dict[str, Target] = {
    t.name: t
    for t in (
        _t("gltf", "glTF 2.0 viewers, three.js, Babylon.js", "gl",
           ("{stem}_mask.png", "mask"), ("{stem}_depth.png", "depth", 16),
           ("{stem}_basecolor.png", "base_color"), ("{stem}_normal.png", "normal"),
           ("{stem}_orm.png", "orm"), ("{stem}_data.png", "data", 16)),
        _t("unity", "Unity built-in / URP Lit", "gl",
           ("{stem}_Albedo.png", "base_color"), ("{stem}_Normal.png", "normal"),
           ("{stem}_MetallicSmoothness.png", "metallic_smoothness"),
           ("{stem}_Occlusion.png", "occlusion"), ("{stem}_CrackData.png", "data", 16)),
        _t("unity-hdrp", "Unity HDRP Lit", "gl",
           ("{stem}_BaseColor.png", "base_color"), ("{stem}_Normal.png", "normal"),
           ("{stem}_MaskMap.png", "mask_map"), ("{stem}_CrackData.png", "data", 16)),
        _t("unreal", "Unreal Engine 5", "dx",
           ("T_{stem}_BC.png", "base_color"), ("T_{stem}_N.png", "normal"),
           ("T_{stem}_ORM.png", "orm"), ("T_{stem}_Data.png", "data", 16)),
        _t("godot", "Godot 4 StandardMaterial3D (ORM)", "gl",
           ("{stem}_albedo.png", "base_color"), ("{stem}_normal.png", "normal"),
           ("{stem}_orm.png", "orm"), ("{stem}_data.png", "data", 16)),
        _t("blender", "Blender Principled BSDF", "gl",
           ("{stem}_base_color.png", "base_color"), ("{stem}_normal.png", "normal", 16),
           ("{stem}_roughness.png", "roughness"), ("{stem}_ao.png", "occlusion"),
           ("{stem}_depth.png", "depth", 16), ("{stem}_data.png", "data", 16)),
    )
}  # fmt: skip
assert tuple(TARGETS) == TARGET_NAMES  # params.TARGETS validates --target; keep them one list


#: Targets whose engine reads a UDIM set (``<name>.<UDIM>.png``) as one texture: Unreal Engine
#: 5 (virtual texturing imports the ``.1001`` sequence as one UDIM texture) and Blender (tiled
#: images, ``<UDIM>`` in the path).  Unity, Godot and glTF 2.0 have no UDIM textures.
UDIM_TARGETS = ("unreal", "blender")


def warn_udim_target(target: str) -> None:
    """One warning when ``target``'s engine cannot read the UDIM set the PNGs are written as."""
    if target in UDIM_TARGETS:
        return
    warnings.warn(
        f"--target {target}: {TARGETS[target].engine} read no UDIM sets, so the maps written "
        "per tile (<name>.<UDIM>.png) need a material per tile there; use the GLB (its tiles "
        "packed into one page), --target unreal or blender, or --uv unwrap for one page",
        CrackbakeWarning,
        stacklevel=4,
    )


def normal_convention(target: str, normal_y: str | None = None) -> str:
    """``gl`` or ``dx``: ``normal_y`` when given, else the target's own."""
    y = normal_y or TARGETS[target].normal_y
    assert y in NORMAL_Y
    return y


def data_scales(maps) -> dict[str, float]:
    """Divisors of the data map's G (width) and B (depth) channels, mesh units (1 when 0);
    the ones the maps share with other pages (``maps.scales``, a UDIM set's tiles) when set."""
    shared = getattr(maps, "scales", None)
    if shared is not None:
        return dict(shared)
    width = maps.width
    if not width.size:
        w = 0.0
    elif width.dtype == np.float16:
        w = half_max(width)
    else:
        w = float(np.max(width))
    d = float(np.max(maps.depth)) if maps.depth.size else 0.0
    return {"width": w if w > 0 else 1.0, "depth": d if d > 0 else 1.0}


def _full(bits: int) -> int:
    return 255 if bits == 8 else 65535


def _dtype(bits: int) -> np.dtype:
    # 16-bit samples come out big-endian, the order PNG stores, saving the encoder a copy.
    return np.dtype(np.uint8) if bits == 8 else np.dtype(">u2")


def quantise(plane: np.ndarray, bits: int, scale: float = 1.0) -> np.ndarray:
    """``plane / scale`` in [0, 1] rounded to uint8 or uint16 (clipped; NaN -> 0)."""
    top = _full(bits)
    dtype = _dtype(bits)
    plane = np.asarray(plane)
    if plane.dtype == np.float16:  # one gather through a table of every half value
        return take_half(_quant_lut(bits, scale), plane)
    # numpy here (inspect's pictures, tiles): a kernel would be compiled on their first use;
    # the write's full-size planes take :func:`quantise_float` (:func:`pack`).
    q = np.asarray(plane, np.float32) * np.float32(top / scale)
    q += np.float32(0.5)
    np.nan_to_num(q, copy=False, nan=0.0)
    np.clip(q, 0, top, out=q)
    return q.astype(dtype)


def _quant_lut(bits: int, scale: float = 1.0) -> np.ndarray:
    """(65536,) table of :func:`quantise` over every float16 bit pattern."""
    top = _full(bits)
    return half_lut(lambda x: np.clip(x / scale * top + 0.5, 0, top)).astype(_dtype(bits))


def _const(shape, value: float, bits: int) -> np.ndarray:
    return np.full(shape, int(round(value * _full(bits))), _dtype(bits))


def _rough_lut(bits: int, smooth: bool = False, look=None) -> np.ndarray:
    """(65536,) table: roughness (or smoothness) of every float16 mask value, quantised
    (the crack's roughness from ``look``, :data:`ROUGHNESS_CRACK` without one)."""
    top = _full(bits)
    a, b = ROUGHNESS_SURFACE, ROUGHNESS_CRACK if look is None else float(look.roughness)
    if smooth:
        a, b = 1 - a, 1 - b
    lut = half_lut(lambda x: np.clip((a + (b - a) * np.clip(x, 0, 1)) * top + 0.5, 0, top))
    return lut.astype(_dtype(bits))


def _roughness(mask: np.ndarray, bits: int, smooth: bool = False, look=None) -> np.ndarray:
    return take_half(_rough_lut(bits, smooth, look), np.asarray(mask, np.float16))


def _packed(content: str, maps, bits: int) -> np.ndarray | None:
    """ORM / mask map / metallic-smoothness by :func:`lut_planes` (one pass over float16
    mask and occlusion, GIL released); None when the maps are not float16."""
    occ = maps.occlusion
    if maps.mask.dtype != np.float16 or (occ is not None and occ.dtype != np.float16):
        return None
    const = {v: (SRC_CONST, _const((), v, bits)) for v in (0.0, 1.0)}
    o = const[1.0] if occ is None else (SRC_B, _quant_lut(bits))
    look = getattr(maps, "look", None)
    rough = (SRC_A, _rough_lut(bits, look=look))
    smooth = (SRC_A, _rough_lut(bits, smooth=True, look=look))
    channels = {
        "orm": [o, rough, const[0.0]],
        "mask_map": [const[0.0], o, const[1.0], smooth],
        "metallic_smoothness": [const[0.0], const[0.0], const[0.0], smooth],
    }[content]
    return lut_planes(maps.mask, maps.mask if occ is None else occ, channels)


def _normal(maps, bits: int, normal_y: str) -> np.ndarray:
    res = maps.mask.shape
    if maps.normal is None:
        out = np.empty((*res, 3), _dtype(bits))
        out[..., 0:2] = _const((), 0.5, bits)
        out[..., 2] = _full(bits)
        return out
    return normal_q(maps.normal, bits, flip_y=normal_y == "dx")  # one pass, GIL released


def pack(content: str, maps, bits: int, normal_y: str = "gl", base=None) -> np.ndarray:
    """The pixels of one packed file.

    Parameters
    ----------
    content : str
        A key of :data:`CONTENTS`.
    maps : CrackMaps
        The bake (``normal`` and ``occlusion`` may be None).
    bits : {8, 16}
    normal_y : {"gl", "dx"}
    base : callable, optional
        Returns the (H, W, 3) uint8 base colour; called only for ``base_color``.

    Returns
    -------
    (H, W) or (H, W, C) uint8, or big-endian uint16 (``>u2``) for 16 bits
    """
    shape = maps.mask.shape
    occ = maps.occlusion
    look = getattr(maps, "look", None)

    def occlusion():
        return _const(shape, 1.0, bits) if occ is None else quantise(occ, bits)

    if content == "base_color":
        return base()
    if content == "normal":
        return _normal(maps, bits, normal_y)
    if content == "mask":
        return quantise(maps.mask, bits)
    if content == "depth":
        scale = data_scales(maps)["depth"]
        if np.asarray(maps.depth).dtype == np.float32:  # one pass, GIL released
            return quantise_float(maps.depth, bits, scale)
        return quantise(maps.depth, bits, scale)
    if content == "occlusion":
        return occlusion()
    if content == "roughness":
        return _roughness(maps.mask, bits, look=look)
    if content != "data":
        fused = _packed(content, maps, bits)
        if fused is not None:
            return fused
    planes = {
        "orm": lambda: (
            occlusion(), _roughness(maps.mask, bits, look=look), _const(shape, 0.0, bits)
        ),
        "mask_map": lambda: (
            _const(shape, 0.0, bits), occlusion(), _const(shape, 1.0, bits),
            _roughness(maps.mask, bits, smooth=True, look=look),
        ),
        "metallic_smoothness": lambda: (
            _const(shape, 0.0, bits), _const(shape, 0.0, bits), _const(shape, 0.0, bits),
            _roughness(maps.mask, bits, smooth=True, look=look),
        ),
        "data": lambda: _data_planes(maps, bits),
    }[content]()  # fmt: skip
    if content == "data" and not isinstance(planes, tuple):
        return planes
    return np.stack(planes, axis=-1)


def _data16_luts() -> tuple:
    # Mask and time (0..1 float16) through one table of every half bit pattern.
    lut = half_lut(lambda x: np.clip(x * 65535 + 0.5, 0, 65535)).astype(np.uint16)
    return lut, lut


def data16_filtered(maps, bands: bool = True):
    """The 16-bit data texture as PNG-filtered scanlines: band by band
    (:func:`packing.data16_bands`, for :func:`~crackbake.exchange.pngenc.png_bands`), or with
    ``bands=False`` all at once (:func:`packing.data16_rows`, (H, 1 + 8 W) uint8, for
    :func:`~crackbake.exchange.pngenc.png_rows`); None unless mask and time are float16."""
    if not all(np.asarray(p).dtype == np.float16 for p in (maps.mask, maps.time)):
        return None
    scales = data_scales(maps)
    pack_rows = data16_bands if bands else data16_rows
    return pack_rows(maps.mask, maps.width, maps.time, maps.depth, _data16_luts(),
                     scales["width"], scales["depth"])  # fmt: skip


#: Rows of the 16-bit data map deflated as one segment (:func:`data16_segments`): 8 segments
#: at 4096², each encoded on its own thread where there are cores for it.
DATA_SEGMENT_ROWS = 512


def data16_segments(maps, rows: int = DATA_SEGMENT_ROWS) -> list | None:
    """The 16-bit data texture's filtered scanlines as segments of ``rows`` rows, for
    :func:`~crackbake.exchange.pngenc.png_segments`: callables that each yield their rows'
    bands (:func:`packing.data16_bands`); None unless mask and time are float16."""
    if not all(np.asarray(p).dtype == np.float16 for p in (maps.mask, maps.time)):
        return None
    scales = data_scales(maps)
    height = maps.mask.shape[0]

    def segment(start: int):
        return lambda: data16_bands(maps.mask, maps.width, maps.time, maps.depth,
                                    _data16_luts(), scales["width"], scales["depth"],
                                    start=start, stop=start + rows)  # fmt: skip

    return [segment(start) for start in range(0, height, max(1, int(rows)))]


def _data_planes(maps, bits: int):
    """R mask, G width, B depth, A time: one fused pass for the usual 16-bit maps (mask and
    time float16)."""
    scales = data_scales(maps)
    halves = all(np.asarray(p).dtype == np.float16 for p in (maps.mask, maps.time))
    if bits == 16 and halves:
        return data16(maps.mask, maps.width, maps.time, maps.depth, _data16_luts(),
                      scales["width"], scales["depth"])  # fmt: skip
    return (
        quantise(maps.mask, bits), quantise(maps.width, bits, scales["width"]),
        quantise(maps.depth, bits, scales["depth"]), quantise(maps.time, bits),
    )  # fmt: skip


def describe(target: str, normal_y: str | None, stem: str, maps) -> dict:
    """The manifest's ``textures`` entry: target, normal convention, files, data scales."""
    t = TARGETS[target]
    udim = getattr(maps, "pages", None) is not None

    def named(f: MapFile) -> str:
        name = f.name.format(stem=stem)
        if udim:  # one file per tile: <name>.<UDIM>.png
            stem_, _, ext = name.rpartition(".")
            name = f"{stem_}.<UDIM>.{ext}"
        return name

    out = {
        "target": target,
        "engine": t.engine,
        "normal_y": normal_convention(target, normal_y),
        "files": {
            named(f): {
                "content": f.content, "bits": f.bits, "channels": CONTENTS[f.content],
                "colorspace": "sRGB" if f.content == "base_color" else "linear",
            }
            for f in t.files
        },  # fmt: skip
        "data_scales": data_scales(maps),
        "normal_baked": maps.normal is not None,
    }
    if udim:
        out["engine_reads_udim"] = target in UDIM_TARGETS
    return out
