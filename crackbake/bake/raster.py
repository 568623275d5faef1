"""GPU bake of a crack network into UV-space texture maps.

The asset's faces are drawn at their UV positions in two passes: the first marks the texels on
a face and, in the depth buffer, whether the face's bin (:mod:`crackbake.bake.grid`: nearby
faces share one list, so memory stays linear in faces + segments) lists any crack segment; the
second draws the faces whose bin does, and, once per texel they own (the depth test), loops over
the listed segments, measuring world-space distances from the texel's point with its footprint
(the derivatives of the position across one texel); the texels of faces with empty lists take an
empty list's values from the targets' clear.  So widths are in mesh units whatever the UV
stretch, and a crack crossing a UV seam continues on both islands.  Large images are drawn in
bands, and empty texels are then filled from their nearest island (dilation) so bilinear
filtering and mip-maps never pull in background.  Given tangents, the second pass also records
each crack texel's point, footprint, face and the segment whose depth wins it, and a compute
pass over the crack texels derives the depth-normal and occlusion maps from them
(:mod:`crackbake.bake.normal_map`).  A camera's placement (the decal bake) records each texel's
point, footprint and bin in float targets first and measures them in one full-screen pass.

All returned images have row 0 at the top (UV v = 1), the order image files store.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from crackbake.bake.cells import image_bins
from crackbake.bake.context import GLScope, finish, shader_source
from crackbake.bake.crack_targets import NAMES, NUMPY_TYPES, band_rows, channel_dtypes
from crackbake.bake.dilation import PlanAhead, dilate
from crackbake.bake.grid import FaceBins, face_bins
from crackbake.bake.normal_map import NormalPass, frame_attributes, shader_variant
from crackbake.bake.prefetch import TargetPrefetch
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.network import Segments
from crackbake.params import DEFAULT_MAX_DISTANCE_FRACTION, MIN_PX_DEFAULT, TILE_DEFAULT


@dataclass(eq=False)
class CrackMaps:
    """Baked crack channels, each (res, res), row 0 = top of the image.

    Attributes
    ----------
    mask : float16, 0..1
        Anti-aliased crack coverage.
    width : float32, mesh units
        Opening width of the nearest crack (0 where there is none within ``max_distance``).
    time : float16, 0..1
        Crack time of the nearest crack point.
    depth : float32, mesh units, >= 0
        Depth of the crack profile at the texel.
    distance : float32, mesh units
        World distance to the nearest crack, clamped at ``max_distance``.
    crack_id : float32
        Id of the nearest crack, -1 where none within ``max_distance``.
    inside : bool
        Texels whose centre lies on a face (before dilation).
    normal : (res, res, 3) float32 or None
        Unit tangent-space normal of the crack's depth profile, OpenGL convention (X along T,
        Y along B = +v, Z along N; flat = (0, 0, 1)), for decoding as
        ``normalize(x T + y B + z N)`` with the tangents baked with; ``None`` without tangents.
        A view of planar storage: each ``normal[..., k]`` is C-contiguous.
    occlusion : (res, res) float16 or None
        Sky visibility 0..1 (1 = open, crack interiors dark); ``None`` without tangents.
    min_px : float
        Least drawn crack width in texels the mask, depth, normal and occlusion were drawn with
        (``width`` holds the physical width).
    look : crackbake.looks.Look or None
        The look the maps were baked with and the written material composites with (None:
        the default look).
    scales : dict or None
        The data map's ``width`` and ``depth`` divisors when they are shared with other pages
        (the tiles of a UDIM set, :mod:`crackbake.bake.udim`); None: this page's own maxima.
    """

    res: int
    mask: np.ndarray
    width: np.ndarray
    time: np.ndarray
    depth: np.ndarray
    distance: np.ndarray
    crack_id: np.ndarray
    inside: np.ndarray
    max_distance: float
    profile_shape: float
    normal: np.ndarray | None = None
    occlusion: np.ndarray | None = None
    min_px: float = 0.0
    timings: dict[str, float] = field(default_factory=dict)
    look: object = None
    scales: dict | None = None

    def channels(self) -> dict[str, np.ndarray]:
        """Role -> image for the maps that were baked (``normal``/``occlusion`` only with
        tangents); the roles of :data:`crackbake.exchange.layers.CRACK_LAYERS`."""
        roles = {
            "mask": self.mask,
            "width": self.width,
            "time": self.time,
            "depth": self.depth,
            "distance": self.distance,
            "id": self.crack_id,
            "normal": self.normal,
            "occlusion": self.occlusion,
        }
        return {k: v for k, v in roles.items() if v is not None}


def _segment_buffer(segments: Segments) -> np.ndarray:
    n = max(len(segments.a), 1)
    buf = np.zeros((n, 4, 4), np.float32)
    if len(segments.a):
        buf[:, 0, :3] = segments.a
        buf[:, 0, 3] = segments.width[:, 0]
        buf[:, 1, :3] = segments.b
        buf[:, 1, 3] = segments.width[:, 1]
        buf[:, 2, 0:2] = segments.depth
        buf[:, 2, 2:4] = segments.time
        buf[:, 3, 0] = segments.crack_id
    return buf


#: Reach of a crack's curled rim beyond its half width, in half widths (shaders/crack_look.glsl).
CURL_REACH = 3.0


def look_terms(look, segments: Segments, seed: int = 0) -> dict:
    """The shader terms of a :class:`crackbake.looks.Look`: ``defines`` (``CRACK_CHIP``,
    ``CRACK_CURL``), ``uniforms``, ``normal_strength`` and ``reach`` (how far beyond its half
    width a crack draws anything, as a factor: the candidate search widens by it)."""
    terms: dict = {"defines": [], "uniforms": {}, "normal_strength": 1.0, "reach": 1.0}
    if look is None:
        return terms
    terms["normal_strength"] = float(look.normal_strength)
    if look.chipping > 0 and len(segments.a):
        w = segments.width[segments.width > 0]
        # Chips about as long as the crack is wide: ragged at the scale of the opening.
        scale = 1.5 * float(np.median(w)) if len(w) else 1.0
        terms["defines"].append("CRACK_CHIP")
        terms["uniforms"].update(u_chip=float(look.chipping), u_chip_scale=scale,
                                 u_chip_seed=int(seed) & 0xFFFFFFFF)
        terms["reach"] *= 1.0 + float(look.chipping)
    if look.curl > 0:
        terms["defines"].append("CRACK_CURL")
        terms["uniforms"]["u_curl"] = float(look.curl)
        terms["reach"] *= 1.0 + CURL_REACH
    return terms


def bake_cracks(
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    segments: Segments,
    res: int,
    max_distance: float | None = None,
    profile_shape: float = 1.0,
    dilate_px: int | None = None,
    tile: int = TILE_DEFAULT,
    ctx=None,
    normals: np.ndarray | None = None,
    tangents: np.ndarray | None = None,
    projection: np.ndarray | None = None,
    min_px: float = MIN_PX_DEFAULT,
    look=None,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    targets: TargetPrefetch | None = None,
    gutter: PlanAhead | None = None,
) -> CrackMaps:
    """Bake crack segments into UV-space maps of the given triangles.

    Parameters
    ----------
    vertices : (V, 3) float
        World positions of the triangles to bake (the asset in its UV atlas, or any other set).
    faces : (F, 3) int
        Triangles indexing ``vertices`` and ``uv``.
    uv : (V, 2) float
        Texture coordinates in [0, 1], v up.
    segments : Segments
        Crack segments in world space (``crackbake.network.segments``).
    res : int
        Output edge in texels (square).
    max_distance : float, optional
        Clamp of the distance channel and reach of the id/width/time channels, mesh units.
        Default 2 % of the bounding-box diagonal.
    profile_shape : float
        Depth profile exponent across the crack: depth = D (1 - |x| / half_width) ** shape;
        1 is a V, 0.5 a rounded U, 2 a sharp slot.
    dilate_px : int, optional
        Limit of the gutter fill in texels; ``None`` fills every empty texel.
    tile : int
        Largest framebuffer edge; bigger images are drawn in bands of at most ``tile**2``
        texels (25 bytes each on the GL side, 28 with the normal map; 76 placed by a camera).
    ctx : moderngl.Context, optional
        The run's context; a temporary one is created (and released) when not given.
    normals : (V, 3) float, optional
        Shading normals of the vertices (``UVMesh.normals``), used with ``tangents``; default
        area-weighted normals welded across UV seams.
    tangents : (V, 4) float, optional
        MikkTSpace tangents (xyz, w = bitangent sign) of the vertices; when given, the maps
        also hold ``normal`` and ``occlusion`` (:mod:`crackbake.bake.normal_map`).
    projection : (4, 4) float, optional
        Placement of the faces in the image: ``None`` draws them at their UVs (the texture
        bake); a mesh -> clip matrix (column vectors, x right, y up, z -1 near .. 1 far) draws
        them through that camera, depth-tested (``shaders/decal_project.vert``: the decal bake
        of :mod:`crackbake.decals.projector`).  ``uv`` must then hold the same placement in [0, 1]
        (``0.5 + 0.5 * clip.xy``), which the candidate bins use for the texel footprint.
    min_px : float
        Least drawn width in texels, >= 0: the mask, depth, normal and occlusion draw each crack
        at least this many texel footprints across (measured across the crack), so a crack
        thinner than a texel still reads at this resolution; the ``width`` channel keeps the
        physical width.  0 draws the physical width only (sub-texel cracks fade to their
        area-averaged coverage).
    look : crackbake.looks.Look, optional
        The run's crack look: its ``chipping`` (ragged drawn edges), ``curl`` (raised rims in
        the normal map) and ``normal_strength`` (the normal's slope scale) change the bake;
        None bakes the default look.  Kept on the maps for the written material.
    seed : int
        Seed of the chipping noise.
    progress : callable, optional
        Called as ``progress(rows_done, res)`` after each GL call of the crack pass (at most
        :data:`SLICE_TEXELS` texels each), in the main thread: a long bake reports as it goes,
        and a SIGINT/SIGTERM handler runs between two calls.
    targets : TargetPrefetch, optional
        Render targets allocated ahead (:func:`~crackbake.bake.crack_targets.target_specs`,
        :mod:`crackbake.bake.prefetch`); those it lacks are created here.  The pixels are the
        same either way.
    gutter : PlanAhead, optional
        The gutter fill planned ahead from :func:`coverage`; used when the bake finds those
        islands and ``dilate_px`` (else planned here).  The pixels are the same either way.

    Returns
    -------
    CrackMaps
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    uv = np.asarray(uv, np.float64)
    if res < 1:
        # RunParams validates the user's --res; this guards direct library calls.
        raise ValueError(f"res must be a positive texel count, got {res}")
    if profile_shape <= 0:
        raise CrackbakeError(f"profile shape {profile_shape} must be > 0 (1 = V profile)")
    if not (np.isfinite(min_px) and min_px >= 0):
        raise CrackbakeError(f"--min-px {min_px} must be a number >= 0 (texels; 0 = physical)")
    max_distance = _max_distance(vertices, segments, max_distance)
    frames = None if tangents is None else frame_attributes(vertices, faces, normals, tangents)

    terms = look_terms(look, segments, seed)
    reached = segments
    if terms["reach"] != 1.0:  # chipped or curled cracks draw beyond their half width
        reached = replace(segments, width=segments.width * terms["reach"])
    if projection is None:
        bins = face_bins(vertices, faces, uv, reached, res, max_distance, float(min_px))
    else:  # a camera's image: lists per image cell (crackbake.bake.cells)
        bins = image_bins(vertices, faces, uv, reached, res, max_distance, projection,
                          float(min_px))  # fmt: skip
    timings["candidates"] = time.perf_counter() - t0

    images = _render(
        ctx, vertices, faces, uv, segments, res, tile, bins,
        float(max_distance), float(profile_shape), timings, frames, projection, float(min_px),
        terms, progress, targets,
    )  # fmt: skip

    maps = _dilated_maps(images, res, dilate_px, max_distance, profile_shape, timings, gutter)
    maps.min_px = float(min_px)
    maps.look = look
    return maps


#: Most texels the crack pass measures in one GL call (rows of a band, scissored): under a second
#: of llvmpipe even in a dense star's centre, so SIGINT/SIGTERM, which Python handles only
#: between calls, stop a bake of any size promptly.  The bands themselves (and so the surface
#: pass's rounding: the pixels) stay as ``tile`` makes them.  2**19 texels cost the 4096² render
#: 3-6 % (a ctx.finish per slice, 32 slices); at 2**21 (8 slices) it equals the unsliced bake's.
SLICE_TEXELS = 1 << 21

#: Crack texel records the normal map's crack pass makes room for at first: a band's texels over
#: RECORDS_SHARE, at least RECORDS_LEAST (48 bytes each; llvmpipe zero-fills the buffer: 0.035
#: CPU-s at 4096²).  A band needing more is drawn again with room for all of them (the crack pass
#: twice); spot glass at 4096² has 25k crack texels (0.15 %), dense networks many more.
RECORDS_SHARE = 16
RECORDS_LEAST = 1 << 16



@dataclass(eq=False)
class _Passes:
    """The programs and vertex arrays of one bake.

    ``surface`` draws the faces at their placement: with a UV placement the class pass
    (``crack_inside.frag`` on each face at the depth of its list's class), with a camera's
    the surface pass (``crack_surface.frag``: world position, footprint, bin per texel).
    ``cracks`` measures the cracks: with a UV placement the listed faces again
    (``crack_bake.frag`` with ``CRACK_FACES``; None when no face lists a segment), with a
    camera's one full-screen triangle reading the surface targets, after ``inside`` marked the
    face texels."""

    surface: object
    cracks: object | None
    inside: object | None
    program: object
    #: With a UV placement: (first, count) of the crack pass's primitives for each slice,
    #: keyed by (band's first row, slice's first row in the band); None: every slice draws all.
    slices: dict | None = None


def _programs(gl: GLScope, vertices, faces, uv, segments: Segments, res: int, bins: FaceBins,
              max_distance: float, profile_shape: float, frames: np.ndarray | None,
              projection: np.ndarray | None = None, min_px: float = 0.0,
              terms: dict | None = None, band: int | None = None) -> _Passes:
    """The bake's passes (:class:`_Passes`) with their buffers and tables.

    The placement is the vertex shader: ``crack_bake.vert`` puts each face at its UVs,
    ``decal_project.vert`` through the ``projection`` camera."""
    ctx = gl.ctx
    with_normals = frames is not None
    projected = projection is not None
    terms = terms or look_terms(None, segments)
    defines = tuple(terms["defines"]) + (("CRACK_CELLS",) if bins.cell else ())
    vertex = np.empty((len(vertices), 5), np.float32)
    vertex[:, 0:2] = uv
    vertex[:, 2:5] = vertices
    vbo = gl.keep(ctx.buffer(vertex))
    ibo = gl.keep(ctx.buffer(np.ascontiguousarray(faces, np.uint32)))
    face_bin = np.asarray(bins.face_bin, np.uint32)
    if projected:
        surface = gl.keep(ctx.program(
            vertex_shader=shader_variant("decal_project.vert", with_normals),
            fragment_shader=shader_variant("crack_surface.frag", with_normals)))  # fmt: skip
        # Column vectors in GLSL's column-major order: the transpose of the row-major array.
        surface["u_projection"].write(np.asarray(projection, np.float32).T.tobytes())
        layout = [(vbo, "8x 3f", "in_pos")]
        prog = gl.keep(ctx.program(
            vertex_shader=shader_variant("crack_screen.vert", with_normals),
            fragment_shader=shader_variant("crack_bake.frag", with_normals, defines)))  # fmt: skip
        prog["u_depth"].value = 1.0  # every face texel
        cracks = gl.keep(ctx.vertex_array(prog, []))
        inside = gl.keep(ctx.program(vertex_shader=shader_source("crack_screen.vert"),
                                     fragment_shader=shader_source("crack_inside.frag")))
        inside["u_depth"].value = 1.0
        inside_screen = gl.keep(ctx.vertex_array(inside, []))
    else:
        # The class pass: each face's corners of its own, at the depth of its class (0.25:
        # its bin lists a segment, 0.75: none), drawn with a constant colour (inside), so
        # llvmpipe runs no per-texel shader work for it.
        surface = gl.keep(ctx.program(
            vertex_shader=shader_variant("crack_bake.vert", with_normals, ("CRACK_CLASS_Z",)),
            fragment_shader=shader_source("crack_inside.frag")))  # fmt: skip
        bounds = np.asarray(bins.bin_start)
        listed_face = bounds[face_bin + 1] > bounds[face_bin]
        corners = np.empty((len(faces), 3, 3), np.float32)
        corners[:, :, 0:2] = vertex[np.asarray(faces), 0:2]
        corners[:, :, 2] = np.where(listed_face, -0.5, 0.5)[:, None]
        cbo = gl.keep(ctx.buffer(corners))
        layout = [(cbo, "2f 1f", "in_uv", "in_z")]
        prog = gl.keep(ctx.program(
            vertex_shader=shader_variant("crack_bake.vert", with_normals),
            fragment_shader=shader_variant("crack_bake.frag", with_normals,
                                           defines + ("CRACK_FACES",))))  # fmt: skip
        # The crack pass draws only the faces whose bin lists a segment, in their order (so
        # where faces overlap the last drawn still wins), each with its face and bin; each
        # slice of it only those reaching the slice's rows (:func:`_slice_runs`).
        listed = np.flatnonzero(listed_face)
        cracks = inside_screen = slices = None
        if len(listed):
            drawn, slices = _slice_runs(uv, faces, listed, res, band or res)
            prim = np.column_stack([drawn, face_bin[drawn]]).astype(np.uint32)
            _table_texture(gl, prim, 1 << LIST_ROW_LOG2, "u4", 2).use(7)
            sub = gl.keep(ctx.buffer(np.ascontiguousarray(faces[drawn], np.uint32)))
            cracks = gl.keep(ctx.vertex_array(prog, [(vbo, "2f 3f", "in_uv", "in_pos")],
                                              index_buffer=sub, index_element_size=4))
        prog["u_res"].value = float(res)
    if projected:
        vao = gl.keep(ctx.vertex_array(surface, layout, index_buffer=ibo, index_element_size=4))
    else:
        vao = gl.keep(ctx.vertex_array(surface, layout))
    if with_normals:
        ibo.bind_to_storage_buffer(5)  # the triangles, read by crack_normal.glsl
        gl.keep(ctx.buffer(frames)).bind_to_storage_buffer(6)
    seg_buffer = _segment_buffer(segments)
    # The crack normals' compute pass reads the segments as a storage buffer (binding 0); the
    # crack pass reads them, and the lists, as textures (units 3, 4: shaders/crack_bake.frag).
    gl.keep(ctx.buffer(seg_buffer)).bind_to_storage_buffer(0)
    _table_texture(gl, seg_buffer.reshape(-1, 4), 4 << SEG_ROW_LOG2, "f4", 4).use(3)
    row = 1 << LIST_ROW_LOG2
    lists = np.empty((len(bins.candidates), 2), np.uint32)
    lists[:, 0] = bins.candidates
    lists[:, 1] = np.asarray(bins.bounds, np.float32).view(np.uint32)
    _table_texture(gl, lists, row, "u4", 2).use(4)
    ranges = np.column_stack([bins.bin_start[:-1], bins.bin_start[1:]]).astype(np.uint32)
    _table_texture(gl, ranges, row, "u4", 2).use(5)
    _table_texture(gl, face_bin.reshape(-1, 1), row, "u4", 1).use(6)
    surface["u_res"].value = float(res)
    prog["u_max_distance"].value = max_distance
    half = 0.5 * float(segments.width.max()) * terms["reach"] if len(segments.a) else 0.0
    prog["u_half_width"].value = half
    for name, value in terms["uniforms"].items():
        if prog.get(name, None) is not None:  # the crack pass uses the chipping terms only
            prog[name].value = value
    prog["u_shape"].value = profile_shape
    prog["u_min_px"].value = min_px
    if bins.cell:
        prog["u_cell"].value = bins.cell
        prog["u_cells_x"].value = bins.cells_x
    return _Passes(vao, cracks, inside_screen, prog, None if projected else slices)


#: Texture table rows of ``shaders/crack_bake.frag``: 2**10 segments (4 texels each), and 2**12
#: list entries, bins or faces (``crack_surface.frag``) a row.
SEG_ROW_LOG2 = 10
LIST_ROW_LOG2 = 12


def _table_texture(gl: GLScope, items: np.ndarray, width: int, dtype: str, components: int):
    """A (rows, width) texture of ``items`` ((N, components), row-major, zero-padded to whole
    rows), sampled with texelFetch only."""
    import moderngl

    rows = max(1, -(-len(items) // width))
    limit = gl.ctx.info["GL_MAX_TEXTURE_SIZE"]
    if rows > limit:
        raise CrackbakeError(
            f"{len(items)} crack segments or candidate entries exceed this OpenGL's texture "
            f"limit ({limit} rows of {width}); bake fewer cracks or a smaller --res"
        )
    table = np.zeros((rows * width, components), items.dtype)
    table[: len(items)] = items
    tex = gl.keep(gl.ctx.texture((width, rows), components, table, dtype=dtype))
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return tex


def _image(prefetch: TargetPrefetch | None, shape: tuple[int, ...], dtype,
           zeros: bool = False) -> np.ndarray:
    """A prefetched (zeroed, paged-in) image when there is one left, else a new one (empty, or
    zeroed when ``zeros``)."""
    image = None if prefetch is None else prefetch.take_array(shape, dtype)
    if image is None:
        image = np.zeros(shape, dtype) if zeros else np.empty(shape, dtype)
    return image


def coverage(ctx, uv: np.ndarray, faces: np.ndarray, res: int, tile: int = TILE_DEFAULT,
             with_normals: bool = True) -> np.ndarray:
    """The texels a UV-placed :func:`bake_cracks` of these triangles finds on a face (its
    ``inside``), drawn without the cracks: the same placement shader (the bake's vertex
    stage, band by band as ``tile`` makes them, so the same rasterisation), one bit out.

    Parameters
    ----------
    ctx : moderngl.Context or None
        The run's context (a temporary one when None).
    uv : (V, 2) float
        Texture coordinates, v up.
    faces : (F, 3) int
        Triangles indexing ``uv``.
    res, tile : int
        As given to :func:`bake_cracks`.
    with_normals : bool
        Whether that bake is given tangents (its vertex stage's variant).

    Returns
    -------
    (res, res) bool
        Row 0 = top of the image.
    """
    import moderngl

    band = band_rows(res, tile)
    inside = np.empty((res, res), np.uint8)
    with GLScope(ctx) as gl:
        prog = gl.keep(gl.ctx.program(
            vertex_shader=shader_variant("crack_bake.vert", with_normals),
            fragment_shader=shader_source("crack_inside.frag")))  # fmt: skip
        vbo = gl.keep(gl.ctx.buffer(np.asarray(uv, np.float32)))
        ibo = gl.keep(gl.ctx.buffer(np.ascontiguousarray(faces, np.uint32)))
        vao = gl.keep(gl.ctx.vertex_array(prog, [(vbo, "2f", "in_uv")], index_buffer=ibo,
                                          index_element_size=4))  # fmt: skip
        fbo = gl.keep(gl.ctx.framebuffer(color_attachments=[
            gl.keep(gl.ctx.texture((res, band), 1, dtype="f1"))]))  # fmt: skip
        prog["u_res"].value = float(res)
        gl.ctx.enable_only(moderngl.NOTHING)
        fbo.use()
        for y0 in range(0, res, band):
            h = min(band, res - y0)
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            prog["u_tile"].value = (0.0, float(y0), float(res), float(band))
            vao.render(moderngl.TRIANGLES)
            fbo.read_into(inside[y0 : y0 + h], viewport=(0, 0, res, h), components=1,
                          dtype="f1")  # fmt: skip
    return inside > 0


def _texture(gl: GLScope, size: tuple[int, int], components: int, dtype: str,
             prefetch: TargetPrefetch | None):
    """A prefetched texture of that kind when there is one left, else a new one."""
    tex = None if prefetch is None else prefetch.take(gl, size, components, dtype)
    return tex if tex is not None else gl.keep(gl.ctx.texture(size, components, dtype=dtype))


def _targets(gl: GLScope, res: int, band: int, dtypes: tuple[str, ...],
             prefetch: TargetPrefetch | None = None, surface: bool = False):
    """Framebuffers of one band: the crack pass's one target per channel, with a depth buffer
    (the faces' classes, or the surface pass's faces: the crack pass shades only where it
    allows); one framebuffer per crack target, to clear each to its own value, the inside
    target's with the depth buffer.  With ``surface``, also the surface pass's three float
    targets (bound as textures for the crack pass) and their framebuffer, else None."""
    import moderngl

    ctx = gl.ctx
    zbuffer = gl.keep(ctx.depth_renderbuffer((res, band)))
    gfbo = None
    if surface:
        gbuffer = [_texture(gl, (res, band), 4, "f4", prefetch) for _ in range(3)]
        for unit, tex in enumerate(gbuffer):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.use(unit)
        gfbo = gl.keep(ctx.framebuffer(color_attachments=gbuffer, depth_attachment=zbuffer))
    textures = [_texture(gl, (res, band), 1, d, prefetch) for d in dtypes]
    fbo = gl.keep(ctx.framebuffer(color_attachments=textures, depth_attachment=zbuffer))
    fbo.depth_mask = False
    singles = [gl.keep(ctx.framebuffer(color_attachments=[t])) for t in textures[:-1]]
    singles.append(gl.keep(ctx.framebuffer(color_attachments=[textures[-1]],
                                           depth_attachment=zbuffer)))
    return gfbo, fbo, singles


class _Records:
    """The crack texels' records the crack pass appends with the normal map
    (``shaders/crack_bake.frag``: storage bindings 9, the count, and 10, the records), read by
    the normal's compute pass; room for ``capacity`` of them, grown when a band needs more."""

    #: Most records of one band: the inside target holds 2 + the index as float32.
    LIMIT = (1 << 24) - 2

    def __init__(self, gl: GLScope, program, capacity: int) -> None:
        self.gl = gl
        self.program = program
        self.count = gl.keep(gl.ctx.buffer(reserve=4))
        self.count.bind_to_storage_buffer(9)
        self.records = None
        self.capacity = 0
        self.grow(capacity)

    def grow(self, capacity: int) -> None:
        capacity = max(1, min(int(capacity), self.LIMIT))
        if self.records is not None:
            self.records.release()
        # llvmpipe zero-fills it (RECORDS_SHARE sizes it).
        self.records = self.gl.ctx.buffer(reserve=48 * capacity)
        self.records.bind_to_storage_buffer(10)
        self.capacity = capacity
        self.program["u_capacity"].value = capacity

    def reset(self) -> None:
        self.count.write(np.zeros(1, np.uint32).tobytes())

    def used(self) -> int:
        """Records the last pass appended (stored or not)."""
        self.gl.ctx.memory_barrier()
        return int(np.frombuffer(self.count.read(), np.uint32)[0])

    def release(self) -> None:
        if self.records is not None:
            self.records.release()
            self.records = None


def _render(
    ctx,
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    segments: Segments,
    res: int,
    tile: int,
    bins: FaceBins,
    max_distance: float,
    profile_shape: float,
    timings: dict[str, float],
    frames: np.ndarray | None = None,
    projection: np.ndarray | None = None,
    min_px: float = 0.0,
    terms: dict | None = None,
    progress: Callable[[int, int], None] | None = None,
    prefetch: TargetPrefetch | None = None,
) -> dict[str, np.ndarray]:
    """Draw the faces at their placement band by band; the planar channel images (row 0 = top)."""
    import moderngl

    with_normals = frames is not None
    # Full-width bands of at most tile*tile texels: each band reads straight into the rows of
    # the planar channel images (no interleaved copy), and GL memory stays bounded (25 bytes a
    # texel: 4 of depth, 21 for the maps; 28 with the normal map, whose inside target holds the
    # crack texels' records as R32F; a camera's placement adds 48 for the surface pass).
    band = band_rows(res, tile)
    with GLScope(ctx) as gl:
        t1 = time.perf_counter()
        passes = _programs(
            gl, vertices, faces, uv, segments, res, bins, max_distance, profile_shape, frames,
            projection, min_px, terms, band,
        )  # fmt: skip
        prog_row0 = passes.program["u_row0"] if bins.cell else None
        dtypes = channel_dtypes(with_normals)
        images = {n: _image(prefetch, (res, res), NUMPY_TYPES[d])
                  for n, d in zip(NAMES, dtypes, strict=True)}  # fmt: skip
        records = None
        if with_normals:
            normal_pass = NormalPass(gl, profile_shape, min_px, terms)
            # Flat and open wherever no crack's depth reaches.  Planar storage: each component
            # dilates as its own image and EXR writers take the planes without a copy.
            images["normal"] = _image(prefetch, (3, res, res), np.float32, zeros=True)
            images["normal"][2] = 1.0
            images["occlusion"] = _image(prefetch, (res, res), np.float16)
            images["occlusion"][:] = 1.0
            records = _Records(gl, passes.program,
                               max(res * band // RECORDS_SHARE, RECORDS_LEAST))  # fmt: skip
        projected = projection is not None
        gfbo, fbo, singles = _targets(gl, res, band, dtypes, prefetch, surface=projected)
        # No blending or culling.  The clear is what crack_bake.frag writes at a face texel
        # whose list is empty (no crack within reach), except for the inside target: 0, off the
        # faces; the gutter fill overwrites every other channel there.
        # A UV placement: the class pass draws the faces (the last drawn wins, as without a
        # depth test), marking them inside and writing each face's class to the depth buffer
        # (0.25 where its bin lists a segment, 0.75 where none: a depth per face, given with its
        # corners, so the pass has no per-texel shader work beyond a constant); the crack
        # pass draws only the listed faces at depth 0.5, shading only where the depth test
        # finds a listed face's class: each such texel is measured by the face that owns it
        # (drawn last), and llvmpipe skips the 4x4 blocks that no listed face owns, which keep
        # the targets' clear (on spot, 90 % of the face texels take no loop step).  No surface
        # targets: the crack shader measures the point and footprint in place.
        # A camera's placement keeps the surface nearest to it (the depth test "<"): the
        # surface pass records each texel's point, footprint and bin in float targets, a
        # one-output pass marks the face texels inside, and the crack pass's full-screen
        # triangle shades every face texel (its depth is the camera's: no classes).
        clear = (0.0, 0.0, 0.0, 0.0, max_distance, -1.0, 0.0)  # NAMES' order
        gl.ctx.enable_only(moderngl.DEPTH_TEST)
        timings["setup"] = time.perf_counter() - t1
        t_surface = t_draw = t_read = t_normals = 0.0
        for y0 in range(0, res, band):
            h = min(band, res - y0)
            tile_rect = (0.0, float(y0), float(res), float(band))
            reports = progress
            while True:
                ta = time.perf_counter()
                # Before the surface pass writes the depth buffer the inside target shares.
                for single, value in zip(singles, clear, strict=True):
                    single.clear(value, value, value, value)
                if projected:
                    gfbo.use()
                    # The depth only: the passes after read the surface targets only where a
                    # face was drawn (the depth test), so their colours need no clear (805 MB
                    # at 4096²).
                    gfbo.color_mask = ((False,) * 4,) * 3
                    gfbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                    gfbo.color_mask = ((True,) * 4,) * 3
                    gfbo.use()
                    gl.ctx.depth_func = "<"
                else:
                    singles[-1].depth_mask = True
                    singles[-1].clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                    singles[-1].use()
                    gl.ctx.depth_func = "1"
                passes.surface.program["u_tile"].value = tile_rect
                passes.surface.render(moderngl.TRIANGLES)
                # Finished here only so the profile splits the two passes (the crack pass
                # waits for the surface targets anyway).
                finish(gl.ctx)
                t_surface += time.perf_counter() - ta
                gl.ctx.depth_func = ">"
                singles[-1].depth_mask = False
                if projected:
                    singles[-1].use()
                    passes.inside.render(moderngl.TRIANGLES, vertices=3)
                if records is not None:
                    records.reset()
                fbo.use()
                if bins.cell:
                    prog_row0.value = y0
                if passes.cracks is not None:
                    if not projected:
                        passes.program["u_tile"].value = tile_rect
                    _crack_pass(gl.ctx, fbo, passes.cracks, res, h, y0, reports,
                                vertices=3 if projected else -1, runs=passes.slices,
                                program=passes.program)  # fmt: skip
                tb = time.perf_counter()
                t_draw += tb - ta
                if records is None or records.used() <= records.capacity:
                    break
                if records.used() > records.LIMIT:
                    raise CrackbakeError(
                        f"{records.used()} crack texels in one band exceed the normal map's "
                        f"{records.LIMIT}; bake with a smaller --tile"
                    )
                records.grow(records.used())  # and draw the band again, reported once
                reports = None
            for k, (n, d) in enumerate(zip(NAMES, dtypes, strict=True)):
                fbo.read_into(images[n][y0 : y0 + h], viewport=(0, 0, res, h), components=1,
                              attachment=k, dtype=d)  # fmt: skip
            tc = time.perf_counter()
            if with_normals:
                # Only the crack texels, from the records the crack pass appended.
                planes = [*images["normal"], images["occlusion"]]
                normal_pass.run(images["inside"][y0 : y0 + h], planes, y0)
            t_read += tc - tb
            t_normals += time.perf_counter() - tc
        if records is not None:
            records.release()
        # The state a bake left before the depth classes, for the run's later draws.
        gl.ctx.depth_func = "<"
        gl.ctx.enable_only(moderngl.DEPTH_TEST if projected else moderngl.NOTHING)
        timings["render"] = t_draw
        timings["surface"] = t_surface
        timings["cracks"] = t_draw - t_surface
        timings["readback"] = t_read
        if with_normals:
            timings["normals"] = t_normals
    return images


def _crack_pass(ctx, fbo, cracks, res: int, rows: int, y0: int = 0, progress=None,
                vertices: int = -1, runs: dict | None = None, program=None) -> None:
    """Run the crack pass (``cracks``: its vertex array, ``vertices`` as its render takes)
    over the band's first ``rows`` rows (image rows ``y0 ..``), in slices of at most
    :data:`SLICE_TEXELS` texels, each finished before the next is drawn.  ``runs``
    (:func:`_slice_runs`): each slice draws its own run of the primitives, from ``program``'s
    ``u_prim_base``; None: every slice draws them all."""
    import moderngl

    step = max(1, SLICE_TEXELS // res)
    try:
        for r0 in range(0, rows, step):
            if step < rows:
                fbo.scissor = (0, r0, res, min(step, rows - r0))
            if runs is None:
                cracks.render(moderngl.TRIANGLES, vertices=vertices)
            else:
                first, count = runs[(y0, r0)]
                if count:
                    program["u_prim_base"].value = first
                    cracks.render(moderngl.TRIANGLES, vertices=3 * count, first=3 * first)
            finish(ctx)  # the GIL free meanwhile: the stress bake's rows go on
            if progress is not None:
                progress(y0 + min(r0 + step, rows), res)
    finally:
        if step < rows:
            fbo.scissor = None


def _slice_runs(uv: np.ndarray, faces: np.ndarray, listed: np.ndarray, res: int,
                band: int) -> tuple[np.ndarray, dict]:
    """The crack pass's faces slice by slice (the slices of :func:`_crack_pass` in every
    band of ``band`` rows): ``drawn`` (D,) int64, the ``listed`` faces that reach each slice's
    rows in their order, one slice's run after the other, and ``{(band's first row, slice's
    first row in the band): (first, count)}`` into it.

    Every slice drew every listed face, and llvmpipe shaded and binned all of them before the
    scissor dropped those elsewhere: at 1.5M faces 0.2 s a slice, 8 slices at 4096².  A
    face's texels lie within its rows ``(1 - v) res`` (``crack_bake.vert``), widened by two
    rows; a face with a coordinate that is not finite goes to every slice.  Within a slice the
    faces keep their order, so where faces overlap the last drawn still wins: the pixels are
    those of every face drawn.
    """
    from crackbake.bake.grid import slice_members

    step = max(1, SLICE_TEXELS // res)
    keys = [(y0, r0) for y0 in range(0, res, band) for r0 in range(0, min(band, res - y0), step)]
    tops = np.array([y0 + r0 for y0, r0 in keys], np.float64)
    bottoms = np.array([y0 + min(r0 + step, band, res - y0) for y0, r0 in keys], np.float64)
    drawn, starts = slice_members(np.ascontiguousarray(np.asarray(uv, np.float64)[:, 1]),
                                  np.ascontiguousarray(faces, np.int64),
                                  np.ascontiguousarray(listed, np.int64), float(res), tops,
                                  bottoms)  # fmt: skip
    slices = {k: (int(starts[s]), int(starts[s + 1] - starts[s])) for s, k in enumerate(keys)}
    return drawn, slices


def _max_distance(vertices: np.ndarray, segments: Segments, max_distance: float | None) -> float:
    """The distance clamp: the default fraction of the diagonal, never below a half width."""
    diagonal = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    if max_distance is None:
        max_distance = DEFAULT_MAX_DISTANCE_FRACTION * diagonal
    if not max_distance > 0:
        raise CrackbakeError(f"max distance {max_distance} must be > 0 (mesh units)")
    if len(segments.a) and max_distance < 0.5 * float(segments.width.max()):
        widest = float(segments.width.max())
        warnings.warn(
            f"max distance {max_distance:g} is below the widest crack's half width; "
            f"raising it to {widest:g} so wide cracks are not cut",
            CrackbakeWarning,
            stacklevel=3,
        )
        max_distance = widest
    return max_distance


def _dilated_maps(
    images: dict[str, np.ndarray],
    res: int,
    dilate_px: int | None,
    max_distance: float,
    profile_shape: float,
    timings: dict[str, float],
    gutter: PlanAhead | None = None,
) -> CrackMaps:
    """Fill the gutters of the rendered channels from their nearest island; the maps."""
    mask, width, time_ch = images["mask"], images["width"], images["time"]
    depth, distance, crack_id = images["depth"], images["distance"], images["id"]
    inside = images.pop("inside") > 0

    t3 = time.perf_counter()
    planes = [mask, width, time_ch, depth, distance, crack_id]
    background = [0.0, 0.0, 0.0, 0.0, max_distance, -1.0]
    with_normals = "occlusion" in images
    if with_normals:
        planes += [*images["normal"], images["occlusion"]]
        background += [0.0, 0.0, 1.0, 1.0]  # flat, open
    plan = None if gutter is None else gutter.plan_for(inside, dilate_px)
    dilate(planes, inside, limit=dilate_px, background=background, plan=plan)
    normal = occlusion = None
    if with_normals:
        # (res, res, 3) view of the planes: normal[..., k] is C-contiguous.
        normal = np.moveaxis(images.pop("normal"), 0, -1)
        occlusion = images.pop("occlusion")
    timings["dilate"] = time.perf_counter() - t3
    return CrackMaps(
        res=res,
        mask=mask,
        width=width,
        time=time_ch,
        depth=depth,
        distance=distance,
        crack_id=crack_id,
        inside=inside,
        max_distance=float(max_distance),
        profile_shape=float(profile_shape),
        normal=normal,
        occlusion=occlusion,
        timings=timings,
    )
