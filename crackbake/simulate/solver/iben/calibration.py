"""Per-run calibration: flaws, footprint factor, percentile reference, shadow grid."""

from __future__ import annotations

import numpy as np

from crackbake.simulate.solver.iben.constants import (
    FLAW,
    FLAW_WAVELENGTH,
    FLAW_WAVES,
    FOOTPRINT_CLIP,
    FOOTPRINT_MIN_LOADED,
    FOOTPRINT_REL,
    REF_PERCENTILE,
    SHADOW_MAX_CELLS,
    SHADOW_REL,
)


def flaw(seed: int, points: np.ndarray) -> np.ndarray:
    """Seeded toughness factors per node, a smooth world-space field in [1 - FLAW, 1 + FLAW].

    The flaws live in world space (a sum of plane waves of wavelength ``FLAW_WAVELENGTH`` x the
    bounding-box diagonal), not per node: cracks then start at the same weak spots whatever the
    simulation resolution, which keeps the crack count resolution independent.
    """
    rng = np.random.default_rng(seed)
    diag = float(np.linalg.norm(points.max(0) - points.min(0))) or 1.0
    k = 2 * np.pi / (FLAW_WAVELENGTH * diag)
    dirs = rng.normal(size=(FLAW_WAVES, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, FLAW_WAVES)
    noise = np.cos(k * points @ dirs.T + phase).sum(1) / np.sqrt(FLAW_WAVES / 2)
    return 1.0 + FLAW * np.tanh(noise)


def surface_wide(norm_sep: np.ndarray, bnd: np.ndarray) -> bool:
    """Whether at least ``FOOTPRINT_MIN_LOADED`` of the interior nodes are loaded."""
    use = (~bnd) & (norm_sep > 0)
    return bool(use.any()) and not use.sum() < FOOTPRINT_MIN_LOADED * max(int((~bnd).sum()), 1)


def footprint_factor(points: np.ndarray, norm_sep: np.ndarray, bnd: np.ndarray) -> np.ndarray:
    """Per-node toughness factor that hides sub-footprint fluctuations of the initial field.

    The initial normalised separation ``v+ / h`` of interior nodes is averaged over a world grid
    of cell ``FOOTPRINT_REL`` x the bounding-box diagonal (trilinear splat and read-back); a
    node's factor is its value over that local mean (clipped to ``FOOTPRINT_CLIP``), so it fails
    when the *footprint's* separation, not its own, exceeds the toughness.  Fluctuations finer
    than the footprint (stress noise, mesh irregularity) are resolved ever better as the sim
    mesh refines and put ever higher peaks in the field: without this the number of cracks
    nucleated grew with the resolution (spot, crackle: +28 % from 100k to 400k faces).
    Boundary nodes and nodes without separation get 1, and so do all nodes when fewer than
    ``FOOTPRINT_MIN_LOADED`` of the interior nodes are loaded (a localized field such as an
    impact, whose own structure would be flattened: tests/test_iben.py radial density).
    """
    n = len(points)
    fac = np.ones(n)
    use = (~bnd) & (norm_sep > 0)
    if not surface_wide(norm_sep, bnd):
        return fac
    lo = points.min(0)
    diag = float(np.linalg.norm(points.max(0) - lo)) or 1.0
    cell = FOOTPRINT_REL * diag
    u = (points - lo) / cell
    dims = np.floor(u.max(0)).astype(np.int64) + 2
    i0 = np.minimum(np.floor(u).astype(np.int64), dims - 2)
    w = u - i0
    acc = np.zeros(int(np.prod(dims)))
    wsum = np.zeros_like(acc)
    corners = []
    for a in (0, 1):
        for b in (0, 1):
            for c in (0, 1):
                idx = np.ravel_multi_index(((i0[:, 0] + a), (i0[:, 1] + b), (i0[:, 2] + c)),
                                           dims)
                wt = ((w[:, 0] if a else 1 - w[:, 0]) * (w[:, 1] if b else 1 - w[:, 1])
                      * (w[:, 2] if c else 1 - w[:, 2]))
                corners.append((idx, wt))
                acc += np.bincount(idx[use], wt[use] * norm_sep[use], minlength=len(acc))
                wsum += np.bincount(idx[use], wt[use], minlength=len(acc))
    mean = np.divide(acc, wsum, out=np.zeros_like(acc), where=wsum > 0)
    num = np.zeros(n)
    den = np.zeros(n)
    for idx, wt in corners:
        wt = wt * (wsum[idx] > 0)
        num += wt * mean[idx]
        den += wt
    local = np.divide(num, den, out=np.zeros(n), where=den > 0)
    ok = use & (local > 0)
    fac[ok] = np.clip(norm_sep[ok] / local[ok], 1.0 / FOOTPRINT_CLIP, FOOTPRINT_CLIP)
    return fac


def percentile_ref(norm_sep: np.ndarray, bnd: np.ndarray) -> float:
    """REF_PERCENTILE of the positive normalised separations ``v+ / h`` of interior nodes.

    Falls back to all nodes when no interior node has a positive separation; 0 when none has.
    """
    pool = norm_sep[(~bnd) & (norm_sep > 0)]
    if len(pool) == 0:
        pool = norm_sep[norm_sep > 0]
    return float(np.percentile(pool, REF_PERCENTILE)) if len(pool) else 0.0


def shadow_grid(
    X0: np.ndarray, period: float = 0.0, radius: float | None = None,
    largest: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Empty shadow grid over the bounding box and its parameters ``origin (3), cell, radius``
    (5,).

    ``radius`` (mesh units) is the shadow radius a localized field asks for (an impact's
    star scales with the impact, not with the mesh: ``StressField.shadow_radius``); ``None``
    or a larger value gives ``SHADOW_REL`` x the bounding-box diagonal, or ``largest`` (mesh
    units) where given (``StressField.shadow_max``: a slow speed impact's few wide wedges).

    With ``period`` > 0 (a square periodic plate ``[0, period)²``, docs/solver.md "Periodic
    plates") the grid spans exactly one period in x and y, so its cells wrap around.
    """
    if period > 0.0:
        return _periodic_grid(X0, period, radius)
    lo, hi = X0.min(0), X0.max(0)
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    cap = SHADOW_REL * diag if largest is None else float(largest)
    radius = SHADOW_REL * diag if radius is None else min(float(radius), cap)
    cell = radius / 3.0
    pad = 2
    while True:
        dims = np.floor((hi - lo) / cell).astype(np.int64) + 1 + 2 * pad
        if int(np.prod(dims)) <= SHADOW_MAX_CELLS:
            break
        cell *= 1.25
    origin = lo - pad * cell
    G = np.zeros((int(dims[0]), int(dims[1]), int(dims[2]), 6))
    return G, np.array([origin[0], origin[1], origin[2], cell, radius])


def _periodic_grid(
    X0: np.ndarray, period: float, radius: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The shadow grid of a periodic plate: radius from the period's diagonal, as on a plate
    (or ``radius`` where that is smaller)."""
    full = SHADOW_REL * float(np.hypot(period, period))
    radius = full if radius is None else min(float(radius), full)
    n = max(int(np.ceil(period / (radius / 3.0))), 4)
    while n * n * 5 > SHADOW_MAX_CELLS:
        n = int(n / 1.25)
    cell = period / n
    z0 = float(X0[:, 2].min()) - 2 * cell
    return np.zeros((n, n, 5, 6)), np.array([0.0, 0.0, z0, cell, radius])
