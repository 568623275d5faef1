"""Impact speed -> number of radial cracks: the star-crack law of broken plates.

Vandenberghe, Vermorel & Villermaux, "Star-shaped crack pattern of broken windows", Phys. Rev.
Lett. 110, 174302 (2013), fired 4 mm steel pellets at glass and Plexiglas (PMMA) plates 0.15-3 mm
thick and counted the radial cracks: their number grows as the square root of the impact speed
for a given plate (1 mm PMMA: about 4 cracks at 20-22 m/s, 8 at 57-78 m/s), and rises with the
plate's stiffness-to-toughness ratio.  crackbake uses

    N = C * (V / c) ** (1/2) * (E h / Gamma) ** (1/3),    c = sqrt(E / rho),

with ``Gamma = K_Ic**2 / E`` (the fracture energy, from the fracture toughness) and ``C``
fitted to the 1 mm PMMA counts.  docs/solver.md ("Impact speed") says which parts are
measured and which are our reading of the paper (its full text was not at hand: the square
root of the speed is the measured law; the thickness and material exponents follow the
secondary accounts and are the extrapolated part).

The law is scale-free in the mesh: N depends on the speed, the plate's thickness and its
material only, so a star at ``speed=V`` has the same arm count on a mesh in metres or in
millimetres.  It costs nothing at run time: the count sets the impact's shadow radius
(:func:`crackbake.simulate.stress.fields.speed_shadow`), one number per impact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from crackbake.errors import CrackbakeError


@dataclass(frozen=True)
class PlateMaterial:
    """Bulk properties of a brittle plate (SI units).

    Attributes
    ----------
    young : float
        Young's modulus E, Pa.
    density : float
        rho, kg/m^3.
    toughness : float
        Mode-I fracture toughness K_Ic, Pa m^0.5.
    """

    young: float
    density: float
    toughness: float

    @property
    def fracture_energy(self) -> float:
        """Gamma = K_Ic^2 / E, J/m^2 (plane stress: a thin plate)."""
        return self.toughness ** 2 / self.young

    @property
    def wave_speed(self) -> float:
        """c = sqrt(E / rho), m/s."""
        return math.sqrt(self.young / self.density)


#: The plates the paper broke: annealed soda-lime glass and PMMA (handbook values).  Tempered
#: glass is left out on purpose: its residual stress dices the whole pane once it breaks, which
#: no star count describes, and the paper did not test it.
MATERIALS: dict[str, PlateMaterial] = {
    "glass": PlateMaterial(young=70e9, density=2500.0, toughness=0.75e6),
    "plexiglas": PlateMaterial(young=3.0e9, density=1190.0, toughness=1.1e6),
}
MATERIAL_DEFAULT = "glass"
#: mm; the middle of the paper's 0.15-3 mm plates.
THICKNESS_DEFAULT = 1.0
#: The measured ranges: outside them the count is extrapolated (one warning).
SPEED_MEASURED = (10.0, 120.0)  # m/s
THICKNESS_MEASURED = (0.15, 3.0)  # mm
#: Accepted values (a typo guard, not physics).
SPEED_MAX = 1000.0  # m/s
THICKNESS_MAX = 100.0  # mm
#: Fewest radial cracks a star is drawn with (the paper's slowest breaking impacts gave 2-4).
ARMS_MIN = 2.0
#: The solver's stars keep about this many arms at 0.3 reach however wide their shadow: a crack
#: through the impact runs both ways and releases the hoop stress across its own line only, so
#: a crossing one and a third follow (benchmarks/bench_speed_law.py: 6.0 arms where the law
#: asks 4.3 or 6.1).  Fewer asked for gets a warning.
ARMS_FEWEST_DRAWN = 6.0


def _fit_constant() -> float:
    """C such that 1 mm PMMA gives N = 0.91 sqrt(V / (m/s)): the least-squares slope of the
    reported counts (4 at 19.4 and 22.2 m/s, 8 at 56.7 and 77.8 m/s) against sqrt(V)."""
    pts = ((19.4, 4.0), (22.2, 4.0), (56.7, 8.0), (77.8, 8.0))
    slope = sum(n * math.sqrt(v) for v, n in pts) / sum(v for v, _ in pts)
    m = MATERIALS["plexiglas"]
    per_root_v = (1.0 / m.wave_speed) ** 0.5 * (m.young * 1e-3 / m.fracture_energy) ** (1.0 / 3.0)
    return slope / per_root_v


#: The law's constant (dimensionless), fitted once to the 1 mm PMMA counts.
LAW_CONSTANT = _fit_constant()


def radial_cracks(speed: float, thickness_mm: float = THICKNESS_DEFAULT,
                  material: str = MATERIAL_DEFAULT) -> float:
    """The mean number of radial cracks of an impact at ``speed`` (m/s) on a plate of
    ``thickness_mm`` (mm) of ``material`` (a :data:`MATERIALS` key).

    Returns
    -------
    float
        N (not rounded: a mean over impacts), at least :data:`ARMS_MIN`.
    """
    m = MATERIALS[material]
    n = (LAW_CONSTANT * (speed / m.wave_speed) ** 0.5
         * (m.young * thickness_mm * 1e-3 / m.fracture_energy) ** (1.0 / 3.0))
    return max(n, ARMS_MIN)


def check_material(name: str | None) -> None:
    """One-line error for an unknown ``--material``."""
    if name is not None and name not in MATERIALS:
        raise CrackbakeError(
            f"--material '{name}' is unknown; use one of {', '.join(MATERIALS)} (the plates the "
            "star-crack law was measured on)"
        )


def extrapolation_note(speed: float, thickness_mm: float) -> str:
    """A one-line warning when ``speed`` or ``thickness_mm`` lies outside the measured
    ranges, else ""."""
    parts = []
    if not SPEED_MEASURED[0] <= speed <= SPEED_MEASURED[1]:
        parts.append(f"speed {speed:g} m/s (measured {SPEED_MEASURED[0]:g}-{SPEED_MEASURED[1]:g})")
    if not THICKNESS_MEASURED[0] <= thickness_mm <= THICKNESS_MEASURED[1]:
        parts.append(f"thickness {thickness_mm:g} mm (measured "
                     f"{THICKNESS_MEASURED[0]:g}-{THICKNESS_MEASURED[1]:g})")
    if not parts:
        return ""
    return ("the star-crack law is extrapolated for " + " and ".join(parts)
            + ": its arm count is a guess there")
