"""From run parameters to the solve stage's inputs: stress sources and solver settings.

:class:`~crackbake.params.RunParams` speaks the command line's language (presets, relative
widths, impact radii that may be unset); the stress field and the solvers take absolute values.
"""

from __future__ import annotations

from crackbake.errors import CrackbakeError
from crackbake.io.mesh import Mesh
from crackbake.io.sidecar import jsonable
from crackbake.params import IMPACT_RADIUS_REL_DEFAULT, RunParams, preset_names
from crackbake.simulate.solver import SolverParams

__all__ = ["sidecar_params", "solver_params", "stress_sources"]


def stress_sources(params: RunParams, mesh: Mesh, relative: dict) -> list:
    """The stress sources a (resolved) parameter set asks for.

    Parameters
    ----------
    params : RunParams
        Resolved (:meth:`RunParams.resolved`).
    mesh : Mesh
        The asset mesh (its diagonal scales relative radii).
    relative : dict
        Preset settings relative to the mesh size, from :meth:`RunParams.resolved`.

    Returns
    -------
    list
        :mod:`crackbake.simulate.stress` source objects, in the order the field sums them.

    Raises
    ------
    CrackbakeError
        When nothing would load the surface, or a preset needs an impact that is missing.
    """
    from crackbake.simulate.stress import (
        CurvatureSource,
        DirectionalSource,
        ImpactSource,
        NoiseSource,
        ShrinkSource,
        WeightSource,
        load_weight_map,
        vertex_weights,
    )

    if relative.get("needs_impact") and not params.impacts:
        raise CrackbakeError(
            f"preset '{params.preset}' needs an impact point; add --impact X,Y,Z "
            "(a point on or near the surface, mesh units)"
        )
    diagonal = mesh.diagonal
    sources: list = []
    for imp in params.impacts:
        radius = imp.radius
        if radius is None:
            radius = relative.get("impact_radius_rel", IMPACT_RADIUS_REL_DEFAULT) * diagonal
        sources.append(ImpactSource(imp.point, radius, imp.strength, hoop=params.hoop))
    if params.shrink:
        sources.append(ShrinkSource(params.shrink, params.shrink_rate or 0.0))
    for x, y, z, strength in params.directions:
        sources.append(DirectionalSource((x, y, z), strength))
    if params.curvature_bias or params.curvature_density:
        sources.append(
            CurvatureSource(params.curvature_bias or 0.0, params.curvature_density or 0.0)
        )
    if not sources:
        raise CrackbakeError(
            "nothing to crack: give --impact X,Y,Z, --shrink S, --direction X,Y,Z, --curvature B "
            f"or a --preset ({', '.join(preset_names())}), or bake a network with --cracks"
        )
    if params.weight_map is not None or params.weight_attribute is not None:
        per_vertex = (
            vertex_weights(mesh, params.weight_attribute)
            if params.weight_attribute is not None
            else None
        )
        image = load_weight_map(params.weight_map) if params.weight_map is not None else None
        sources.append(WeightSource(per_vertex, image, params.weight_invert))
    if params.noise:
        sources.append(NoiseSource(params.noise))
    return sources


def solver_params(params: RunParams, mesh: Mesh, relative: dict) -> SolverParams:
    """:class:`SolverParams` from a resolved parameter set (relative widths made absolute)."""
    width = params.crack_width
    if width is None:
        width = relative.get("crack_width_rel", 0.001) * mesh.diagonal
    return SolverParams(
        method=params.method or "iben",
        toughness=params.toughness,
        tip_factor=params.tip_factor,
        relax_steps=params.relax_steps,
        relax_rate=params.relax_rate,
        relax_share=params.relax_share,
        max_cracks=params.max_cracks,
        max_steps=params.max_steps,
        max_crack_length=params.max_crack_length,
        crack_width=width,
        depth_ratio=params.depth_ratio,
        seed=params.seed,
    )


def sidecar_params(effective: dict) -> dict:
    """Parameters stored in the sidecar: everything that shapes the network, no output paths."""
    drop = {
        "out",
        "formats",
        "float32",
        "unwrap_timeout",
        "cache",
        "tile",
        "res",
        "padding",
        "dilate",
        "max_distance",
        "profile",
        "cracks",
    }
    return jsonable({k: v for k, v in effective.items() if k not in drop})
