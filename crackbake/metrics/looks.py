"""How a network's cracks will look: their width against the cells, the surface share they open
and how much their width varies along each crack.

* ``width_cell_ratio``: the length-weighted mean width over the cell size (the square root of
  the mean cell area, :func:`crackbake.metrics.cells.cell_areas`);
* ``crack_area_share``: the area the cracks open (each segment's length times its mean width),
  over the surface area: the share of the surface the mask covers, junction overlaps counted
  twice;
* ``width_cv``: per polyline, the coefficient of variation (std / mean, length-weighted over its
  segments) of its width; the median over the polylines with at least ``min_points`` points.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from crackbake.geometry import face_areas

__all__ = ["crack_area_share", "width_cell_ratio", "width_cv"]


def _segment_widths(points: np.ndarray, width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return seg, 0.5 * (width[:-1] + width[1:])


def width_cv(polylines: Sequence[np.ndarray], widths: Sequence[np.ndarray],
             min_points: int = 5) -> float:
    """Median over the polylines of the coefficient of variation of the width along each.

    Parameters
    ----------
    polylines : sequence of (N_i, 3) float
        Crack points, mesh units.
    widths : sequence of (N_i,) float
        Width at each point, mesh units.
    min_points : int
        Polylines with fewer points are left out (too short to vary).

    Returns
    -------
    float
        Dimensionless; NaN when no polyline qualifies.
    """
    cvs = []
    for p, w in zip(polylines, widths, strict=True):
        p = np.asarray(p, np.float64)
        w = np.asarray(w, np.float64)
        if len(p) < min_points:
            continue
        seg, mid = _segment_widths(p, w)
        total = seg.sum()
        if not total > 0:
            continue
        mean = (seg * mid).sum() / total
        if not mean > 0:
            continue
        std = np.sqrt((seg * (mid - mean) ** 2).sum() / total)
        cvs.append(std / mean)
    return float(np.median(cvs)) if cvs else float("nan")


def crack_area_share(polylines: Sequence[np.ndarray], widths: Sequence[np.ndarray],
                     vertices: np.ndarray, faces: np.ndarray) -> float:
    """Area the cracks open (length x width summed over segments) over the surface area."""
    opened = 0.0
    for p, w in zip(polylines, widths, strict=True):
        p = np.asarray(p, np.float64)
        if len(p) < 2:
            continue
        seg, mid = _segment_widths(p, np.asarray(w, np.float64))
        opened += float((seg * mid).sum())
    total = float(face_areas(np.asarray(vertices, np.float64), np.asarray(faces, np.int64)).sum())
    return opened / total


def width_cell_ratio(mean_width: float, mean_cell_area: float) -> float:
    """Mean crack width over the cell size (the square root of the mean cell area)."""
    return float(mean_width / np.sqrt(mean_cell_area))
