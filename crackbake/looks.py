"""How a material's cracks look: the ``[look]`` table of a preset and ``--look KEY=VALUE``.

The crack network says where the cracks run; the look says how they are drawn into the
textures:

=================  =========================================================================
key                meaning
=================  =========================================================================
``color``          sRGB 0..255 crack colour (three numbers): what a crack looks like on the
                   default grey surface (:data:`crackbake.exchange.materials.SURFACE_RGB`)
``mode``           how ``color`` is composited over the base colour by the crack mask:
                   ``darken`` (towards ``min(surface, color)``, times the occlusion: dark
                   grooves), ``lighten`` (towards ``max(surface, color)``, no occlusion: bright
                   fracture lines, e.g. glass) or ``multiply`` (the surface times ``color``,
                   times the occlusion: stains that keep the texture's detail); on a textured
                   asset the texture is scaled by the same ratio the grey surface is
``roughness``      roughness at the crack (linear 0..1); the intact surface keeps
                   :data:`crackbake.exchange.materials.ROUGHNESS_SURFACE`
``normal_strength``  slope scale of the baked normal map (1 = the groove's true slope)
``width_variation``  coefficient of variation that seeded noise along each crack's arc length
                   adds to its width (and depth), 0 = the solver's widths unchanged
``chipping``       relative amplitude of seeded noise on the crack's half width in the bake
                   (ragged, chipped edges), 0 = straight edges
``curl``           raised cell edges: height of a rim beside each crack, as a fraction of the
                   crack's depth (mud's curled cells), 0 = none
=================  =========================================================================

Presets set their own in ``presets/<name>.toml``'s ``[look]`` table; the command line overrides
single keys (``--look mode=lighten --look color=250,250,255``).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, replace

import numpy as np

from crackbake.errors import CrackbakeError

MODES = ("darken", "lighten", "multiply")
#: Correlation length of the width noise along a crack, of the mesh's bounding-box diagonal
#: (several crack widths: the opening swells and narrows, it does not flicker point to point).
WIDTH_NOISE_SCALE = 0.01

#: Numeric keys: (low, high) both included.
_RANGES: dict[str, tuple[float, float]] = {
    "roughness": (0.0, 1.0),
    "normal_strength": (0.0, 100.0),
    "width_variation": (0.0, 4.0),
    "chipping": (0.0, 0.9),
    "curl": (0.0, 1.0),
}


@dataclass(frozen=True)
class Look:
    """The look of one run's cracks (module docstring); the defaults are the historical look:
    near-black, darkened by the occlusion, rough, uniform width, clean edges."""

    color: tuple[float, float, float] = (24.0, 20.0, 18.0)
    mode: str = "darken"
    roughness: float = 1.0
    normal_strength: float = 1.0
    width_variation: float = 0.0
    chipping: float = 0.0
    curl: float = 0.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["color"] = list(self.color)
        return d


KEYS = tuple(Look.__dataclass_fields__)


def _color(value, where: str) -> tuple[float, float, float]:
    if isinstance(value, str):
        value = value.split(",")
    try:
        rgb = tuple(float(c) for c in value)
    except (TypeError, ValueError):
        rgb = ()
    if len(rgb) != 3 or not all(math.isfinite(c) and 0 <= c <= 255 for c in rgb):
        raise CrackbakeError(
            f"{where} color '{value}': give three sRGB values 0..255, e.g. color=24,20,18"
        )
    return rgb  # type: ignore[return-value]


def check_look(values: dict, where: str) -> dict:
    """``values`` checked and converted (colour to a 3-tuple, numbers to float).

    Raises
    ------
    CrackbakeError
        An unknown key, a mode not in :data:`MODES`, a value out of range; one line naming
        ``where`` (the preset or ``--look``) and the fix.
    """
    out = {}
    for key, value in values.items():
        if key not in KEYS:
            raise CrackbakeError(f"{where}: unknown look key '{key}'; use one of {', '.join(KEYS)}")
        if key == "color":
            out[key] = _color(value, where)
        elif key == "mode":
            if value not in MODES:
                raise CrackbakeError(
                    f"{where} mode '{value}' is unknown; use one of {', '.join(MODES)}"
                )
            out[key] = value
        else:
            low, high = _RANGES[key]
            if isinstance(value, str):
                try:
                    value = float(value)
                except ValueError:
                    raise CrackbakeError(f"{where} {key} '{value}' is not a number; give a "
                                         f"number from {low:g} to {high:g}") from None
            ok = (isinstance(value, numbers.Real) and not isinstance(value, bool)
                  and math.isfinite(value) and low <= value <= high)
            if not ok:
                raise CrackbakeError(
                    f"{where} {key} {value} is out of range; use a number from {low:g} to {high:g}"
                )
            out[key] = float(value)
    return out


def parse_look(items) -> dict:
    """``--look KEY=VALUE`` options (repeatable) as a checked dict of overrides."""
    values = {}
    for text in items:
        key, sep, value = str(text).partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key or not value.strip():
            raise CrackbakeError(
                f"--look '{text}': expected KEY=VALUE, e.g. --look mode=lighten; keys: "
                f"{', '.join(KEYS)}"
            )
        values[key] = value.strip()
    return check_look(values, "--look")


def resolve_look(preset: dict, overrides: dict) -> Look:
    """The preset's ``[look]`` table, then ``overrides`` (both checked), over the defaults."""
    look = replace(Look(), **check_look(dict(preset.get("look", {})), "preset [look]"))
    return replace(look, **check_look(dict(overrides), "--look"))


def _arc(points: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def width_factors(points: np.ndarray, variation: float, scale: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Seeded multiplicative width noise along one polyline, (N,) float64 with mean about 1.

    Gaussian values at knots ``scale`` apart along the arc length, joined by a smoothstep,
    exponentiated as a log-normal of coefficient of variation ``variation`` (so the factor is
    always positive and the mean width stays about the same).
    """
    s = _arc(np.asarray(points, np.float64))
    n_knots = int(math.ceil(s[-1] / scale)) + 2
    z = rng.standard_normal(n_knots)
    x = s / scale + rng.random()  # a random phase: knots do not sit at the crack's start
    i = np.minimum(np.floor(x).astype(np.int64), n_knots - 2)
    f = x - i
    f = f * f * (3 - 2 * f)
    # Smoothstep interpolation of unit-variance knots has a variance of (1 - 2f(1-f))^2..1;
    # dividing by its root keeps the noise unit-variance along the whole crack.
    g = ((1 - f) * z[i] + f * z[i + 1]) / np.sqrt((1 - f) ** 2 + f**2)
    sigma = math.sqrt(math.log1p(variation**2))
    return np.exp(sigma * g - 0.5 * sigma**2)


def vary_widths(network, variation: float, seed: int, scale: float):
    """``network`` with each crack's width and depth scaled by :func:`width_factors` (in place).

    Parameters
    ----------
    network : crackbake.network.CrackNetwork
    variation : float
        Coefficient of variation of the factor; 0 leaves the network untouched.
    seed : int
        Run seed; each crack draws from ``(seed, crack id)``, so the result does not depend on
        the order in which cracks are processed.
    scale : float
        Correlation length along the arc, mesh units.
    """
    if variation <= 0 or scale <= 0:
        return network
    for crack in network.cracks:
        rng = np.random.default_rng([int(seed), 0x100C5, int(crack.id)])
        k = width_factors(crack.points, variation, scale, rng)
        crack.width = crack.width * k
        crack.depth = crack.depth * k
    return network


#: Fewest cells a network must cut the surface into for :func:`open_to_cells` to size its
#: widths by them: with fewer, "the cell" is most of the surface and its size says nothing of
#: the pattern (a few cracks across a mesh would open as wide as a tenth of the mesh).
FEWEST_CELLS = 4
#: Sample spacing of the cells :func:`open_to_cells` measures, as a divisor of the surface area
#: over the crack length (:func:`crackbake.metrics.cells.cell_areas` defaults to 16): on mud's
#: plates the cell size comes out within 1 % of the default's at a tenth of its time (a quarter
#: of the samples' squared density loses the smallest cells: 7 % larger).
CELL_SPACING_DIVISOR = 6.0


def open_to_cells(network, share: float, vertices: np.ndarray,
                  faces: np.ndarray) -> tuple[float, int]:
    """Scale every crack's width and depth (in place) so that the length-weighted mean width is
    ``share`` of the cell size, the square root of the mean area of the cells the cracks cut
    the surface into (:func:`crackbake.metrics.cells.cell_areas`, samples
    :data:`CELL_SPACING_DIVISOR` per area / length).

    A shrinking layer opens each gap by about its strain times the span of the cells beside it,
    so the gap over the cell size is the material's (drying clay: a few per cent) whatever the
    mesh's size or the number of cracks; a width relative to the mesh's diagonal opens the same
    pattern 3 % of its cell size on one mesh and 5 % on another.  The widths keep their shape
    along and between the cracks (the solver's openings, the look's noise).

    Parameters
    ----------
    network : crackbake.network.CrackNetwork
    share : float
        Mean width over the cell size, > 0.
    vertices : (V, 3) float, faces : (F, 3) int
        The surface the cracks lie on (the asset mesh).

    Returns
    -------
    factor : float
        The scale applied; 1.0 (the network untouched) when it cuts fewer than
        :data:`FEWEST_CELLS` cells or has no width.
    cells : int
        Cells measured.
    """
    from crackbake.geometry import face_areas
    from crackbake.metrics.cells import cell_areas

    pts = [c.points for c in network.cracks if len(c.points) >= 2]
    if not pts:
        return 1.0, 0
    seg = np.concatenate([np.linalg.norm(np.diff(c.points, axis=0), axis=1)
                          for c in network.cracks if len(c.points) >= 2])
    mid = np.concatenate([0.5 * (c.width[:-1] + c.width[1:])
                          for c in network.cracks if len(c.points) >= 2])
    if not seg.sum() > 0:
        return 1.0, 0
    mean_width = float((seg * mid).sum() / seg.sum())
    total = float(face_areas(np.asarray(vertices, np.float64), np.asarray(faces, np.int64)).sum())
    areas = cell_areas(vertices, faces, pts, spacing=total / seg.sum() / CELL_SPACING_DIVISOR)
    if len(areas) < FEWEST_CELLS or not mean_width > 0:
        return 1.0, len(areas)
    factor = share * math.sqrt(float(areas.mean())) / mean_width
    for crack in network.cracks:
        crack.width = crack.width * factor
        crack.depth = crack.depth * factor
    return factor, len(areas)
