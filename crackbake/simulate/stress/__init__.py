"""Initial stress on the simulation mesh: sources, geodesic impact distance, fields, weights.

* :mod:`~crackbake.simulate.stress.sources`: the source dataclasses (impact, shrinkage,
  directional, curvature, painted weights, noise), validated on construction.
* :mod:`~crackbake.simulate.stress.geodesic`: snapping a point to the surface and the geodesic
  distance from it (fast marching, edge-Dijkstra fallback).
* :mod:`~crackbake.simulate.stress.fields`: per-source tensor fields and :func:`stress_field`.
* :mod:`~crackbake.simulate.stress.weights`: painted weights (vertex attributes, weight maps).
"""

from crackbake.io.images import LUMA, load_weight_map
from crackbake.simulate.stress.fields import (
    CURVATURE_CLIP,
    NOISE_SCALE_DIAGONAL,
    NOISE_WAVES,
    StressField,
    impact_detail,
    impact_refinement,
    noise_origin,
    stress_field,
)
from crackbake.simulate.stress.geodesic import impact_distance, iso_length
from crackbake.simulate.stress.sources import (
    CurvatureSource,
    DirectionalSource,
    ImpactSource,
    NoiseSource,
    ShrinkSource,
    WeightSource,
)
from crackbake.simulate.stress.weights import vertex_weights

__all__ = [
    "CURVATURE_CLIP",
    "LUMA",
    "NOISE_SCALE_DIAGONAL",
    "NOISE_WAVES",
    "CurvatureSource",
    "DirectionalSource",
    "ImpactSource",
    "NoiseSource",
    "ShrinkSource",
    "StressField",
    "WeightSource",
    "impact_detail",
    "impact_distance",
    "impact_refinement",
    "noise_origin",
    "iso_length",
    "load_weight_map",
    "stress_field",
    "vertex_weights",
]
