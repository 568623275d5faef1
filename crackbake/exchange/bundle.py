"""The files one run writes: EXR master, the target's PNGs, GLB, preview, sidecar and OBJ lines.

Encoding is the slow part of the output stage, so every file is encoded on a thread pool
(zlib and OpenEXR release the GIL while compressing) while the main thread renders the preview
with the run's GL context.  Each distinct texture is encoded once: the GLB embeds the very PNG
bytes the glTF/Godot profile writes as files.
"""

from __future__ import annotations

import os
import sys
import threading
import warnings
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from crackbake import __version__
from crackbake.bake.preview import preview_camera, render_preview, up_vector
from crackbake.bake.raster import CrackMaps
from crackbake.bake.uv import UVMesh
from crackbake.errors import CrackbakeWarning
from crackbake.exchange.exr import exr_threads, write_exr
from crackbake.exchange.frames import submit_frames
from crackbake.exchange.glb import write_glb
from crackbake.exchange.layers import (
    crack_attributes,
    crack_planes,
    run_attributes,
    stress_attributes,
    stress_planes,
)
from crackbake.exchange.materials import (
    GLB_TEXTURE_MAX,
    base_color,
    base_color_table,
    downsample,
)
from crackbake.exchange.pngenc import png_bytes, png_segments, write_bytes
from crackbake.exchange.targets import (
    TARGETS,
    data16_segments,
    data_scales,
    normal_convention,
    pack,
)
from crackbake.exchange.usd import UsdTextures, write_usd, write_usdz
from crackbake.io.mesh import Mesh
from crackbake.io.obj_lines import write_obj
from crackbake.io.sidecar import write_sidecar
from crackbake.io.texture import base_color_texture, base_color_tiles
from crackbake.network import CrackNetwork
from crackbake.params import RunParams
from crackbake.transaction.stage import OutputStage

if TYPE_CHECKING:  # the stress bake's module (scipy.spatial) is a solving run's, not a re-bake's
    from crackbake.bake.stress import StressMaps

#: Largest edge of the textures the preview samples (its picture is 1024 pixels wide).
PREVIEW_TEXTURE_MAX = 2048
#: Encoding threads.  More than cores on small machines: the jobs spend most of their time in
#: zlib, OpenEXR and nogil kernels with the GIL released, and short texture jobs should not wait
#: behind the EXR; at most 6 (each holds a few full-size temporaries).  On 2 cores 3 beat 4
#: (warm write at 4096², median 1.56 s against 1.73 s): the jobs are bound by memory traffic,
#: and fewer at once evict each other's data less.
WRITE_THREADS = max(3, min(6, os.cpu_count() or 1))
#: Worker threads of the EXR encoders while the EXRs are written (OpenEXR's global count, which
#: :mod:`crackbake.exchange.exrzip` follows too; the library default is none: the calling
#: thread compresses alone).  The master is the longest job; with workers it takes the cores
#: the texture jobs leave when they finish instead of ending alone on one (warm write at 4096²
#: on 2 cores: best 1.6 s against 2.0 s, the same CPU seconds, with the bindings' encoder).
#: The 16-bit data PNG's segments take as many (:func:`~crackbake.exchange.pngenc.png_segments`).
EXR_THREADS = max(2, min(4, os.cpu_count() or 1))
#: Nice levels the encoder threads take below the thread that starts them (Linux, where each
#: thread has its own; the EXR's chunk threads inherit it).  The pool starts before the stress
#: bake, whose GL draws run on the main thread (about one core: 0.40-0.57 of its 0.49-0.68
#: CPU s): at equal priority five encoder threads took most of both cores from it and its wall
#: tripled; below it they take the core it leaves, and after it they leave the preview's draw
#: (the main thread again) its core.
ENCODER_NICE = 5


def _below_caller(nice: int | None) -> None:
    """Pool initializer: this thread ``ENCODER_NICE`` levels below ``nice`` (Linux only)."""
    if nice is None:
        return
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice + ENCODER_NICE)
    except OSError:  # a sandbox that refuses it: equal priority, as before
        pass


def _caller_nice() -> int | None:
    """The calling thread's nice value on Linux (None elsewhere: there PRIO_PROCESS takes a
    process id, not a thread's)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    except OSError:
        return None


@dataclass(eq=False)
class _Smaller:
    """The maps a GLB texture or the preview needs, box-filtered to a smaller page."""

    mask: np.ndarray
    normal: np.ndarray | None
    occlusion: np.ndarray | None
    look: object = None


def _smaller(maps: CrackMaps, size: int) -> CrackMaps | _Smaller:
    if maps.mask.shape[0] <= size:
        return maps
    normal = None
    if maps.normal is not None:
        normal = downsample(maps.normal, size)
        normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    occ = None if maps.occlusion is None else downsample(maps.occlusion, size)
    return _Smaller(downsample(maps.mask, size), normal, occ, getattr(maps, "look", None))


class _Encoder:
    """Encodes each distinct (content, bits, normal_y, size) texture once on the pool."""

    def __init__(self, pool: ThreadPoolExecutor, maps: CrackMaps, texture: np.ndarray | None,
                 stage=None):  # fmt: skip
        self.pool = pool
        self.maps = maps
        self.texture = texture
        self.stage = stage  # hashes each file as it is written (OutputStage.remember)
        self.requests: dict[tuple, list] = {}

    def want(self, key: tuple, path=None) -> tuple:
        self.requests.setdefault(key, [])
        if path is not None:
            self.requests[key].append(path)
        return key

    def start(self, keep: set[tuple]) -> dict[tuple, Future]:
        """Submit every requested texture; keep ``keep``'s bytes (the GLB's).

        Order: the 16-bit RGBA data map (the longest), then the GLB's textures (so the GLB is
        assembled while the rest encode), then the others.
        """
        order = sorted(self.requests, key=lambda k: (k[0] != "data", k not in keep))
        return {k: self.pool.submit(self._job, k, self.requests[k], k in keep) for k in order}

    def _job(self, key: tuple, paths: list, keep: bool) -> bytes | None:
        content, bits, normal_y, size = key
        maps = _smaller(self.maps, size)
        segments = data16_segments(maps) if (content, bits) == ("data", 16) else None
        if segments is not None:  # packed straight into filtered scanlines, band by band
            h, w = maps.mask.shape
            data = png_segments(segments, w, h, 16, 4, threads=EXR_THREADS)
        else:
            pixels = pack(content, maps, bits, normal_y, base=lambda: self._base(maps, size))
            data = png_bytes(pixels, srgb=content == "base_color")
        for path in paths:
            write_bytes(path, data)
            if self.stage is not None:
                self.stage.remember(path, data)
        return data if keep else None

    def _base(self, maps, size: int) -> np.ndarray:
        tex = self.texture
        if tex is not None and tex.shape[0] > size:
            tex = downsample(tex, size)
        look = getattr(maps, "look", None)
        return base_color(maps.mask, occlusion=maps.occlusion, texture=tex, look=look)


def write_outputs(
    stage: OutputStage,
    stem: str,
    params: RunParams,
    mesh: Mesh,
    uvmesh: UVMesh,
    network: CrackNetwork,
    maps: CrackMaps,
    ctx=None,
    stress: StressMaps | None = None,
    effective: dict | None = None,
) -> None:
    """Write the requested maps, the GLB, the USD, the preview and the network into ``stage``.

    Parameters
    ----------
    stage : OutputStage
        Staging folder; nothing reaches the output folder until the caller commits.
    stem : str
        Prefix of the map file names (the mesh file's stem).
    params : RunParams
        ``formats``, ``float32``, ``target`` and ``normal_y`` decide what is written.
    mesh, uvmesh, network, maps
        The stages' results (``maps.normal``, ``maps.occlusion`` and ``uvmesh.tangents`` are
        used when present).
    ctx : moderngl.Context, optional
        The run's GL context, for the preview; a temporary one when not given.
    stress : StressMaps, optional
        The baked stress fields: written as ``<stem>_stress.exr`` with the ``stress`` format.
    effective : dict, optional
        The run's effective parameters (the manifest's ``params``), summarised in the EXR
        headers' ``comments`` (:func:`~crackbake.exchange.layers.run_attributes`).
    """
    with Writer(stage, stem, params, mesh, uvmesh, network, maps, ctx, effective) as writer:
        writer.finish(stress)


class Writer:
    """The write stage begun as soon as the crack maps exist: a context manager.

    Entering it starts encoding every file that only needs the crack maps (the crack EXR, the
    target's PNGs, the GLB's textures, the preview's pages, ``cracks.json`` and ``cracks.obj``)
    on the encoder pool, so the caller's next stage (the stress bake: the main thread and GL,
    about one core) runs beside them; :meth:`finish` then adds the stress EXR, draws the preview
    with ``ctx`` on the calling thread, assembles the GLB and USD and waits for every file.
    Leaving it, normally or by an exception (the stress bake's, a failed encoder's), waits for
    every job, so nothing is still writing into the stage when the caller commits or discards
    it.  Arguments as :func:`write_outputs`'s.
    """

    def __init__(self, stage: OutputStage, stem: str, params: RunParams, mesh: Mesh,
                 uvmesh: UVMesh, network: CrackNetwork, maps: CrackMaps, ctx=None,
                 effective: dict | None = None, preview=None):  # fmt: skip
        self.stage, self.stem, self.params, self.ctx = stage, stem, params, ctx
        # the preview's mesh-only work (crackbake.bake.preview.preview_ahead), begun on a
        # thread: .result()
        self.preview = preview
        self.mesh, self.uvmesh, self.network, self.maps = mesh, uvmesh, network, maps
        self.effective = effective
        self.udim = getattr(uvmesh, "udim", None) is not None
        self.jobs: list[Future] = []
        self._exit = ExitStack()
        self.pool: ThreadPoolExecutor | None = None

    def __enter__(self) -> Writer:
        if self.udim:  # the tiles' set is written whole by finish()
            return self
        formats = set(self.params.formats)
        self._exit.enter_context(exr_threads(EXR_THREADS if {"exr", "stress"} & formats
                                             else None))  # fmt: skip
        try:
            self.pool = self._exit.enter_context(
                ThreadPoolExecutor(WRITE_THREADS, thread_name_prefix="crackbake-write",
                                   initializer=_below_caller, initargs=(_caller_nice(),))
            )  # fmt: skip
            self._start()
        except BaseException:
            self._join()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self._join()

    def _join(self) -> None:
        try:
            for job in self.jobs:  # every job ends before the stage can be committed or discarded
                job.exception()
        finally:
            self._exit.close()

    def _start(self) -> None:
        stage, stem, params, maps = self.stage, self.stem, self.params, self.maps
        formats, pool, jobs = params.formats, self.pool, self.jobs
        self.exr = {"compression": params.exr_compression,
                    "run": run_attributes(__version__, self.effective)}  # fmt: skip
        texture = None
        if self.mesh.source and {"png", "glb", "preview", "usd", "usdz"} & set(formats):
            texture = base_color_texture(self.mesh.source, maps.res, params.allow_outside_textures)
        if "exr" in formats:
            # The longest job, so it starts first.  Its planes (the normal's float16 split) are
            # converted in the job: numpy casts release the GIL, and the texture packs are
            # nogil kernels, so the conversion no longer waits behind them.
            path = stage.path(f"{stem}_cracks.exr")
            jobs.append(pool.submit(_write_exr, path, maps, params.float32, **self.exr,
                                    stage=stage))  # fmt: skip
        self.pages = None
        if "preview" in formats:  # the picture is drawn by finish(); its pages are ready by then
            with_normal = getattr(self.uvmesh, "tangents", None) is not None
            self.pages = pool.submit(_preview_levels, maps, texture, with_normal)
            jobs.append(self.pages)
        enc = _Encoder(pool, maps, texture, stage)
        if "png" in formats:
            normal_y = normal_convention(params.target, params.normal_y)
            for f in TARGETS[params.target].files:
                ny = normal_y if f.content == "normal" else "gl"
                enc.want((f.content, f.bits, ny, maps.res), stage.path(f.name.format(stem=stem)))
        self.glb_keys = {}
        if "glb" in formats:
            size = min(maps.res, GLB_TEXTURE_MAX)
            self.glb_keys = {s: enc.want((s, 8, "gl", size)) for s in ("base_color", "normal",
                                                                        "orm")}  # fmt: skip
        self.usd_textures = None
        if {"usd", "usdz"} & set(formats):
            self.usd_textures = _usd_textures(enc, stage, stem, params, maps)
        self.encoded = enc.start(set(self.glb_keys.values()))
        jobs.extend(self.encoded.values())
        jobs.extend(submit_frames(pool, stage.path, stem, maps, params.frames))
        jobs.append(pool.submit(_write_network, self.network, stage))

    def finish(self, stress: StressMaps | None = None) -> None:
        """Write the stress EXR, the preview, the GLB and the USD, and wait for every file;
        raises the first failed job's error (in submission order)."""
        stage, stem, params = self.stage, self.stem, self.params
        mesh, uvmesh, maps, formats = self.mesh, self.uvmesh, self.maps, params.formats
        if self.udim:
            with exr_threads(EXR_THREADS if {"exr", "stress"} & set(formats) else None):
                _write_udim(stage, stem, params, mesh, uvmesh, self.network, maps, self.ctx,
                            stress, self.effective)  # fmt: skip
            return
        if stress is not None and "stress" in formats:
            path = stage.path(f"{stem}_stress.exr")
            self.jobs.append(self.pool.submit(_write_stress_exr, path, stress, **self.exr,
                                              stage=stage))  # fmt: skip
        up = ahead = None
        if self.preview is not None:
            ahead = self.preview.result()
            up = ahead.up
        elif self.pages is not None or self.usd_textures is not None:
            up = up_vector(params.up, mesh, cache=params.cache)  # once: a hull when guessed
        if self.pages is not None:
            colour, normal, levels = self.pages.result()
            _draw_preview(stage, mesh, uvmesh, self.network, colour, normal, self.ctx, up,
                          levels, ahead)  # fmt: skip
        if self.glb_keys:
            _write_glb(stage.path(f"{stem}.glb"), stem, uvmesh, maps, self.encoded,
                       self.glb_keys)  # fmt: skip
        if self.usd_textures is not None:
            usd_args = (stem, uvmesh, self.usd_textures, up)
            doc = f"crackbake {__version__}: {stem}"
            if "usd" in formats:
                write_usd(stage.path(f"{stem}.usda"), *usd_args, doc=doc)
            if "usdz" in formats:
                for future in self.encoded.values():  # the package copies the textures in
                    future.result()
                write_usdz(stage.path(f"{stem}.usdz"), *usd_args, doc=doc)
        for job in self.jobs:
            job.result()  # the first failure, in submission order


def _write_network(network: CrackNetwork, stage) -> None:
    for name, write in (("cracks.json", write_sidecar), ("cracks.obj", write_obj)):
        write(network, stage.path(name))
        stage.remember(stage.path(name))  # hashed here, beside the encoders


def _write_exr(path, maps: CrackMaps, float32: bool, compression: str, run: dict,
               stage=None) -> None:  # fmt: skip
    planes = crack_planes(maps.channels(), float32=float32)
    attributes = crack_attributes(
        __version__, maps.max_distance, maps.profile_shape, channels=planes
    )
    write_exr(path, planes, attributes={**run, **attributes}, compression=compression)
    if stage is not None:  # hashed here, beside the other encoders (OutputStage.remember)
        stage.remember(path)


def _write_stress_exr(path, stress: StressMaps, compression: str, run: dict,
                      stage=None) -> None:  # fmt: skip
    attributes = stress_attributes(__version__, units=stress.units)
    attributes["crackbake:stressFrame"] = stress.frame
    write_exr(path, stress_planes(stress.fields(), units=stress.units),
              attributes={**run, **attributes}, compression=compression)  # fmt: skip
    if stage is not None:
        stage.remember(path)


#: The glTF profile's name of each file the USD material reads, when the run's own PNGs hold
#: no such map: (content, bits, file suffix).
_USD_FILES = (("base_color", 8, "basecolor"), ("normal", 8, "normal"), ("orm", 8, "orm"),
              ("data", 16, "data"))  # fmt: skip


def _usd_textures(enc: _Encoder, stage, stem: str, params, maps: CrackMaps) -> UsdTextures:
    """The PNGs the USD material binds: the target's own files where they hold the map USD
    reads (base colour, OpenGL normal, ORM or roughness + occlusion, 16-bit data), the glTF
    profile's names for the rest (``<stem>_usd_<map>.png`` where such a name is taken)."""
    have: dict[str, str] = {}
    taken: set[str] = set()
    if "png" in params.formats:
        normal_y = normal_convention(params.target, params.normal_y)
        for f in TARGETS[params.target].files:
            name = f.name.format(stem=stem)
            taken.add(name.lower())  # case-insensitive file systems: _Normal and _normal clash
            usable = (f.content != "normal" or normal_y == "gl") and (
                f.content != "data" or f.bits == 16
            )
            if usable:
                have.setdefault(f.content, name)
    if "roughness" in have and "occlusion" in have and "orm" not in have:
        rough, occ = (have["roughness"], "r"), (have["occlusion"], "r")
        wanted = [f for f in _USD_FILES if f[0] != "orm"]
    else:
        rough = occ = None
        wanted = list(_USD_FILES)
    for content, bits, suffix in wanted:
        if content in have:
            continue
        name = f"{stem}_{suffix}.png"
        if name.lower() in taken:
            name = f"{stem}_usd_{suffix}.png"
        enc.want((content, bits, "gl", maps.res), stage.path(name))
        have[content] = name
    if rough is None:
        rough, occ = (have["orm"], "g"), (have["orm"], "r")
    scales = data_scales(maps)
    return UsdTextures(
        base_color=have["base_color"], normal=have["normal"], occlusion=occ, roughness=rough,
        data=have["data"], width_scale=scales["width"], depth_scale=scales["depth"],
    )  # fmt: skip


def _write_glb(path, stem, uvmesh: UVMesh, maps: CrackMaps, encoded, keys: dict) -> None:
    """glTF material: base colour, ORM (occlusion + metallic-roughness), normal with TANGENT."""
    orm = encoded[keys["orm"]].result()
    extra = {"occlusion": orm, "metallic_roughness": orm}
    tangents = getattr(uvmesh, "tangents", None)
    if maps.normal is not None and tangents is not None:
        extra["normal"] = encoded[keys["normal"]].result()
    write_glb(
        path,
        uvmesh.vertices,
        uvmesh.faces,
        uvmesh.uv,
        uvmesh.normals,
        encoded[keys["base_color"]].result(),
        name=stem,
        extra_textures=extra,
        tangents=tangents,
        material_extras=_look_extras(maps),
    )


def _look_extras(maps: CrackMaps) -> dict | None:
    """The material's ``extras``: the crack look the textures were composited with."""
    from crackbake.looks import Look

    look = getattr(maps, "look", None)
    return {"crackbake_look": (look if look is not None else Look()).to_dict()}


def _preview_pages(maps: CrackMaps, texture, with_normal: bool, size: int = PREVIEW_TEXTURE_MAX):
    """The preview's base colour and 8-bit normal map (or None), at most ``size`` on an edge.

    The last halving, the compositing and the quantisation run fused (one pass each, GIL
    released, so the encoders keep both cores); the pictures are the ones the numpy path
    (:func:`_smaller`, :func:`base_color`, :func:`pack`) gives, bit for bit.
    """
    n = maps.mask.shape[0]
    look = getattr(maps, "look", None)
    fused = size < n <= 4 * size and n % 4 == 0  # one numpy halving at most, then the kernels
    if fused and texture is not None and texture.shape[:2] != maps.mask.shape:
        fused = False
    if not fused:
        small = _smaller(maps, size)
        tex = texture
        if tex is not None and tex.shape[0] > size:
            tex = downsample(tex, size)
        colour = base_color(small.mask, occlusion=small.occlusion, texture=tex, look=look)
        normal = None
        if with_normal and small.normal is not None:
            normal = pack("normal", small, 8, "gl")
        return colour, normal
    from crackbake.exchange.halving import base_color_half, normal_half  # above 2048² only

    half = 2 * size
    mask, occ = downsample(maps.mask, half), maps.occlusion
    occ = None if occ is None else downsample(occ, half)
    tex = None if texture is None else downsample(texture, half)
    colour = base_color_half(mask, occ, base_color_table(tex is not None, look), tex)
    normal = None
    if with_normal and maps.normal is not None:
        normal = normal_half(downsample(maps.normal, half))
    return colour, normal


def _write_preview(stage, mesh, uvmesh, network, maps, texture, ctx, up=None) -> None:
    pages = _preview_pages(maps, texture, getattr(uvmesh, "tangents", None) is not None)
    _draw_preview(stage, mesh, uvmesh, network, *pages, ctx, up)


def _preview_levels(maps: CrackMaps, texture, with_normal: bool):
    """:func:`_preview_pages` and their mip levels (:func:`~crackbake.bake.preview.mip_levels`):
    (colour, normal, (colour's levels, normal's levels))."""
    from crackbake.bake.preview import mip_levels

    colour, normal = _preview_pages(maps, texture, with_normal)
    return colour, normal, (mip_levels(colour), None if normal is None else mip_levels(normal))


def _draw_preview(stage, mesh, uvmesh, network, colour, normal, ctx, up=None,
                  levels=None, ahead=None) -> None:  # fmt: skip
    """Render ``preview.png`` from its pages (:func:`_preview_pages`) with ``ctx``; ``ahead``:
    :func:`~crackbake.bake.preview.preview_ahead` of ``mesh`` and ``uvmesh``."""
    tangents = getattr(uvmesh, "tangents", None)
    view_dir, up, target, distance = preview_camera(mesh, network, up, ahead)
    picture = render_preview(
        uvmesh.vertices,
        uvmesh.faces,
        uvmesh.uv,
        uvmesh.normals,
        colour,
        view_dir=view_dir,
        up=up,
        target=target,
        distance=distance,
        normal_map=normal,
        tangents=tangents,
        ctx=ctx,
        levels=levels,
        closed=None if ahead is None else ahead.closed,
    )
    write_bytes(stage.path("preview.png"), png_bytes(picture, level=6, srgb=True))


class _TileStage:
    """A stage whose file names get one tile's ``.<UDIM>`` before their extension."""

    def __init__(self, stage, number: int):
        self.stage, self.number = stage, number

    def path(self, name: str):
        from crackbake.bake.udim import udim_name

        return self.stage.path(udim_name(name, self.number))


def _udim_textures(textures: UsdTextures) -> UsdTextures:
    """The USD material's files as UDIM sets: ``<name>.<UDIM>.png``."""
    from dataclasses import replace

    from crackbake.bake.udim import udim_name

    def tag(name: str) -> str:
        return udim_name(name, "<UDIM>")

    return replace(
        textures, base_color=tag(textures.base_color), normal=tag(textures.normal),
        occlusion=(tag(textures.occlusion[0]), textures.occlusion[1]),
        roughness=(tag(textures.roughness[0]), textures.roughness[1]), data=tag(textures.data),
    )  # fmt: skip


def _write_udim(stage, stem, params, mesh, uvmesh, network, maps, ctx, stress, effective) -> None:
    """A UDIM set (:mod:`crackbake.bake.udim`): every map per tile, ``<name>.<UDIM>.<ext>``; the
    GLB and the preview on the tiles packed into one page, UVs remapped (glTF has no UDIM).
    Each tile's base colour composites the cracks over that tile's own texture
    (:func:`~crackbake.io.texture.base_color_tiles`), as one page does over the asset's."""
    from dataclasses import replace

    from crackbake.bake.udim import packed_maps, packed_uv, udim_name
    from crackbake.exchange.targets import warn_udim_target

    formats = params.formats
    exr = {"compression": params.exr_compression, "run": run_attributes(__version__, effective)}
    if "png" in formats:
        warn_udim_target(params.target)
    textures = None  # the asset's own base colour per tile, composited as on one page
    if mesh.source and {"png", "glb", "preview", "usd"} & set(formats):
        textures = base_color_tiles(mesh.source, maps.numbers, maps.res,
                                    params.allow_outside_textures)  # fmt: skip
    if "usdz" in formats:
        warnings.warn(
            "--formats usdz: AR Quick Look (ARKit) reads no UDIM textures, so no .usdz is "
            "written for UDIM tiles; use the .usda (--formats usd, <UDIM> textures), the GLB, "
            "or --uv unwrap for one page",
            CrackbakeWarning,
            stacklevel=4,
        )
    with ThreadPoolExecutor(WRITE_THREADS, thread_name_prefix="crackbake-write") as pool:
        jobs: list[Future] = []
        encoded: dict = {}
        try:
            for k, (number, page) in enumerate(zip(maps.numbers, maps.pages, strict=True)):
                if "exr" in formats:
                    path = stage.path(f"{stem}_cracks.{number}.exr")
                    jobs.append(pool.submit(_write_exr, path, page, params.float32, **exr))
                if stress is not None and "stress" in formats:
                    path = stage.path(f"{stem}_stress.{number}.exr")
                    jobs.append(pool.submit(_write_stress_exr, path, stress[k], **exr))
                enc = _Encoder(pool, page, None if textures is None else textures[k])
                if "png" in formats:
                    normal_y = normal_convention(params.target, params.normal_y)
                    for f in TARGETS[params.target].files:
                        ny = normal_y if f.content == "normal" else "gl"
                        name = udim_name(f.name.format(stem=stem), number)
                        enc.want((f.content, f.bits, ny, page.res), stage.path(name))
                if "usd" in formats:  # the same names on every tile: one <UDIM> set each
                    usd_textures = _usd_textures(enc, _TileStage(stage, number), stem, params,
                                                 page)  # fmt: skip
                jobs.extend(enc.start(set()).values())
                frames = submit_frames(pool, lambda n, u=number: stage.path(udim_name(n, u)),
                                       stem, page, params.frames)  # fmt: skip
                jobs.extend(frames)
            packed = None
            if {"glb", "preview"} & set(formats):
                packed = packed_maps(maps, GLB_TEXTURE_MAX, textures)
                flat = replace(uvmesh, uv=packed_uv(uvmesh.uv, uvmesh.faces, uvmesh.udim),
                               udim=None)  # fmt: skip
            if "glb" in formats:
                enc = _Encoder(pool, packed, packed.texture)
                size = min(packed.res, GLB_TEXTURE_MAX)
                glb_keys = {s: enc.want((s, 8, "gl", size)) for s in ("base_color", "normal",
                                                                       "orm")}
                encoded = enc.start(set(glb_keys.values()))
                jobs.extend(encoded.values())
            up = None
            if {"preview", "usd"} & set(formats):
                up = up_vector(params.up, mesh, cache=params.cache)
            if "preview" in formats:
                _write_preview(stage, mesh, flat, network, packed, packed.texture, ctx, up)
            write_sidecar(network, stage.path("cracks.json"))
            write_obj(network, stage.path("cracks.obj"))
            if "glb" in formats:
                _write_glb(stage.path(f"{stem}.glb"), stem, flat, packed, encoded, glb_keys)
            if "usd" in formats:
                write_usd(stage.path(f"{stem}.usda"), stem, uvmesh, _udim_textures(usd_textures),
                          up, doc=f"crackbake {__version__}: {stem}")
        finally:
            for job in jobs:
                job.exception()
        for job in jobs:
            job.result()
