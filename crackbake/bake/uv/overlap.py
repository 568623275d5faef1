"""How much of a UV layout is covered twice (stacked or mirrored islands), measured on the GPU."""

from __future__ import annotations

import numpy as np

from crackbake.bake.context import GLScope, shader_source


def uv_overlap_fraction(
    uv: np.ndarray, faces: np.ndarray, res: int = 1024, ctx=None, texel_counts: bool = False
) -> float | tuple[int, int]:
    """Fraction of the covered UV area that more than one face covers.

    The UV triangles are rasterised with OpenGL (EGL) into a ``res`` x ``res`` R32F target with
    additive blending, giving the number of faces over each texel centre.  GL's rasterisation
    rules give a texel centre on an edge shared by two faces to only one of them, so adjacent
    faces do not count as overlap.

    Parameters
    ----------
    uv : (V, 2) float
        Texture coordinates; the page is [0, 1]^2 (anything outside is clipped away).
    faces : (F, 3) int
        Triangles indexing ``uv``.
    res : int
        Raster resolution, texels per side.
    ctx : moderngl.Context, optional
        The run's GL context; a temporary one is created (and released) when not given.
    texel_counts : bool
        Return the two texel counts instead of their ratio (pages measured apart, the tiles
        of a UDIM layout, add up).

    Returns
    -------
    float or (int, int)
        (#texels covered at least twice) / (#texels covered at least once); 0.0 when nothing is
        covered.  With ``texel_counts``: the two counts.

    Raises
    ------
    CrackbakeError
        When no headless OpenGL context can be created.
    """
    import moderngl

    uv = np.ascontiguousarray(uv, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (V, 2), got {uv.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
    if len(faces) == 0 or len(uv) == 0:
        return 0.0 if not texel_counts else (0, 0)
    if faces.min() < 0 or faces.max() >= len(uv):
        raise ValueError("faces index vertices that uv does not have")
    res = int(res)

    with GLScope(ctx) as gl:
        ctx = gl.ctx
        prog = gl.keep(
            ctx.program(
                vertex_shader=shader_source("uv_overlap.vert"),
                fragment_shader=shader_source("uv_overlap.frag"),
            )
        )
        vbo = gl.keep(ctx.buffer(uv.tobytes()))
        ibo = gl.keep(ctx.buffer(faces.tobytes()))
        vao = gl.keep(
            ctx.vertex_array(prog, [(vbo, "2f", "in_uv")], index_buffer=ibo, index_element_size=4)
        )
        target = gl.keep(ctx.texture((res, res), 1, dtype="f4"))
        fbo = gl.keep(ctx.framebuffer(color_attachments=[target]))
        fbo.use()
        ctx.viewport = (0, 0, res, res)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        # Mirrored islands are back-facing in UV; they must count too (no culling, no depth).
        ctx.enable_only(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        vao.render(moderngl.TRIANGLES)
        counts = np.empty((res, res), dtype=np.float32)
        fbo.read_into(counts, components=1, dtype="f4")

    # Counts are small whole numbers in float32; compare at the half-way points.
    covered = int(np.count_nonzero(counts >= 0.5))
    if covered == 0:
        return 0.0 if not texel_counts else (0, 0)
    twice = int(np.count_nonzero(counts >= 1.5))
    return (twice, covered) if texel_counts else twice / covered


def _copy_vertices(uv: np.ndarray, faces: np.ndarray, copies: np.ndarray) -> np.ndarray:
    """Unindexed (3K, 3) float32 rows (u, v, copy id + 1) of the face copies ``copies`` (K, 3)
    = (face, du, dv), each at its UVs minus its tile offset."""
    corners = uv[faces[copies[:, 0]]] - copies[:, None, 1:3].astype(np.float64)  # (K, 3, 2)
    rows = np.empty((len(copies), 3, 3), np.float32)
    rows[..., :2] = corners
    rows[..., 2] = (np.arange(len(copies), dtype=np.float32) + 1.0)[:, None]
    return rows.reshape(-1, 3)


def wrap_conflicts(
    uv: np.ndarray, faces: np.ndarray, copies: np.ndarray, res: int = 1024, ctx=None
) -> tuple[np.ndarray, int]:
    """Which face copies, shifted into the 0-1 tile, would land on texels another face covers.

    A face whose UVs reach past the page is sampled by engines with REPEAT wrapping: its part
    beyond u = 1 shows at u - 1, and so on.  Drawing it there as well (a copy shifted by whole
    tiles) bakes what the engine will show, unless that place already belongs to another face.
    Each round rasterises the remaining copies (count, then copy id) over the faces' own
    coverage and drops the copies seen on a contested texel, until none is contested; two
    copies on one texel drop only the last drawn, so the other may stay.

    Parameters
    ----------
    uv : (V, 2) float
        Texture coordinates (the page is [0, 1]^2, anything outside it is clipped away).
    faces : (F, 3) int
        Triangles indexing ``uv``.
    copies : (K, 3) int
        Candidate copies: (face, du, dv), drawn at ``uv - (du, dv)``.
    res : int
        Raster resolution, texels per side.
    ctx : moderngl.Context, optional
        The run's GL context; a temporary one when not given.

    Returns
    -------
    keep : (K,) bool
        Copies that overlap nothing.
    lost_texels : int
        Texels (at ``res``) the dropped copies cover inside the page: what the engine shows
        there belongs to another face.
    """
    import moderngl

    copies = np.asarray(copies, np.int64).reshape(-1, 3)
    keep = np.ones(len(copies), bool)
    if len(copies) == 0:
        return keep, 0
    uv = np.asarray(uv, np.float64)
    faces = np.asarray(faces, np.int64)
    with GLScope(ctx) as gl:
        ctx = gl.ctx
        count_prog = gl.keep(
            ctx.program(
                vertex_shader=shader_source("uv_overlap.vert"),
                fragment_shader=shader_source("uv_overlap.frag"),
            )
        )
        id_prog = gl.keep(
            ctx.program(
                vertex_shader=shader_source("uv_wrap.vert"),
                fragment_shader=shader_source("uv_wrap.frag"),
            )
        )
        target = gl.keep(ctx.texture((res, res), 1, dtype="f4"))
        fbo = gl.keep(ctx.framebuffer(color_attachments=[target]))
        fbo.use()
        ctx.viewport = (0, 0, res, res)

        def draw(rows: np.ndarray, ids: bool) -> np.ndarray:
            vbo = ctx.buffer(np.ascontiguousarray(rows, np.float32).tobytes())
            layout = (vbo, "2f 1f", "in_uv", "in_id") if ids else (vbo, "2f 4x", "in_uv")
            vao = ctx.vertex_array(id_prog if ids else count_prog, [layout])
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            if ids:
                ctx.enable_only(moderngl.NOTHING)
            else:
                ctx.enable_only(moderngl.BLEND)
                ctx.blend_func = moderngl.ONE, moderngl.ONE
                ctx.blend_equation = moderngl.FUNC_ADD
            vao.render(moderngl.TRIANGLES)
            out = np.empty((res, res), np.float32)
            fbo.read_into(out, components=1, dtype="f4")
            vao.release()
            vbo.release()
            return out

        own = np.zeros((len(faces), 3), np.int64)
        own[:, 0] = np.arange(len(faces))
        covered = draw(_copy_vertices(uv, faces, own), ids=False) >= 0.5
        rows = _copy_vertices(uv, faces, copies)
        while keep.any():
            active = np.flatnonzero(keep)
            sel = rows.reshape(-1, 3, 3)[active].reshape(-1, 3)  # ids stay global
            count = draw(sel, ids=False)
            contested = ((count >= 0.5) & covered) | (count >= 1.5)
            if not contested.any():
                break
            ids = draw(sel, ids=True)[contested]
            keep[np.unique(ids[ids >= 0.5]).astype(np.int64) - 1] = False
        lost = 0
        if not keep.all():
            dropped = rows.reshape(-1, 3, 3)[~keep].reshape(-1, 3)
            lost = int(np.count_nonzero(draw(dropped, ids=False) >= 0.5))
    return keep, lost
