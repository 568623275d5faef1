"""Measures of an impact's crack star, read from the network's polylines.

Every measure works on the distance from the impact *over the surface* at each polyline point:
the straight distance on a flat plate, and on a curved mesh the geodesic one from
:func:`surface_distance` (fast marching on a triangle mesh of the surface, the solver's own
:func:`crackbake.simulate.stress.impact_distance`, interpolated inside the face nearest each
crack point).  Separate shells that touch (closer than a sim edge: an eye in its socket, a
nail on a finger) are one surface there, as for the solver, which carries cracks across them:
the distance crosses from the shell it reached onto the shell it touches
(:func:`crackbake.simulate.stress.geodesic.impact_distance`'s hop).  Lengths along a crack are
straight segments between its points (the solver writes one per sim edge crossed, so they are
short).

The impact's **reach** is where its stress field ends: ``pi * radius / 2`` for
:class:`crackbake.simulate.stress.ImpactSource` (:func:`impact_reach`).  Distances below are
fractions of it.

* :func:`radial_arms`: arms crossing the circle at 0.3 reach, running within 45 degrees of the
  radial direction;
* :func:`arm_straightness`: chord / arc length of each arm inside 0.6 reach;
* :func:`tangential_share`: share of the crack length between 0.35 and 0.65 reach running more
  than 45 degrees off radial (the concentric links);
* :func:`annulus_density`: crack length per unit area in annuli of the reach;
* :func:`length_beyond`: crack length past the reach.

The radial direction of a segment needs no vector field: along a surface path the distance
changes at most as fast as the arc (``|grad d| = 1``), so ``|d_b - d_a| / |b - a|`` is the
cosine of the angle between the segment and the radial direction.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = [
    "annulus_areas",
    "annulus_density",
    "arm_straightness",
    "impact_reach",
    "length_beyond",
    "mean_edge",
    "missing_stars",
    "own_cracks",
    "polylines",
    "radial_arms",
    "star_checks",
    "star_metrics",
    "surface_distance",
    "surface_fold",
    "tangential_share",
    "trimmed_mean",
    "web_stars",
]

#: A star has at least this many radial arms crossing the 0.3-reach circle
#: (:func:`radial_arms`): plates and spot's flank, leg, horn and ear grow 9-18.
STAR_MIN_ARMS = 5
#: Below this many sim edges across the 0.3-reach circle's radius the sim mesh itself cannot
#: space a star's arms (a plate hit with a radius of 3 sim edges grows 3).
STAR_MIN_EDGES = 4.0

#: A star's arms run straight out from the impact: the trimmed mean (:func:`trimmed_mean`) of
#: their geodesic straightness (:func:`arm_straightness`, ``geodesic=True``) is 0.90-0.99 on
#: plates, spot's flank and horn, a finger hit at its tip, a plate lying on a plate and
#: suzanne's forehead (seeds 0-2).  Below this the arms wander and the pattern is a web of
#: cells: suzanne's low-poly brow between the eyes, 0.81-0.87 (issue 18 §3; docs/solver.md,
#: "A web, not a star").
STAR_MIN_RADIAL = 0.885
#: The share of the lowest and of the highest values :func:`trimmed_mean` leaves out.
TRIM = 0.2

#: A web on a surface that turns more than this (degrees, :func:`surface_fold`) within the
#: 0.3-reach circle is blamed on the fold: suzanne's low-poly brow turns 78 and webs (0.81), a
#: plate 0 and spot's flank under 30; the tips of spot's horn and ear and of a finger turn
#: 92-115 but grow stars there (0.93-0.96), so are never called webs.
WEB_FOLD_DEG = 30.0
#: A web on a smoother surface with fewer sim edges than this across the 0.3-reach circle's
#: radius is blamed on the sim mesh: ``crackbake decals`` on 5,000 sim faces (4.7 edges)
#: grew a web (0.83) on its flat plate.
WEB_MIN_EDGES = 8.0

#: A segment counts as radial when it runs within this angle of the radial direction (degrees).
RADIAL_DEG = 45.0


def impact_reach(radius: float) -> float:
    """Distance where an :class:`ImpactSource` of ``radius`` ends: ``pi * radius / 2``."""
    return 0.5 * np.pi * float(radius)


def polylines(network: Any) -> list[np.ndarray]:
    """The (N, 3) point arrays of a :class:`CrackNetwork`, a ``cracks.json`` dict or a list."""
    if isinstance(network, dict):
        cracks = [c["points"] for c in network["cracks"]]
    elif hasattr(network, "cracks"):
        cracks = [c.points for c in network.cracks]
    else:
        cracks = list(network)
    return [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in cracks if len(p) >= 2]


def own_cracks(
    polys: list[np.ndarray], impact: np.ndarray, reach: float, others: list
) -> list[np.ndarray]:
    """The parts of the polylines nearer (in reaches) to ``impact`` than to any of ``others``.

    With several impacts on one surface each star is measured on its own cracks: the runs of
    points whose straight distance over the impact's reach is at most that to every other
    impact (a power-free Voronoi cell scaled by the reaches), cut where a polyline leaves it.

    Parameters
    ----------
    polys : list of (N_i, 3) float arrays
    impact : (3,) array_like
    reach : float
        This impact's reach, mesh units.
    others : list of (point (3,), reach)
        The other impacts.

    Returns
    -------
    list of (K_j, 3) float arrays, each with at least 2 points.
    """
    if not others:
        return polys
    c = np.asarray(impact, dtype=np.float64).reshape(3)
    pts = np.asarray([o[0] for o in others], dtype=np.float64).reshape(-1, 3)
    reaches = np.asarray([o[1] for o in others], dtype=np.float64)
    out = []
    for p in polys:
        mine = np.linalg.norm(p - c, axis=1) / reach
        theirs = (np.linalg.norm(p[:, None] - pts[None], axis=2) / reaches).min(axis=1)
        own = mine <= theirs
        # Runs of owned points (a crack crossing into another star's cell is cut there).
        edges = np.flatnonzero(np.diff(np.r_[0, own.astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a >= 2:
                out.append(p[a:b])
    return out


def _interpolated(tri: np.ndarray, d: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Barycentric interpolation of corner values ``d`` (K, 3) of faces ``tri`` (K, 3, 3) at
    the points ``q`` (K, 3) projected on each face's plane.

    Linear interpolation of a cone field errs by about ``h^2 / (8 d)`` on a face of size ``h``
    at distance ``d``: negligible on a fine mesh except at the impact itself, where the straight
    distance (the caller's lower bound) takes over.
    """
    from crackbake.geometry import barycentric

    w = barycentric(tri, q)
    return np.einsum("kc,kc->k", w, d)


def mean_edge(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Mean edge length of a triangle mesh, mesh units (0 without faces): the gap below which
    separate shells touch, as the solver's ``_mates`` link on a sim mesh."""
    from crackbake.geometry import edges

    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0.0
    v = np.asarray(vertices, dtype=np.float64)
    e = edges(f, len(v))[0]
    return float(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).mean())


def surface_fold(vertices: np.ndarray, faces: np.ndarray, point, radius: float) -> float:
    """How far the surface turns round ``point``: the 90th percentile of the angle between the
    normal of the face nearest ``point`` and the normals of the faces whose centroids lie within
    ``radius`` of it (degrees; 0 on a plane, about ``radius / R`` radians on a sphere of radius
    R, 78 on suzanne's low-poly brow at a star's 0.3 reach).

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
    point : (3,) float, mesh units
    radius : float, mesh units

    Returns
    -------
    float, degrees in [0, 180]
    """
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    dist = np.linalg.norm(tri.mean(axis=1) - np.asarray(point, dtype=np.float64), axis=1)
    near = dist <= radius
    if not near.any():
        return 0.0
    cos = np.clip(normal[near] @ normal[int(np.argmin(dist))], -1.0, 1.0)
    return float(np.degrees(np.arccos(np.percentile(cos, 10.0))))


def surface_distance(
    points: np.ndarray,
    impact: np.ndarray,
    vertices: np.ndarray | None = None,
    faces: np.ndarray | None = None,
    max_distance: float | None = None,
    link: float | None = None,
) -> np.ndarray:
    """Distance over the surface from ``impact`` to each of ``points``.

    Parameters
    ----------
    points : (P, 3) array_like
        Points on the surface, mesh units.
    impact : (3,) array_like
        The impact point, mesh units (snapped to the surface when a mesh is given).
    vertices, faces : (N, 3) float and (M, 3) int, optional
        A triangle mesh of the surface; the finer, the closer the geodesic (the solver's sim
        mesh is a good choice).  Without it the straight distance is used (right on a plate).
    max_distance : float, optional
        Only distances up to this need be right; points farther get ``inf``.
    link : float, optional
        Separate shells of the mesh closer than this (mesh units) are one surface: the
        distance crosses the gap (the solver's sim edge, ``SimMesh.edge_length``, as its
        cracks do).  Default: the mesh's mean edge length (:func:`mean_edge`); 0: each shell
        alone.

    Returns
    -------
    (P,) float64
        Mesh units: the geodesic distance (fast marching on the mesh, interpolated inside the
        face nearest each point), never below the straight distance.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    imp = np.asarray(impact, dtype=np.float64).reshape(3)
    straight = np.linalg.norm(pts - imp, axis=1)
    if vertices is None or faces is None or len(pts) == 0:
        return straight
    from crackbake.geometry import shared_centroids
    from crackbake.simulate.stress.geodesic import impact_distance

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    link = mean_edge(v, f) if link is None else float(link)
    node, snapped, _ = impact_distance(SimpleNamespace(vertices=v, faces=f, edge_length=link),
                                       imp, max_distance)
    nearest = _nearest_centroid(*shared_centroids(v, f), snapped, max_distance, pts)
    d = node[f[nearest]]
    out = np.full(len(pts), np.inf)
    ok = np.isfinite(d).all(axis=1)
    out[ok] = _interpolated(v[f[nearest[ok]]], d[ok], pts[ok])
    return np.maximum(out, np.linalg.norm(pts - snapped, axis=1))


def _nearest_centroid(centroid: np.ndarray, corner_reach: float, snapped: np.ndarray,
                      max_distance: float | None, pts: np.ndarray) -> np.ndarray:
    """The face whose centroid (M, 3) lies nearest each of ``pts`` (P, 3), (P,) int.

    Searched first among the faces of the impact's patch (the ball :func:`impact_distance`
    keeps: centroids within ``max_distance`` + ``corner_reach`` of ``snapped``), a fraction of
    a large sim mesh, whose search grid costs that fraction.
    A point whose nearest patch centroid is closer than the ball's rim is to it has found its
    face (every centroid outside lies strictly farther); the others are searched among all.
    """
    from crackbake.nearest import nearest_k

    def query(among, at):
        d, i = nearest_k(among, at, 1)
        return d[:, 0], i[:, 0]

    if max_distance is None or not np.isfinite(max_distance):
        return query(centroid, pts)[1]
    rim = (float(max_distance) + corner_reach) * (1 + 1e-9)
    ball = np.flatnonzero(np.linalg.norm(centroid - snapped, axis=1) <= rim)
    if len(ball) == 0:
        return query(centroid, pts)[1]
    dist, near = query(centroid[ball], pts)
    nearest = ball[near]
    # A margin for the rounding of the two distances: a point that close to the rim asks all.
    outside = np.linalg.norm(pts - snapped, axis=1) + dist > rim * (1 - 1e-9)
    if outside.any():
        nearest[outside] = query(centroid, pts[outside])[1]
    return nearest


def _segments(polys: list[np.ndarray], dists: list[np.ndarray]):
    """Flat segment arrays: start/end points, distances, lengths, polyline and index."""
    a = np.concatenate([p[:-1] for p in polys]) if polys else np.zeros((0, 3))
    b = np.concatenate([p[1:] for p in polys]) if polys else np.zeros((0, 3))
    da = np.concatenate([d[:-1] for d in dists]) if polys else np.zeros(0)
    db = np.concatenate([d[1:] for d in dists]) if polys else np.zeros(0)
    return a, b, da, db, np.linalg.norm(b - a, axis=1)


def _band_length(da, db, length, lo: float, hi: float) -> np.ndarray:
    """Per segment, the length whose (linearly interpolated) distance lies in ``[lo, hi)``;
    unreached points (``inf``) count as lying beyond every finite distance."""
    finite = [abs(x) for x in (lo, hi) if np.isfinite(x)]
    finite += [float(np.abs(x[np.isfinite(x)]).max()) for x in (da, db) if np.isfinite(x).any()]
    big = 10.0 * max(finite + [1.0])
    da = np.where(np.isfinite(da), da, big)
    db = np.where(np.isfinite(db), db, big)
    lo_d, hi_d = np.minimum(da, db), np.maximum(da, db)
    span = hi_d - lo_d
    inside = np.clip(np.minimum(hi_d, hi) - np.maximum(lo_d, lo), 0.0, None)
    frac = np.where(span > 0, inside / np.where(span > 0, span, 1.0),
                    ((lo_d >= lo) & (lo_d < hi)).astype(float))
    return length * frac


def _radial_cos(da, db, length) -> np.ndarray:
    """|cos| of the angle between each segment and the radial direction (0 when unknown)."""
    ok = (length > 0) & np.isfinite(da) & np.isfinite(db)
    step = np.abs(np.where(ok, db, 0.0) - np.where(ok, da, 0.0))
    return np.clip(step / np.where(ok, length, 1.0), 0.0, 1.0)


def radial_arms(
    polys: list[np.ndarray], dists: list[np.ndarray], reach: float, at: float = 0.3
) -> list[tuple[int, int, np.ndarray]]:
    """Radial arms crossing the circle ``d = at * reach``.

    A crossing counts when its segment runs within :data:`RADIAL_DEG` of the radial direction;
    crossings closer than 5 % of the circle's radius to one already counted are the same arm
    (a crack zig-zagging over the circle).

    Parameters
    ----------
    polys : list of (N_i, 3) float arrays
        Crack polylines, mesh units.
    dists : list of (N_i,) float arrays
        Surface distance of each point from the impact (:func:`surface_distance`).
    reach : float
        The impact's reach, mesh units (:func:`impact_reach`).
    at : float
        Circle radius, a fraction of ``reach``.

    Returns
    -------
    list of (polyline index, segment index, crossing point (3,))
    """
    c = at * reach
    arms: list[tuple[int, int, np.ndarray]] = []
    cos_max = np.cos(np.radians(RADIAL_DEG))
    for i, (p, d) in enumerate(zip(polys, dists, strict=True)):
        da, db = d[:-1], d[1:]
        length = np.linalg.norm(p[1:] - p[:-1], axis=1)
        cross = ((da - c) * (db - c) < 0) | ((da == c) & (db != c))
        cross &= _radial_cos(da, db, length) >= cos_max
        for k in np.flatnonzero(cross):
            t = (c - da[k]) / (db[k] - da[k])
            x = p[k] + t * (p[k + 1] - p[k])
            if all(np.linalg.norm(x - y) >= 0.05 * c for _, _, y in arms):
                arms.append((i, int(k), x))
    return arms


def _arms_inside(polys, dists, reach: float, at: float, inside: float):
    """Per radial arm, its points and distances from the innermost point out to ``inside``
    reach (the last point cut on that circle)."""
    lim = inside * reach
    for i, k, _ in radial_arms(polys, dists, reach, at):
        p, d = polys[i], dists[i]
        lo, hi = k, k + 1  # the crossing segment's point indices
        while lo > 0 and d[lo - 1] <= lim:
            lo -= 1
        while hi < len(d) - 1 and d[hi + 1] <= lim:
            hi += 1
        inner = lo + int(np.argmin(d[lo:hi + 1]))
        if inner <= k:  # the arm runs from `inner` forward, out past the crossing
            idx, nxt = np.arange(inner, hi + 1), hi + 1
        else:
            idx, nxt = np.arange(inner, lo - 1, -1), lo - 1
        seg, ds = p[idx], d[idx]
        if 0 <= nxt < len(d) and np.isfinite(d[nxt]) and d[nxt] > lim > ds[-1]:
            t = (lim - ds[-1]) / (d[nxt] - ds[-1])
            seg = np.vstack([seg, seg[-1] + t * (p[nxt] - seg[-1])])
            ds = np.append(ds, lim)
        yield seg, ds


def arm_straightness(
    polys: list[np.ndarray],
    dists: list[np.ndarray],
    reach: float,
    at: float = 0.3,
    inside: float = 0.6,
    geodesic: bool = False,
) -> np.ndarray:
    """Chord / arc length of each radial arm (:func:`radial_arms`) inside ``inside * reach``.

    An arm is the run of its polyline around its crossing whose points lie within ``inside``
    reach (cut on that circle), from the run's point nearest the impact outward, so two arms
    one polyline joins through the impact are measured apart.  The chord is the straight 3-D
    one, so on a curved surface even a geodesic arm scores below 1 (an arm folding round an
    ear's rim scores ~0.3); ``geodesic=True`` uses the gain in surface distance from the
    impact instead (``(d_end - d_start) / arc``: 1 for a geodesic radial arm on any surface).

    Returns
    -------
    (A,) float64
        One value per arm, in (0, 1].
    """
    out = []
    for seg, ds in _arms_inside(polys, dists, reach, at, inside):
        arc = np.linalg.norm(np.diff(seg, axis=0), axis=1).sum()
        if arc > 0:
            chord = ds[-1] - ds[0] if geodesic else np.linalg.norm(seg[-1] - seg[0])
            out.append(min(chord / arc, 1.0))
    return np.asarray(out, dtype=np.float64)


def tangential_share(
    polys: list[np.ndarray], dists: list[np.ndarray], reach: float,
    band: tuple[float, float] = (0.35, 0.65),
) -> float:
    """Share of the crack length in ``band`` (fractions of ``reach``) running more than
    :data:`RADIAL_DEG` off the radial direction; ``nan`` without crack length there."""
    _, _, da, db, length = _segments(polys, dists)
    part = _band_length(da, db, length, band[0] * reach, band[1] * reach)
    total = part.sum()
    if not total > 0:
        return float("nan")
    tangential = _radial_cos(da, db, length) < np.cos(np.radians(RADIAL_DEG))
    return float(part[tangential].sum() / total)


def annulus_areas(reach: float, bins: int = 5, vertices=None, faces=None, node_distance=None):
    """Surface area of the annuli ``[k, k + 1) * reach / bins``, (bins,), mesh units squared.

    Without a mesh: the plane's ``pi (r_1^2 - r_0^2)``.  With a (fine) mesh and the distance
    at its nodes: the area of the faces whose mean corner distance falls in each annulus.
    """
    edges = np.linspace(0.0, reach, bins + 1)
    if vertices is None:
        return np.pi * np.diff(edges**2)
    from crackbake.geometry import face_areas

    f = np.asarray(faces, dtype=np.int64)
    d = np.asarray(node_distance, dtype=np.float64)[f].mean(axis=1)
    ok = np.isfinite(d) & (d < reach)
    idx = np.minimum((d[ok] / reach * bins).astype(np.int64), bins - 1)
    return np.bincount(idx, face_areas(np.asarray(vertices, float), f)[ok], minlength=bins)


def annulus_density(
    polys: list[np.ndarray], dists: list[np.ndarray], reach: float, bins: int = 5,
    areas: np.ndarray | None = None,
) -> np.ndarray:
    """Crack length per unit area in ``bins`` annuli of width ``reach / bins``, (bins,).

    ``areas`` (bins,) default to plane annuli (:func:`annulus_areas`); units 1 / mesh unit.
    """
    _, _, da, db, length = _segments(polys, dists)
    edges = np.linspace(0.0, reach, bins + 1)
    lengths = np.array([_band_length(da, db, length, lo, hi).sum()
                        for lo, hi in zip(edges[:-1], edges[1:], strict=True)])
    areas = annulus_areas(reach, bins) if areas is None else np.asarray(areas, float)
    return lengths / np.where(areas > 0, areas, np.inf)


def length_beyond(polys: list[np.ndarray], dists: list[np.ndarray], reach: float) -> float:
    """Crack length farther than ``reach`` from the impact (unreached points count), mesh units."""
    _, _, da, db, length = _segments(polys, dists)
    return float(_band_length(da, db, length, reach, np.inf).sum())


def star_metrics(
    network: Any,
    impact: np.ndarray,
    reach: float,
    vertices: np.ndarray | None = None,
    faces: np.ndarray | None = None,
    bins: int = 5,
    others: list | None = None,
    link: float | None = None,
) -> dict:
    """Every star measure of one impact.

    Parameters
    ----------
    network : CrackNetwork, cracks.json dict or list of (N, 3) arrays
    impact : (3,) array_like
        Impact point, mesh units.
    reach : float
        The impact's reach, mesh units (:func:`impact_reach` of its radius).
    vertices, faces : optional
        A fine triangle mesh of the surface for geodesic distances (see
        :func:`surface_distance`); without it distances are straight (a plate).
    bins : int
        Annuli of the density profile.
    others : list of (point (3,), reach), optional
        The other impacts of the run: the star is measured on its own cracks only
        (:func:`own_cracks`).
    link : float, optional
        Touching shells closer than this are one surface (:func:`surface_distance`).

    Returns
    -------
    dict
        ``arms`` (int), ``straightness`` (per-arm array), ``straight_median``,
        ``straight_min``, ``radial_median`` (median geodesic straightness,
        :func:`arm_straightness`), ``tangential`` (float), ``density`` (bins,) 1 / mesh unit,
        ``falling`` (bool: every annulus at most as dense as the one inside it),
        ``beyond`` (mesh units), ``length`` (total, mesh units).
    """
    polys = polylines(network)
    if others:
        polys = own_cracks(polys, impact, reach, others)
    flat = np.concatenate(polys) if polys else np.zeros((0, 3))
    if vertices is not None and faces is not None and link is None:
        link = mean_edge(vertices, faces)
    d_all = surface_distance(flat, impact, vertices, faces, max_distance=2.0 * reach, link=link)
    split = np.cumsum([len(p) for p in polys])[:-1]
    dists = np.split(d_all, split) if polys else []
    areas = None
    if vertices is not None and faces is not None:
        node = surface_distance(vertices, impact, vertices, faces, max_distance=2.0 * reach,
                                link=link)
        areas = annulus_areas(reach, bins, vertices, faces, node)
    straight = arm_straightness(polys, dists, reach)
    radial = arm_straightness(polys, dists, reach, geodesic=True)
    density = annulus_density(polys, dists, reach, bins, areas)
    return {
        "arms": len(radial_arms(polys, dists, reach)),
        "straightness": straight,
        "straight_median": float(np.median(straight)) if len(straight) else float("nan"),
        "straight_min": float(straight.min()) if len(straight) else float("nan"),
        "radial_median": float(np.median(radial)) if len(radial) else float("nan"),
        "tangential": tangential_share(polys, dists, reach),
        "density": density,
        "falling": bool(np.all(np.diff(density) <= 0)),
        "beyond": length_beyond(polys, dists, reach),
        "length": float(sum(np.linalg.norm(np.diff(p, axis=0), axis=1).sum() for p in polys)),
    }


def trimmed_mean(values: np.ndarray, trim: float = TRIM) -> float:
    """Mean of ``values`` (K,) without the ``floor(trim K)`` lowest and highest; ``nan`` when
    empty.  One crack following a crease (straightness 0.3) does not sink a star's mean, and
    two straight arms do not lift a web's median."""
    v = np.sort(np.asarray(values, dtype=np.float64).reshape(-1))
    if len(v) == 0:
        return float("nan")
    cut = int(np.floor(trim * len(v)))
    return float(v[cut:len(v) - cut].mean())


def star_checks(network: Any, vertices: np.ndarray | None = None,
                faces: np.ndarray | None = None,
                link: float | None = None) -> list[tuple[dict, int, float]]:
    """Per impact of ``network``: its radial arms and how straight they run out.

    Per impact, on its own cracks (:func:`own_cracks`), the radial arms crossing the circle at
    0.3 reach (:func:`radial_arms`) and the :func:`trimmed_mean` of their geodesic
    straightness inside 0.6 reach (:func:`arm_straightness`), distances over
    ``vertices``/``faces`` (a fine mesh of the surface, the sim mesh; straight without),
    across touching shells closer than ``link`` (the sim edge; :func:`surface_distance`).
    One fast-marching pass per impact, stopped at the reach (none in a run: the stress field's
    distance from the same point is kept, :func:`~crackbake.simulate.stress.impact_distance`).

    Returns
    -------
    list of (impact dict, arms, radial)
        In ``network.impacts`` order; ``radial`` in (0, 1], ``nan`` without arms.
    """
    impacts = list(network.impacts if hasattr(network, "impacts") else network["impacts"])
    polys = polylines(network)
    if vertices is not None and faces is not None and link is None:
        link = mean_edge(vertices, faces)
    out = []
    for k, imp in enumerate(impacts):
        reach = impact_reach(imp["radius"])
        others = [(o["point"], impact_reach(o["radius"]))
                  for i, o in enumerate(impacts) if i != k]
        own = own_cracks(polys, imp["point"], reach, others)
        arms, radial = 0, float("nan")
        if own:
            flat = np.concatenate(own)
            d = surface_distance(flat, imp["point"], vertices, faces, max_distance=reach,
                                 link=link)
            dists = np.split(d, np.cumsum([len(p) for p in own])[:-1])
            arms = len(radial_arms(own, dists, reach))
            radial = trimmed_mean(arm_straightness(own, dists, reach, geodesic=True))
        out.append((imp, arms, radial))
    return out


def missing_stars(network: Any, vertices: np.ndarray | None = None,
                  faces: np.ndarray | None = None,
                  link: float | None = None,
                  checks: list | None = None) -> list[tuple[dict, int]]:
    """The impacts of ``network`` whose cracks hold no star.

    Parameters as :func:`star_checks` (``checks``: its result, when already measured).

    Returns
    -------
    list of (impact dict, arms)
        The impacts (``network.impacts`` entries) with fewer than :data:`STAR_MIN_ARMS` radial
        arms crossing the circle at 0.3 reach.
    """
    if checks is None:
        checks = star_checks(network, vertices, faces, link)
    return [(imp, arms) for imp, arms, _ in checks if arms < STAR_MIN_ARMS]


def web_stars(network: Any, vertices: np.ndarray | None = None,
              faces: np.ndarray | None = None,
              link: float | None = None,
              checks: list | None = None) -> list[tuple[dict, int, float]]:
    """The impacts of ``network`` whose arms are enough for a star but wander: a web of cells.

    Parameters as :func:`star_checks` (``checks``: its result, when already measured).

    Returns
    -------
    list of (impact dict, arms, radial)
        The impacts with at least :data:`STAR_MIN_ARMS` arms whose trimmed-mean geodesic
        straightness is below :data:`STAR_MIN_RADIAL`.
    """
    if checks is None:
        checks = star_checks(network, vertices, faces, link)
    return [(imp, arms, radial) for imp, arms, radial in checks
            if arms >= STAR_MIN_ARMS and radial < STAR_MIN_RADIAL]
