"""Per-network measures of a crack pattern: what tells the material presets apart.

All measures come from the polylines (``cracks.json``) and, for the cell areas, the surface they
lie on:

* ``cracks``, ``length``: polyline count (as in ``cracks.json``: the solver splits a crack where
  another meets it) and total length (mesh units);
* ``mean_width``: length-weighted mean opening width (mesh units);
* ``straightness``: chord / arc of each polyline piece between junctions (a polyline is also cut
  where another crack ends on its inside), length-weighted mean; 1 for straight cracks; given
  the faces the points lie on, geodesic (the chord of the polyline unrolled into the plane);
* ``stem_angle``: mean over the T-junctions (:func:`junctions`: three polyline ends at one point,
  or an end on another polyline's inside) of the angle in degrees between the stem and the
  through-crack, each direction taken over ``scale`` of arc length; 90 for a perpendicular T;
* ``mean_cell_area``: the mean area of the cells the cracks cut the surface into (mesh units^2).

Cells are measured on the surface itself, so the same code runs on a plate and on a closed mesh
(no UV seams, no rasteriser): the surface is sampled uniformly (about 4 points per ``h^2``), the
samples within ``0.75 h`` of a crack are removed, the others joined to their neighbours within
``h`` (on the same side of the surface: normals within 60 degrees), and each connected group is a
cell.  Any neighbour pair straddling a crack has one end within ``h / 2`` of it, so a crack that
closes a cell always separates it; groups below :data:`MIN_CELL_POINTS` samples are noise of the
removal band and are dropped; the removed samples join their nearest cell, so the cell areas add
up to the surface area (the area of one sample times its cell's sample count).  ``h`` defaults
to a sixteenth of ``area / length`` (half the spacing of a square grid of that density).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from crackbake.geometry import face_areas, face_normals

__all__ = ["NetworkStats", "cell_areas", "developed", "junctions", "network_stats", "straightness"]

#: Cells with fewer samples than this are fragments of the removal band, not cells.
MIN_CELL_POINTS = 30
#: Samples per h^2 (about 12 neighbours within h: well above the connectivity threshold).
DENSITY = 4.0
#: Most surface samples one cell measure draws (bounds time and memory).
MAX_SAMPLES = 2_000_000


@dataclass(frozen=True)
class NetworkStats:
    """Measures of one crack network (see the module docstring); NaN where undefined."""

    cracks: int
    length: float
    mean_width: float
    straightness: float
    t_junctions: int
    stem_angle: float
    cells: int
    mean_cell_area: float

    def to_dict(self) -> dict:
        return asdict(self)


def _arc(points: np.ndarray) -> np.ndarray:
    """Cumulative arc length at each point, (N,)."""
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))]


def _at_arc(points: np.ndarray, arc: np.ndarray, s: float) -> np.ndarray:
    """The point at arc length ``s`` (clamped to the ends), (3,)."""
    s = min(max(s, 0.0), arc[-1])
    return np.array([np.interp(s, arc, points[:, k]) for k in range(points.shape[1])])


def _segments(polylines: Sequence[np.ndarray]):
    """Flattened segments: start (S, 3), end (S, 3), owning polyline (S,), arc at start (S,)."""
    a = np.concatenate([p[:-1] for p in polylines])
    b = np.concatenate([p[1:] for p in polylines])
    owner = np.concatenate([np.full(len(p) - 1, i) for i, p in enumerate(polylines)])
    start = np.concatenate([_arc(p)[:-1] for p in polylines])
    return a, b, owner, start


def _direction(p: np.ndarray, end: int, scale: float) -> np.ndarray:
    """Unit direction from the polyline's end ``end`` (0 or -1) into it, over ``scale`` of arc."""
    arc = _arc(p)
    v = _at_arc(p, arc, scale if end == 0 else arc[-1] - scale) - p[end]
    return v / max(float(np.linalg.norm(v)), 1e-300)


def _fold(stem: np.ndarray, through: np.ndarray) -> float:
    """Angle in degrees (0..90) between a stem direction and a through line."""
    c = abs(float(np.dot(stem, through))) / max(float(np.linalg.norm(through)), 1e-300)
    return float(np.degrees(np.arccos(min(c, 1.0))))


def _on_interior(polylines: list[np.ndarray], ends: np.ndarray, pts: np.ndarray, tol: float):
    """Ends lying on the inside of another polyline: (end row, through polyline, arc) each."""
    a, b, owner, start = _segments(polylines)
    seg_len = np.linalg.norm(b - a, axis=1)
    near = cKDTree(0.5 * (a + b)).query_ball_point(pts, 0.5 * float(seg_len.max()) + tol)
    q = np.repeat(np.arange(len(ends)), [len(n) for n in near])
    s = np.concatenate([np.asarray(n, np.int64) for n in near])
    keep = owner[s] != ends[q, 0]  # a crack does not meet itself at its own end
    q, s = q[keep], s[keep]
    ab = b[s] - a[s]
    t = np.clip(np.einsum("ij,ij->i", pts[q] - a[s], ab) / np.maximum(seg_len[s] ** 2, 1e-300),
                0.0, 1.0)
    d = np.linalg.norm(pts[q] - (a[s] + t[:, None] * ab), axis=1)
    arc = start[s] + t * seg_len[s]
    total = np.array([_arc(p)[-1] for p in polylines])[owner[s]]
    inside = (d <= tol) & (arc > tol) & (arc < total - tol)
    q, s, arc, d = q[inside], s[inside], arc[inside], d[inside]
    first = np.unique(q[np.lexsort((d, q))], return_index=True)[1]  # nearest per end
    order = np.lexsort((d, q))[first]
    return [(int(q[k]), int(owner[s[k]]), float(arc[k])) for k in order]


def junctions(polylines: Sequence[np.ndarray], tol: float | None = None,
              scale: float | None = None) -> tuple[np.ndarray, dict[int, list[float]]]:
    """T-junctions of a network and the stem angle at each.

    The solver writes a crack meeting another as polylines split at the junction, so a T is
    usually three polyline ends at one point: the two most nearly opposite branches form the
    through-crack, the third is the stem.  A crack ending on the inside of another polyline is
    a T too (through-crack = that polyline, cut there for :func:`straightness`).  Points where
    four or more ends meet (crossings) have no stem and are not counted.

    Parameters
    ----------
    polylines : sequence of (N_i, 3) float
        The cracks, N_i >= 2.
    tol : float, optional
        Largest gap between ends (or an end and a crack) that still meet, mesh units; default a
        quarter of the median segment length.
    scale : float, optional
        Arc length over which branch directions are taken; default 5 median segment lengths.

    Returns
    -------
    angles : (T,) float
        Stem angle of each T-junction, degrees in 0..90 (90 = perpendicular).
    cuts : dict
        Polyline index -> arc lengths where a stem ends on its inside.
    """
    polylines = [np.asarray(p, np.float64) for p in polylines if len(p) >= 2]
    if len(polylines) < 2:
        return np.zeros(0), {}
    seg = np.concatenate([np.linalg.norm(np.diff(p, axis=0), axis=1) for p in polylines])
    tol = 0.25 * float(np.median(seg)) if tol is None else float(tol)
    scale = 5.0 * float(np.median(seg)) if scale is None else float(scale)
    ends = np.array([[i, e] for i in range(len(polylines)) for e in (0, -1)])
    pts = np.array([polylines[i][e] for i, e in ends])
    pairs = cKDTree(pts).query_pairs(tol, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), (len(pts), len(pts)))
    _, node = connected_components(graph, directed=False)
    size = np.bincount(node)
    angles = []
    for n in np.flatnonzero(size == 3):
        dirs = np.array([_direction(polylines[i], e, scale) for i, e in ends[node == n]])
        dots = [(float(dirs[i] @ dirs[j]), i, j) for i, j in ((0, 1), (0, 2), (1, 2))]
        _, i, j = min(dots)  # the most nearly opposite pair runs through
        angles.append(_fold(dirs[3 - i - j], dirs[i] - dirs[j]))
    cuts: dict[int, list[float]] = {}
    lone = size[node] == 1
    for k, through, arc in _on_interior(polylines, ends[lone], pts[lone], tol):
        stem, end = ends[lone][k]
        q = polylines[through]
        qa = _arc(q)
        along = _at_arc(q, qa, arc + scale) - _at_arc(q, qa, arc - scale)
        angles.append(_fold(_direction(polylines[stem], end, scale), along))
        cuts.setdefault(through, []).append(arc)
    return np.array(angles, np.float64), cuts


def developed(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The polyline unrolled into the plane: same segment lengths, turning only by its geodesic
    turning angles (the turn measured in the tangent plane of the surface normal at each point),
    so a crack that runs straight over a curved surface unrolls to a straight line.

    Parameters
    ----------
    points : (N, 3) float
    normals : (N, 3) float
        Unit surface normal at each point.

    Returns
    -------
    (N, 2) float
    """
    d = np.diff(points, axis=0)
    seg = np.linalg.norm(d, axis=1)
    d = d / np.maximum(seg, 1e-300)[:, None]
    n = normals[1:-1]
    a = d[:-1] - np.einsum("ij,ij->i", d[:-1], n)[:, None] * n
    b = d[1:] - np.einsum("ij,ij->i", d[1:], n)[:, None] * n
    turn = np.arctan2(np.einsum("ij,ij->i", np.cross(a, b), n), np.einsum("ij,ij->i", a, b))
    heading = np.r_[0.0, np.cumsum(turn)]
    step = seg[:, None] * np.c_[np.cos(heading), np.sin(heading)]
    return np.vstack([np.zeros((1, 2)), np.cumsum(step, axis=0)])


def straightness(polylines: Sequence[np.ndarray], cuts: dict[int, list[float]] | None = None,
                 normals: Sequence[np.ndarray] | None = None) -> np.ndarray:
    """Chord / arc and arc length of each polyline piece between cuts.

    Parameters
    ----------
    polylines : sequence of (N_i, 3) float
    cuts : dict, optional
        Polyline index -> arc lengths where it is cut (its T-junctions).
    normals : sequence of (N_i, 3) float, optional
        Unit surface normals at the points: the chord is then taken on the :func:`developed`
        polyline (geodesic straightness), so the curvature of the surface itself does not count
        as wandering; without, the chord is the straight 3D distance (exact on a plane).

    Returns
    -------
    (P, 2) float
        Per piece: chord / arc (1 = straight), arc length (mesh units).
    """
    rows = []
    for i, p in enumerate(polylines):
        p = np.asarray(p, np.float64)
        arc = _arc(p)
        if normals is not None and len(p) > 2:
            p = developed(p, np.asarray(normals[i], np.float64))
        marks = np.unique(np.r_[0.0, sorted((cuts or {}).get(i, [])), arc[-1]])
        for s0, s1 in zip(marks[:-1], marks[1:], strict=True):
            if s1 - s0 <= 0:
                continue
            chord = np.linalg.norm(_at_arc(p, arc, s1) - _at_arc(p, arc, s0))
            rows.append((min(chord / (s1 - s0), 1.0), s1 - s0))
    return np.array(rows, np.float64).reshape(-1, 2)


def _surface_samples(vertices, faces, n: int, seed: int):
    """``n`` area-uniform samples on the triangles: points (n, 3) and their face normals."""
    rng = np.random.default_rng(seed)
    area = face_areas(vertices, faces)
    face = rng.choice(len(faces), size=n, p=area / area.sum())
    r = rng.random((n, 2))
    flip = r.sum(axis=1) > 1
    r[flip] = 1 - r[flip]
    tri = vertices[faces[face]]
    pts = tri[:, 0] + r[:, :1] * (tri[:, 1] - tri[:, 0]) + r[:, 1:] * (tri[:, 2] - tri[:, 0])
    return pts, face_normals(vertices, faces)[face]


def _crack_samples(polylines: Sequence[np.ndarray], step: float) -> np.ndarray:
    """Points along every polyline no farther apart than ``step``, (M, 3)."""
    a, b, _, _ = _segments(polylines)
    k = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / step), 1).astype(np.int64)
    seg = np.repeat(np.arange(len(a)), k + 1)
    first = np.repeat(np.cumsum(k + 1) - (k + 1), k + 1)
    t = (np.arange(len(seg)) - first) / k[seg]
    return a[seg] + t[:, None] * (b[seg] - a[seg])


def cell_areas(vertices: np.ndarray, faces: np.ndarray, polylines: Sequence[np.ndarray],
               spacing: float | None = None, seed: int = 0) -> np.ndarray:
    """Areas of the cells the cracks cut the surface into (module docstring), mesh units^2.

    Parameters
    ----------
    vertices : (V, 3) float, faces : (F, 3) int
        The surface the cracks lie on.
    polylines : sequence of (N_i, 3) float
        The cracks.
    spacing : float, optional
        Sample spacing ``h``, mesh units; default ``area / length / 16``, no finer than
        :data:`MAX_SAMPLES` allows.
    seed : int
        Seed of the surface samples (the result is deterministic for a seed).

    Returns
    -------
    (C,) float
        Cell areas, largest first; they sum to the surface area.
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    polylines = [np.asarray(p, np.float64) for p in polylines if len(p) >= 2]
    total = float(face_areas(vertices, faces).sum())
    length = sum(float(_arc(p)[-1]) for p in polylines)
    h = spacing if spacing is not None else (total / length / 16 if length > 0 else total**0.5)
    h = max(h, (DENSITY * total / MAX_SAMPLES) ** 0.5)
    n = int(np.ceil(DENSITY * total / h**2))
    pts, normals = _surface_samples(vertices, faces, n, seed)
    cut = np.zeros(n, bool)
    if polylines:
        # Crack samples h/2 apart: a point within h/2 of a crack is within 0.75 h of a sample.
        tree = cKDTree(_crack_samples(polylines, 0.5 * h))
        cut = np.isfinite(tree.query(pts, distance_upper_bound=0.75 * h)[0])
    kept = np.flatnonzero(~cut)
    pairs = cKDTree(pts[kept]).query_pairs(h, output_type="ndarray")
    same_side = np.einsum("ij,ij->i", normals[kept[pairs[:, 0]]], normals[kept[pairs[:, 1]]]) > 0.5
    pairs = pairs[same_side]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), (len(kept), len(kept)))
    _, label = connected_components(graph, directed=False)
    count = np.bincount(label)
    big = count[label] >= MIN_CELL_POINTS
    if not big.any():
        return np.array([total])
    cells = np.unique(label[big], return_inverse=True)[1]
    # Every other sample joins the nearest cell, so the cells tile the surface.
    owner = np.empty(n, np.int64)
    owner[kept[big]] = cells
    rest = np.setdiff1d(np.arange(n), kept[big], assume_unique=True)
    if len(rest):
        _, nearest = cKDTree(pts[kept[big]]).query(pts[rest])
        owner[rest] = cells[nearest]
    return np.sort(np.bincount(owner) * (total / n))[::-1]


def network_stats(polylines: Sequence[np.ndarray], widths: Sequence[np.ndarray] | None = None,
                  vertices: np.ndarray | None = None, faces: np.ndarray | None = None,
                  point_faces: Sequence[np.ndarray] | None = None, scale: float | None = None,
                  spacing: float | None = None, seed: int = 0) -> NetworkStats:
    """Every measure of the module docstring for one network.

    Parameters
    ----------
    polylines : sequence of (N_i, 3) float
        Crack points (``Crack.points``).
    widths : sequence of (N_i,) float, optional
        Width at each point (``Crack.width``); NaN mean width without.
    vertices, faces : optional
        The surface, for the cells (NaN cell area without).
    point_faces : sequence of (N_i,) int, optional
        Face of ``faces`` holding each point (``Crack.faces``): straightness is then geodesic
        (:func:`straightness` with those faces' normals).
    scale : float, optional
        Arc length over which stem and through directions are taken; default 5 median segment
        lengths (a few simulation edges: the direction the crack takes, not its last zig-zag).
    spacing, seed
        Of :func:`cell_areas`.
    """
    polylines = [np.asarray(p, np.float64) for p in polylines]
    good = [i for i, p in enumerate(polylines) if len(p) >= 2]
    polylines = [polylines[i] for i in good]
    if not polylines:
        nan = float("nan")
        return NetworkStats(0, 0.0, nan, nan, 0, nan, 0, nan)
    seg = np.concatenate([np.linalg.norm(np.diff(p, axis=0), axis=1) for p in polylines])
    length = float(seg.sum())
    mean_width = float("nan")
    if widths is not None:
        w = [np.asarray(widths[i], np.float64) for i in good]
        mid = np.concatenate([0.5 * (x[:-1] + x[1:]) for x in w])
        mean_width = float((mid * seg).sum() / max(length, 1e-300))
    angles, cuts = junctions(polylines, scale=scale)
    normals = None
    if point_faces is not None and vertices is not None and faces is not None:
        fn = face_normals(np.asarray(vertices, np.float64), np.asarray(faces, np.int64))
        normals = [fn[np.asarray(point_faces[i], np.int64)] for i in good]
    pieces = straightness(polylines, cuts, normals)
    straight = float((pieces[:, 0] * pieces[:, 1]).sum() / pieces[:, 1].sum())
    cells = np.zeros(0)
    if vertices is not None and faces is not None:
        cells = cell_areas(vertices, faces, polylines, spacing, seed)
    return NetworkStats(
        cracks=len(polylines),
        length=length,
        mean_width=mean_width,
        straightness=straight,
        t_junctions=len(angles),
        stem_angle=float(angles.mean()) if len(angles) else float("nan"),
        cells=len(cells),
        mean_cell_area=float(cells.mean()) if len(cells) else float("nan"),
    )
