"""Decals from an impact: an orthographic projector over the impact and the crack bake through it.

The projector's frame (right-handed, mesh units): origin at the impact's surface point (the centre
of the box), local +X = image right, +Y = image up, +Z = the surface normal there, towards the
projector; it projects along -Z.  The box spans ``x in [-w/2, w/2]``, ``y in [-h/2, h/2]``,
``z in [-d/2, d/2]``; the depth ``d`` is measured from the mesh (the surface around the impact
inside the footprint, plus a margin), so the curved surface under the decal stays inside.

The decal texture is the crack bake of :func:`crackbake.bake.raster.bake_cracks` with the faces
drawn through the projector's camera (depth-tested: the surface nearest to the projector) instead
of at their UVs, every other pass unchanged, so the decal measures the same world-space cracks as
the UV bake.  The normal map is in the projector's frame (T = +X, B = +Y, N = +Z): what an engine's
decal shader decodes, whatever the surface's own tangents.  Texel ``(row, col)`` of a ``res``
image covers ``x = (col + 0.5) / res * w - w/2``, ``y = h/2 - (row + 0.5) / res * h``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from crackbake.bake.raster import CrackMaps, bake_cracks
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.geometry import closest_on_triangles, face_areas, face_normals
from crackbake.network import Segments
from crackbake.params import MIN_PX_DEFAULT

#: Depth margin on each side of the measured surface, as a fraction of the decal size.
DEPTH_MARGIN = 0.025
#: Radius over which the impact's normal is averaged, as a fraction of the decal size.
NORMAL_RADIUS = 0.125
#: Texels of gutter fill around the surface seen in the decal (bilinear filtering, mip-maps).
DECAL_DILATE_PX = 4
#: Angle fade (degrees between the surface normal and the projector's axis): the decal is baked
#: at full strength up to the first angle and fades out (smoothstep) by the second, as engines'
#: angle fade does (Unity's DecalProjector start/end angle fade, Godot's normal fade).  Beyond
#: about 70 degrees one decal texel spans several texel widths of surface, and its cracks turn
#: into blocky dashed streaks.
ANGLE_FADE_DEG = (60.0, 80.0)
#: The box stops this share of the way from the surface under the decal to the next surface
#: behind (or in front of) it along the projection, so an engine paints only the first surface.
SECOND_SURFACE_SHARE = 0.5


@dataclass(frozen=True)
class Projector:
    """An orthographic decal projector in mesh space.

    Attributes
    ----------
    matrix : (4, 4) float64
        Projector local -> mesh, column vectors (``p_mesh = matrix @ [x, y, z, 1]``); columns
        0-2 are the unit axes +X (image right), +Y (image up), +Z (towards the projector),
        column 3 the box centre.
    width, height, depth : float
        Box extents along local X, Y, Z, mesh units.
    """

    matrix: np.ndarray
    width: float
    height: float
    depth: float

    @property
    def axes(self) -> np.ndarray:
        """(3, 3): rows +X, +Y, +Z in mesh space."""
        return self.matrix[:3, :3].T

    @property
    def centre(self) -> np.ndarray:
        return self.matrix[:3, 3]

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """Mesh points (N, 3) -> projector local coordinates (N, 3)."""
        return (np.asarray(points, np.float64) - self.centre) @ self.axes.T

    def clip_matrix(self) -> np.ndarray:
        """Mesh -> clip (4, 4), column vectors: x, y in [-1, 1] across the box (+y = image up),
        z = -1 at the projector's face (local z = d/2) .. +1 at the far face."""
        scale = np.diag([2.0 / self.width, 2.0 / self.height, -2.0 / self.depth, 1.0])
        inverse = np.eye(4)
        inverse[:3, :3] = self.axes
        inverse[:3, 3] = -self.axes @ self.centre
        return scale @ inverse

    def image_uv(self, points: np.ndarray) -> np.ndarray:
        """Mesh points (N, 3) -> decal texture coordinates (N, 2), u right, v up, [0, 1] inside."""
        local = self.to_local(points)
        return np.stack([local[:, 0] / self.width + 0.5, local[:, 1] / self.height + 0.5], 1)


def _frame(normal: np.ndarray) -> np.ndarray:
    """Rows X, Y, Z of the projector: Z = normal, Y = the mesh's +Y made perpendicular to it
    (-Z where the normal is within 2.6 degrees of +-Y: a floor or ceiling), X = Y x Z."""
    z = normal / np.linalg.norm(normal)
    ref = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.999 else np.array([0.0, 0.0, -1.0])
    y = ref - np.dot(ref, z) * z
    y /= np.linalg.norm(y)
    return np.stack([np.cross(y, z), y, z])


def make_projector(
    vertices: np.ndarray, faces: np.ndarray, point: np.ndarray, size: float
) -> Projector:
    """The projector of one impact: over the surface point nearest ``point``, facing along the
    area-weighted face normal within ``NORMAL_RADIUS * size``, deep enough for the surface under it.

    Parameters
    ----------
    vertices : (V, 3) float
        Mesh positions, mesh units.
    faces : (F, 3) int
        Triangles.
    point : (3,) float
        The impact point (need not lie on the surface).
    size : float
        Decal width = height, mesh units.

    Returns
    -------
    Projector
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    p = np.asarray(point, np.float64)
    tri = vertices[faces]
    closest, _ = closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    dist = np.linalg.norm(closest - p, axis=1)
    hit = int(np.argmin(dist))
    centre = closest[hit]
    normals = face_normals(vertices, faces)
    near = np.linalg.norm(closest - centre, axis=1) <= NORMAL_RADIUS * size
    # Only the side the impact is on: the far side of a thin ear or sheet lies near too, and
    # its opposite normals would cancel the average.
    near &= normals @ normals[hit] > 0
    near[hit] = True
    n = (normals[near] * face_areas(vertices, faces)[near, None]).sum(0)
    if not np.linalg.norm(n) > 0:
        raise CrackbakeError(
            f"the surface at the impact ({_xyz(p)}) has no normal (degenerate faces); "
            "move the impact onto a face with area"
        )
    axes = _frame(n)
    half, own = _surface_half_depth(vertices, faces, normals, axes, centre, size, hit)
    reach = half * 1.05 + DEPTH_MARGIN * size
    other = _other_surface_depth(vertices, faces, own, axes, centre, size, normals, half)
    if other < reach:
        # Another surface (the far side of a thin ear, a wall behind) lies inside the box an
        # engine projects through: stop the box between the two.
        reach = half + SECOND_SURFACE_SHARE * (other - half)
        if other <= half * 1.0001:
            warnings.warn(
                f"the decal at ({_xyz(centre)}) cannot hold the surface under it "
                f"(reaching {half:.4g} deep) without reaching another surface {other:.4g} "
                "behind or in front of it, which engines will paint too; use a smaller --decal",
                CrackbakeWarning,
                stacklevel=2,
            )
    # Never a box of no depth (a flat surface with a coincident back-facing sheet): engines
    # divide by it.
    depth = 2.0 * max(reach, DEPTH_MARGIN * 1e-3 * size)
    matrix = np.eye(4)
    matrix[:3, :3] = axes.T
    matrix[:3, 3] = centre
    return Projector(matrix=matrix, width=float(size), height=float(size), depth=float(depth))


def _xyz(p) -> str:
    """A point as a message writes it: ``0.5, 0.25, 0`` (numpy 2 would print np.float64(...))."""
    return ", ".join(f"{float(x):.6g}" for x in p)


def _surface_half_depth(vertices, faces, normals, axes, centre, size, hit) -> float:
    """Largest |local z| of the surface under the footprint: the faces facing the projector whose
    footprint overlaps the box, connected (through shared vertices) to the impact's face."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    local = (vertices - centre) @ axes.T
    lo = local[faces].min(axis=1)
    hi = local[faces].max(axis=1)
    half = 0.5 * size
    keep = (normals @ axes[2] > 0) & (lo[:, 0] <= half) & (hi[:, 0] >= -half)
    keep &= (lo[:, 1] <= half) & (hi[:, 1] >= -half)
    keep[hit] = True
    idx = np.nonzero(keep)[0]
    sub = faces[idx]
    # Faces x vertices incidence; faces sharing a vertex are linked.
    rows = np.repeat(np.arange(len(idx)), 3)
    inc = coo_matrix((np.ones(rows.size), (rows, sub.ravel())), shape=(len(idx), len(vertices)))
    _, label = connected_components((inc @ inc.T).tocsr(), directed=False)
    own = label == label[int(np.searchsorted(idx, hit))]
    return float(np.abs(local[sub[own].ravel(), 2]).max()), idx[own]


def _other_surface_depth(vertices, faces, own, axes, centre, size, normals=None,
                         own_depth: float = 0.0) -> float:
    """Nearest |local z| of any surface inside the footprint other than the decal's own
    (``own``: the faces :func:`_surface_half_depth` measured), mesh units; inf when none.

    The nearest hit along the projection per point of a 64 x 64 grid over the footprint (a
    depth pre-pass in the projector's view, both facings): a hit on a face outside ``own``
    counts, as an engine would paint it if the box reached it.  A face of another piece that
    faces the projector and lies within the own surface's depth (``own_depth``; ``normals``
    (M, 3) given) does not: it is a piece touching the surface (separate shells meeting in one
    plane, a button on a coat), which the engine should paint with it.
    """
    local = (vertices - centre) @ axes.T
    half = 0.5 * size
    tri = local[faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    inside = (lo[:, 0] <= half) & (hi[:, 0] >= -half) & (lo[:, 1] <= half) & (hi[:, 1] >= -half)
    inside[own] = False
    if normals is not None:
        tol = own_depth + 1e-6 * size
        inside &= ~((normals @ axes[2] > 0) & (np.abs(tri[:, :, 2]).max(axis=1) <= tol))
    cand = np.flatnonzero(inside)
    if len(cand) == 0:
        return float("inf")
    g = (np.arange(64) + 0.5) / 64 * size - half
    px, py = (a.ravel() for a in np.meshgrid(g, g))
    best = np.inf
    for chunk in np.array_split(cand, max(1, len(cand) // 256)):  # 256 x 4096 per round
        a, b, c = (tri[chunk, k] for k in range(3))
        # 2-D barycentrics of every grid point in every candidate face (orthographic rays).
        d = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
        ok = np.abs(d) > 1e-300
        a, b, c, d = a[ok], b[ok], c[ok], d[ok]
        if len(d) == 0:
            continue
        w0 = ((b[:, 1, None] - c[:, 1, None]) * (px - c[:, 0, None])
              + (c[:, 0, None] - b[:, 0, None]) * (py - c[:, 1, None])) / d[:, None]
        w1 = ((c[:, 1, None] - a[:, 1, None]) * (px - c[:, 0, None])
              + (a[:, 0, None] - c[:, 0, None]) * (py - c[:, 1, None])) / d[:, None]
        w2 = 1.0 - w0 - w1
        hit = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        z = np.abs(w0 * a[:, 2, None] + w1 * b[:, 2, None] + w2 * c[:, 2, None])
        if hit.any():
            best = min(best, float(z[hit].min()))
    return best


def decal_faces(vertices: np.ndarray, faces: np.ndarray, projector: Projector) -> np.ndarray:
    """Indices of the faces a decal bake draws: facing the projector and overlapping its box."""
    local = projector.to_local(vertices)
    lo = local[faces].min(axis=1)
    hi = local[faces].max(axis=1)
    ext = 0.5 * np.array([projector.width, projector.height, projector.depth])
    overlap = np.all((lo <= ext) & (hi >= -ext), axis=1)
    facing = face_normals(vertices, faces) @ projector.axes[2] > 0
    return np.nonzero(overlap & facing)[0]


def bake_decal(
    vertices: np.ndarray,
    faces: np.ndarray,
    segments: Segments,
    projector: Projector,
    res: int,
    max_distance: float,
    profile_shape: float = 1.0,
    tile: int | None = None,
    ctx=None,
    min_px: float = MIN_PX_DEFAULT,
    angle_fade: tuple[float, float] | None = ANGLE_FADE_DEG,
    progress=None,
) -> CrackMaps:
    """Bake the crack network as the projector sees it: the decal texture set.

    Parameters
    ----------
    vertices, faces
        The baked mesh (the UV bake's), mesh units.
    segments : Segments
        The crack network in mesh space.
    projector : Projector
    res : int
        Decal edge in texels.
    max_distance : float
        The UV bake's distance clamp (``CrackMaps.max_distance``), so both measure alike.
    profile_shape : float
        Depth profile exponent, as in the UV bake.
    tile : int, optional
        Largest framebuffer edge (default the bake's).
    ctx : moderngl.Context, optional
    min_px : float
        Least drawn crack width in decal texels (``bake_cracks``).
    angle_fade : (float, float) or None
        Start and end of the angle fade, degrees between the surface normal and the
        projector's axis (:data:`ANGLE_FADE_DEG`; :func:`angle_fade_image`); None: no fade.
    progress : callable, optional
        ``progress(rows_done, res)`` after each GL call of the crack pass (``bake_cracks``).

    Returns
    -------
    CrackMaps
        Row 0 = top of the image (local +Y); ``inside`` marks texels showing the surface; the
        normal is in the projector's frame (OpenGL: +Y = image up), flat (0, 0, 1).
    """
    vertices = np.asarray(vertices, np.float64)
    sub = np.asarray(faces, np.int64)[decal_faces(vertices, faces, projector)]
    if len(sub) == 0:
        raise CrackbakeError("no surface faces the decal projector; check the impact point")
    clip = projector.clip_matrix()
    homo = np.c_[vertices, np.ones(len(vertices))] @ clip.T
    placement = 0.5 + 0.5 * homo[:, :2]
    n_vertices = len(vertices)
    normals = np.broadcast_to(projector.axes[2], (n_vertices, 3))
    tangents = np.empty((n_vertices, 4))
    tangents[:, :3] = projector.axes[0]
    tangents[:, 3] = 1.0  # B = cross(N, T) = +Y, image up
    extra = {} if tile is None else {"tile": tile}
    maps = bake_cracks(
        vertices, sub, placement, segments, res, max_distance=max_distance,
        profile_shape=profile_shape, dilate_px=DECAL_DILATE_PX, ctx=ctx, normals=normals,
        tangents=tangents, projection=clip, min_px=min_px, progress=progress, **extra,
    )  # fmt: skip
    if angle_fade is not None:
        fade_maps(maps, angle_fade_image(vertices, sub, projector, res, angle_fade, ctx))
    return maps


def angle_fade_image(vertices: np.ndarray, faces: np.ndarray, projector: Projector, res: int,
                     angles: tuple[float, float] = ANGLE_FADE_DEG, ctx=None) -> np.ndarray:
    """Per decal texel, the angle fade of the surface nearest the projector there, (res, res)
    float32 in [0, 1], row 0 = top: 1 where the surface normal lies within ``angles[0]``
    degrees of the projector's axis, 0 beyond ``angles[1]``, smoothstep between (1 where no
    surface is drawn).  The faces are drawn as the decal bake draws them (depth-tested)."""
    import moderngl

    from crackbake.bake.context import GLScope, shader_source

    start, end = (float(a) for a in angles)
    if not 0.0 <= start < end <= 180.0:
        raise CrackbakeError(f"angle fade {start:g}..{end:g} degrees must rise within 0..180")
    vbo_data = np.ascontiguousarray(vertices, np.float32)
    with GLScope(ctx) as gl:
        c = gl.ctx
        prog = gl.keep(c.program(vertex_shader=shader_source("decal_project.vert"),
                                 fragment_shader=shader_source("decal_facing.frag")))
        vbo = gl.keep(c.buffer(vbo_data))
        ibo = gl.keep(c.buffer(np.ascontiguousarray(faces, np.uint32)))
        vao = gl.keep(c.vertex_array(prog, [(vbo, "3f", "in_pos")], index_buffer=ibo,
                                     index_element_size=4))
        prog["u_projection"].write(np.asarray(projector.clip_matrix(), np.float32).T.tobytes())
        prog["u_res"].value = float(res)
        prog["u_tile"].value = (0.0, 0.0, float(res), float(res))
        prog["u_axis"].value = tuple(float(x) for x in projector.axes[2])
        prog["u_cos"].value = (float(np.cos(np.radians(start))), float(np.cos(np.radians(end))))
        target = gl.keep(c.texture((res, res), 1, dtype="f4"))
        depth = gl.keep(c.depth_renderbuffer((res, res)))
        fbo = gl.keep(c.framebuffer(color_attachments=[target], depth_attachment=depth))
        fbo.use()
        c.viewport = (0, 0, res, res)
        fbo.clear(1.0, 1.0, 1.0, 1.0, depth=1.0)
        c.enable_only(moderngl.DEPTH_TEST)
        vao.render(moderngl.TRIANGLES)
        out = np.empty((res, res), np.float32)
        fbo.read_into(out, components=1, dtype="f4")
    return out


def fade_maps(maps: CrackMaps, fade: np.ndarray) -> None:
    """Fade a decal's crack channels in place by ``fade`` (res, res): the coverage, the depth
    and the normal's and occlusion's departure from flat and open shrink with it (the width,
    time, id and distance channels describe the crack, not how it shows, and stay)."""
    part = fade < 1.0  # texels at full strength keep their exact values
    f = np.clip(fade[part], 0.0, 1.0)
    maps.mask[part] = (maps.mask[part].astype(np.float32) * f).astype(maps.mask.dtype)
    maps.depth[part] = maps.depth[part] * f
    if maps.occlusion is not None:
        occ = maps.occlusion[part].astype(np.float32)
        maps.occlusion[part] = (1.0 - (1.0 - occ) * f).astype(maps.occlusion.dtype)
    if maps.normal is not None:
        n = maps.normal[part] * f[:, None]
        n[:, 2] += 1.0 - f
        maps.normal[part] = n / np.linalg.norm(n, axis=-1, keepdims=True)


def bake_decals(uvmesh, segs: Segments, maps: CrackMaps, impacts, size: float, res: int,
                tile: int | None = None, ctx=None) -> list[tuple[Projector, CrackMaps, dict]]:
    """One decal per impact on the baked mesh: ``(projector, maps, impact dict)`` each.

    ``maps`` is the run's UV bake: its distance clamp, profile and least drawn width (in the
    decal's texels) are reused, so the decal measures what the UV bake measured.
    """
    out = []
    for imp in impacts:
        proj = make_projector(uvmesh.vertices, uvmesh.faces, imp.point, size)
        dec = bake_decal(uvmesh.vertices, uvmesh.faces, segs, proj, res, maps.max_distance,
                         maps.profile_shape, tile, ctx, min_px=maps.min_px)  # fmt: skip
        out.append((proj, dec, imp.to_dict()))
    return out
