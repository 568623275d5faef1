"""A shaded picture of the textured output mesh (``preview.png``), drawn headless with EGL.

It answers the first question after a run (did the cracks land where I wanted?) without
opening a DCC tool, and makes the README's pictures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackbake.bake.context import GLScope, finish, shader_source
from crackbake.geometry import face_cross, unit_rows
from crackbake.io.mesh import Mesh
from crackbake.network import CrackNetwork


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """4x4 view matrix (right-handed, camera looks down -z)."""
    f = target - eye
    f = f / np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:  # looking along up: pick any perpendicular
        s = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else [0.0, 0.0, 1.0])
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """4x4 OpenGL projection matrix."""
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def render_preview(
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    normals: np.ndarray,
    color: np.ndarray,
    size: int = 1024,
    view_dir: tuple[float, float, float] = (0.9, 0.45, 1.0),
    up: tuple[float, float, float] = (0.0, 1.0, 0.0),
    target: np.ndarray | None = None,
    distance: float | None = None,
    normal_map: np.ndarray | None = None,
    tangents: np.ndarray | None = None,
    ctx=None,
    levels: tuple | None = None,
    closed: bool | None = None,
) -> np.ndarray:
    """Render the mesh textured with ``color`` from a three-quarter view.

    With ``normal_map`` and ``tangents`` the shading normal is perturbed per pixel exactly as
    engines decode tangent-space maps (``n = normalize(x T + y B + z N)``, ``B = w N x T``), so
    cracks read as grooves.

    Parameters
    ----------
    vertices, faces, uv, normals
        The output mesh: (V, 3), (F, 3), (V, 2) with v up, (V, 3).
    color : (H, W, 3) uint8
        sRGB base colour, row 0 = top of the image (UV v = 1).
    size : int
        Picture edge in pixels.
    view_dir : 3 floats
        Direction from the target towards the camera, world space.
    up : 3 floats
        World up for the camera.
    target : (3,) float, optional
        Point looked at; the bounding-box centre by default.
    distance : float, optional
        Camera distance from ``target``; by default the whole mesh fits the frame.
    normal_map : (H, W, 3) float or uint8, optional
        Tangent-space normals, OpenGL +Y, row 0 = top: unit floats (``CrackMaps.normal``) or
        8-bit ``n * 0.5 + 0.5`` as the normal PNGs store them.
    tangents : (V, 4) float, optional
        MikkTSpace tangents (xyz, w = bitangent sign); needed with ``normal_map``.
    ctx : moderngl.Context, optional
    levels : (list, list or None), optional
        ``color``'s and ``normal_map``'s (uint8) mip levels below their own
        (:func:`mip_levels`), made beforehand on another thread; None: GL makes them.
    closed : bool, optional
        :func:`closed_surface` of the faces, worked out beforehand (faces from
        :data:`CULL_FACES` only); None: worked out here when needed.

    Returns
    -------
    (size, size, 3) uint8
        sRGB picture, row 0 = top.
    """
    vertices = np.asarray(vertices, np.float64)
    lo, hi = vertices.min(0), vertices.max(0)
    centre = 0.5 * (lo + hi) if target is None else np.asarray(target, np.float64)
    radius = max(float(np.linalg.norm(vertices - centre, axis=1).max()), 1e-12)
    fov = 35.0
    if distance is None:
        distance = radius / np.sin(np.radians(fov) / 2) * 1.02
    d = np.asarray(view_dir, np.float64)
    d = d / np.linalg.norm(d)
    eye = centre + d * distance
    view = look_at(eye, centre, np.asarray(up, np.float64))
    proj = perspective(fov, 1.0, max(distance - 2 * radius, distance * 1e-3), distance + 2 * radius)
    mvp = (proj @ view).astype(np.float32)
    key = d + np.asarray(up, np.float64) * 0.6 + np.cross(np.asarray(up, np.float64), d) * 0.4
    key = key / np.linalg.norm(key)
    fill = -np.cross(np.asarray(up, np.float64), d)
    fill = fill / max(np.linalg.norm(fill), 1e-12)
    near = max(distance - 2 * radius, distance * 1e-3)
    cull = None
    if len(faces) >= CULL_FACES:
        cull = hidden_side(vertices, faces, eye, near, closed)

    with GLScope(ctx) as gl:
        pixels = _draw(
            gl, (vertices, faces, uv, normals, tangents), color, normal_map, size, mvp, key, fill,
            cull, levels,
        )
    return np.ascontiguousarray(np.flipud(pixels))


#: Faces from which the preview skips the faces turned away from the camera when no one can
#: see them (:func:`hidden_side`).  llvmpipe's cost is per drawn triangle, most of them under a
#: pixel at this size: 1.5M faces took 3.8 CPU s to draw, 2.2 s culled.  Below it the draw is
#: cheap and every face is drawn as before.
CULL_FACES = 200_000


def closed_surface(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Whether the faces, welded by position, close one consistently wound surface: the
    camera-free half of :func:`hidden_side` (0.25-0.35 s at 1.5M faces), which a run works out
    on a thread while it solves."""
    from crackbake.geometry import position_groups
    from crackbake.geometry_kernels import closed_oriented_kernel

    v = np.ascontiguousarray(vertices, np.float64)
    f = np.ascontiguousarray(faces, np.int64)
    return bool(closed_oriented_kernel(f, position_groups(v)))


@dataclass(frozen=True, eq=False)
class PreviewAhead:
    """What the preview needs of the mesh alone, worked out before the cracks exist.

    Attributes
    ----------
    closed : bool or None
        :func:`closed_surface` of the drawn faces (None below :data:`CULL_FACES` faces).
    up : (3,) float64
        :func:`up_vector`.
    cross : (F, 3) float64
        The asset faces' :func:`~crackbake.geometry.face_cross`.
    views : tuple
        :func:`view_scores` for ``up``.
    """

    closed: bool | None
    up: np.ndarray
    cross: np.ndarray
    views: tuple


def preview_ahead(mesh: Mesh, vertices: np.ndarray, faces: np.ndarray, up: str | None = None,
                  cache: bool = False) -> PreviewAhead:
    """The preview's mesh-only work: for a run to do on a thread while it solves (about 2 s of
    the write stage at 1.5M faces: the up axis's cache key, the faces' cross products, the
    views' area scores, the culling check).

    Parameters
    ----------
    mesh : Mesh
        The asset (the cracks' faces index its faces).
    vertices, faces : (V, 3) float, (F, 3) int
        The faces the preview draws (the UV mesh's).
    up, cache
        As :func:`up_vector`'s.
    """
    closed = closed_surface(vertices, faces) if len(faces) >= CULL_FACES else None
    cross = face_cross(mesh.vertices, mesh.faces)
    axis = up_vector(up, mesh, cross, cache=cache)
    return PreviewAhead(closed, axis, cross, view_scores(cross, axis))


def hidden_side(vertices: np.ndarray, faces: np.ndarray, eye: np.ndarray,
                near: float, closed: bool | None = None) -> str | None:
    """Which side of the faces the camera at ``eye`` cannot see: ``"back"`` (or ``"front"`` for
    a surface wound clockwise seen from outside) when the faces, welded by position, close one
    consistently wound surface, the eye is outside it and no face comes within twice the near
    plane ``near`` of the eye (a clipped face would open a view inside); None otherwise (an open
    surface shows its inside through the opening: every face is drawn).

    Culling those faces leaves the picture as it was except where a face turned away won the
    depth test against the face in front of it at the silhouette (a few pixels in a million).
    ``closed``: :func:`closed_surface` of these faces, when worked out before."""
    from crackbake.geometry_kernels import eye_view_kernel

    v = np.ascontiguousarray(vertices, np.float64)
    f = np.ascontiguousarray(faces, np.int64)
    if not (closed_surface(v, f) if closed is None else closed):
        return None
    volume, winding, closest = eye_view_kernel(v, f, np.asarray(eye, np.float64))
    if abs(winding) > 0.5 or not closest > 2.0 * near or volume == 0.0:
        return None
    return "back" if volume > 0 else "front"


def mip_levels(image: np.ndarray) -> list[np.ndarray] | None:
    """The mip levels below an (N, N, 3) uint8 image, N a power of two, down to 1 x 1: what
    llvmpipe's ``glGenerateMipmap`` makes, byte for byte (each level's 2 x 2 blocks averaged
    by pairs, rounding halves up: ``((a + b + 1) >> 1 + (c + d + 1) >> 1 + 1) >> 1``); None
    for other shapes, which GL mip-maps itself.

    Why: llvmpipe makes the levels with a blit whose shader it compiles on the main thread at
    the preview's first use (py-spy of the README run: ``build_mipmaps`` was the largest item
    of the write stage's main thread); these levels are made on an encoder thread instead.
    """
    n = image.shape[0]
    if image.dtype != np.uint8 or image.shape[1:] != (n, 3) or n < 2 or n & (n - 1):
        return None
    from crackbake.exchange.halving import mip_half

    out, a = [], image
    while a.shape[0] > 1:
        a = mip_half(a)
        out.append(a)
    return out


def _texture(gl: GLScope, image: np.ndarray, unit: int, dtype: str = "f1", levels=None):
    """Upload an (H, W, 3) image, bottom row first (GL's first row is v = 0), mip-mapped:
    ``levels`` (:func:`mip_levels`, row 0 the top) when given, else by GL."""
    import moderngl

    img = np.ascontiguousarray(np.flipud(image[..., :3]))
    tex = gl.keep(gl.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype=dtype))
    if levels is None or not _upload_levels(gl.ctx, tex, levels, unit):
        tex.build_mipmaps()
    tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    tex.anisotropy = 8.0
    tex.use(unit)
    return tex


def _upload_levels(ctx, tex, levels: list[np.ndarray], unit: int) -> bool:
    """Define ``tex``'s mip levels 1.. from ``levels`` (row 0 the top) with
    ``glTexImage2D`` (moderngl allocates level 0 only); False when GL's entry points are not
    reachable (another moderngl backend), and nothing was changed."""
    import ctypes

    load = getattr(getattr(ctx.mglo, "_context", None), "load", None)
    address = load("glTexImage2D") if load is not None else 0
    store = load("glPixelStorei") if load is not None else 0
    if not address or not store:
        return False
    uint, sint, ptr = ctypes.c_uint, ctypes.c_int, ctypes.c_void_p
    image_2d = ctypes.CFUNCTYPE(None, uint, sint, sint, sint, sint, sint, uint, uint, ptr)(address)
    pixel_store = ctypes.CFUNCTYPE(None, uint, sint)(store)
    tex.use(unit)  # bound to the active unit while its levels are defined
    pixel_store(0x0CF5, 1)  # GL_UNPACK_ALIGNMENT: rows of 3-byte texels
    for k, level in enumerate(levels, 1):
        img = np.ascontiguousarray(np.flipud(level))
        image_2d(0x0DE1, k, 0x8051, img.shape[1], img.shape[0], 0, 0x1907, 0x1401,
                 img.ctypes.data)  # GL_TEXTURE_2D, GL_RGB8, GL_RGB, GL_UNSIGNED_BYTE  # fmt: skip
    return True


def _draw(gl: GLScope, mesh, color, normal_map, size, mvp, key, fill,
          cull: str | None = None, levels: tuple | None = None) -> np.ndarray:
    """Draw the textured mesh with 4x MSAA; the (size, size, 3) uint8 picture, row 0 = bottom.
    ``cull``: the side of the faces not drawn (:func:`hidden_side`), None to draw both."""
    import moderngl

    vertices, faces, uv, normals, tangents = mesh
    use_map = normal_map is not None and tangents is not None
    if not use_map:
        tangents = np.zeros((len(vertices), 4))

    ctx = gl.ctx
    prog = gl.keep(
        ctx.program(
            vertex_shader=shader_source("preview.vert"),
            fragment_shader=shader_source("preview.frag"),
        )
    )
    data = np.concatenate(
        [vertices, np.asarray(normals, np.float64), np.asarray(uv, np.float64),
         np.asarray(tangents, np.float64)], axis=1,
    ).astype(np.float32)  # fmt: skip
    vbo = gl.keep(ctx.buffer(data.tobytes()))
    ibo = gl.keep(ctx.buffer(np.asarray(faces, np.uint32).tobytes()))
    vao = gl.keep(
        ctx.vertex_array(
            prog,
            [(vbo, "3f 3f 2f 4f", "in_pos", "in_normal", "in_uv", "in_tangent")],
            index_buffer=ibo,
        )
    )
    color_levels, normal_levels = levels if levels is not None else (None, None)
    _texture(gl, np.asarray(color, np.uint8), 0, levels=color_levels)
    prog["u_color"].value = 0
    prog["u_use_normal_map"].value = int(use_map)
    if use_map:
        nm = np.asarray(normal_map)
        if nm.dtype != np.uint8:
            nm = np.clip(nm * 127.5 + 128.0, 0, 255).astype(np.uint8)
        _texture(gl, nm, 1, levels=normal_levels if nm is normal_map else None)
        prog["u_normal_map"].value = 1
    prog["u_mvp"].write(mvp.T.tobytes())  # GLSL matrices are column-major
    prog["u_key"].value = tuple(key.astype(np.float32))
    prog["u_fill"].value = tuple(fill.astype(np.float32))

    samples = min(4, ctx.info.get("GL_MAX_SAMPLES", 4))
    ms_color = gl.keep(ctx.renderbuffer((size, size), 4, samples=samples))
    ms_depth = gl.keep(ctx.depth_renderbuffer((size, size), samples=samples))
    ms_fbo = gl.keep(ctx.framebuffer([ms_color], ms_depth))
    out_tex = gl.keep(ctx.texture((size, size), 4))
    out_fbo = gl.keep(ctx.framebuffer([out_tex]))
    ms_fbo.use()
    if cull is None:
        ctx.enable_only(moderngl.DEPTH_TEST)
    else:
        ctx.cull_face = cull
        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
    ms_fbo.clear(0.16, 0.17, 0.19, 1.0, depth=1.0)
    vao.render(moderngl.TRIANGLES)
    finish(ctx)  # the GIL free while llvmpipe draws: the write stage's encoders go on
    if cull is not None:  # the context's other draws see both sides
        ctx.enable_only(moderngl.DEPTH_TEST)
        ctx.cull_face = "back"
    ctx.copy_framebuffer(out_fbo, ms_fbo)
    finish(ctx)
    return np.frombuffer(out_fbo.read(components=3), np.uint8).reshape(size, size, 3)


#: ``--up`` names and their axes.
UP_VECTORS = {
    "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0),
    "-x": (-1.0, 0.0, 0.0), "-y": (0.0, -1.0, 0.0), "-z": (0.0, 0.0, -1.0),
}  # fmt: skip
# Z-up needs strong evidence: its support polygon this many times Y's, the mesh's centre over it,
# and not over Y's.
Z_UP_SUPPORT_RATIO = 3.0


def _support(pts: np.ndarray, hull, area: np.ndarray, axis: int, centre: np.ndarray):
    """Area of the hull facets facing straight down along ``axis`` (within 5 degrees) and
    whether ``centre`` lies over the polygon they span (the mesh would stand on them)."""
    from scipy.spatial import ConvexHull, QhullError

    down = hull.equations[:, axis] < -np.cos(np.radians(5))  # outward normal points down
    score = float(area[down].sum())
    if score <= 0.0:
        return 0.0, False
    keep = [k for k in range(3) if k != axis]
    foot = pts[np.unique(hull.simplices[down])][:, keep]
    try:
        poly = ConvexHull(foot)
    except (QhullError, ValueError):  # a line of support: a knife edge, no stand
        return score, False
    inside = (poly.equations[:, :2] @ centre[keep] + poly.equations[:, 2] <= 1e-12).all()
    return score, bool(inside)


def up_axis(mesh: Mesh, cross: np.ndarray | None = None) -> np.ndarray:
    """The mesh's up axis, +Y unless the mesh clearly stands on its -Z side.

    OBJ, PLY and glTF are Y-up by convention (glTF by definition, so it is always +Y).  Z-up
    (scans and CAD exports) is taken only with strong evidence: the convex hull's facets facing
    straight down along -Z (within 5 degrees: the support polygon of the feet or base it would
    rest on) cover at least :data:`Z_UP_SUPPORT_RATIO` times those along -Y, the surface's
    centre lies over that polygon (it would stand), and not over the -Y one.  So a Y-up figure
    on two small feet with a flat back stays upright; spot rotated to Z-up stands on its
    hooves.  ``--up`` overrides the guess.

    Parameters
    ----------
    mesh : Mesh
    cross : (F, 3) float, optional
        The faces' :func:`~crackbake.geometry.face_cross`, when the caller has it already.

    Returns
    -------
    (3,) float64
        ``(0, 1, 0)`` or ``(0, 0, 1)``.
    """
    from scipy.spatial import ConvexHull, QhullError

    y_up, z_up = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    if _is_gltf(mesh):
        return y_up
    pts = np.asarray(mesh.vertices, np.float64)
    pts = pts[:: max(1, len(pts) // 100_000)]  # the hull of a subset: scans have millions
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):  # flat or degenerate: no support to judge by
        return y_up
    tri = pts[hull.simplices]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if cross is None:
        cross = face_cross(mesh.vertices, mesh.faces)
    from crackbake.geometry_kernels import area_centre_kernel

    # One pass over the faces: the (F, 3, 3) corner gather took seconds at 1.5M faces.
    centre = area_centre_kernel(np.ascontiguousarray(mesh.vertices, np.float64),
                                np.ascontiguousarray(mesh.faces, np.int64),
                                np.ascontiguousarray(cross, np.float64))
    score_y, stands_y = _support(pts, hull, area, 1, centre)
    score_z, stands_z = _support(pts, hull, area, 2, centre)
    strong = score_z >= Z_UP_SUPPORT_RATIO * score_y and stands_z and not stands_y
    return z_up if strong else y_up


def up_vector(up: str | None, mesh: Mesh, cross: np.ndarray | None = None,
              cache: bool = False) -> np.ndarray:  # fmt: skip
    """The preview's up: the ``--up`` axis (``x``, ``y``, ``z``, ``-x``, ``-y``, ``-z``) or, when
    None, :func:`up_axis`'s guess (``cross``: the faces' cross products if known; ``cache``:
    read and keep the guess in the mesh cache, :mod:`crackbake.bake.mesh_cache`); (3,)
    float64."""
    if up is not None:
        return np.asarray(UP_VECTORS[up], np.float64)
    if not cache:
        return up_axis(mesh, cross)
    from crackbake.bake.mesh_cache import read_up, up_key, write_up

    key = up_key(mesh.vertices, mesh.faces, _is_gltf(mesh))
    axis = read_up(key)
    if axis is None:
        axis = up_axis(mesh, cross)
        write_up(key, axis)
    return axis


def _is_gltf(mesh: Mesh) -> bool:
    return str(mesh.source).lower().endswith((".gltf", ".glb"))


def _frame(up: np.ndarray) -> np.ndarray:
    """Rotation taking +Y (the candidate directions' up) to ``up`` (a unit axis)."""
    y = np.array([0.0, 1.0, 0.0])
    up = np.asarray(up, np.float64)
    c = float(up @ y)
    if c > 0.5:
        return np.eye(3)
    if c < -0.5:
        return np.diag([1.0, -1.0, -1.0])  # half a turn about x
    k = np.cross(y, up)  # a quarter turn about k: R = I + K + K^2
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + kx + kx @ kx


def preview_direction(
    mesh: Mesh, network: CrackNetwork, up: np.ndarray | None = None
) -> tuple[float, float, float]:
    """The camera direction (from the mesh towards the camera) that shows the most cracks.

    Candidates are the 17 directions of the upper half of a cube's corners, edges and faces
    (``up`` is up; :func:`up_axis` when not given), tilted 20 degrees upwards, and the 8 of its
    lower corners and edges; each scores the crack length facing it, with the mesh area
    facing it breaking ties (and choosing the view when there are no cracks).  A view from
    below counts :data:`BELOW_WEIGHT` of its score: cracks facing down choose it.
    """
    cross = face_cross(mesh.vertices, mesh.faces)
    up = up_axis(mesh, cross) if up is None else np.asarray(up, np.float64)
    return _direction(cross, network, up)


#: What a view from below is worth against one from above showing the same crack length.
BELOW_WEIGHT = 0.5


def _direction(cross: np.ndarray, network: CrackNetwork, up: np.ndarray,
               views: tuple | None = None):
    """:func:`preview_direction` from the faces' edge cross products (F, 3); ``views``: their
    :func:`view_scores` for ``up``, worked out beforehand."""
    cand, weight, score = view_scores(cross, up) if views is None else views
    if network.cracks:
        # Every crack's segments at once (a loop over 2,000 cracks took 0.7 s of the write
        # stage): the steps between two cracks' points are left out.
        pts = np.concatenate([np.asarray(c.points, np.float64) for c in network.cracks])
        fcs = np.concatenate([np.asarray(c.faces) for c in network.cracks])
        last = np.cumsum([len(c.points) for c in network.cracks]) - 1
        inner = np.ones(len(pts), bool)
        inner[last] = False
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)[inner[:-1]]
        fcs = fcs[inner]
        n = unit_rows(cross[fcs])[0]
        score = score + (seg[:, None] * np.maximum(np.einsum("si,ci->sc", n, cand), 0)).sum(axis=0)
    return tuple(float(x) for x in cand[int(np.argmax(score * weight))])


def view_scores(cross: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The preview's candidate view directions for ``up`` (C, 3), their weights (C,) and the
    mesh's own score of each (C,): the area facing it, scaled to at most 1e-3 (it only breaks
    ties between crack lengths).  The camera-free, crack-free part of :func:`_direction`:
    a run works it out on a thread while it solves (0.5-1 s at 1.5M faces)."""
    cand = np.array(
        [
            (x, y, z)
            for x in (-1, 0, 1)
            for y in (0, 1)
            for z in (-1, 0, 1)
            if (x, y, z) != (0, 0, 0)
        ],
        float,
    )
    cand /= np.linalg.norm(cand, axis=1, keepdims=True)
    cand[:, 1] += np.tan(np.radians(20))
    cand /= np.linalg.norm(cand, axis=1, keepdims=True)
    # Views from below (not straight up: up would then have no direction in the picture),
    # after the others (ties keep a view from above) and worth BELOW_WEIGHT
    # of their score: only cracks that face down (an impact on a chin's or a shelf's
    # underside) choose one; from above they were seen edge-on at the picture's rim.
    below = np.array([(x, -1, z) for x in (-1, 0, 1) for z in (-1, 0, 1) if x or z], float)
    below /= np.linalg.norm(below, axis=1, keepdims=True)
    weight = np.concatenate([np.ones(len(cand)), np.full(len(below), BELOW_WEIGHT)])
    cand = np.concatenate([cand, below]) @ _frame(up).T
    from crackbake.geometry_kernels import facing_sum_kernel

    # A kernel, not matmul or einsum: a (F, 3) @ (3, 17) product goes to BLAS threads (1.5 s
    # at 1.5M faces on a busy 2-core machine) and einsum's (F, 17) temporary took 0.9 s.
    cross = np.ascontiguousarray(cross, np.float64)
    score = 0.5 * facing_sum_kernel(cross, np.ascontiguousarray(cand))
    score = 1e-3 * score / max(score.max(), 1e-300)
    return cand, weight, score


def preview_camera(mesh: Mesh, network: CrackNetwork, up: str | np.ndarray | None = None,
                   ahead: PreviewAhead | None = None):
    """Where the preview camera looks from: ``(view_dir, up, target, distance)``.

    The view is :func:`preview_direction` with ``up`` (an ``--up`` name, a (3,) vector from
    :func:`up_vector`; None: the mesh's :func:`up_axis`) up; the camera aims at
    the middle of the crack points seen from there and comes close enough that they fill
    about 80 % of the frame, but never closer than framing 40 % of the mesh (so the picture
    keeps context) nor farther than framing the whole mesh.  Without cracks it frames the mesh.
    ``ahead``: :func:`preview_ahead` of the same mesh (its up axis then replaces ``up``).
    """
    if ahead is not None:  # the mesh's part, worked out on a thread while the run solved
        an, up, views = ahead.cross, ahead.up, ahead.views
    else:
        an = face_cross(mesh.vertices, mesh.faces)  # once, for the up axis and the direction
        up = (up_vector(up, mesh, an) if up is None or isinstance(up, str)
              else np.asarray(up, float))
        views = None
    view_dir = np.asarray(_direction(an, network, up, views))
    lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
    if not network.cracks:
        return tuple(view_dir), tuple(up), None, None
    pts = np.concatenate([np.asarray(c.points) for c in network.cracks])
    fcs = np.concatenate([np.asarray(c.faces) for c in network.cracks])
    seen = an[fcs] @ view_dir > 0
    pts = pts[seen] if seen.any() else pts
    target = 0.5 * (pts.min(0) + pts.max(0))
    mesh_radius = float(np.linalg.norm(mesh.vertices - target, axis=1).max())
    crack_radius = float(np.linalg.norm(pts - target, axis=1).max())
    half = np.radians(35.0) / 2  # render_preview's field of view
    frame = np.clip(crack_radius / 0.8, 0.4 * 0.5 * np.linalg.norm(hi - lo), mesh_radius)
    return tuple(view_dir), tuple(up), target, float(frame / np.sin(half))


def warm() -> None:
    """Compile (or load from numba's cache) the up-axis kernel, which only meshes with volume
    reach (:mod:`crackbake.precompile`'s plates are flat, so their hull fails first), and the
    culling check's, which only meshes above :data:`CULL_FACES` faces reach: a tetrahedron,
    with the argument types :func:`up_axis` and :func:`hidden_side` pass."""
    from crackbake.geometry_kernels import area_centre_kernel

    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    area_centre_kernel(v, f, face_cross(v, f))
    hidden_side(v, f, np.array([3.0, 3.0, 3.0]), 0.1)  # the culling kernels (above 200k faces)
