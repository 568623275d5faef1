"""Impacts and directional tension from the command line: parsed and bounded."""

from __future__ import annotations

import math
from dataclasses import dataclass

from crackbake.errors import CrackbakeError
from crackbake.params.ranges import LENGTH_MAX, RADIUS_REL_MAX, STRESS_MAX, check_range


@dataclass(frozen=True)
class Impact:
    """An impact point: where the surface was hit, how wide and how hard.

    Attributes
    ----------
    point : tuple of 3 float
        Mesh units; snapped to the nearest surface point by the solver.
    radius : float or None
        Mesh units; ``None`` picks a default from the mesh size.
    strength : float
        Relative strength (1 = the preset's default).
    radius_rel : float or None
        The radius as a fraction of the mesh's bounding-box diagonal (``--impact X,Y,Z:0.2d``),
        instead of ``radius``.
    speed : float or None
        Impact speed, m/s (``--impact X,Y,Z:speed=V``): the star's radial arm count follows
        the star-crack law (:func:`crackbake.params.speed.radial_cracks`, with the run's
        ``thickness`` and ``material``).  None: the preset's star.
    """

    point: tuple[float, float, float]
    radius: float | None = None
    strength: float = 1.0
    radius_rel: float | None = None
    speed: float | None = None

    def resolved_radius(self, diagonal: float, default_rel: float) -> float:
        """The radius in mesh units on a mesh of bounding-box ``diagonal``.

        ``radius`` when given, else ``radius_rel`` (or ``default_rel`` when neither is set)
        times ``diagonal``.
        """
        if self.radius is not None:
            return float(self.radius)
        rel = self.radius_rel if self.radius_rel is not None else default_rel
        return float(rel) * float(diagonal)

    def to_dict(self) -> dict:
        d = {"point": list(self.point), "radius": self.radius, "strength": self.strength}
        if self.radius_rel is not None:
            d["radius_rel"] = self.radius_rel
        if self.speed is not None:
            d["speed"] = self.speed
        return d


def parse_direction(text: str) -> tuple[float, float, float, float]:
    """Parse ``X,Y,Z[:STRENGTH]`` (directional tension)."""
    syntax = "expected X,Y,Z[:STRENGTH], e.g. --direction 0,1,0:1.5"
    parts = text.strip().split(":")
    try:
        xyz = [float(c) for c in parts[0].split(",")]
        strength = float(parts[1]) if len(parts) > 1 else 1.0
    except ValueError:
        raise CrackbakeError(f"--direction '{text}': {syntax}") from None
    if len(parts) > 2 or len(xyz) != 3 or not all(math.isfinite(c) for c in [*xyz, strength]):
        raise CrackbakeError(f"--direction '{text}': {syntax}")
    if not any(xyz):
        raise CrackbakeError(f"--direction '{text}': the direction must not be zero")
    if abs(strength) > STRESS_MAX or max(abs(c) for c in xyz) > LENGTH_MAX:
        raise CrackbakeError(
            f"--direction '{text}': the strength must lie within +-{STRESS_MAX:g} and the "
            f"direction components within +-{LENGTH_MAX:g}"
        )
    return (xyz[0], xyz[1], xyz[2], strength)


def parse_impact(text: str) -> Impact:
    """Parse ``X,Y,Z[:RADIUS[:STRENGTH]]``; ``RADIUS`` in mesh units, or with a ``d`` suffix
    (``0.2d``) as a fraction of the mesh's bounding-box diagonal.  ``X,Y,Z[:RADIUS]:speed=V``
    gives an impact speed (m/s) in place of the strength (:attr:`Impact.speed`).

    Raises
    ------
    CrackbakeError
        Malformed text, with the expected syntax.
    """
    syntax = ("expected X,Y,Z[:RADIUS[:STRENGTH]] with RADIUS in mesh units or a fraction of "
              "the bounding-box diagonal (0.2d), e.g. --impact 0.1,0.2,0.9:0.3:1.5, or "
              "X,Y,Z[:RADIUS]:speed=V with V in m/s, e.g. --impact 0.1,0.2,0.9:speed=30")
    parts = text.strip().split(":")
    speed = None
    if len(parts) > 1 and parts[-1].strip().lower().startswith("speed="):
        from crackbake.params.speed import SPEED_MAX

        raw_speed = parts.pop().strip()[len("speed="):]
        try:
            speed = float(raw_speed)
        except ValueError:
            raise CrackbakeError(f"--impact '{text}': {syntax}") from None
        if not (math.isfinite(speed) and 0 < speed <= SPEED_MAX):
            raise CrackbakeError(
                f"--impact '{text}': the speed must be a number above 0 up to {SPEED_MAX:g} m/s"
            )
        if len(parts) > 2:
            raise CrackbakeError(f"--impact '{text}': a speed replaces the strength; {syntax}")
    if not 1 <= len(parts) <= 3:
        raise CrackbakeError(f"--impact '{text}': {syntax}")
    raw = parts[1].strip() if len(parts) > 1 else ""
    relative = raw[-1:].lower() == "d"
    try:
        xyz = tuple(float(c) for c in parts[0].split(","))
        radius = float(raw[:-1] if relative else raw) if raw != "" else None
        strength = float(parts[2]) if len(parts) > 2 else 1.0
    except ValueError:
        raise CrackbakeError(f"--impact '{text}': {syntax}") from None
    if len(xyz) != 3 or not all(math.isfinite(c) for c in xyz):
        raise CrackbakeError(f"--impact '{text}': {syntax}")
    high, unit = (RADIUS_REL_MAX, "bounding-box diagonals") if relative else (LENGTH_MAX,
                                                                             "mesh units")
    if radius is not None and not (math.isfinite(radius) and 0 < radius <= high):
        raise CrackbakeError(
            f"--impact '{text}': the radius must be a number above 0 up to {high:g} ({unit})"
        )
    if not (math.isfinite(strength) and 0 < strength <= STRESS_MAX):
        raise CrackbakeError(
            f"--impact '{text}': the strength must be a number above 0 up to {STRESS_MAX:g} "
            "(1 = the preset's own)"
        )
    if relative:
        return Impact(point=xyz, strength=strength, radius_rel=radius,  # type: ignore[arg-type]
                      speed=speed)
    return Impact(point=xyz, radius=radius, strength=strength, speed=speed)  # type: ignore[arg-type]


def check_impact(imp: Impact) -> None:
    """The bounds :func:`parse_impact` applies, for impacts built in code."""
    try:
        xyz = [float(c) for c in imp.point]
    except (TypeError, ValueError):
        xyz = []
    if len(xyz) != 3 or not all(math.isfinite(c) for c in xyz):
        shown = ", ".join(f"{c:g}" for c in xyz) if xyz else repr(imp.point)
        raise CrackbakeError(f"impact point ({shown}): must be three finite numbers x, y, z")
    check_range("impact radius", imp.radius, 0.0, LENGTH_MAX, " mesh units", True)
    check_range("impact radius", imp.radius_rel, 0.0, RADIUS_REL_MAX, " bounding-box diagonals",
                 True)
    if imp.radius is not None and imp.radius_rel is not None:
        raise CrackbakeError(
            "impact radius: give it in mesh units (radius) or as a fraction of the bounding-box "
            "diagonal (radius_rel), not both"
        )
    check_range("impact strength", imp.strength, 0.0, STRESS_MAX, "", True)
    if imp.speed is not None:
        from crackbake.params.speed import SPEED_MAX

        check_range("impact speed", imp.speed, 0.0, SPEED_MAX, " m/s", True)
