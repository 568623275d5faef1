"""From run parameters to the solve stage's inputs: stress sources and solver settings.

:class:`~crackbake.params.RunParams` speaks the command line's language (presets, relative
widths, impact radii that may be unset); the stress field and the solvers take absolute values.
"""

from __future__ import annotations

import warnings

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh
from crackbake.io.sidecar import jsonable
from crackbake.params import (
    CRACK_WIDTH_REL_DEFAULT,
    IMPACT_RADIUS_REL_DEFAULT,
    RunParams,
    preset_names,
)
from crackbake.simulate.solver import SolverParams

__all__ = ["check_scale", "sidecar_params", "solver_params", "stress_sources"]


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
    # The sources' module alone: the fields' and geodesics' scipy imports are the simulation
    # branch's, after the UV stage (crackbake.simulate.stress imports them on first use).
    from crackbake.simulate.stress.sources import (
        CurvatureSource,
        DirectionalSource,
        ImpactSource,
        NoiseSource,
        ShrinkSource,
        WeightSource,
    )

    if relative.get("needs_impact") and not params.impacts:
        raise CrackbakeError(
            f"preset '{params.preset}' needs an impact point; add --impact X,Y,Z "
            "(a point on or near the surface, mesh units)"
        )
    diagonal = mesh.diagonal
    sources: list = []
    for imp in params.impacts:
        radius = imp.resolved_radius(
            diagonal, relative.get("impact_radius_rel", IMPACT_RADIUS_REL_DEFAULT))
        # A radius the user did not give is fitted to a thin feature (issue 18 §3).
        fit = imp.radius is None and imp.radius_rel is None
        sources.append(ImpactSource(imp.point, radius, imp.strength, hoop=params.hoop, fit=fit,
                                    arms=speed_arms(imp, params)))
    if params.shrink:
        sources.append(ShrinkSource(params.shrink, params.shrink_rate or 0.0))
    elif params.cycles > 1:
        raise CrackbakeError(
            f"--cycles {params.cycles} re-dries a shrinkage network, and this run has no "
            "shrinkage: use a shrinkage preset (--preset mud, crackle or concrete) or --shrink S, "
            "or drop --cycles"
        )
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
        from crackbake.io.images import load_weight_map
        from crackbake.simulate.stress.weights import vertex_weights

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


def speed_arms(imp, params: RunParams) -> float | None:
    """The radial arm count of an impact given a speed (the star-crack law with the run's
    plate), with a warning where the law is extrapolated; None for a strength impact."""
    if imp.speed is None:
        return None
    from crackbake.params.speed import (
        ARMS_FEWEST_DRAWN,
        MATERIAL_DEFAULT,
        THICKNESS_DEFAULT,
        extrapolation_note,
        radial_cracks,
    )

    thickness = params.thickness if params.thickness is not None else THICKNESS_DEFAULT
    note = extrapolation_note(imp.speed, thickness)
    if note:
        warnings.warn(f"impact at speed={imp.speed:g}: {note}", CrackbakeWarning, stacklevel=2)
    arms = radial_cracks(imp.speed, thickness, params.material or MATERIAL_DEFAULT)
    if arms < ARMS_FEWEST_DRAWN - 0.5:
        warnings.warn(
            f"impact at speed={imp.speed:g}: the star-crack law gives {arms:.1f} radial cracks, "
            f"but the solver's stars keep about {ARMS_FEWEST_DRAWN:g}, so this one gets about "
            f"{ARMS_FEWEST_DRAWN:g} (speeds that the law gives at least {ARMS_FEWEST_DRAWN:g} for "
            "follow it)",
            CrackbakeWarning, stacklevel=2)
    return arms


def solver_params(params: RunParams, mesh: Mesh, relative: dict) -> SolverParams:
    """:class:`SolverParams` from a resolved parameter set (relative widths made absolute)."""
    width = params.crack_width
    if width is None:
        width = relative.get("crack_width_rel", CRACK_WIDTH_REL_DEFAULT) * mesh.diagonal
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
        "exr_compression",
        "unwrap_timeout",
        "max_memory",
        "cache",
        "tile",
        "res",
        "padding",
        "dilate",
        "max_distance",
        "profile",
        "cracks",
        "frames",
    }
    return jsonable({k: v for k, v in effective.items() if k not in drop})


#: Supported size of a mesh: its bounding-box diagonal, mesh units.  The GPU bake measures
#: distances to cracks in float32 world units and squares them; crack widths are about 1e-3 of
#: the diagonal, so squared widths underflow float32 (1e-38) below a diagonal of about 1e-13 and
#: squared spans overflow (3e38) above about 1e15.  The bounds keep a margin of 1000 on both.
DIAGONAL_RANGE = (1e-10, 1e10)
#: Largest distance of the bounding-box centre from the origin, in diagonals: float32 positions
#: far from the origin resolve only ~6e-8 of their magnitude, which at 1e3 diagonals is ~1e-4 of
#: the diagonal, a tenth of a default crack width.
MAX_OFFSET_DIAGONALS = 1e3


def check_scale(mesh: Mesh) -> None:
    """Refuse meshes whose size or position the float32 bake cannot resolve.

    Raises
    ------
    CrackbakeError
        The bounding-box diagonal lies outside :data:`DIAGONAL_RANGE`, or the mesh sits more
        than :data:`MAX_OFFSET_DIAGONALS` diagonals from the origin.
    """
    import numpy as np

    diagonal = float(mesh.diagonal)
    lo, hi = DIAGONAL_RANGE
    if not lo <= diagonal <= hi:
        raise CrackbakeError(
            f"the mesh is {diagonal:.3g} units across; crackbake supports sizes from {lo:g} to "
            f"{hi:g} units (the GPU bake works in 32-bit floats): rescale the mesh"
        )
    centre = 0.5 * (np.asarray(mesh.bbox_min) + np.asarray(mesh.bbox_max))
    offset = float(np.linalg.norm(centre))
    if offset > MAX_OFFSET_DIAGONALS * diagonal:
        raise CrackbakeError(
            f"the mesh lies {offset:.3g} units from the origin, {offset / diagonal:.3g} times its "
            f"own size (limit {MAX_OFFSET_DIAGONALS:g}); 32-bit GPU math cannot resolve its "
            "cracks there: move the mesh near the origin"
        )


def with_spacing(field, params: RunParams, diagonal: float):
    """``field`` with the run's ``--spacing`` applied to its shadow radius (mesh units), set
    in place (``field.shadow_radius``) and returned.

    The solver's shadow radius is the field's (an impact's) where given, else
    ``SHADOW_REL`` x the diagonal; ``spacing`` x ``diagonal`` caps either, so a preset or the
    user can ask for a finer network without changing the stress itself.
    """
    if params.spacing is None:
        return field
    radius = float(params.spacing) * float(diagonal)
    current = getattr(field, "shadow_radius", None)
    if current is not None:
        radius = min(radius, float(current))
    field.shadow_radius = radius
    shadows = getattr(field, "impact_shadows", None)
    if shadows:
        field.impact_shadows = [min(float(r), float(params.spacing) * float(diagonal))
                                for r in shadows]
    return field
