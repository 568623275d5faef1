"""A decal library's files: mip-safe atlases, ``decals.json``, a lit contact sheet, the manifest.

Atlas layout (:func:`atlas_layout`): variants sit in a grid of square cells, row-major from the
top-left.  Each cell is the variant's ``res`` texels plus a gutter filled by edge extension (every
gutter texel repeats the nearest texel of its own variant).  The gutter rule: at mip level ``L``,
the deepest level where one variant is still at least 4 texels wide (``2**L`` = largest power of
two <= res / 4), a box-filtered 2x2 mip chain must never mix two variants and a bilinear tap
inside a variant must read only its own cell.  So the cell edge is a multiple of ``2**L`` (each
level-L texel averages one aligned ``2**L`` block, inside one cell) and the gutter is at least
``2**L`` texels per side (one whole texel at level L around the variant).  For a power-of-two
``res`` the cell is ``1.5 res``: 1024 -> 1536, gutter 256 per side, variant 4 texels wide inside a
6-texel cell at level 8.
"""

from __future__ import annotations

import json
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from crackbake import __version__
from crackbake.errors import CrackbakeError
from crackbake.exchange.pngenc import png_bytes, write_bytes
from crackbake.exchange.targets import CONTENTS, pack, quantise

FORMAT = "crackbake-decals"
VERSION = 1
#: Largest atlas edge written, texels (what engines import; 16 variants of 4096 would be 24576).
ATLAS_MAX = 16384
#: One variant is this many texels wide at the deepest mip level the gutters protect.
MIP_TEXELS = 4

#: Atlas files: role -> (file name, content described, bits).
ROLES: dict[str, tuple[str, str, int]] = {
    "alpha": ("decals_alpha.png", "grey crack coverage 0..1: the decal's opacity", 8),
    "normal": ("decals_normal.png", "RGB tangent-space normal, n * 0.5 + 0.5 (Y: normal_y)", 8),
    "orm": ("decals_orm.png", CONTENTS["orm"], 8),
    "height": ("decals_height.png", "grey height: 1 = surface, 0 = depth_scale below it", 16),
}


@dataclass(frozen=True)
class Layout:
    """Where the variants go.  ``cell``, ``pad`` (gutter before the variant, texels; the gutter
    after it is ``cell - res - pad``), ``block`` = ``2**level``."""

    n: int
    res: int
    cols: int
    rows: int
    cell: int
    pad: int
    level: int

    @property
    def block(self) -> int:
        return 1 << self.level

    @property
    def width(self) -> int:
        return self.cols * self.cell

    @property
    def height(self) -> int:
        return self.rows * self.cell

    def origin(self, i: int) -> tuple[int, int]:
        """Top-left texel (x, y; y down from the top row) of variant ``i``'s cell."""
        return (i % self.cols) * self.cell, (i // self.cols) * self.cell


def atlas_layout(n: int, res: int) -> Layout:
    """The grid (``ceil(sqrt n)`` columns) and the mip-safe cell; refuses atlases over
    :data:`ATLAS_MAX`."""
    level = max(0, int(math.floor(math.log2(res / MIP_TEXELS))))
    block = 1 << level
    cell = -(-(res + 2 * block) // block) * block  # gutter >= one level-L texel per side
    cols = math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    layout = Layout(n, res, cols, rows, cell, (cell - res) // 2, level)
    if max(layout.width, layout.height) > ATLAS_MAX:
        raise CrackbakeError(
            f"-n {n} at --res {res} needs a {layout.width}x{layout.height} atlas, over "
            f"{ATLAS_MAX}; lower --res or -n"
        )
    return layout


def uv_rect(layout: Layout, i: int) -> dict:
    """Variant ``i``'s rectangle: pixels and UV scale/bias in both v conventions.

    ``atlas_uv = decal_uv * scale + bias``; ``v_up`` (Unity, OpenGL, Blender: v = 0 at the image's
    bottom row) or ``v_down`` (glTF, Unreal, Godot, DirectX: v = 0 at the top row), the decal's
    own uv taken in the same convention.
    """
    ox, oy = layout.origin(i)
    x0, y0, r = ox + layout.pad, oy + layout.pad, layout.res
    w, h = layout.width, layout.height
    return {
        "rect_px": [x0, y0, r, r],
        "uv_scale": [r / w, r / h],
        "uv_bias_v_up": [x0 / w, (h - y0 - r) / h],
        "uv_bias_v_down": [x0 / w, y0 / h],
    }


def _neutral(normal_y: str) -> dict[str, np.ndarray]:
    """Texel values of a cell with no variant (no crack, flat), packed like the variants."""
    flat = SimpleNamespace(
        mask=np.zeros((1, 1), np.float16), occlusion=np.ones((1, 1), np.float16),
        normal=np.array([[[0.0, 0.0, 1.0]]], np.float32),
    )  # fmt: skip
    return {
        "alpha": pack("mask", flat, 8)[0, 0],
        "normal": pack("normal", flat, 8, normal_y)[0, 0],
        "orm": pack("orm", flat, 8)[0, 0],
        "height": np.array(65535, ">u2"),
    }


def _packed(maps, role: str, normal_y: str, depth_scale: float) -> np.ndarray:
    if role == "alpha":
        return pack("mask", maps, 8)
    if role == "height":  # 1 = the surface: engines' height maps are white-up
        return quantise(depth_scale - np.asarray(maps.depth, np.float32), 16, depth_scale)
    return pack(role, maps, 8, normal_y)


def build_atlases(layout: Layout, maps_list: list, normal_y: str) -> tuple[dict, float]:
    """Every role's atlas array and the library's depth scale (deepest crack, mesh units).

    Returns
    -------
    atlases : dict of role -> (H, W) or (H, W, 3) uint8 / big-endian uint16
    depth_scale : float
        Height 0 is this far below the surface (1 when nothing is deeper than 0).
    """
    deepest = max((float(np.max(m.depth)) for m in maps_list), default=0.0)
    depth_scale = deepest if deepest > 0 else 1.0
    neutral = _neutral(normal_y)
    atlases = {}
    for role in ROLES:
        value = neutral[role]
        atlas = np.empty((layout.height, layout.width, *value.shape), value.dtype)
        atlas[...] = value
        lo, hi = layout.pad, layout.cell - layout.res - layout.pad
        for i, maps in enumerate(maps_list):
            img = _packed(maps, role, normal_y, depth_scale)
            widths = ((lo, hi), (lo, hi)) + ((0, 0),) * (img.ndim - 2)
            ox, oy = layout.origin(i)
            atlas[oy : oy + layout.cell, ox : ox + layout.cell] = np.pad(img, widths, mode="edge")
        atlases[role] = atlas
    return atlases, depth_scale


def mip_chain(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """Box-filtered mips 0..levels of an (H, W[, C]) image (float64; each level averages aligned
    2x2 blocks of the one above, as GPUs' mip generation does for even sizes)."""
    out = [np.asarray(image, np.float64)]
    for _ in range(levels):
        a = out[-1]
        h, w = a.shape[0] // 2, a.shape[1] // 2
        a = a[: 2 * h, : 2 * w].reshape(h, 2, w, 2, *a.shape[2:])
        out.append(a.mean(axis=(1, 3)))
    return out


def contact_sheet(layout: Layout, atlases: dict, normal_y: str, thumb: int = 384) -> np.ndarray:
    """A picture of every variant lit through its normal map and occlusion: (H, W, 3) uint8 sRGB.

    A low light from the upper left (tangent space (-0.6, 0.65, 0.45)), Lambert shading normalised
    so a flat texel is 1, times occlusion, over a pale glass-grey albedo darkened by the alpha;
    shaded at full resolution, then box-filtered to ``thumb`` texels per variant.
    """
    f = max(1, layout.res // thumb)
    t = layout.res // f
    gap = 8
    sheet = np.full((layout.rows * (t + gap) + gap, layout.cols * (t + gap) + gap, 3), 0.08)
    light = np.array([-0.6, 0.65, 0.45])  # low, so the crack walls catch or lose it
    light /= np.linalg.norm(light)
    for i in range(layout.n):
        x0, y0, r, _ = uv_rect(layout, i)["rect_px"]
        sl = np.s_[y0 : y0 + r, x0 : x0 + r]
        n = atlases["normal"][sl].astype(np.float32) / 127.5 - 1.0
        if normal_y == "dx":
            n[..., 1] = -n[..., 1]
        n /= np.linalg.norm(n, axis=-1, keepdims=True) + 1e-6
        occ = atlases["orm"][sl][..., 0] / 255.0
        alpha = atlases["alpha"][sl] / 255.0
        lit = np.clip(n @ light, 0.0, None) / light[2]
        albedo = np.array([0.72, 0.78, 0.8]) * (1.0 - 0.7 * alpha)[..., None]
        shade = albedo * (occ * (0.25 + 0.75 * lit))[..., None]
        shade = shade[: t * f, : t * f].reshape(t, f, t, f, 3).mean(axis=(1, 3))
        row, col = divmod(i, layout.cols)
        sy, sx = gap + row * (t + gap), gap + col * (t + gap)
        sheet[sy : sy + t, sx : sx + t] = shade
    return (np.clip(sheet, 0, 1) ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)


def engine_blocks(rect: dict, size: float, depth: float) -> dict:
    """Per-engine values for one variant: Unity's ``DecalProjector`` fields (uv v-up), the
    parameters an Unreal decal material or a Godot ``StandardMaterial3D`` multiplies its UVs by
    (both v-down: UV (0, 0) is the texture's top-left), and Godot's ``AtlasTexture`` region."""
    scale, up, down = rect["uv_scale"], rect["uv_bias_v_up"], rect["uv_bias_v_down"]
    return {
        "unity": {"uvScale": scale, "uvBias": up, "size": [size, size, depth],
                  "pivot": [0.0, 0.0, depth / 2]},
        "unreal": {"UVScale": scale, "UVBias": down,
                   "use": "material: TexCoord[0] * UVScale + UVBias (UV origin top-left)"},
        "godot": {"uv1_scale": [*scale, 1.0], "uv1_offset": [*down, 0.0],
                  "atlas_region_px": rect["rect_px"]},
    }  # fmt: skip


def document(params, layout: Layout, baked: list, depth_scale: float) -> dict:
    """The ``decals.json`` content (the top-level fields shared with mesh-projected decals:
    ``format``, ``version``, ``generator``, ``units``, ``normal_y``, ``textures``, ``decals``)."""
    files = {role: ROLES[role][0] for role in ROLES}
    depth = params.projector_depth
    decals = []
    for b in baked:
        v = b.variant
        impact = None
        if v.impact is not None:
            x, y, z = v.impact.point
            impact = {"point": [x, y, z], "uv": [x / params.size, y / params.size],
                      "radius": v.impact.radius, "strength": v.impact.strength}  # fmt: skip
        rect = uv_rect(layout, v.index)
        decals.append({
            "name": v.name, "index": v.index, "seed": v.seed, "impact": impact,
            "size": [params.size, params.size], "depth": depth,
            "crack_depth_max": float(np.max(b.maps.depth)), "cracks": b.cracks,
            **rect,
            **engine_blocks(rect, params.size, depth),
            "textures": files, "normal_y": params.normal_y,
        })  # fmt: skip
    return {
        "format": FORMAT,
        "version": VERSION,
        "generator": f"crackbake {__version__}",
        "kind": "library",
        "units": "mesh units (the plate side is --size; 1 = 1 m in engines that assume metres)",
        "preset": params.preset,
        "seed": params.seed,
        "normal_y": params.normal_y,
        "normal": {
            "space": "tangent",
            "encoding": "n * 0.5 + 0.5",
            "frame": "T = +X = image right, B = +Y = image up, N = +Z out of the surface",
            "y": "gl: +Y up (OpenGL, Unity, Godot, Blender)"
            if params.normal_y == "gl"
            else "dx: -Y (DirectX, Unreal)",
        },  # fmt: skip
        "uv": {
            "rule": "atlas_uv = decal_uv * uv_scale + uv_bias, decal_uv in [0, 1]^2",
            "v_up": "uv_bias_v_up: v = 0 at the image's bottom row (Unity, OpenGL, Blender)",
            "v_down": "uv_bias_v_down: v = 0 at the top row (glTF, Unreal, Godot, DirectX)",
            "rect_px": "x, y (from the top-left texel), width, height",
        },
        "atlas": {
            "width": layout.width,
            "height": layout.height,
            "grid": [layout.cols, layout.rows],
            "cell": layout.cell,
            "gutter": [layout.pad, layout.cell - layout.res - layout.pad],
            "mip_safe_level": layout.level,
            "variant_texels_at_mip_safe_level": layout.res >> layout.level,
        },  # fmt: skip
        "textures": {
            role: {
                "file": name,
                "content": text,
                "bits": bits,
                "colorspace": "linear",
                **({"depth_scale": depth_scale} if role == "height" else {}),
            }
            for role, (name, text, bits) in ROLES.items()
        },  # fmt: skip
        "decals": decals,
    }


def write_library(stage, params, baked: list, timings: dict, t0: float) -> dict:
    """Write atlases, ``contact_sheet.png``, ``decals.json`` and ``manifest.json`` into the open
    :class:`~crackbake.transaction.stage.OutputStage`; return the decals.json document."""
    import time

    t = time.perf_counter()
    layout = atlas_layout(params.n, params.res)
    atlases, depth_scale = build_atlases(layout, [b.maps for b in baked], params.normal_y)
    jobs = [(ROLES[r][0], a, False) for r, a in atlases.items()]
    jobs.append(("contact_sheet.png", contact_sheet(layout, atlases, params.normal_y), True))

    def encode(job):
        name, pixels, srgb = job
        write_bytes(stage.path(name), png_bytes(pixels, srgb=srgb))

    with ThreadPoolExecutor(max_workers=len(jobs)) as pool:  # zlib releases the GIL
        list(pool.map(encode, jobs))
    doc = document(params, layout, baked, depth_scale)
    stage.path("decals.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    timings["write"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    manifest = {
        "crackbake": __version__,
        "kind": "decal library",
        "params": {"preset": params.preset, "n": params.n, "size": params.size,
                   "res": params.res, "seed": params.seed, "normal_y": params.normal_y,
                   "depth": params.projector_depth, "sim_faces": params.sim_faces},
        "files": stage.records(),
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }  # fmt: skip
    stage.path("manifest.json").write_text(json.dumps(manifest, indent=1) + "\n", "utf-8")
    return {**doc, "timings_s": manifest["timings_s"]}
