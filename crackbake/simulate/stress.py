"""Initial stress fields on the simulation mesh (method.md §A2, §B6).

Every source adds (or multiplies) a symmetric 3x3 **world-space** tensor per sim face lying in the
face plane (``S @ n == 0``), tension positive: the convention of
:mod:`crackbake.simulate.solver.fem`.
Additive sources (impact, shrinkage, directional, curvature) are summed; painted weights then
multiply the sum, and noise perturbs what is left, so a zero weight always means zero stress.

All terms are linear in their strength (§B6): a strength ``s`` is the principal stress it adds.

Impacts use the *geodesic* distance over the surface, not the straight-line one, so an impact on
one wall of a thin shell or a bottle does not leak through to the opposite wall.  The distance
comes from geometry-central's fast marching (``potpourri3d``), run only on the part of the mesh
that can lie within the impact's reach; where that library is missing or the patch is not
manifold, shortest edge paths (Dijkstra, a few percent longer than the true geodesic) stand in.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh
from crackbake.simulate.solver.fem import face_frames, face_geometry

# Curvature ratios are clipped at this multiple of the mesh's mean curvature so that a few sharp
# creases cannot swamp every other source.
CURVATURE_CLIP = 5.0
# Default noise feature size, in sim edge lengths.
# Default noise feature size, fraction of the bounding-box diagonal: in world units, so the
# pattern does not change with the simulation resolution.
NOISE_SCALE_DIAGONAL = 0.02
# Sinusoids summed per noise field (more is smoother-looking but slower).
NOISE_WAVES = 8
# Rec. 709 luminance weights, for colour weight maps and vertex colours.
LUMA = np.array([0.2126, 0.7152, 0.0722])


# --------------------------------------------------------------------------------------------
# Sources
# --------------------------------------------------------------------------------------------


def _finite_vector(value, name: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.array([np.nan])
    if v.shape != (3,) or not np.isfinite(v).all():
        raise CrackbakeError(f"{name} must be three finite numbers x,y,z; got {value!r}")
    return v


def _finite_number(value, name: str, positive: bool = False, nonnegative: bool = False) -> None:
    ok = isinstance(value, int | float | np.floating | np.integer) and np.isfinite(value)
    if ok and positive:
        ok = value > 0
    if ok and nonnegative:
        ok = value >= 0
    if not ok:
        need = "a positive" if positive else "a non-negative" if nonnegative else "a finite"
        raise CrackbakeError(f"{name} must be {need} number; got {value!r}")


@dataclass(frozen=True)
class ImpactSource:
    """Glass-like impact: radial cracks linked by concentric ones.

    Adds ``w (r r^T + hoop c c^T)`` with ``w = strength * 2 cos(d / radius)`` for geodesic distance
    ``d <= pi * radius / 2`` (zero beyond), ``r`` the unit surface gradient of ``d`` and
    ``c = n x r``.  Hoop tension above radial (``hoop > 1``) opens radial cracks first.

    Attributes
    ----------
    point : (3,) floats
        Impact point, mesh units; snapped to the nearest surface point.
    radius : float or None
        Mesh units; ``None`` means 0.15 x the asset's bounding-box diagonal.
    strength : float
        Principal (radial) stress at the impact point is ``2 * strength``.
    hoop : float
        Ratio of hoop (tangential) to radial tension.
    """

    point: tuple[float, float, float]
    radius: float | None = None
    strength: float = 1.0
    hoop: float = 1.25

    def __post_init__(self) -> None:
        _finite_vector(self.point, "impact point")
        if self.radius is not None:
            _finite_number(self.radius, "impact radius", positive=True)
        _finite_number(self.strength, "impact strength")
        _finite_number(self.hoop, "impact hoop ratio", nonnegative=True)


@dataclass(frozen=True)
class ShrinkSource:
    """Uniform in-plane shrinkage ``strength * (I - n n^T)``: crackle glaze, mud, crackle glass.

    ``rate`` (relative to ``strength``) is added per solver step, so the field keeps growing as
    the solver runs: ``growth = rate * strength * (I - n n^T)``.
    """

    strength: float = 1.0
    rate: float = 0.0

    def __post_init__(self) -> None:
        _finite_number(self.strength, "shrink strength")
        _finite_number(self.rate, "shrink rate", nonnegative=True)


@dataclass(frozen=True)
class DirectionalSource:
    """Uniaxial tension along a world direction: parallel cracks as in wood or rock.

    Adds the in-plane part of the world tensor ``strength * d d^T`` (``d`` unit), i.e.
    ``strength * (P d)(P d)^T`` with ``P`` the projection onto the face plane.  It fades smoothly
    to zero on faces facing along ``d``, where the direction would be meaningless.
    """

    direction: tuple[float, float, float]
    strength: float = 1.0

    def __post_init__(self) -> None:
        d = _finite_vector(self.direction, "tension direction")
        if np.linalg.norm(d) == 0:
            raise CrackbakeError("tension direction is zero; give a direction such as 0,0,1")
        _finite_number(self.strength, "tension strength")


@dataclass(frozen=True)
class CurvatureSource:
    """Tension from surface curvature.

    ``bias`` adds tension along the principal direction of largest |curvature|, scaled by how
    much that curvature exceeds the other one, so cracks run along the least-curved direction (on
    a cylinder: along the axis).  ``density`` adds isotropic in-plane tension growing with the
    curvature magnitude, for more cracks where the surface bends most.  Both are relative to the
    area-weighted median curvature of the mesh's curved faces (so O(1) for strength 1 at any
    scale, and sharp creases do not set the scale), clipped at :data:`CURVATURE_CLIP`.
    """

    bias: float = 1.0
    density: float = 0.0

    def __post_init__(self) -> None:
        _finite_number(self.bias, "curvature bias")
        _finite_number(self.density, "curvature density")


@dataclass(frozen=True, eq=False)
class WeightSource:
    """Painted weights multiplying the whole field per face.

    Attributes
    ----------
    per_vertex : (V,) float64 or None
        One scalar per **asset** vertex (see :func:`vertex_weights`), 1 = full strength.
    image : (H, W) float64 or None
        Grayscale in [0, 1], row 0 at the top (``v = 1``), sampled bilinearly through the asset
        UVs with repeat wrapping (see :func:`load_weight_map`).
    invert : bool
        Use ``1 - weight`` (each of ``per_vertex`` and ``image``).
    """

    per_vertex: np.ndarray | None = None
    image: np.ndarray | None = None
    invert: bool = False

    def __post_init__(self) -> None:
        if self.per_vertex is None and self.image is None:
            raise CrackbakeError(
                "weight source has neither per-vertex weights nor an image; give one of them"
            )
        if self.per_vertex is not None:
            w = np.asarray(self.per_vertex, dtype=np.float64)
            if w.ndim != 1 or not np.isfinite(w).all():
                raise CrackbakeError(
                    "per-vertex weights must be one finite number per vertex; check the attribute"
                )
        if self.image is not None:
            im = np.asarray(self.image, dtype=np.float64)
            if im.ndim != 2 or min(im.shape) < 1 or not np.isfinite(im).all():
                raise CrackbakeError(
                    "weight image must be a finite 2-D grayscale array; load it with "
                    "load_weight_map"
                )


@dataclass(frozen=True)
class NoiseSource:
    """Light seeded random perturbation of the field.

    Scales the field by ``1 + amount * noise`` (``noise`` a smooth unit-variance field of feature
    size ``scale``) and adds a random in-plane direction term of relative size ``amount``.

    Attributes
    ----------
    amount : float
        Relative size of the perturbation (0.1 = about 10 %).
    scale : float or None
        Feature size, mesh units; ``None`` means 2 % of the bounding-box diagonal.
    """

    amount: float = 0.1
    scale: float | None = None

    def __post_init__(self) -> None:
        _finite_number(self.amount, "noise amount", nonnegative=True)
        if self.scale is not None:
            _finite_number(self.scale, "noise scale", positive=True)


@dataclass(eq=False)
class StressField:
    """The initial stress on the simulation mesh.

    Attributes
    ----------
    stress : (M, 3, 3) float64
        World-space in-plane tensors per sim face, tension positive.
    growth : (M, 3, 3) float64
        Added to ``stress`` per solver step (shrinkage rate); zeros when nothing grows.
    weight : (M,) float64
        Painted-weight multiplier applied (ones without a weight source).
    impacts : list of dict
        ``{"point": [x, y, z] snapped, "radius": r, "strength": s}`` per impact, as used.
    """

    stress: np.ndarray
    growth: np.ndarray
    weight: np.ndarray
    impacts: list[dict] = field(default_factory=list)


# --------------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------------


def _closest_on_triangles(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closest point to ``p`` on each triangle ``(a, b, c)``, each (K, 3).

    Returns the points (K, 3) and their barycentric coordinates (K, 3).
    """
    ab, ac, ap = b - a, c - a, p - a
    d00 = np.einsum("ka,ka->k", ab, ab)
    d01 = np.einsum("ka,ka->k", ab, ac)
    d11 = np.einsum("ka,ka->k", ac, ac)
    d20 = np.einsum("ka,ka->k", ap, ab)
    d21 = np.einsum("ka,ka->k", ap, ac)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-300 * np.maximum(d00 * d11, 1e-300)
    safe = np.where(ok, den, 1.0)
    v = (d11 * d20 - d01 * d21) / safe
    w = (d00 * d21 - d01 * d20) / safe
    u = 1.0 - v - w
    inside = ok & (u >= 0) & (v >= 0) & (w >= 0)
    bary = np.stack([u, v, w], axis=1)
    best = a + v[:, None] * ab + w[:, None] * ac
    best_d = np.where(inside, np.einsum("ka,ka->k", best - p, best - p), np.inf)
    # Projection outside the triangle: the closest point lies on one of its edges.
    for i, (s, e) in enumerate(((a, b), (b, c), (c, a))):
        se = e - s
        ll = np.einsum("ka,ka->k", se, se)
        t = np.clip(np.einsum("ka,ka->k", p - s, se) / np.where(ll > 0, ll, 1.0), 0.0, 1.0)
        q = s + t[:, None] * se
        dq = np.einsum("ka,ka->k", q - p, q - p)
        better = dq < best_d
        if better.any():
            bb = np.zeros((better.sum(), 3))
            bb[:, i] = 1.0 - t[better]
            bb[:, (i + 1) % 3] = t[better]
            bary[better] = bb
            best[better] = q[better]
            best_d = np.where(better, dq, best_d)
    return best, bary


def _snap(sim, point: np.ndarray) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, float]:
    """Nearest surface point.

    Returns the point (3,), its sim face, its barycentrics (3,), the face centroids (M, 3) and
    the largest centroid-to-corner distance.
    """
    tri = sim.vertices[sim.faces]
    centroid = tri.mean(axis=1)
    dc = np.linalg.norm(centroid - point, axis=1)
    # The face holding the true closest point q has |centroid - p| <= |q - p| + |centroid - q|
    # <= min centroid distance + the largest centroid-to-corner distance; only those can win.
    reach = np.sqrt(np.einsum("eka,eka->ek", tri - centroid[:, None], tri - centroid[:, None]))
    cand = np.flatnonzero(dc <= dc.min() + reach.max() * (1 + 1e-9) + 1e-300)
    q, bary = _closest_on_triangles(point, *(tri[cand, k] for k in range(3)))
    dist = np.linalg.norm(q - point, axis=1)
    k = int(np.argmin(dist))
    return q[k], int(cand[k]), bary[k], centroid, float(reach.max())


def _fast_marching(vertices, faces, face: int, bary: np.ndarray) -> np.ndarray:
    import potpourri3d as pp3d

    solver = pp3d.MeshFastMarchingDistanceSolver(vertices, faces)
    return np.asarray(solver.compute_distance([[(face, [float(x) for x in bary])]]), np.float64)


def _edge_dijkstra(vertices, faces, face: int, point: np.ndarray, limit: float) -> np.ndarray:
    from scipy.sparse.csgraph import dijkstra

    n = len(vertices)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    length = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    # A virtual node n stands for the point inside its face; csgraph drops zero weights, so a
    # point sitting on a node gets a vanishing positive one instead.
    corner = faces[face]
    to_corner = np.maximum(np.linalg.norm(vertices[corner] - point, axis=1), 1e-300)
    rows = np.concatenate([e[:, 0], np.full(3, n)])
    cols = np.concatenate([e[:, 1], corner])
    w = np.concatenate([np.maximum(length, 1e-300), to_corner])
    graph = sp.coo_matrix((w, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    d = dijkstra(graph, directed=False, indices=n, limit=limit)
    return d[:n]


def impact_distance(
    sim, point, max_distance: float | None = None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Geodesic distance over the sim surface from the surface point nearest ``point``.

    Parameters
    ----------
    sim : SimMesh
        Uses ``vertices`` (N, 3) and ``faces`` (M, 3).
    point : (3,) array_like
        Mesh units; snapped to the nearest point of the surface.
    max_distance : float, optional
        Only distances up to this need be right: the computation is restricted to the faces that
        lie within this straight-line reach of the point (a geodesic that short cannot leave
        them), and nodes outside get ``inf``.

    Returns
    -------
    distance : (N,) float64
        Per node, mesh units; ``inf`` where unreachable (other connected pieces, or beyond
        ``max_distance``).
    snapped : (3,) float64
        The surface point the distance is measured from.
    face : int
        Sim face holding ``snapped``.
    """
    vertices = np.asarray(sim.vertices, dtype=np.float64)
    faces = np.asarray(sim.faces, dtype=np.int64)
    p = _finite_vector(point, "impact point")
    snapped, face, bary, centroid, reach = _snap(sim, p)

    if max_distance is not None and np.isfinite(max_distance):
        # A geodesic of length <= max_distance stays inside that ball around the point, and a
        # face meeting the ball has its centroid within max_distance + reach of the point.
        keep = np.linalg.norm(centroid - snapped, axis=1) <= (max_distance + reach) * (1 + 1e-9)
        keep[face] = True
        sub_faces_global = faces[keep]
        nodes, sub_faces = np.unique(sub_faces_global, return_inverse=True)
        sub_faces = sub_faces.reshape(-1, 3)
        sub_face = int(np.count_nonzero(keep[:face]))
        limit = float(max_distance)
    else:
        nodes = np.arange(len(vertices))
        sub_faces, sub_face, limit = faces, face, np.inf
    sub_vertices = vertices[nodes]

    try:
        d_sub = _fast_marching(sub_vertices, sub_faces, sub_face, bary)
    except (ImportError, RuntimeError, ValueError) as exc:
        why = "potpourri3d is not installed" if isinstance(exc, ImportError) else str(exc)
        warnings.warn(
            f"geodesic distance for the impact falls back to edge paths ({why}); distances run "
            "a few percent long. Install potpourri3d / repair non-manifold geometry to avoid it",
            CrackbakeWarning,
            stacklevel=2,
        )
        d_sub = _edge_dijkstra(sub_vertices, sub_faces, sub_face, snapped, limit)

    distance = np.full(len(vertices), np.inf)
    distance[nodes] = d_sub
    distance[~np.isfinite(distance)] = np.inf
    return distance, snapped, face


def _project(stress: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """``P S P`` symmetrised, with ``P = I - n n^T``; (M, 3, 3)."""
    sn = np.matmul(stress, normal[:, :, None])[:, :, 0]
    nsn = np.einsum("ea,ea->e", normal, sn)
    out = (
        stress
        - _outer(sn, normal)
        - _outer(normal, sn)
        + nsn[:, None, None] * _outer(normal, normal)
    )
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-row outer products of (K, 3) arrays, (K, 3, 3)."""
    return a[:, :, None] * b[:, None, :]


def _plane_identity(normal: np.ndarray) -> np.ndarray:
    return np.eye(3)[None] - _outer(normal, normal)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1)
    return v / np.where(n > 0, n, 1.0)[..., None], n


# --------------------------------------------------------------------------------------------
# Per-source fields
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Geometry:
    vertices: np.ndarray  # (N, 3)
    faces: np.ndarray  # (M, 3)
    area: np.ndarray  # (M,)
    normal: np.ndarray  # (M, 3)
    grad: np.ndarray  # (M, 3, 3)
    centroid: np.ndarray  # (M, 3)


def _impact_field(sim, geo: _Geometry, src: ImpactSource, radius: float) -> tuple[np.ndarray, dict]:
    reach = 0.5 * np.pi * radius
    dist, snapped, face = impact_distance(sim, src.point, max_distance=reach)
    moved = float(np.linalg.norm(snapped - np.asarray(src.point, dtype=np.float64)))
    extent = float(np.linalg.norm(geo.vertices.max(axis=0) - geo.vertices.min(axis=0)))
    if moved > 0.01 * extent:
        warnings.warn(
            f"impact point {tuple(float(x) for x in src.point)} lies {moved:.4g} off the surface; "
            f"snapped to {tuple(round(float(x), 6) for x in snapped)}",
            CrackbakeWarning,
            stacklevel=3,
        )
    nodal = dist[geo.faces]  # (M, 3)
    d_face = nodal.mean(axis=1)  # inf when any corner is out of reach
    # Inside the source face the surface is flat, so the straight distance is the geodesic one.
    d_face[face] = np.linalg.norm(geo.centroid[face] - snapped)
    active = np.flatnonzero(d_face <= reach)
    stress = np.zeros((len(geo.faces), 3, 3))
    w = src.strength * 2.0 * np.cos(d_face[active] / radius)
    n = geo.normal[active]
    # Radial direction: the surface gradient of the distance.  First-order fast marching biases
    # that gradient towards mesh edges (up to ~20 degrees on irregular meshes), so where it
    # agrees with the straight direction from the impact (projected into the face: exact on flat
    # parts, close on gently curved ones) the straight one is used; past a fold or round a
    # bend they part ways and the gradient alone is right.  Blend over 25..40 degrees apart.
    g = np.einsum("ei,eia->ea", nodal[active], geo.grad[active])
    g = _face_vertex_smooth(geo.faces[active], geo.area[active], g)  # steadies per-face noise
    g, g_len = _unit(g - np.einsum("ea,ea->e", g, n)[:, None] * n)
    chord = geo.centroid[active] - snapped
    chord = _unit(chord - np.einsum("ea,ea->e", chord, n)[:, None] * n)[0]
    agree = np.einsum("ea,ea->e", g, chord)
    cos25, cos40 = np.cos(np.radians(25.0)), np.cos(np.radians(40.0))
    t = np.clip((cos25 - agree) / (cos25 - cos40), 0.0, 1.0)
    t = np.where(g_len > 0.5, t, 0.0)  # gradient lost (source face, cone tip): straight only
    r = (1 - t)[:, None] * chord + t[:, None] * g
    # The impact sits on the centroid itself: any in-plane direction is as good.
    lost = np.linalg.norm(r, axis=1) < 1e-9
    if lost.any():
        faces_lost = geo.faces[active[lost]]
        r[lost] = geo.vertices[faces_lost[:, 1]] - geo.vertices[faces_lost[:, 0]]
    r -= np.einsum("ea,ea->e", r, n)[:, None] * n
    r = _unit(r)[0]
    c = np.cross(n, r)
    stress[active] = w[:, None, None] * (_outer(r, r) + src.hoop * _outer(c, c))
    info = {
        "point": [float(x) for x in snapped],
        "radius": float(radius),
        "strength": float(src.strength),
    }
    return stress, info


def _directional_field(geo: _Geometry, src: DirectionalSource) -> np.ndarray:
    d = _unit(_finite_vector(src.direction, "tension direction"))[0]
    pd = d[None] - (geo.normal @ d)[:, None] * geo.normal
    return src.strength * _outer(pd, pd)


def _vertex_normals(geo: _Geometry) -> np.ndarray:
    weighted = geo.normal * geo.area[:, None]
    acc = np.zeros((len(geo.vertices), 3))
    idx = geo.faces.reshape(-1)
    for a in range(3):
        acc[:, a] = np.bincount(idx, np.repeat(weighted[:, a], 3), minlength=len(acc))
    return _unit(acc)[0]


def _face_vertex_smooth(faces: np.ndarray, area: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Area-weighted face -> node -> face average of per-face values (K, ...) over (K, 3) faces."""
    k = len(faces)
    flat = values.reshape(k, -1)
    nodes, local = np.unique(faces, return_inverse=True)
    local = local.reshape(-1)
    inc = sp.csr_matrix(
        (np.repeat(area, 3), (local, np.repeat(np.arange(k), 3))), shape=(len(nodes), k)
    )
    node_area = np.asarray(inc.sum(axis=1)).reshape(-1)
    node = (inc @ flat) / np.where(node_area > 0, node_area, 1.0)[:, None]
    return node[local.reshape(k, 3)].mean(axis=1).reshape(values.shape)


def _node_normals(sim, mesh: Mesh, geo: _Geometry) -> np.ndarray:
    """Unit normals at the sim nodes, (N, 3).

    The asset's own (shading) normals interpolated at each node where the sim mesh says where
    its nodes lie: a low-poly asset is flat inside each face, but its shading normals describe
    the smooth surface it stands for.  Geometric area-weighted normals otherwise.
    """
    geometric = _vertex_normals(geo)
    node_face = getattr(sim, "node_face", None)
    node_bary = getattr(sim, "node_bary", None)
    normals = getattr(mesh, "normals", None)
    if node_face is None or node_bary is None or normals is None:
        return geometric
    node_face = np.asarray(node_face, dtype=np.int64)
    if node_face.shape != (len(geo.vertices),) or len(normals) != len(mesh.vertices):
        return geometric
    vn = np.einsum("nk,nka->na", np.asarray(node_bary), normals[mesh.faces[node_face]])
    vn, length = _unit(vn)
    return np.where((length > 1e-6)[:, None], vn, geometric)


def _curvature_field(sim, mesh: Mesh, geo: _Geometry, src: CurvatureSource) -> np.ndarray:
    m = len(geo.faces)
    vn = _node_normals(sim, mesh, geo)
    # Shape operator of each face: the gradient of the linearly interpolated node normals,
    # restricted to the face plane and symmetrised (its sign does not matter here).
    shape = np.matmul(np.swapaxes(vn[geo.faces], 1, 2), geo.grad)
    shape = _project(shape, geo.normal)
    # One smoothing pass: per-face normal differences on an irregular mesh are noisy.
    shape = _project(_face_vertex_smooth(geo.faces, geo.area, shape), geo.normal)
    frames = face_frames(geo.normal, geo.vertices, geo.faces)  # (M, 3, 2)
    k = np.matmul(np.swapaxes(frames, 1, 2), np.matmul(shape, frames))
    a, b, c = k[:, 0, 0], k[:, 0, 1], k[:, 1, 1]
    mean = 0.5 * (a + c)
    half_gap = np.hypot(0.5 * (a - c), b)
    magnitude = np.sqrt(2.0 * (mean**2 + half_gap**2))  # sqrt(k1^2 + k2^2)
    # Reference curvature: the area-weighted median over the curved faces.  A mean would be
    # dragged up by sharp creases (whose smoothed curvature is ~angle / edge length) and down by
    # flat parts, leaving the smooth curved surface far from O(1).
    extent = float(np.linalg.norm(geo.vertices.max(axis=0) - geo.vertices.min(axis=0)))
    curved = np.flatnonzero(magnitude * extent > 1e-6)
    ref = 0.0
    if len(curved):
        order = curved[np.argsort(magnitude[curved])]
        cum = np.cumsum(geo.area[order])
        ref = float(magnitude[order[min(np.searchsorted(cum, 0.5 * cum[-1]), len(order) - 1)]])
    if not ref * extent > 1e-6:
        warnings.warn(
            "the mesh is flat, so the curvature source adds no stress; drop it or use "
            "another source",
            CrackbakeWarning,
            stacklevel=3,
        )
        return np.zeros((m, 3, 3))
    stress = np.zeros((m, 3, 3))
    if src.bias:
        # Eigenvalues mean +- half_gap; the larger |k| is mean + half_gap when mean >= 0, with
        # eigenvector at angle theta, else the other one (perpendicular).
        theta = 0.5 * np.arctan2(2.0 * b, a - c)
        cos, sin = np.cos(theta), np.sin(theta)
        local = np.where((mean >= 0)[:, None], np.stack([cos, sin], 1), np.stack([-sin, cos], 1))
        t = np.matmul(frames, local[:, :, None])[:, :, 0]
        anisotropy = 2.0 * np.minimum(np.abs(mean), half_gap)  # |k_max| - |k_min|
        amp = src.bias * np.minimum(anisotropy / ref, CURVATURE_CLIP)
        stress += amp[:, None, None] * _outer(t, t)
    if src.density:
        amp = src.density * np.minimum(magnitude / ref, CURVATURE_CLIP)
        stress += amp[:, None, None] * _plane_identity(geo.normal)
    return stress


def _asset_barycentrics(sim, mesh: Mesh, geo: _Geometry) -> tuple[np.ndarray, np.ndarray]:
    """Asset face (M,) and barycentrics (M, 3) of every sim face centroid."""
    af = np.asarray(sim.asset_face, dtype=np.int64)
    if af.shape != (len(geo.faces),) or af.min() < 0 or af.max() >= len(mesh.faces):
        raise CrackbakeError(
            "simulation mesh does not match the asset mesh (asset_face out of range); "
            "rebuild it from this mesh"
        )
    from crackbake.simulate.simmesh import asset_barycentric

    bary = np.clip(asset_barycentric(mesh, af, geo.centroid), 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    return af, bary


def _sample_image(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear, repeat-wrapped lookup of an (H, W) image at (K, 2) UVs; row 0 is v = 1."""
    h, w = image.shape
    x = np.mod(uv[:, 0], 1.0) * w - 0.5
    y = (1.0 - np.mod(uv[:, 1], 1.0)) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa, xb = np.mod(x0, w), np.mod(x0 + 1, w)
    ya, yb = np.mod(y0, h), np.mod(y0 + 1, h)
    top = image[ya, xa] * (1 - fx) + image[ya, xb] * fx
    bottom = image[yb, xa] * (1 - fx) + image[yb, xb] * fx
    return top * (1 - fy) + bottom * fy


def _weight_field(
    sim, mesh: Mesh, geo: _Geometry, src: WeightSource, bary_cache: list
) -> np.ndarray:
    if not bary_cache:
        bary_cache.append(_asset_barycentrics(sim, mesh, geo))
    af, bary = bary_cache[0]
    corners = mesh.faces[af]
    weight = np.ones(len(geo.faces))
    if src.per_vertex is not None:
        pv = np.asarray(src.per_vertex, dtype=np.float64)
        if len(pv) != len(mesh.vertices):
            raise CrackbakeError(
                f"{len(pv)} per-vertex weights for a mesh of {len(mesh.vertices)} vertices; "
                "read them from the same mesh file"
            )
        pv = 1.0 - pv if src.invert else pv
        weight *= np.einsum("ek,ek->e", pv[corners], bary)
    if src.image is not None:
        if mesh.uv is None:
            raise CrackbakeError(
                f"{Path(mesh.source).name or 'the mesh'} has no UVs to sample the weight map "
                "through; give the mesh UVs or paint vertex weights instead"
            )
        uv = np.einsum("eka,ek->ea", mesh.uv[corners], bary)
        im = np.asarray(src.image, dtype=np.float64)
        im = 1.0 - im if src.invert else im
        weight *= _sample_image(im, uv)
    if (weight < 0).any():
        warnings.warn(
            "negative painted weights clipped to 0 (a weight of 1 is full strength)",
            CrackbakeWarning,
            stacklevel=3,
        )
        weight = np.maximum(weight, 0.0)
    return weight


def _smooth_noise(points: np.ndarray, scale: float, rng: np.random.Generator, count: int):
    """``count`` smooth unit-variance random fields at (M, 3) points, (count, M).

    Each is a sum of :data:`NOISE_WAVES` plane waves of random direction, phase and wavelength
    near ``scale`` (solid noise, so it is seamless across UV seams and thin walls alike).
    """
    k = rng.normal(size=(3, count * NOISE_WAVES))
    k /= np.linalg.norm(k, axis=0, keepdims=True)
    k *= (2 * np.pi / scale) * rng.uniform(0.7, 1.4, size=count * NOISE_WAVES)
    phase = rng.uniform(0, 2 * np.pi, size=count * NOISE_WAVES)
    # Phases in float64 (large coordinates), cosines in float32: it is only noise.
    arg = ((points - points.mean(axis=0)) @ k + phase).astype(np.float32)
    np.cos(arg, out=arg)
    out = arg.reshape(len(points), count, NOISE_WAVES).sum(axis=2, dtype=np.float64).T
    return out * np.sqrt(2.0 / NOISE_WAVES)


def _apply_noise(
    stress: np.ndarray, geo: _Geometry, src: NoiseSource, scale: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy stress and the multiplier used (so growth can follow it)."""
    fields = _smooth_noise(geo.centroid, scale, rng, 4)
    factor = np.maximum(1.0 + src.amount * fields[0], 0.0)
    size = np.sqrt(np.einsum("eab,eab->e", stress, stress))
    if not size.any():
        size = np.ones_like(size)  # nothing else to perturb: noise alone is a weak field
    t = fields[1:].T
    t -= np.einsum("ea,ea->e", t, geo.normal)[:, None] * geo.normal
    # E|P t|^2 = 2 for unit-variance components, hence the half.
    extra = (0.5 * src.amount * size)[:, None, None] * _outer(t, t)
    return factor[:, None, None] * stress + extra, factor


# --------------------------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------------------------


def stress_field(sim, mesh: Mesh, sources: Sequence, seed: int = 0) -> StressField:
    """Sum the stress sources into the initial field on the simulation mesh.

    Parameters
    ----------
    sim : SimMesh
        Uses ``vertices`` (N, 3), ``faces`` (M, 3), ``asset_face`` (M,) and ``edge_length``.
    mesh : Mesh
        The asset mesh ``sim`` was built from (bounding box for default radii, per-vertex
        weights and UVs for weight maps).
    sources : sequence of ImpactSource, ShrinkSource, DirectionalSource, CurvatureSource,
        WeightSource, NoiseSource
        Any number of each; additive ones are summed, weights multiply the sum, noise perturbs
        the result.  An empty sequence gives a zero field.
    seed : int
        Seeds the noise; the field is otherwise deterministic.

    Returns
    -------
    StressField
    """
    vertices = np.asarray(sim.vertices, dtype=np.float64)
    faces = np.asarray(sim.faces, dtype=np.int64)
    area, normal, grad = face_geometry(vertices, faces)
    geo = _Geometry(vertices, faces, area, normal, grad, vertices[faces].mean(axis=1))
    m = len(faces)

    stress = np.zeros((m, 3, 3))
    growth = np.zeros((m, 3, 3))
    weight = np.ones(m)
    impacts: list[dict] = []
    noises: list[NoiseSource] = []
    bary_cache: list = []
    for src in sources:
        if isinstance(src, ImpactSource):
            radius = 0.15 * mesh.diagonal if src.radius is None else float(src.radius)
            s, info = _impact_field(sim, geo, src, radius)
            stress += s
            impacts.append(info)
        elif isinstance(src, ShrinkSource):
            plane = _plane_identity(normal)
            stress += src.strength * plane
            growth += src.rate * src.strength * plane
        elif isinstance(src, DirectionalSource):
            stress += _directional_field(geo, src)
        elif isinstance(src, CurvatureSource):
            stress += _curvature_field(sim, mesh, geo, src)
        elif isinstance(src, WeightSource):
            weight *= _weight_field(sim, mesh, geo, src, bary_cache)
        elif isinstance(src, NoiseSource):
            noises.append(src)
        else:
            raise TypeError(f"not a stress source: {type(src).__name__}")

    stress *= weight[:, None, None]
    growth *= weight[:, None, None]
    for i, src in enumerate(noises):
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), i]))
        scale = src.scale if src.scale is not None else NOISE_SCALE_DIAGONAL * mesh.diagonal
        stress, factor = _apply_noise(stress, geo, src, scale, rng)
        growth *= factor[:, None, None]

    # Exactly in-plane and symmetric whatever rounding did; degenerate faces carry nothing.
    flat = area <= 0
    stress = _project(stress, normal)
    if growth.any():
        growth = _project(growth, normal)
    stress[flat] = 0.0
    growth[flat] = 0.0
    return StressField(stress=stress, growth=growth, weight=weight, impacts=impacts)


def load_weight_map(path) -> np.ndarray:
    """Read an image as a grayscale weight map.

    Colour images become Rec. 709 luminance of the stored values (no colour-space conversion, so
    mid-grey 128 is about 0.5); alpha is ignored (flatten the image onto a background first).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (H, W) float64 in [0, 1], row 0 at the top of the image (``v = 1``).

    Raises
    ------
    CrackbakeError
        Missing or unreadable file.
    """
    path = Path(path)
    if not path.is_file():
        raise CrackbakeError(f"{path}: weight map not found; check the path")
    try:
        pixels = _read_oiio(path)
    except ImportError:
        pixels = _read_pillow(path)
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    channels = pixels.shape[2]
    if channels >= 3:
        gray = pixels[:, :, :3] @ LUMA
    else:
        gray = pixels[:, :, 0]  # gray or gray + alpha
    if not np.isfinite(gray).all():
        raise CrackbakeError(f"{path}: weight map holds NaN or infinite pixels; fix the image")
    if gray.min() < 0 or gray.max() > 1:
        warnings.warn(
            f"{path.name}: weight map values outside [0, 1] clipped",
            CrackbakeWarning,
            stacklevel=2,
        )
        gray = np.clip(gray, 0.0, 1.0)
    return gray


def _read_oiio(path: Path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise CrackbakeError(
            f"{path}: could not read the weight map ({oiio.geterror() or 'unknown format'}); "
            "use a PNG, JPEG, TIFF or EXR image"
        )
    try:
        spec = inp.spec()
        data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    if data is None:
        raise CrackbakeError(f"{path}: could not decode the weight map; re-save the image")
    return np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)


def _read_pillow(path: Path) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("L"), dtype=np.float64) / 255.0
    except (OSError, UnidentifiedImageError) as exc:
        raise CrackbakeError(
            f"{path}: could not read the weight map ({exc}); use a PNG, JPEG or TIFF image"
        ) from exc


def _attribute_names(geom) -> list[str]:
    names = set(getattr(geom, "vertex_attributes", {}) or {})
    raw = (geom.metadata or {}).get("_ply_raw", {}).get("vertex", {}).get("data", {})
    if isinstance(raw, dict):
        names |= set(raw) - {"x", "y", "z", "nx", "ny", "nz"}
    if getattr(geom.visual, "kind", None) == "vertex":
        names.add("(vertex colours)")
    return sorted(names)


def _attribute_values(geom, name: str) -> np.ndarray | None:
    attrs = getattr(geom, "vertex_attributes", {}) or {}
    raw = (geom.metadata or {}).get("_ply_raw", {}).get("vertex", {}).get("data", {})
    # glTF requires custom attributes to start with '_'; accept the name with or without it.
    for key in (name, "_" + name, name.lstrip("_")):
        if key in attrs:
            return np.asarray(attrs[key])
        if isinstance(raw, dict) and key in raw:
            return np.asarray(raw[key])
    return None


def _to_scalar(values: np.ndarray, n: int, what: str, path: Path) -> np.ndarray:
    values = np.asarray(values)
    integer = np.issubdtype(values.dtype, np.integer)
    values = values.astype(np.float64).reshape(n, -1) if values.size % max(n, 1) == 0 else None
    if values is None:
        raise CrackbakeError(f"{path}: {what} does not hold one value per vertex; re-export it")
    if values.shape[1] >= 3:
        # Colour-like attribute: luminance; 8-bit colours scale to [0, 1].
        values = values[:, :3] @ LUMA
        return values / 255.0 if integer else values
    return values[:, 0]


def vertex_weights(
    mesh_path, attribute: str | None = None, object_name: str | None = None
) -> np.ndarray | None:
    """Per-asset-vertex weights painted in a mesh file.

    Parameters
    ----------
    mesh_path : str or Path
        The asset file (PLY or glTF/GLB; any trimesh-readable format with vertex colours works).
    attribute : str, optional
        Named vertex attribute (a PLY vertex property, or a glTF ``_NAME`` attribute; the
        leading underscore may be left out).  ``None`` reads the vertex colours' luminance.
    object_name : str, optional
        The same ``--object`` pick given to :func:`crackbake.io.mesh.load_mesh`, so the values line
        up with its vertices.

    Returns
    -------
    (V,) float64 or None
        One weight per vertex of ``load_mesh(mesh_path, object_name)``, used as is (1 = full
        strength; colours map to [0, 1]).  ``None`` only when ``attribute`` is ``None`` and the
        file has no vertex colours.

    Raises
    ------
    CrackbakeError
        Unreadable file, or no attribute of that name (the message lists those available).
    """
    import trimesh

    from crackbake.io.mesh import _scene_geometries

    path = Path(mesh_path)
    if not path.is_file():
        raise CrackbakeError(f"{path}: file not found; check the path")
    try:
        loaded = trimesh.load(str(path), file_type=path.suffix.lower()[1:], process=False)
    except Exception as exc:  # trimesh raises many types for corrupt input
        raise CrackbakeError(f"{path}: could not read vertex weights ({exc})") from exc
    if isinstance(loaded, trimesh.Scene):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CrackbakeWarning)  # load_mesh already warned
            geoms = _scene_geometries(loaded, object_name, path)
    else:
        geoms = [loaded]
    geoms = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces) > 0]
    if not geoms:
        raise CrackbakeError(f"{path}: no triangle mesh to read vertex weights from")

    parts = []
    for g in geoms:
        n = len(g.vertices)
        if attribute is None:
            if getattr(g.visual, "kind", None) != "vertex":
                if len(geoms) == 1:
                    return None
                raise CrackbakeError(
                    f"{path}: some objects have no vertex colours; paint all of them or pick "
                    "one with --object"
                )
            colours = np.asarray(g.visual.vertex_colors)
            parts.append(_to_scalar(colours, n, "vertex colours", path))
            continue
        values = _attribute_values(g, attribute)
        if values is None:
            names = ", ".join(_attribute_names(g)) or "none"
            raise CrackbakeError(f"{path}: no vertex attribute '{attribute}'; available: {names}")
        parts.append(_to_scalar(values, n, f"attribute '{attribute}'", path))
    weights = np.concatenate(parts)
    if not np.isfinite(weights).all():
        raise CrackbakeError(f"{path}: vertex weights hold NaN or infinite values; fix them")
    return weights
