"""Depth-normal and occlusion maps of the crack bake: inputs, shader variant, conventions.

The normal map is computed analytically per texel in ``shaders/crack_normal.glsl``, run by a
compute pass (``shaders/crack_normal.comp``) over the texels whose depth a crack segment wins
(the crack pass records that segment): the crack's own depth profile, height ``h = -depth``, is
differentiated in world space at the texel's surface point, so the result is exact at the texel
centre whatever the UV stretch and continuous across UV seams (no image-space filter).  Steps
per texel:

1. The winning depth term (the segment whose depth is the texel's depth) is
   ``D(t) (1 - d / hw(t)) ** shape`` with ``d`` the world distance to the segment, ``t`` the
   closest point's parameter, ``hw`` the half width.  Its gradient is
   ``d(depth)/dd * g/|g| + d(depth)/dt * grad t`` (``g`` from the closest point to the texel;
   ``grad t = ab / |ab|^2`` inside the segment, 0 past its ends).
2. Sub-texel cracks (width below the texel footprint ``fw`` across the crack) are baked as their
   area average, a tent ``D w / ((shape + 1) fw) * (1 - d / fw)``; their normal is the slope of
   that filtered height field, i.e. of the profile averaged over the texel footprint (a thin crack
   fades out of the normal map as it fades out of the mask, instead of aliasing).  Here ``w``
   is the drawn width ``max(w, min_px fw)`` (``--min-px``; the default 1 draws a hairline as
   a crack exactly one footprint wide, in this filtered form).
3. ``n' = normalize(N + P(grad depth))``, ``N`` the interpolated vertex normal, ``P`` the
   projection onto the plane normal to ``N`` (a height field over the shading normal).
4. Tangent space exactly as engines decode (MikkTSpace): ``n = normalize(x T + y B + z N)`` with
   ``T``, ``N`` interpolated and not renormalised, ``B = sign * cross(N, T)``; the bake solves
   ``[T B N] (x, y, z) = n'`` and normalises.  OpenGL convention (+Y along B = +v), flat
   ``(0, 0, 1)``.

Occlusion is the sky visibility (cosine-weighted view factor to the open sky) of the texel's point
in an infinitely long groove of the crack's cross-section, relative to the perturbed normal:
``(sin b - sin a) / 2`` for the horizons at angles ``a``, ``b`` from the normal (the 2D view
factor of a long groove).  For a V of slope angle ``alpha`` it rises from ``cos(alpha)^2`` at the
axis to ``(1 + cos(alpha)) / 2`` at the rim; 1 on open ground.  Sub-texel cracks get
``1 - coverage * (1 - mean wall visibility)``, the mean being ``2 hw / wall length`` by
reciprocity (``cos(alpha)`` for a V).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.bake.context import shader_source
from crackbake.errors import CrackbakeError
from crackbake.geometry import welded_vertex_normals

#: GLSL symbol that switches the normal/occlusion outputs on in the bake shaders.
DEFINE = "CRACK_NORMALS"
_INCLUDE = "// @crack_normal.glsl"
_LOOK_INCLUDE = "// @crack_look.glsl"


def shader_variant(name: str, normals: bool, defines: tuple[str, ...] = ()) -> str:
    """Source of ``shaders/<name>``, with the normal-map code compiled in when ``normals``.

    ``defines``: more symbols to define (the look's ``CRACK_CHIP``, ``CRACK_CURL``:
    ``shaders/crack_look.glsl``, inserted where a shader says ``// @crack_look.glsl``).
    Without normals or defines the text is the plain file (its ``#ifdef`` blocks drop out), so
    the other channels run exactly the code they always ran.
    """
    src = shader_source(name)
    lines = src.split("\n")
    out = []
    symbols = ((DEFINE,) if normals else ()) + tuple(defines)
    for line in lines:
        if line.startswith(_INCLUDE):
            out.append(shader_source("crack_normal.glsl") if normals else "")
        elif line.startswith(_LOOK_INCLUDE):
            out.append(shader_source("crack_look.glsl"))
        else:
            out.append(line)
        if line.startswith("#version"):
            out.extend(f"#define {d} 1" for d in symbols)
    return "\n".join(out)


def frame_attributes(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None, tangents: np.ndarray
) -> np.ndarray:
    """Per-vertex position, normal and tangent, (V, 12) float32, for the crack pass.

    The crack pass interpolates normal and tangent at a texel's point from its face's corners
    (only at crack texels: no per-texel frame targets).

    Parameters
    ----------
    vertices : (V, 3) float
        Positions of the baked mesh.
    faces : (F, 3) int
        Its triangles.
    normals : (V, 3) float or None
        Shading normals the tangents were computed with; ``None`` takes area-weighted normals
        welded across UV seams (the asset's normals when its file has none).
    tangents : (V, 4) float
        xyz tangent, w = +1/-1 bitangent sign (``B = w * cross(N, T)`` points towards +v).

    Returns
    -------
    (V, 12) float32
        Columns: position xyz, 0, normal xyz, 0, tangent xyzw (std430 ``vec4`` triples).
    """
    n_vertices = len(vertices)
    tangents = np.asarray(tangents, np.float64)
    if tangents.shape != (n_vertices, 4):
        raise CrackbakeError(
            f"tangents have shape {tangents.shape}, expected ({n_vertices}, 4) (xyz, sign) for "
            "the baked vertices; compute them with crackbake.bake.tangents on the same mesh"
        )
    if normals is None:
        normals = welded_vertex_normals(vertices, faces)
    normals = np.asarray(normals, np.float64)
    if normals.shape != (n_vertices, 3):
        raise CrackbakeError(
            f"normals have shape {normals.shape}, expected ({n_vertices}, 3); pass the normals "
            "of the baked vertices (UVMesh.normals)"
        )
    if not (np.isfinite(tangents).all() and np.isfinite(normals).all()):
        raise CrackbakeError("tangents or normals contain NaN/inf; recompute them on the mesh")
    out = np.zeros((n_vertices, 12), np.float32)
    out[:, 0:3] = vertices
    out[:, 4:7] = normals
    out[:, 8:12] = tangents
    return out


#: Texels per compute dispatch: GL guarantees 65535 work groups of 64 invocations.
_DISPATCH = 65535 * 64


class NormalPass:
    """The compute pass (``shaders/crack_normal.comp``) that fills the normal and occlusion at
    the crack texels of each band, reading the records the crack pass appended (storage binding
    10) and the segment, face and frame buffers (storage bindings 0, 5, 6) the bake set up.

    Parameters
    ----------
    gl : GLScope
        The bake's scope (objects kept there are released with it).
    profile_shape : float
        Depth profile exponent.
    min_px : float
        Least drawn crack width, texels (as the crack pass draws it).
    look_terms : dict, optional
        The look's shader terms (:func:`crackbake.bake.raster.look_terms`): ``defines``,
        ``uniforms`` and ``normal_strength`` (the normal's slope scale, default 1).
    """

    def __init__(self, gl, profile_shape: float, min_px: float = 0.0,
                 look_terms: dict | None = None) -> None:
        self.gl = gl
        terms = look_terms or {}
        self.prog = gl.keep(gl.ctx.compute_shader(
            shader_variant("crack_normal.comp", True, tuple(terms.get("defines", ())))))
        self.prog["u_shape"].value = float(profile_shape)
        self.prog["u_min_px"].value = float(min_px)
        self.prog["u_normal_strength"].value = float(terms.get("normal_strength", 1.0))
        for name, value in terms.get("uniforms", {}).items():
            if self.prog.get(name, None) is not None:
                self.prog[name].value = value

    def run(self, code: np.ndarray, planes: list[np.ndarray], y0: int) -> None:
        """Compute the crack texels of one band into ``planes`` (normal x, y, z, occlusion).

        Parameters
        ----------
        code : (h, res) float32
            The crack pass's inside target of the band: 0 off the faces, 1 on a face with no
            crack depth, ``2 + record`` where a segment's depth term wins: the index of the
            record the crack pass appended there (storage binding 10: the texel's point, face,
            footprint and that segment).
        planes : list of four (res, res) arrays
            Written at rows ``y0 + row`` of the crack texels (others keep their flat value).
        y0 : int
            First image row of the band.
        """
        rows, cols, record = crack_texels(np.ascontiguousarray(code, np.float32))
        if len(rows) == 0:
            return
        ctx = self.gl.ctx
        job = np.zeros((len(rows), 4), np.int32)
        job[:, 0], job[:, 1], job[:, 2] = cols, rows, record
        out = np.empty((len(rows), 4), np.float32)
        for start in range(0, len(rows), _DISPATCH):
            part = job[start : start + _DISPATCH]
            jobs = ctx.buffer(part)
            result = ctx.buffer(reserve=part.nbytes)
            try:
                jobs.bind_to_storage_buffer(7)
                result.bind_to_storage_buffer(8)
                self.prog["u_count"].value = len(part)
                self.prog.run(group_x=(len(part) + 63) // 64)
                ctx.memory_barrier()
                out[start : start + len(part)] = np.frombuffer(result.read(), np.float32).reshape(
                    -1, 4
                )
            finally:
                jobs.release()
                result.release()
        for k, plane in enumerate(planes):
            plane[y0 + rows, cols] = out[:, k]


@njit(cache=True, nogil=True)
def crack_texels(code: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The texels of a band whose inside code is 2 or more, in row-major order: their rows,
    columns and records (the code minus 2, truncated), each (K,) int64.

    ``np.nonzero(code >= 2)`` and a gather give the same arrays; on a 4096² band they took
    40-60 ms of the bake's main thread (a 16 MB mask, then numpy's 2-D nonzero), this scan
    (one counting pass, one filling pass) about a tenth of that.
    """
    h, w = code.shape
    n = 0
    for i in range(h):
        row = code[i]
        for j in range(w):
            n += row[j] >= np.float32(2.0)
    rows = np.empty(n, np.int64)
    cols = np.empty(n, np.int64)
    record = np.empty(n, np.int64)
    k = 0
    for i in range(h):
        row = code[i]
        for j in range(w):
            v = row[j]
            if v >= np.float32(2.0):
                rows[k] = i
                cols[k] = j
                record[k] = np.int64(v) - 2
                k += 1
    return rows, cols, record
