"""GPU bake of the solver's stress fields into UV-space maps, in each texel's tangent frame.

The simulation triangles are drawn in UV space (docs/method.md, "The simulation mesh contract":
every sim triangle lies inside one asset face, so each of its corners has that face's UV at its
barycentric coordinates; a node on a UV seam gets one UV per island).  The stress travels as a
world-space tensor per simulation node (the area-weighted mean of its faces' tensors: nodes the
solver split along a crack keep each side's own value, so the maps stay discontinuous exactly
across cracks) and is linearly interpolated per texel.  Both fields go through one draw of the
final (split) sim mesh: the initial field's node values are carried onto it
(:func:`crackbake.bake.stress_fields.on_final_mesh`, exact because the split mesh refines the
initial one).  Per texel the tensors are expressed in the texel's tangent frame.  A simulation
grown on a decimated proxy (:mod:`crackbake.simulate.simmesh.proxy`) has nodes near the asset, not
in its faces: there the asset's own faces are drawn, each UV-mesh vertex taking the values at its
closest point on the final sim mesh (:func:`at_points`).  Per texel::

    N  = normalize(interpolated shading normal)
    e1 = normalize(T - N (N . T))       tangent, along +u
    e2 = w * cross(N, e1)               bitangent, along +v (w = the tangent's bitangent sign)

i.e. the frame engines decode tangent-space normal maps in (MikkTSpace ``T``, ``B = w N x T``),
orthonormalised.  Components: ``xx = e1.S.e1``, ``yy = e2.S.e2``, ``xy = e1.S.e2``; principal
values ``p1 >= p2`` and the unit direction of ``p1`` as ``(cos a, sin a)`` in ``(e1, e2)``,
``a`` in (-90, 90] degrees (a direction is only defined up to sign; texels without one, no
stress or the same in every direction, and the gutters between islands get (0, 0)).

Units: the solver's stress units, i.e. the stress sources' *strength* (every source is linear in
its strength, which is the principal stress it adds; crackbake/simulate/stress/sources.py).
They are relative, not pascals: a directional source of strength 1 gives 1.  Tension positive.
The separation ``sep`` is dimensionless, relative to the toughness: >= 1 is where the material
fails.  Rows: row 0 = top of the image (v = 1).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from crackbake.bake.context import GLScope, finish, shader_source
from crackbake.bake.dilation import nearest_island
from crackbake.bake.stress_fields import (
    draw_data,
    initial_separation,
    nodal_values,
    on_final_mesh,
)
from crackbake.errors import CrackbakeError
from crackbake.geometry import SurfaceIndex
from crackbake.params import TILE_DEFAULT

__all__ = ["FIELDS", "FRAME", "STRESS_UNITS", "StressMaps", "TensorMaps", "bake_stress",
           "initial_separation"]

#: The two fields, in output order: the solver's initial and final (effective) stress.
FIELDS = ("stress0", "stress")
#: Units of xx, yy, xy, p1, p2 (recorded in the EXR header).
STRESS_UNITS = "source strength (relative)"
#: The tangent frame, for headers.
FRAME = ("tangent: e1 = normalize(T - N(N.T)) (+u), e2 = w cross(N, e1) (+v); "
         "components xx, yy, xy; dir = (cos, sin) of p1 in (e1, e2)")


@dataclass(eq=False)
class TensorMaps:
    """One stress field in the tangent frame, each plane (res, res) float32, row 0 = top.

    Attributes
    ----------
    xx, yy, xy : float32
        Tensor components in ``(e1, e2)``, solver stress units.
    p1, p2 : float32
        Principal values, ``p1 >= p2``.
    dir : (res, res, 2) float32
        Unit direction of ``p1`` in ``(e1, e2)``, first component >= 0.
    sep : float32
        Separation relative to the toughness (>= 1 failed), dimensionless.
    """

    xx: np.ndarray
    yy: np.ndarray
    xy: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    dir: np.ndarray
    sep: np.ndarray


@dataclass(eq=False)
class StressMaps:
    """The baked stress fields (see the module docstring for frame and units).

    Attributes
    ----------
    res : int
    stress0 : TensorMaps
        The initial field (before any crack).
    stress : TensorMaps
        The final field (what the cracks left: iben's effective stress).
    inside : (res, res) bool
        Texels whose centre lies on a simulation triangle (before dilation).
    units, frame : str
        :data:`STRESS_UNITS`, :data:`FRAME`.
    """

    res: int
    stress0: TensorMaps
    stress: TensorMaps
    inside: np.ndarray
    units: str = STRESS_UNITS
    frame: str = FRAME
    timings: dict[str, float] = field(default_factory=dict)

    def fields(self) -> dict[str, TensorMaps]:
        """``{"stress0": ..., "stress": ...}``."""
        return {"stress0": self.stress0, "stress": self.stress}

    def planes(self) -> dict[str, np.ndarray]:
        """Every plane by role name ``<field>.<xx|yy|xy|p1|p2|dir_x|dir_y|sep>``, (res, res)."""
        out: dict[str, np.ndarray] = {}
        for name, f in self.fields().items():
            for comp in ("xx", "yy", "xy", "p1", "p2"):
                out[f"{name}.{comp}"] = getattr(f, comp)
            out[f"{name}.dir_x"] = f.dir[..., 0]
            out[f"{name}.dir_y"] = f.dir[..., 1]
            out[f"{name}.sep"] = f.sep
        return out


def _tangents(uvmesh, tangents) -> np.ndarray:
    t = getattr(uvmesh, "tangents", None) if tangents is None else tangents
    if t is None:
        raise CrackbakeError(
            "stress maps need tangents; pass tangents= or bake with "
            "crackbake.bake.tangents.with_tangents(uvmesh)")
    t = np.asarray(t, np.float64)
    if t.shape != (len(uvmesh.vertices), 4):
        raise CrackbakeError(
            f"tangents have shape {t.shape}; they must be (V, 4) for the {len(uvmesh.vertices)} "
            "UV-mesh vertices (compute them on the same UV mesh)")
    return t


def _initial_mesh(result, initial):
    """Vertices and faces of the mesh ``stress_initial`` lives on."""
    if initial is None:
        if len(result.stress_initial) != len(result.faces):
            raise CrackbakeError(
                "the solver split faces, so the initial stress needs the initial simulation "
                "mesh: pass initial=Solved.sim")
        initial = result
    verts = np.asarray(initial.vertices, np.float64)
    faces = np.asarray(initial.faces, np.int64)
    if len(faces) != len(result.stress_initial):
        raise CrackbakeError(
            f"the initial mesh has {len(faces)} faces but the initial stress "
            f"{len(result.stress_initial)}; pass the simulation mesh the solver started from")
    return verts, faces


def at_points(vertices: np.ndarray, faces: np.ndarray, nodal: np.ndarray,
              points: np.ndarray) -> np.ndarray:
    """Nodal values (N, C) of a mesh interpolated at the closest mesh point to each of
    ``points`` (K, 3): (K, C).  On a cracked mesh a point takes the side of the crack it is on."""
    face, bary, _ = SurfaceIndex(vertices, faces).closest(points)
    corner = faces[face]
    # Corner by corner, in the einsum's order ((0 + 1) + 2): the same bits without its
    # (K, 3, C) gather (250 MB at a 1.5M-face asset's vertices).
    out = bary[:, 0, None] * nodal[corner[:, 0]]
    out += bary[:, 1, None] * nodal[corner[:, 1]]
    out += bary[:, 2, None] * nodal[corner[:, 2]]
    return out


def bake_stress(uvmesh, result, res: int, tangents: np.ndarray | None = None, initial=None,
                dilate_px: int | None = None, tile: int = TILE_DEFAULT, ctx=None,
                rows: tuple | None = None) -> StressMaps:
    """Bake the solver's initial and final stress into tangent-frame maps.

    Parameters
    ----------
    uvmesh : UVMesh
        The output mesh (``vertices``, ``faces`` in asset order, ``uv`` v up, ``normals``).
    result : SolverResult
        ``vertices``/``faces``/``asset_face`` (final sim mesh), ``stress_final`` (per final
        face), ``separation`` (per final node), ``stress_initial``, ``stats["tau"]``; an
        optional ``separation_initial`` (per initial node, relative to the toughness) replaces
        the derived initial separation.
    res : int
        Output edge in texels.
    tangents : (V, 4) float, optional
        Per UV-mesh vertex: unit T and bitangent sign w (``B = w N x T`` points to +v);
        default ``uvmesh.tangents``.
    initial : SimMesh, optional
        The mesh ``stress_initial`` lives on (``Solved.sim``); needed once iben split faces.
    dilate_px : int, optional
        Gutter fill limit in texels (``None``: fill every empty texel).
    tile : int
        Largest framebuffer edge: images are drawn in full-width bands of <= tile**2 texels.
    ctx : moderngl.Context, optional
        The run's context; a temporary one when not given.
    rows : tuple, optional
        :func:`stress_rows` of these arguments, prepared ahead (on another thread while the
        crack bake runs); the maps are the same either way.
    """
    if res < 1:
        raise ValueError(f"res must be a positive texel count, got {res}")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    data, index = rows if rows is not None else stress_rows(uvmesh, result, tangents, initial)
    timings["prepare"] = time.perf_counter() - t0
    planes = _render(ctx, data, res, tile, timings, index)
    t1 = time.perf_counter()
    inside = planes.pop("inside")
    source = _sources(inside, dilate_px)
    timings["nearest"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    maps = {f: _principal_maps(planes, f, res, source) for f in FIELDS}
    timings["principal"] = time.perf_counter() - t2
    return StressMaps(res=res, stress0=maps["stress0"], stress=maps["stress"], inside=inside,
                      timings=timings)


def stress_rows(uvmesh, result, tangents: np.ndarray | None = None,
                initial=None) -> tuple[np.ndarray, np.ndarray | None]:
    """The stress bake's vertex rows: the CPU half of :func:`bake_stress` (same arguments),
    no GL.

    Returns
    -------
    data : (R, 9 + 14) float32
        Rows of uv, T, w, N and both fields' nodal values (:func:`draw_data` or, for a proxy
        run, :func:`vertex_rows`).
    index : (3M,) uint32 or None
        The indexed draw's corners (a proxy run), None for an unindexed draw.
    """
    tan = _tangents(uvmesh, tangents)
    v0, f0 = _initial_mesh(result, initial)
    s0 = np.asarray(result.stress_initial, np.float64)
    # A solver that reports the separation it started from (per initial node) is used as is;
    # otherwise it is derived from the initial stress (initial_separation).
    sep0 = getattr(result, "separation_initial", None)
    if sep0 is None or len(sep0) != len(v0):
        sep0 = initial_separation(v0, f0, s0, result.stats)
    v1 = np.asarray(result.vertices, np.float64)
    f1 = np.asarray(result.faces, np.int64)
    final = nodal_values(v1, f1, np.asarray(result.stress_final, np.float64),
                         np.asarray(result.separation, np.float64))
    first = on_final_mesh(v0, f0, nodal_values(v0, f0, s0, sep0), v1)
    nodal = np.concatenate([first, final], axis=1)
    index = None
    if getattr(initial, "proxy", None) is None:
        asset_face = np.asarray(result.asset_face, np.int64)
        data = draw_data(uvmesh, tan, v1, f1, asset_face, nodal)
        data = wrapped_rows(data, asset_face, getattr(uvmesh, "wraps", None))
    else:  # sim nodes lie near the asset, not in its faces: draw the asset at its own vertices
        data, index = vertex_rows(uvmesh, tan, at_points(v1, f1, nodal, uvmesh.vertices),
                                  getattr(uvmesh, "wraps", None))
    return data, index


def vertex_rows(uvmesh, tangents: np.ndarray, nodal: np.ndarray,
                wraps: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The asset's own faces for an indexed draw: rows (V', 9 + C) float32 and indices (3M,)
    uint32, the same corner values as :func:`draw_data` with each face its own asset face,
    followed by :func:`wrapped_rows`' copies, in the same order.

    A corner's barycentrics in its own face are exactly 1 and 0 (the same products on both
    sides of the division), so its row is its vertex's: one row per vertex, where the unindexed
    buffer held three per face (430 MB at 1.5M faces, built, copied and uploaded: 1.3 s).  A
    face of no area interpolates the surface attributes of all three corners at its first
    vertex (``draw_data``'s fallback), so it gets three rows of its own.

    Parameters
    ----------
    uvmesh : UVMesh
        ``vertices`` (V, 3), ``faces`` (M, 3), ``uv`` (V, 2), ``normals`` (V, 3).
    tangents : (V, 4) float
    nodal : (V, C) float
        The fields at the asset's vertices.
    wraps : (K, 3) int, optional
        ``UVMesh.wraps``: (face, du, dv) of each copy drawn shifted by (-du, -dv).
    """
    faces = np.asarray(uvmesh.faces, np.int64)
    n_vertices = len(uvmesh.vertices)
    rows = np.empty((n_vertices, 9 + nodal.shape[1]), np.float32)
    rows[:, 0:2] = uvmesh.uv
    rows[:, 2:6] = tangents
    rows[:, 6:9] = uvmesh.normals
    rows[:, 9:] = nodal
    index = faces.copy()
    flat = _flat_faces(np.ascontiguousarray(uvmesh.vertices, np.float64), faces)
    if len(flat):  # uv, T, w, N of all three corners at the first; the fields their own
        own = rows[faces[flat].reshape(-1)]
        own[:, :9] = np.repeat(rows[faces[flat, 0], :9], 3, axis=0)
        rows = np.concatenate([rows, own])
        index[flat] = n_vertices + np.arange(3 * len(flat)).reshape(-1, 3)
    if wraps is None or not len(wraps):
        return rows, index.astype(np.uint32).reshape(-1)
    wraps = np.asarray(wraps, np.int64)
    corners = rows[index[wraps[:, 0]].reshape(-1)]
    corners[:, 0:2] -= np.repeat(wraps[:, 1:3], 3, axis=0).astype(np.float32)
    copies = len(rows) + np.arange(3 * len(wraps)).reshape(-1, 3)
    return (np.concatenate([rows, corners]),
            np.concatenate([index, copies]).astype(np.uint32).reshape(-1))


@njit(cache=True, nogil=True)
def _flat_faces(vertices, faces):  # pragma: no cover - numba
    """Faces whose Gram determinant ``d11 d22 - d12^2`` (:func:`draw_data`'s, the same sums)
    is 0: (K,) int64."""
    out = np.empty(len(faces), np.int64)
    n = 0
    for f in range(len(faces)):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        d11 = d12 = d22 = 0.0
        for a in range(3):
            e1 = vertices[i1, a] - vertices[i0, a]
            e2 = vertices[i2, a] - vertices[i0, a]
            d11 += e1 * e1
            d12 += e1 * e2
            d22 += e2 * e2
        if d11 * d22 - d12 * d12 == 0.0:
            out[n] = f
            n += 1
    return out[:n]


def wrapped_rows(data: np.ndarray, asset_face: np.ndarray, wraps: np.ndarray | None) -> np.ndarray:
    """``data`` (3M, C) plus, for each wrapped copy (face, du, dv) of ``UVMesh.wraps``, the rows
    of the sim triangles inside that asset face with their UVs shifted by (-du, -dv): the
    stress shows where engines sampling with REPEAT show the straying face."""
    if wraps is None or len(wraps) == 0:
        return data
    wraps = np.asarray(wraps, np.int64)
    order = np.argsort(asset_face, kind="stable")
    lo = np.searchsorted(asset_face[order], wraps[:, 0], side="left")
    hi = np.searchsorted(asset_face[order], wraps[:, 0], side="right")
    tris = np.concatenate([order[a:b] for a, b in zip(lo, hi, strict=True)])
    shift = np.repeat(wraps[:, 1:3], hi - lo, axis=0).astype(np.float32)
    rows = data.reshape(-1, 3, data.shape[1])[tris].copy()
    rows[:, :, 0:2] -= shift[:, None, :]
    return np.concatenate([data, rows.reshape(-1, data.shape[1])])


_OUT = ("xx", "yy", "xy", "sep")
# Texels per band: small bands keep llvmpipe's target allocation (32 bytes a texel) cheap;
# measured at 4096^2 on spot: 0.28 s of set-up with one 4096-row band, none with 256-row ones,
# the same draw time.
_BAND_TEXELS = 1 << 20


def _render(ctx, data: np.ndarray, res: int, tile: int, timings: dict[str, float],
            index: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Draw both fields in one pass, band by band; planar images
    ``<field>.<xx|yy|xy|sep>`` and ``inside``.  ``data`` rows are drawn three a triangle, or
    by ``index`` (3M,) uint32 when given.

    The eight targets are cleared to -1, so ``inside`` is where ``sep`` (>= 0 on every drawn
    texel) was written: a ninth target would exceed llvmpipe's eight draw buffers.
    """
    import moderngl

    with GLScope(ctx) as gl:
        t = time.perf_counter()
        prog = gl.keep(gl.ctx.program(vertex_shader=shader_source("stress_bake.vert"),
                                      fragment_shader=shader_source("stress_bake.frag")))
        prog["u_res"].value = float(res)
        vbo = gl.keep(gl.ctx.buffer(data))
        ibo = None if index is None else gl.keep(gl.ctx.buffer(index))
        vao = gl.keep(gl.ctx.vertex_array(
            prog, [(vbo, "2f 3f 1f 3f 3f 3f 1f 3f 3f 1f", "in_uv", "in_t", "in_w", "in_n",
                    "in_sd0", "in_so0", "in_sep0", "in_sd", "in_so", "in_sep")],
            index_buffer=ibo, index_element_size=4))
        band = max(1, min(res, min(tile * tile, _BAND_TEXELS) // res))
        names = [f"{f}.{c}" for f in FIELDS for c in _OUT]
        images = {n: np.empty((res, res), np.float32) for n in names}
        tex = [gl.keep(gl.ctx.texture((res, band), 1, dtype="f4")) for _ in names]
        fbo = gl.keep(gl.ctx.framebuffer(color_attachments=tex))
        gl.ctx.enable_only(moderngl.NOTHING)
        timings["setup"] = time.perf_counter() - t
        t_draw = t_read = 0.0
        for y0 in range(0, res, band):
            h = min(band, res - y0)
            ta = time.perf_counter()
            prog["u_tile"].value = (0.0, float(y0), float(res), float(band))
            fbo.use()
            fbo.clear(-1.0, -1.0, -1.0, -1.0)
            vao.render(moderngl.TRIANGLES)
            finish(gl.ctx)  # the GIL free meanwhile: the encoders go on
            tb = time.perf_counter()
            for k, n in enumerate(names):
                fbo.read_into(images[n][y0:y0 + h], viewport=(0, 0, res, h), components=1,
                              attachment=k, dtype="f4")
            t_draw += tb - ta
            t_read += time.perf_counter() - tb
        timings["render"] = t_draw
        timings["readback"] = t_read
    images["inside"] = images["stress.sep"] >= 0.0
    return images


def _sources(inside: np.ndarray, limit: int | None) -> np.ndarray:
    """Flat index of the texel each texel takes its values from (itself inside an island, the
    nearest island texel in the gutter, -1 beyond ``limit`` texels or with no island)."""
    source, dist2 = nearest_island(inside)
    if limit is not None:
        source[dist2 > int(limit) ** 2] = -1
    return source


@njit(parallel=True, cache=True, fastmath=True)
def _fill_principal(source, xx, yy, xy, sep, p1, p2, dx, dy):
    """Gutter fill (copy from ``source``, zeros where it is -1) fused with the principal values
    and the unit p1 direction (cos a, sin a), a in (-90, 90] degrees.

    One pass per field instead of a dilation pass per plane plus a principal pass.  Branch-free
    so that it vectorises (3x faster than with branches): every texel is written, island texels
    with their own value (their source is themselves), so concurrent reads of them see the same
    bits.  Half-angle formulas (cos 2a = h / r, sin 2a = xy / r) need no trigonometry;
    texels with no direction (r = 0: no stress, or the same in every direction) and gutter
    texels (no surface) get (0, 0); the other channels are filled from the nearest island.
    """
    one = np.float32(1.0)
    half_ = np.float32(0.5)
    zero = np.float32(0.0)
    for i in prange(xx.shape[0]):
        j = source[i]
        ok = j >= 0
        k = max(np.int64(j), np.int64(0))  # any valid index where there is no source
        a = xx[k] if ok else zero
        c = yy[k] if ok else zero
        b = xy[k] if ok else zero
        s = sep[k] if ok else zero
        xx[i] = a
        yy[i] = c
        xy[i] = b
        sep[i] = s
        mean = half_ * (a + c)
        h = half_ * (a - c)
        r = np.sqrt(h * h + b * b)
        p1[i] = mean + r
        p2[i] = mean - r
        # No direction where the stress has none, nor in the gutters (no surface there).
        has = (r > 0) & (j == i)
        c2 = h / r if has else one
        cx = np.sqrt(max(half_ * (one + c2), zero))
        sy = np.sqrt(max(half_ * (one - c2), zero))
        dx[i] = cx if has else zero
        dy[i] = (sy if b >= 0 else -sy) if has else zero


def _principal_maps(planes: dict[str, np.ndarray], name: str, res: int,
                    source: np.ndarray) -> TensorMaps:
    xx, yy, xy = planes[f"{name}.xx"], planes[f"{name}.yy"], planes[f"{name}.xy"]
    sep = planes[f"{name}.sep"]
    p1 = np.empty_like(xx)
    p2 = np.empty_like(xx)
    direction = np.empty((res, res, 2), np.float32)
    flat = direction.reshape(-1, 2)
    _fill_principal(source, xx.reshape(-1), yy.reshape(-1), xy.reshape(-1), sep.reshape(-1),
                    p1.reshape(-1), p2.reshape(-1), flat[:, 0], flat[:, 1])
    return TensorMaps(xx=xx, yy=yy, xy=xy, p1=p1, p2=p2, dir=direction, sep=sep)


def warm() -> None:
    """Compile (or load from numba's cache) the kernel of :func:`vertex_rows`, which only a
    proxy's stress bake reaches (assets above 200k faces; :mod:`crackbake.precompile`'s plates
    are smaller)."""
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    _flat_faces(v, np.array([[0, 1, 2]], np.int64))
