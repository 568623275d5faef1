"""Stress sources: what loads the surface, as frozen dataclasses validated on construction.

Every source is linear in its strength (docs/method.md, "The formulas"): a strength ``s`` is
the principal stress it adds.  :func:`crackbake.simulate.stress.stress_field` turns a list of
them into the field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackbake.errors import CrackbakeError


def _shown(value) -> str:
    """``value`` for a message: numpy scalars and arrays as plain numbers (no ``np.float64``)."""
    try:
        return repr(np.asarray(value).tolist())
    except (TypeError, ValueError):
        return repr(value)


def _finite_vector(value, name: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.array([np.nan])
    if v.shape != (3,) or not np.isfinite(v).all():
        raise CrackbakeError(f"{name} must be three finite numbers x,y,z; got {_shown(value)}")
    return v


def _finite_number(value, name: str, positive: bool = False, nonnegative: bool = False) -> None:
    ok = isinstance(value, int | float | np.floating | np.integer) and np.isfinite(value)
    if ok and positive:
        ok = value > 0
    if ok and nonnegative:
        ok = value >= 0
    if not ok:
        need = "a positive" if positive else "a non-negative" if nonnegative else "a finite"
        raise CrackbakeError(f"{name} must be {need} number; got {_shown(value)}")


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
    fit : bool or None
        True: ``radius`` is a default the user did not choose; on a thin feature (a lobe, a
        sheet's rim, a sharp corner) it is shrunk until the star no longer wraps round the
        feature (:func:`crackbake.simulate.stress.fields.fitted_radius`), with a warning.
        False: a chosen radius, kept, with a warning when its star wraps.  None: a radius
        fitted before (the same run on a rebuilt sim mesh), used as is.
    """

    point: tuple[float, float, float]
    radius: float | None = None
    strength: float = 1.0
    hoop: float = 1.25
    fit: bool | None = False
    arms: float | None = None

    def __post_init__(self) -> None:
        _finite_vector(self.point, "impact point")
        if self.arms is not None:
            _finite_number(self.arms, "impact arm count", positive=True)
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
