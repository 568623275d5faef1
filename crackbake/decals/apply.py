"""A decal applied back onto its mesh through its written transform: the consistency check.

What an engine does with a decal, in our own renderer: every texel of the mesh's UV layout
gets its surface point (a GL pass, ``shaders/decal_apply.frag``), which the decal's projector
matrix (as ``decals.json`` stores it) takes into the projector's box; points inside, on faces
facing the projector, sample the decal image bilinearly at ``u = x / w + 0.5``,
``v = y / h + 0.5``.  Comparing the result with the UV bake of the same network shows whether
the decal puts the cracks where the UV bake has them.
"""

from __future__ import annotations

import numpy as np

from crackbake.bake.context import GLScope, shader_source
from crackbake.geometry import face_normals


def uv_surface(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, res: int, ctx=None):
    """Surface point and face of every texel of the UV layout.

    Returns
    -------
    points : (res, res, 3) float32
        Mesh-space point drawn at each texel (row 0 = top, v = 1).
    face : (res, res) int64
        Face drawn there, -1 where none.
    """
    import moderngl

    vertex = np.empty((len(vertices), 5), np.float32)
    vertex[:, 0:2] = uv
    vertex[:, 2:5] = vertices
    with GLScope(ctx) as gl:
        c = gl.ctx
        prog = gl.keep(c.program(vertex_shader=shader_source("crack_bake.vert"),
                                 fragment_shader=shader_source("decal_apply.frag")))
        vbo = gl.keep(c.buffer(vertex))
        ibo = gl.keep(c.buffer(np.ascontiguousarray(faces, np.uint32)))
        vao = gl.keep(c.vertex_array(prog, [(vbo, "2f 3f", "in_uv", "in_pos")],
                                     index_buffer=ibo, index_element_size=4))
        tex = gl.keep(c.texture((res, res), 4, dtype="f4"))
        fbo = gl.keep(c.framebuffer(color_attachments=[tex]))
        prog["u_res"].value = float(res)
        prog["u_tile"].value = (0.0, 0.0, float(res), float(res))
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        c.enable_only(moderngl.NOTHING)
        vao.render(moderngl.TRIANGLES)
        data = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    data = data.reshape(res, res, 4)
    return data[..., :3].copy(), data[..., 3].astype(np.int64) - 1


def bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Sample an image (H, W[, C]), row 0 = top, at texture coordinates u right, v up,
    texel centres at (i + 0.5) / W, edges clamped (GL's LINEAR with CLAMP_TO_EDGE)."""
    h, w = image.shape[:2]
    x = np.clip(u * w - 0.5, 0, w - 1)
    y = np.clip((1.0 - v) * h - 0.5, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2)
    fx, fy = x - x0, y - y0
    img = np.asarray(image, np.float64)
    if img.ndim == 3:
        fx, fy = fx[..., None], fy[..., None]
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bottom = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def apply_decal(
    points: np.ndarray, face: np.ndarray, vertices: np.ndarray, faces: np.ndarray, entry: dict,
    image: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Project a decal image onto the texels of a UV layout through its ``decals.json`` entry.

    Parameters
    ----------
    points, face
        :func:`uv_surface` of the mesh.
    vertices, faces
        The mesh, for the facing test.
    entry : dict
        One item of ``decals.json``'s ``decals``: ``matrix``, ``width``, ``height``, ``depth``.
    image : (H, W[, C]) array
        The decal texture, row 0 = top.

    Returns
    -------
    value : (res, res[, C]) float64
        The sampled decal where covered, 0 elsewhere.
    covered : (res, res) bool
        Texels inside the box, on a face facing the projector.
    """
    m = np.asarray(entry["matrix"], np.float64)
    rot, centre = m[:3, :3], m[:3, 3]
    local = (points.reshape(-1, 3) - centre) @ rot  # rot orthonormal: inverse = transpose
    half = 0.5 * np.array([entry["width"], entry["height"], entry["depth"]])
    f = face.reshape(-1)
    facing = np.zeros(len(f), bool)
    on = f >= 0
    facing[on] = face_normals(vertices, faces)[f[on]] @ rot[:, 2] > 0
    covered = facing & np.all(np.abs(local) <= half, axis=1)
    u = local[:, 0] / entry["width"] + 0.5
    v = local[:, 1] / entry["height"] + 0.5
    value = bilinear(image, u, v)
    value[~covered] = 0
    res = face.shape
    return value.reshape(*res, *image.shape[2:]), covered.reshape(res)
