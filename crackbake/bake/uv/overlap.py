"""How much of a UV layout is covered twice (stacked or mirrored islands), measured on the GPU."""

from __future__ import annotations

import numpy as np

from crackbake.bake.context import GLScope, shader_source


def uv_overlap_fraction(
    uv: np.ndarray, faces: np.ndarray, res: int = 1024, ctx=None
) -> float:
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

    Returns
    -------
    float
        (#texels covered at least twice) / (#texels covered at least once); 0.0 when nothing is
        covered.

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
        return 0.0
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
        return 0.0
    return int(np.count_nonzero(counts >= 1.5)) / covered
