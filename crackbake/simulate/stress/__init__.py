"""Initial stress on the simulation mesh: sources, geodesic impact distance, fields, weights.

* :mod:`~crackbake.simulate.stress.sources`: the source dataclasses (impact, shrinkage,
  directional, curvature, painted weights, noise), validated on construction.
* :mod:`~crackbake.simulate.stress.geodesic`: snapping a point to the surface and the geodesic
  distance from it (fast marching, edge-Dijkstra fallback).
* :mod:`~crackbake.simulate.stress.fields`: per-source tensor fields and :func:`stress_field`.
* :mod:`~crackbake.simulate.stress.weights`: painted weights (vertex attributes, weight maps).

The names below are imported from their modules on first use (PEP 562): a run checks its
sources (:func:`crackbake.simulate.setup.stress_sources`) before the UV stage without loading
the fields' and geodesics' scipy.sparse and scipy.spatial, which the simulation branch imports.
"""

from __future__ import annotations

import importlib

# name -> the module that defines it (the package's own unless dotted)
_SOURCES = {
    "LUMA": "crackbake.io.images",
    "load_weight_map": "crackbake.io.images",
    "CURVATURE_CLIP": "fields",
    "NOISE_SCALE_DIAGONAL": "fields",
    "NOISE_WAVES": "fields",
    "StressField": "fields",
    "impact_detail": "fields",
    "impact_refinement": "fields",
    "noise_origin": "fields",
    "stress_field": "fields",
    "impact_distance": "geodesic",
    "iso_length": "geodesic",
    "CurvatureSource": "sources",
    "DirectionalSource": "sources",
    "ImpactSource": "sources",
    "NoiseSource": "sources",
    "ShrinkSource": "sources",
    "WeightSource": "sources",
    "vertex_weights": "weights",
}

__all__ = sorted(_SOURCES)


def __getattr__(name: str):
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    path = module if "." in module else f"{__name__}.{module}"
    value = getattr(importlib.import_module(path), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
