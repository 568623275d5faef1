"""Initial stress fields on the simulation mesh (docs/method.md, "The formulas").

Every source adds (or multiplies) a symmetric 3x3 **world-space** tensor per sim face lying in the
face plane (``S @ n == 0``), tension positive: the convention of
:mod:`crackbake.simulate.solver.fem`.
Additive sources (impact, shrinkage, directional, curvature) are summed; painted weights then
multiply the sum, and noise perturbs what is left, so a zero weight always means zero stress.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.geometry import (
    corner_mean,
    shared_centroids,
    shared_shells,
    unit_rows,
    vertex_normals,
)
from crackbake.io.mesh import Mesh
from crackbake.simulate.solver.fem import face_frames, face_geometry
from crackbake.simulate.stress.geodesic import (
    _snap,
    impact_distance,
    iso_length,
)
from crackbake.simulate.stress.sources import (
    CurvatureSource,
    DirectionalSource,
    ImpactSource,
    NoiseSource,
    ShrinkSource,
    WeightSource,
    _finite_vector,
)
from crackbake.simulate.stress.weights import weight_field

CURVATURE_CLIP = 5.0
# Default noise feature size, fraction of the bounding-box diagonal: in world units, so the
# pattern does not change with the simulation resolution.
NOISE_SCALE_DIAGONAL = 0.02
# Sinusoids summed per noise field (more is smoother-looking but slower).
NOISE_WAVES = 8
#: Shadow radius of an impact's cracks (``StressField.shadow_radius``), a fraction of its reach
#: ``pi r / 2``.  The solver's own radius, 0.1 of the bounding-box diagonal, is 0.42 of the
#: default glass reach on a plate and wider still relative to a small impact, so each radial crack
#: released the hoop stress of a wide wedge and a star kept 4-7 arms; at 0.12 plates get 16-18
#: (0.2: 10-13, 0.09: 18-21 with weaker links on spot's leg; benchmarks/bench_glass.py).
IMPACT_SHADOW_REACH = 0.12
#: The shadow radius is also at most the length of the geodesic circle at 0.3 reach (the circle
#: the arms are counted on) over this: on a flat mesh that circle is ``0.6 pi`` reach, so 15
#: leaves :data:`IMPACT_SHADOW_REACH` in charge (0.126 reach), while round a thin feature (spot's
#: horn: 0.4 of the flat length) the spacing shrinks with the circumference and as many arms fit.
IMPACT_SHADOW_ARMS = 15.0
#: An impact given a speed asks for ``N`` radial arms (:func:`speed_shadow`); its shadow radius
#: is ``SPEED_SHADOW_SCALE * circle * N ** -SPEED_SHADOW_POWER`` with ``circle`` the geodesic
#: circle at 0.3 reach.  A shadow of ``circle / N`` alone gave too many arms to slow impacts
#: and too few to fast ones (the arms crossing 0.3 reach grew as about N ** 0.7: branches and
#: arms started off the impact fill a wide wedge), so the power undoes that response
#: (calibrated on plates over speeds and seeds: benchmarks/bench_speed_law.py).
SPEED_SHADOW_SCALE = 3.16
SPEED_SHADOW_POWER = 1.414
#: The largest shadow radius of a run with a speed impact, a fraction of the bounding-box
#: diagonal (the solver's own cap is 0.1: at the default radius that allows no fewer than
#: about 5 arms; 0.3 allows about 2).
SPEED_SHADOW_MAX = 0.3
#: ... and at least this many sim edge lengths (a finer shadow than the mesh resolves only
#: splits one crack's release into grid noise).
IMPACT_SHADOW_EDGES = 2.0
#: Below this many sim edge lengths per shadow radius (spot's horn at the default 100k faces:
#: 2.7, 9 arms) a run whose sim size the user left to the default is rebuilt finer
#: (:func:`impact_detail`; the horn at 4: 13 arms).  Broad impacts sit at 5.5-8.
IMPACT_SHADOW_MIN_EDGES = 4.0
#: ... by at most this factor in edge length (2: up to 4x the sim faces).
IMPACT_REFINE_MAX = 2.0
#: ... inside the ball of this many reaches round the impact only (straight distance): the
#: star and the cracks a little past its reach; the rest of the surface, another impact's star
#: included, keeps the sim mesh it had (:func:`impact_refinement`).
IMPACT_REFINE_REACH = 1.5


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
    shadow_radius : float or None
        Radius of a crack's world-scale stress shadow the solver should use, mesh units, when
        there are impacts (a star scales with its impact): the smallest over the impacts of
        :data:`IMPACT_SHADOW_REACH` x the reach, or the length of the geodesic circle at 0.3
        reach / :data:`IMPACT_SHADOW_ARMS` where that is less (a thin feature), but at least
        :data:`IMPACT_SHADOW_EDGES` sim edge lengths.  ``None`` (the solver's own, from the
        mesh size) without impacts.
    impact_shadows : list of float
        The shadow radius each impact asks for (same rules), mesh units, in impact order: with
        several impacts the solver gives each crack the radius of the impact nearest to it (in
        reaches), so a thin feature's narrow shadow does not spread to a broad impact's star.
    impact_share : (K, M) float32 or None
        With K >= 2 impacts, the share of each face's stress that impact k contributes (its
        raw tensor norm over the sum of all additive contributions' norms): the solver loads
        the impacts one after the other in this order (a later star's cracks stop at an
        earlier star's, as in real glass).  None with fewer than two impacts.
    shadow_max : float or None
        The largest shadow radius the solver may use, mesh units; None: its own
        (``SHADOW_REL`` x the bounding-box diagonal).  Set to :data:`SPEED_SHADOW_MAX` x the
        diagonal when an impact has a speed: a slow one's few arms need wider wedges.
    """

    stress: np.ndarray
    growth: np.ndarray
    weight: np.ndarray
    impacts: list[dict] = field(default_factory=list)
    shadow_radius: float | None = None
    impact_shadows: list[float] = field(default_factory=list)
    impact_share: np.ndarray | None = None
    shadow_max: float | None = None



def _project(stress: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """``P S P`` symmetrised, with ``P = I - n n^T``; (M, 3, 3)."""
    sn = np.matmul(stress, normal[:, :, None])[:, :, 0]
    nsn = np.einsum("ea,ea->e", normal, sn)
    # S - s n^T - n s^T + (n.s) n n^T, in that order, in place (no (M, 3, 3) temporaries).
    out = stress - _outer(sn, normal)
    out -= _outer(normal, sn)
    nn = _outer(normal, normal)
    nn *= nsn[:, None, None]
    out += nn
    sym = out + np.swapaxes(out, 1, 2)
    sym *= 0.5
    return sym


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-row outer products of (K, 3) arrays, (K, 3, 3)."""
    return a[:, :, None] * b[:, None, :]


def _plane_identity(normal: np.ndarray) -> np.ndarray:
    return np.eye(3)[None] - _outer(normal, normal)



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


# An impact point farther than this many bounding-box diagonals from the surface is a typo (or a
# point in other units), not an intent: snapping it would pick an arbitrary spot.  Nearer, it is
# snapped to the surface with a warning.
IMPACT_MAX_DIAGONALS = 1.0


def _refuse_far_impact(p: np.ndarray, distance: float, nearest: np.ndarray, diag: float) -> None:
    """The one-line error for an impact ``distance`` off the surface (``CrackbakeError``)."""
    shown = ", ".join(f"{float(x):g}" for x in p)
    near = ", ".join(f"{float(x):.6g}" for x in nearest)
    raise CrackbakeError(
        f"impact point ({shown}) is {distance / diag:.3g} mesh diagonals from the surface (a typo "
        f"or other units?); the nearest surface point is ({near}): give a point on or within "
        f"{IMPACT_MAX_DIAGONALS:g} mesh diagonal of the surface"
    )


def _check_impact_near(point, geo: _Geometry, sim=None) -> None:
    """Refuse an impact point whose bounding-box gap alone puts it more than
    :data:`IMPACT_MAX_DIAGONALS` off the mesh (``CrackbakeError``); the exact surface distance is
    checked once the point is snapped (:func:`_impact_field`)."""
    p = _finite_vector(point, "impact point")
    lo, hi = geo.vertices.min(axis=0), geo.vertices.max(axis=0)
    # Per-axis gap to the box, so 1e308 coordinates do not overflow a norm.
    gap = float(np.max(np.maximum(np.maximum(lo - p, p - hi), 0.0)))
    diag = float(np.linalg.norm(hi - lo))
    if gap > IMPACT_MAX_DIAGONALS * diag:
        # The nearest surface point of a point that far is (near enough) that of its projection
        # a little outside the box, and this keeps the distances finite.
        q = np.clip(p, lo - diag, hi + diag)
        nearest = _snap(sim, q)[0] if sim is not None else np.clip(p, lo, hi)
        _refuse_far_impact(p, gap, nearest, diag)


def _impact_radius(radius: float, sim) -> float:
    """The radius raised to the sim edge length (smaller would stress no face at all)."""
    h = float(getattr(sim, "edge_length", 0.0) or 0.0)
    if radius < h:
        warnings.warn(
            f"impact radius {radius:g} is below the simulation edge length {h:.4g}; using "
            f"{h:.4g} (raise --detail/--sim-faces for finer impacts)",
            CrackbakeWarning,
            stacklevel=3,
        )
        return h
    return radius


def impact_detail(field: StressField, edge_length: float) -> float | None:
    """The finer sim edge length an impact's star needs, or None when ``edge_length`` will do.

    The shadow radius (:class:`StressField`) is what spaces a star's arms; round a thin feature
    it shrinks with the feature's circumference and may span too few sim edges to resolve them.
    Then the edge length that gives :data:`IMPACT_SHADOW_MIN_EDGES` per shadow radius, at most
    :data:`IMPACT_REFINE_MAX` times finer, mesh units.
    """
    if field.shadow_radius is None or not field.impacts or edge_length <= 0.0:
        return None
    want = field.shadow_radius / IMPACT_SHADOW_MIN_EDGES
    if want >= edge_length * (1.0 - 1e-9):
        return None
    return max(want, edge_length / IMPACT_REFINE_MAX)


def impact_refinement(field: StressField, sim):
    """Where the sim mesh should be finer for the impacts' stars, or None where it will do.

    Per impact, as :func:`impact_detail` with the edge length the sim mesh has at the impact
    (``sim.edge_at``) and that impact's own shadow radius (``StressField.impact_shadows``),
    inside a ball of :data:`IMPACT_REFINE_REACH` reaches round it.

    Returns
    -------
    crackbake.simulate.simmesh.Local or None
    """
    from crackbake.simulate.simmesh import Local

    shadows = list(field.impact_shadows or [])
    if len(shadows) != len(field.impacts):
        return None
    rows = []
    for info, shadow in zip(field.impacts, shadows, strict=True):
        edge = _edge_at(sim, info["point"])
        want = shadow / IMPACT_SHADOW_MIN_EDGES
        if edge <= 0.0 or want >= edge * (1.0 - 1e-9):
            continue
        reach = 0.5 * np.pi * float(info["radius"])
        rows.append((info["point"], IMPACT_REFINE_REACH * reach,
                     max(want, edge / IMPACT_REFINE_MAX)))
    if not rows:
        return None
    old = getattr(sim, "local", None)
    centres = np.asarray([r[0] for r in rows], np.float64).reshape(-1, 3)
    radii = np.asarray([r[1] for r in rows], np.float64)
    edges = np.asarray([r[2] for r in rows], np.float64)
    if old is not None:  # a ball refined before stays refined
        centres = np.concatenate([old.centres, centres])
        radii = np.concatenate([old.radii, radii])
        edges = np.concatenate([old.edges, edges])
    return Local(centres=centres, radii=radii, edges=edges)


def _edge_at(sim, point) -> float:
    """The sim mesh's target edge length at ``point`` (its local refinement, if any)."""
    at = getattr(sim, "edge_at", None)
    if at is not None:
        return float(at(point))
    return float(getattr(sim, "edge_length", 0.0) or 0.0)


def speed_shadow(circle: float, arms: float, edge: float) -> float:
    """The shadow radius that grows ``arms`` radial arms (a mean over seeds) across a circle of
    length ``circle`` (the geodesic circle at 0.3 reach, mesh units):
    ``SPEED_SHADOW_SCALE circle arms ** -SPEED_SHADOW_POWER``, and at least
    :data:`IMPACT_SHADOW_EDGES` sim edges ``edge`` (the mesh resolves no finer)."""
    return max(SPEED_SHADOW_SCALE * circle * float(arms) ** -SPEED_SHADOW_POWER,
               IMPACT_SHADOW_EDGES * edge)


def _impact_shadow(geo: _Geometry, dist: np.ndarray, radius: float, edge: float,
                   arms: float | None = None) -> float:
    """The shadow radius an impact of ``radius`` asks for (``StressField.shadow_radius``), mesh
    units; ``dist`` (N,) its geodesic distance, ``edge`` the sim edge length; ``arms`` the
    radial arm count a speed impact asks for (:func:`speed_shadow`), None for the preset's."""
    flat = IMPACT_SHADOW_REACH * 0.5 * np.pi * radius
    circle = iso_length(geo.vertices, geo.faces, dist, 0.3 * 0.5 * np.pi * radius)
    if arms is not None:
        return speed_shadow(circle if circle > 0.0 else 0.6 * np.pi * 0.5 * np.pi * radius,
                            arms, edge)
    # No circle at all: the source face's own neighbourhood holds it, and the flat value stands.
    if circle <= 0.0:
        return flat
    return max(min(flat, circle / IMPACT_SHADOW_ARMS), min(IMPACT_SHADOW_EDGES * edge, flat))


def _impact_field(
    sim, geo: _Geometry, src: ImpactSource, radius: float
) -> tuple[np.ndarray, dict, float]:
    _check_impact_near(src.point, geo, sim)
    radius = _impact_radius(radius, sim)
    reach = 0.5 * np.pi * radius
    dist, snapped, face = impact_distance(sim, src.point, max_distance=reach)
    moved = float(np.linalg.norm(snapped - np.asarray(src.point, dtype=np.float64)))
    extent = float(np.linalg.norm(geo.vertices.max(axis=0) - geo.vertices.min(axis=0)))
    if moved > IMPACT_MAX_DIAGONALS * extent:
        _refuse_far_impact(np.asarray(src.point, np.float64), moved, snapped, extent)
    if moved > 0.01 * extent:
        warnings.warn(
            f"impact point {tuple(float(x) for x in src.point)} lies {moved:.4g} off the surface; "
            f"snapped to {tuple(round(float(x), 6) for x in snapped)}",
            CrackbakeWarning,
            stacklevel=3,
        )
    edge = _edge_at(sim, snapped)
    # An ImpactSource without a radius has the default one: fitted too.
    fitted, wraps = _fit_radius(geo, dist, face, snapped, radius,
                                True if src.radius is None else src.fit, edge)
    if fitted != radius:
        radius, reach = fitted, 0.5 * np.pi * fitted
        dist, snapped, face = impact_distance(sim, src.point, max_distance=reach)
    nodal = dist[geo.faces]  # (M, 3)
    # A small separate piece wraps too: its own warning says more.
    small = _warn_small_piece(geo, nodal, snapped, radius, edge)
    if not small:
        small = _warn_off_piece(geo, dist, face, snapped, radius, edge)
    if not small and wraps:
        warnings.warn(wraps, CrackbakeWarning, stacklevel=3)
    d_face = nodal.mean(axis=1)  # inf when any corner is out of reach
    # Inside the source face the surface is flat, so the straight distance is the geodesic one.
    d_face[face] = np.linalg.norm(geo.centroid[face] - snapped)
    # The source face always takes part: a radius about its size must still stress it.
    active = np.union1d(np.flatnonzero(d_face <= reach), [face])
    stress = np.zeros((len(geo.faces), 3, 3))
    w = src.strength * 2.0 * np.cos(np.minimum(d_face[active], reach) / radius)
    n = geo.normal[active]
    # Radial direction: the surface gradient of the distance.  First-order fast marching biases
    # that gradient towards mesh edges (up to ~20 degrees on irregular meshes), so where it
    # agrees with the straight direction from the impact (projected into the face: exact on flat
    # parts, close on gently curved ones) the straight one is used; past a fold or round a
    # bend they part ways and the gradient alone is right.  Blend over 25..40 degrees apart.
    g = np.einsum("ei,eia->ea", nodal[active], geo.grad[active])
    g = _face_vertex_smooth(geo.faces[active], geo.area[active], g)  # steadies per-face noise
    g, g_len = unit_rows(g - np.einsum("ea,ea->e", g, n)[:, None] * n)
    chord = geo.centroid[active] - snapped
    chord = unit_rows(chord - np.einsum("ea,ea->e", chord, n)[:, None] * n)[0]
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
    r = unit_rows(r)[0]
    c = np.cross(n, r)
    stress[active] = w[:, None, None] * (_outer(r, r) + src.hoop * _outer(c, c))
    info = {
        "point": [float(x) for x in snapped],
        "radius": float(radius),
        "strength": float(src.strength),
    }
    if src.arms is not None:
        info["arms"] = float(src.arms)
    shadow = _impact_shadow(geo, dist, radius, edge, src.arms)
    if src.arms is not None and shadow <= IMPACT_SHADOW_EDGES * edge:
        most = speed_arms_resolved(shadow, geo, dist, radius)
        if most < src.arms - 1.0:
            warnings.warn(
                f"the impact at {tuple(round(float(x), 6) for x in snapped)} asks for "
                f"{src.arms:.1f} radial cracks but the sim mesh resolves about {most:.0f} there; "
                "raise --sim-faces or --detail, or give it a larger radius",
                CrackbakeWarning, stacklevel=3)
    return stress, info, shadow


def speed_arms_resolved(shadow: float, geo: _Geometry, dist: np.ndarray, radius: float) -> float:
    """The arm count a speed impact's star gets with ``shadow`` (mesh units): the inverse of
    :func:`speed_shadow` on its circle at 0.3 reach."""
    circle = iso_length(geo.vertices, geo.faces, dist, 0.3 * 0.5 * np.pi * radius)
    if circle <= 0.0:
        circle = 0.6 * np.pi * 0.5 * np.pi * radius
    return float((SPEED_SHADOW_SCALE * circle / shadow) ** (1.0 / SPEED_SHADOW_POWER))


def _fit_radius(geo: _Geometry, dist: np.ndarray, face: int, snapped: np.ndarray,
                radius: float, fit: bool | None, edge: float) -> tuple[float, str]:
    """The radius an impact uses (``ImpactSource.fit``) and a warning for the caller, or "".

    A default radius is shrunk to a thin feature its star would wrap round
    (:func:`fitted_radius`), said in one warning (here); a given one is kept, and the caller
    warns when its star wraps (a web of cells, not a star, is likely); one fitted before is
    used as it is.
    """
    if fit is None:
        return radius, ""
    # Not below what the sim mesh, refined for a thin feature, resolves (the 0.3-reach circle
    # spanning IMPACT_SHADOW_MIN_EDGES edges of the finer mesh) nor below the edge itself.
    least = max(edge, IMPACT_SHADOW_MIN_EDGES * edge / IMPACT_REFINE_MAX / (0.3 * 0.5 * np.pi))
    r, share, share0 = fitted_radius(geo.vertices, geo.faces, dist, face, radius, least,
                                     1.5 * edge)
    if share0 < BACK_SHARE_MAX:
        return radius, ""
    at = ", ".join(f"{float(x):.4g}" for x in snapped)
    xyz = at.replace(" ", "")  # as --impact takes it
    wraps = f"{share0:.0%} of its star would face away"
    if not fit:
        return radius, (
            f"the impact at ({at}) wraps round a thin feature or corner ({wraps}): expect a web "
            f"of cells, not a star; give a smaller radius (--impact {xyz}:{r:.3g} "
            f"{'fits' if share < BACK_SHARE_MAX else 'wraps less'}) or a broader point")
    if share < BACK_SHARE_MAX:
        said = f"radius {r:.3g} used instead of {radius:.3g} (it fits: {share:.0%})"
    else:
        said = (f"radius {r:.3g} used, the one of those tried that wraps least, still wraps "
                f"({share:.0%}): a broader point gives a star")
    warnings.warn(
        f"the impact at ({at}) lies on a thin feature ({wraps}): {said}; --impact "
        f"{xyz}:RADIUS chooses",
        CrackbakeWarning,
        stacklevel=4,
    )
    return r, ""


#: An impact whose reachable surface within its reach is under this share of a flat star's
#: (``pi reach^2``) and ends there (a small separate piece) gets a warning.
SMALL_PIECE_SHARE = 0.25


def _warn_small_piece(geo: _Geometry, nodal: np.ndarray, snapped: np.ndarray, radius: float,
                      edge: float) -> bool:
    """Warn when the surface the impact can reach is a piece too small for its star; whether
    it warned.

    ``nodal`` (M, 3) is the impact's geodesic distance at each face's corners (``inf`` past
    the reach or on other pieces).  The piece counts as small when every point it reaches lies
    more than two sim edges inside the reach (the piece ends before the star would) and its
    area is under :data:`SMALL_PIECE_SHARE` of ``pi reach^2``.
    """
    reach = 0.5 * np.pi * radius
    finite = np.isfinite(nodal).all(axis=1)
    if not finite.any():
        return False
    far = float(nodal[finite].max())
    area = float(geo.area[finite].sum())
    flat = np.pi * reach * reach
    if far >= reach - 2.0 * edge or area >= SMALL_PIECE_SHARE * flat:
        return False
    corners = geo.vertices[geo.faces[finite]].reshape(-1, 3)
    size = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    at = ", ".join(f"{float(x):.4g}" for x in snapped)
    warnings.warn(
        f"the impact at ({at}) lands on a separate piece {size:.3g} across (area {area:.3g}, "
        f"{area / flat:.0%} of its star's): the star cannot grow past that piece; give another "
        f"--impact point on a larger part, or a radius of about {2.0 * far / np.pi:.3g} (this "
        "piece's reach) for a star that fits it",
        CrackbakeWarning,
        stacklevel=4,
    )
    return True


#: An impact on a small separate piece (under :data:`SMALL_PIECE_SHARE` of its star's disc,
#: ``pi reach^2``) touching larger shells (an eye in its socket, a nail on a finger) whose reach
#: holds more than this share of its surface on those shells gets a warning: the cracks cross
#: only where the shells touch, and round the piece grows a web of cells, not a star.  Large
#: pieces meeting at a seam (a tiled floor) carry a star across and are not warned.
OFF_PIECE_SHARE = 0.5


def _warn_off_piece(geo: _Geometry, dist: np.ndarray, face: int, snapped: np.ndarray,
                    radius: float, edge: float) -> bool:
    """Warn when the impact lands on a small piece and its star's reach lies mostly on the
    larger shells that piece touches (which ``dist`` reached across the gap); whether it
    warned.

    ``dist`` (N,) is the impact's geodesic distance at the sim nodes (``inf`` past the reach),
    ``face`` the sim face holding ``snapped``, ``edge`` the sim edge there.  The piece is
    small when its area is under :data:`SMALL_PIECE_SHARE` of ``pi reach^2``; the share off
    it is the reached area (faces within the reach) on other shells.  Measured on the reach,
    not on the star's circle at 0.3 reach: suzanne's eye (0.81 across, default radius) holds
    that circle whole (its rim lies at 0.40-0.46 reach), yet 86 % of the reach lies on the head,
    which cracks into a web round the eye and brow.  The warning names the piece's size (its
    bounding-box diagonal) and the fix: the largest radius, tried down by :data:`FIT_STEP`,
    that this check passes (while its 0.3-reach circle spans ``STAR_MIN_EDGES`` sim edges), or
    a point on the larger piece.
    """
    from crackbake.metrics.star import STAR_MIN_EDGES

    faces = geo.faces
    d = dist[faces].max(axis=1)  # inf past the reach
    shell = shared_shells(faces, len(geo.vertices))
    mine = shell[faces[:, 0]] == shell[faces[face, 0]]
    if mine[np.isfinite(d)].all():  # the distance reached no other shell
        return False
    piece = float(geo.area[mine].sum())

    def off_share(reach: float) -> float:
        """The share of the reach off the piece; 0 where the piece is not small."""
        if piece >= SMALL_PIECE_SHARE * np.pi * reach * reach:
            return 0.0
        near = d <= reach
        on, off = geo.area[near & mine].sum(), geo.area[near & ~mine].sum()
        return float(off / (on + off))

    reach = 0.5 * np.pi * radius
    share = off_share(reach)
    if share <= OFF_PIECE_SHARE:
        return False
    fits = reach
    while 0.3 * fits * FIT_STEP >= STAR_MIN_EDGES * edge:
        fits *= FIT_STEP
        if off_share(fits) <= OFF_PIECE_SHARE:
            break
    else:
        fits = 0.0
    fits /= 0.5 * np.pi
    own = np.unique(faces[mine])
    corners = geo.vertices[own]
    size = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    # Rounded to a millionth of the piece: no 1e-17 for a coordinate on a symmetry plane.
    at = ",".join(f"{float(x) + 0.0:.4g}" for x in np.round(snapped / size, 6) * size)
    fix = f"it radius {fits:.3g} (fits the piece) or " if fits else ""
    warnings.warn(
        f"the impact at ({at}) lands on a piece {size:.3g} across touching a larger one, "
        f"{share:.0%} of its star's reach off it: expect a web of cells round it, not a star; "
        f"give {fix}a point on the larger piece",
        CrackbakeWarning,
        stacklevel=4,
    )
    return True


def _directional_field(geo: _Geometry, src: DirectionalSource) -> np.ndarray:
    d = unit_rows(_finite_vector(src.direction, "tension direction")[None])[0][0]
    pd = d[None] - (geo.normal @ d)[:, None] * geo.normal
    return src.strength * _outer(pd, pd)



def field_kernels() -> list:
    """The numba kernels an impact's field calls on the run's thread, in the order it first
    calls them (its faces' geometry, the geodesic patch's manifold split, the face-node
    smoothing): for :func:`crackbake.jit.preload` on that thread before any other thread
    loads kernels.  numba loads each kernel under one process-wide lock, so a kernel the field
    loads at its first call waited for whatever another thread was loading then (the
    preview's and the solver's warm-up, 57-165 ms of the README bake's field)."""
    from crackbake.geometry_kernels import face_geometry_kernel
    from crackbake.simulate.simmesh.manifold_kernels import fan_split, sorted_sides

    return [face_geometry_kernel, sorted_sides, fan_split, _incidence_sums]


def _face_vertex_smooth(faces: np.ndarray, area: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Area-weighted face -> node -> face average of per-face values (K, ...) over (K, 3) faces."""
    k = len(faces)
    flat = np.ascontiguousarray(values.reshape(k, -1), np.float64)
    nodes, local = np.unique(faces, return_inverse=True)
    local = np.ascontiguousarray(local.reshape(k, 3), np.int64)
    node_area, node_sum = _incidence_sums(local, np.ascontiguousarray(area, np.float64), flat,
                                          len(nodes))  # fmt: skip
    node = node_sum / np.where(node_area > 0, node_area, 1.0)[:, None]
    return corner_mean(node[local]).reshape(values.shape)


@njit(cache=True, nogil=True)
def _pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's pairwise summation of ``a[lo:lo + n]`` (its add reduction), term by term."""
    if n < 8:
        res = -0.0
        for i in range(n):
            res += a[lo + i]
        return res
    if n <= 128:
        r = a[lo:lo + 8].copy()
        i = 8
        while i < n - (n % 8):
            for j in range(8):
                r[j] += a[lo + i + j]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += a[lo + i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_sum(a, lo, n2) + _pairwise_sum(a, lo + n2, n - n2)


@njit(cache=True, nogil=True)
def _incidence_sums(local: np.ndarray, area: np.ndarray, flat: np.ndarray, n_nodes: int):
    """Each node's summed face area and area-weighted sum of its faces' rows of ``flat``.

    The sums scipy.sparse made of the node-by-face incidence matrix (``inc.sum(axis=1)``,
    ``inc @ flat``), in its order and association, so the field keeps its bits without
    scipy's 0.35 s import: entries by node then face, a face's repeated corner merged (area
    added to itself), the areas reduced as numpy's ``add.reduceat`` (the first, plus the
    pairwise sum of the rest), the rows accumulated one entry after another from zero.
    """
    k = len(local)
    count = np.zeros(n_nodes + 1, np.int64)
    for f in range(k):
        for c in range(3):
            node = local[f, c]
            if (c == 0 or local[f, 0] != node) and (c < 2 or local[f, 1] != node):
                count[node + 1] += 1
    for i in range(n_nodes):
        count[i + 1] += count[i]
    fill = count[:-1].copy()
    face = np.empty(count[-1], np.int64)
    weight = np.empty(count[-1])
    for f in range(k):
        for c in range(3):
            node = local[f, c]
            if (c == 0 or local[f, 0] != node) and (c < 2 or local[f, 1] != node):
                w = area[f]
                for d in range(c + 1, 3):
                    if local[f, d] == node:
                        w += area[f]
                face[fill[node]] = f
                weight[fill[node]] = w
                fill[node] += 1
    m = flat.shape[1]
    node_area = np.zeros(n_nodes)
    node_sum = np.zeros((n_nodes, m))
    for i in range(n_nodes):
        s, e = count[i], count[i + 1]
        if e > s:
            node_area[i] = weight[s] + _pairwise_sum(weight, s + 1, e - s - 1)
        for t in range(s, e):
            w = weight[t]
            f = face[t]
            for j in range(m):
                node_sum[i, j] += w * flat[f, j]
    return node_area, node_sum


def _node_normals(sim, mesh: Mesh, geo: _Geometry) -> np.ndarray:
    """Unit normals at the sim nodes, (N, 3).

    The asset's own (shading) normals interpolated at each node where the sim mesh says where
    its nodes lie: a low-poly asset is flat inside each face, but its shading normals describe
    the smooth surface it stands for.  Geometric area-weighted normals otherwise.
    """
    geometric = vertex_normals(geo.vertices, geo.faces)
    node_face = getattr(sim, "node_face", None)
    node_bary = getattr(sim, "node_bary", None)
    normals = getattr(mesh, "normals", None)
    if node_face is None or node_bary is None or normals is None:
        return geometric
    node_face = np.asarray(node_face, dtype=np.int64)
    if node_face.shape != (len(geo.vertices),) or len(normals) != len(mesh.vertices):
        return geometric
    vn = np.einsum("nk,nka->na", np.asarray(node_bary), normals[mesh.faces[node_face]])
    vn, length = unit_rows(vn)
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



def noise_origin(sim) -> np.ndarray:
    """The point the stress noise's phases are measured from on ``sim``: the mean of its face
    centroids, (3,)."""
    v = np.asarray(sim.vertices, dtype=np.float64)
    return corner_mean(v[np.asarray(sim.faces, dtype=np.int64)]).mean(axis=0)


def _smooth_noise(points: np.ndarray, origin: np.ndarray, scale: float,
                  rng: np.random.Generator, count: int):
    """``count`` smooth unit-variance random fields at (M, 3) points, (count, M).

    Each is a sum of :data:`NOISE_WAVES` plane waves of random direction, phase and wavelength
    near ``scale`` (solid noise, so it is seamless across UV seams and thin walls alike), with
    phases relative to ``origin`` (3,) (:func:`stress_field`'s ``noise_origin``).
    """
    k = rng.normal(size=(3, count * NOISE_WAVES))
    k /= np.linalg.norm(k, axis=0, keepdims=True)
    k *= (2 * np.pi / scale) * rng.uniform(0.7, 1.4, size=count * NOISE_WAVES)
    phase = rng.uniform(0, 2 * np.pi, size=count * NOISE_WAVES)
    # Phases in float64 (large coordinates), cosines in float32: it is only noise.
    arg = ((points - origin) @ k + phase).astype(np.float32)
    np.cos(arg, out=arg)
    out = arg.reshape(len(points), count, NOISE_WAVES).sum(axis=2, dtype=np.float64).T
    return out * np.sqrt(2.0 / NOISE_WAVES)


def _noise_fields(geo: _Geometry, noises: list[NoiseSource], seed: int, origin: np.ndarray,
                  diagonal: float) -> list[np.ndarray]:
    """Each noise source's four smooth fields at the face centroids ((4, M) each, in order):
    what :func:`_apply_noise` perturbs the stress with."""
    out = []
    for i, src in enumerate(noises):
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), i]))
        scale = src.scale if src.scale is not None else NOISE_SCALE_DIAGONAL * diagonal
        out.append(_smooth_noise(geo.centroid, origin, scale, rng, 4))
    return out


class _NoiseAhead:
    """:func:`_noise_fields` on a thread while the other sources are summed: they depend on
    the mesh and the seed only, and numpy releases the GIL in their products and cosines
    (about 40 ms of the README bake's stress field on 2 cores)."""

    def __init__(self, *args) -> None:
        import threading

        self._fields: list[np.ndarray] | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, args=args, daemon=True,
                                        name="crackbake-noise")  # fmt: skip
        self._thread.start()

    def _work(self, *args) -> None:
        try:
            self._fields = _noise_fields(*args)
        except BaseException as exc:  # noqa: BLE001 - raised again on the caller's thread
            self._error = exc

    def result(self) -> list[np.ndarray]:
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._fields


def _apply_noise(
    stress: np.ndarray, geo: _Geometry, src: NoiseSource, fields: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy stress and the multiplier used (so growth can follow it); ``fields`` (4, M): the
    source's :func:`_noise_fields`."""
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


def stress_field(sim, mesh: Mesh, sources: Sequence, seed: int = 0,
                 noise_origin: np.ndarray | None = None) -> StressField:
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
    noise_origin : (3,) float, optional
        Where the noise's phases are measured from; default :func:`noise_origin` of ``sim``.
        A sim mesh rebuilt finer round thin-feature impacts passes the origin of the uniform one
        it replaces, so the noise at a point does not depend on which other impacts refined
        their balls (docs/solver.md, "Several impacts").

    Returns
    -------
    StressField
    """
    vertices = np.asarray(sim.vertices, dtype=np.float64)
    faces = np.asarray(sim.faces, dtype=np.int64)
    area, normal, grad = face_geometry(vertices, faces)
    sources = list(sources)
    # With impacts, the centroids their snap takes too (once per mesh, :func:`shared_centroids`).
    has_impacts = any(isinstance(s, ImpactSource) for s in sources)
    centroid = (shared_centroids(vertices, faces)[0] if has_impacts
                else corner_mean(vertices[faces]))
    geo = _Geometry(vertices, faces, area, normal, grad, centroid)
    m = len(faces)

    stress = np.zeros((m, 3, 3))
    growth = np.zeros((m, 3, 3))
    weight = np.ones(m)
    impacts: list[dict] = []
    shadows: list[float] = []
    impact_norms: list[np.ndarray] = []  # per impact, its raw tensor norm per face
    impact_sum = None
    noises = [src for src in sources if isinstance(src, NoiseSource)]
    origin = geo.centroid.mean(axis=0) if noise_origin is None else np.asarray(noise_origin)
    ahead = _NoiseAhead(geo, noises, seed, origin, mesh.diagonal) if noises else None
    bary_cache: list = []
    for src in sources:
        if isinstance(src, ImpactSource):
            radius = 0.15 * mesh.diagonal if src.radius is None else float(src.radius)
            s, info, shadow = _impact_field(sim, geo, src, radius)
            stress += s
            impacts.append(info)
            shadows.append(shadow)
            impact_norms.append(np.sqrt(np.einsum("eab,eab->e", s, s)))
            impact_sum = s if impact_sum is None else impact_sum + s
        elif isinstance(src, ShrinkSource):
            plane = _plane_identity(normal)
            stress += src.strength * plane
            growth += src.rate * src.strength * plane
        elif isinstance(src, DirectionalSource):
            stress += _directional_field(geo, src)
        elif isinstance(src, CurvatureSource):
            stress += _curvature_field(sim, mesh, geo, src)
        elif isinstance(src, WeightSource):
            weight *= weight_field(sim, mesh, geo.centroid, src, bary_cache)
        elif isinstance(src, NoiseSource):
            pass  # on a thread meanwhile (_NoiseAhead)
        else:
            raise TypeError(f"not a stress source: {type(src).__name__}")

    share = (_impact_share(stress - impact_sum, impact_norms) if len(impact_norms) >= 2
             else None)
    stress *= weight[:, None, None]
    growth *= weight[:, None, None]
    for src, fields in zip(noises, ahead.result() if ahead is not None else [], strict=True):
        stress, factor = _apply_noise(stress, geo, src, fields)
        growth *= factor[:, None, None]

    # Exactly in-plane and symmetric whatever rounding did; degenerate faces carry nothing.
    flat = area <= 0
    stress = _project(stress, normal)
    if growth.any():
        growth = _project(growth, normal)
    stress[flat] = 0.0
    growth[flat] = 0.0
    speed = any("arms" in info for info in impacts)
    return StressField(stress=stress, growth=growth, weight=weight, impacts=impacts,
                       shadow_radius=min(shadows) if shadows else None,
                       impact_shadows=shadows, impact_share=share,
                       shadow_max=SPEED_SHADOW_MAX * mesh.diagonal if speed else None)


def _impact_share(rest: np.ndarray, norms: list[np.ndarray]) -> np.ndarray:
    """Per impact, its share of each face's stress, (K, M) float32: its tensor norm over the
    sum of every impact's norm and the norm of ``rest`` (M, 3, 3), what the other additive
    sources (shrinkage, tension, curvature) added."""
    norm = np.stack(norms)  # (K, M)
    den = norm.sum(axis=0) + np.sqrt(np.einsum("eab,eab->e", rest, rest))
    return np.where(den > 0, norm / np.where(den > 0, den, 1.0), 0.0).astype(np.float32)



#: The ball round an impact whose back-facing share :func:`back_share` measures, in reaches
#: of surface (geodesic) distance: a star's radial arms and its rings lie inside it.  A
#: straight ball would hold both sides of a thin plate hit in its middle.
BACK_BALL_REACH = 0.75
#: The impact's own normal is the mean over this ball (reaches, geodesic): one face's normal
#: is noisy on scans and tilted at a hoof's rim; a wider ball averages a sheet's two sides.
BACK_NORMAL_REACH = 0.03
#: A face faces away when the dot of its unit normal with the impact's is below this (turned
#: over about 96 degrees): a cylinder's side (dot 0: a finger hit at its tip) does not count,
#: the far side of a lobe, a sheet or a sharp corner does.
BACK_DOT = -0.1
#: An impact whose back-facing share reaches this wraps round a feature smaller than its star
#: and grows a web of cells (issue 18 §3; benchmarks/bench_extremities.py has the table).
BACK_SHARE_MAX = 0.15
#: A default radius is shrunk by steps of this factor until the share falls below
#: :data:`BACK_SHARE_MAX` (:func:`fitted_radius`) ...
FIT_STEP = 2.0 ** -0.25
#: ... down to this share of the default at most.  On a sheet's rim (the bunny's ear, the
#: teapot's spout) every ball wraps and the share stays high; there half the default radius
#: grows a fan of 5-8 straight arms, a quarter 2-7 arms on a patch too small to read.
FIT_MIN = 0.5


def back_share(vertices: np.ndarray, faces: np.ndarray, distance: np.ndarray, face: int,
               reach: float, ball: float = BACK_BALL_REACH, below: float = BACK_DOT,
               normal_min: float = 0.0) -> float:
    """Share of the surface near an impact that faces away from the impact's side.

    Parameters
    ----------
    vertices : (N, 3) float64
    faces : (M, 3) int
    distance : (N,) float64
        The impact's surface distance at each node, mesh units (``inf`` where not reached).
    face : int
        The face holding the impact.
    reach : float
        The impact's reach, mesh units.
    ball : float
        Faces whose mean corner distance is at most ``ball * reach`` count.
    below : float
        A face faces away when its unit normal's dot with the impact's (the area-weighted
        mean within :data:`BACK_NORMAL_REACH` reach or ``normal_min``, the larger) is below
        this.
    normal_min : float
        Mesh units: at least the faces round the impact's corner (1.5 sim edges), so that an
        impact on a box's corner does not take one side face's normal for its own.

    Returns
    -------
    float
        Area share in [0, 1]: 0 on a plate, a gently curved body or a finger hit at its tip,
        0.2-0.5 where the ball wraps round to the far side of a thin lobe or sheet, or past a
        sharp corner (the star would wrap round it).
    """
    d = distance[faces]
    d = np.where(np.isfinite(d).all(axis=1), corner_mean(d), np.inf)
    d[face] = 0.0
    inside = d <= ball * reach
    tri = vertices[faces[inside]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # |n| = 2 x area
    n0 = n[d[inside] <= max(BACK_NORMAL_REACH * reach, normal_min)].sum(axis=0)
    area = np.linalg.norm(n, axis=1)
    total = float(area.sum())
    n0_len = float(np.linalg.norm(n0))
    if not total > 0 or not n0_len > 0:
        return 0.0
    cos = (n @ (n0 / n0_len)) / np.where(area > 0, area, 1.0)
    return float(area[cos < below].sum() / total)


def fitted_radius(vertices: np.ndarray, faces: np.ndarray, distance: np.ndarray, face: int,
                  radius: float, least: float = 0.0,
                  normal_min: float = 0.0) -> tuple[float, float, float]:
    """The largest radius up to ``radius`` whose star does not wrap round a thin feature.

    Tries ``radius`` times :data:`FIT_STEP` powers down to :data:`FIT_MIN` (and not below
    ``least``) until the :func:`back_share` falls below :data:`BACK_SHARE_MAX`; where none does
    (an impact on a sheet's rim, a knob), the one that wraps least (the larger on a tie): a
    smaller star is not always a flatter one (on a knob's top its sides face away).
    ``distance`` (N,) is the impact's surface distance, right up to :data:`BACK_BALL_REACH` of
    ``radius``'s reach; ``face`` the face holding it; ``normal_min`` as :func:`back_share`'s.

    Returns
    -------
    radius : float
        Mesh units.
    share : float
        Its back-facing share.
    share0 : float
        The share at ``radius``.
    """
    # Every ball tried lies in the first: measure on its faces only.
    d = distance[faces]
    keep = np.isfinite(d).all(axis=1) & (corner_mean(d) <= BACK_BALL_REACH * 0.5 * np.pi * radius)
    keep[face] = True
    sub, at = faces[keep], int(np.count_nonzero(keep[:face]))
    share0 = None
    best = None
    scale = 1.0
    while True:
        r = radius * scale
        share = back_share(vertices, sub, distance, at, 0.5 * np.pi * r, normal_min=normal_min)
        share0 = share if share0 is None else share0
        if share < BACK_SHARE_MAX:
            return r, share, share0
        if best is None or share < best[1]:  # the larger radius on a tie
            best = (r, share)
        scale *= FIT_STEP
        if scale < FIT_MIN * (1 - 1e-9) or radius * scale < least:
            return best[0], best[1], share0
