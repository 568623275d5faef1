"""Crack solvers: grow a crack network on the simulation mesh from a stress field.

Two methods share the FEM kernels of :mod:`crackbake.simulate.solver.fem`:

* ``iben`` (default): Iben & O'Brien 2006/2009 — separation tensors, a max-priority queue, cracks
  cut through triangles (edge splits, node splits), residual pushed to the tips, local
  quasi-static relaxation.  :mod:`crackbake.simulate.solver.iben` (docs/solver.md).
* ``thesis``: the 2023 NCCA MSc variant — tensors computed once, each crack grown to its end along
  mesh edges, scalar relaxation between cracks.  :mod:`crackbake.simulate.solver.thesis`.

Both take a :class:`crackbake.simulate.simmesh.SimMesh` and a
:class:`crackbake.simulate.stress.StressField` and return a :class:`SolverResult`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crackbake.errors import CrackbakeError

__all__ = ["CrackPath", "SolverParams", "SolverResult"]


@dataclass(frozen=True)
class SolverParams:
    """Parameters of both crack methods.

    Attributes
    ----------
    method : str
        ``iben`` or ``thesis``.
    toughness : float
        Failure threshold relative to the field's typical separation on this mesh (so it does not
        depend on the simulation resolution); 1 is a moderate value, larger gives fewer cracks.
    tip_factor : float
        Fraction alpha of the excess separation pushed to new crack tips (0..1).
    relax_steps : int
        Relaxation passes after each crack.
    relax_rate : float
        Relaxation strength (iben: virtual displacement per unit force, relative; thesis: unused).
    relax_share : float
        thesis: share of each node's value passed to its neighbours per pass (0..1).
    max_cracks : int
        Stop starting new cracks after this many (cracks already started keep growing).
    max_steps : int
        Stop after this many solver steps (iben: crack events, one node cut each, plus
        shrinkage growth steps; thesis: tip advances).
    max_crack_length : float or None
        Longest single crack, mesh units (``None``: unlimited).
    crack_width : float or None
        Widest crack opening, mesh units (``None``: 0.1 % of the bounding-box diagonal).
    depth_ratio : float
        Crack depth = depth_ratio x width.
    seed : int
        Random seed (tie-breaking, jitter).
    """

    method: str = "iben"
    toughness: float = 0.7
    tip_factor: float = 0.75
    relax_steps: int = 10
    relax_rate: float = 0.6
    relax_share: float = 0.05
    max_cracks: int = 500
    max_steps: int = 100000
    max_crack_length: float | None = None
    crack_width: float | None = None
    depth_ratio: float = 0.5
    seed: int = 0

    def validate(self) -> None:
        """Raise :class:`crackbake.errors.CrackbakeError` naming the first value out of range.

        The one check of these parameters; the solvers call it before they start.
        """
        if not self.toughness > 0:
            raise CrackbakeError(f"toughness is {self.toughness}; it must be > 0 (try 1.0)")
        if not 0 <= self.tip_factor <= 1:
            raise CrackbakeError(
                f"tip factor is {self.tip_factor}; it must be in [0, 1] (try 0.75)")
        if not 0.0 <= self.relax_share <= 1.0:
            raise CrackbakeError(
                f"relax share is {self.relax_share}; it must be in [0, 1] (try 0.05)")
        if self.relax_steps < 0 or not self.relax_rate >= 0:
            raise CrackbakeError("relax steps and relax rate must be >= 0 (try 3 and 0.1)")
        if self.max_cracks < 0 or self.max_steps < 0:
            raise CrackbakeError("max cracks and max steps must be >= 0")
        if self.max_crack_length is not None and not self.max_crack_length > 0:
            raise CrackbakeError(
                f"max crack length is {self.max_crack_length}; it must be > 0 mesh units"
            )
        if self.crack_width is not None and not self.crack_width > 0:
            raise CrackbakeError(f"crack width is {self.crack_width}; it must be > 0 mesh units")
        if not self.depth_ratio >= 0:
            raise CrackbakeError(f"depth ratio is {self.depth_ratio}; it must be >= 0")


@dataclass(eq=False)
class CrackPath:
    """One crack polyline on the surface.

    Attributes
    ----------
    points : (N, 3) float64
        Mesh units, on the surface; N >= 2.
    asset_faces : (N,) int64
        Asset (output-mesh) face holding each point.
    time : (N,) float64
        0..1, when the point cracked (solver step / total steps).
    width : (N,) float64
        Opening width, mesh units, tapering to 0 at free tips.
    depth : (N,) float64
        Mesh units.
    """

    points: np.ndarray
    asset_faces: np.ndarray
    time: np.ndarray
    width: np.ndarray
    depth: np.ndarray


@dataclass(eq=False)
class SolverResult:
    """What a solver run produced.

    Attributes
    ----------
    cracks : list of CrackPath
    vertices, faces : (N', 3), (M', 3)
        The simulation mesh after all splits.
    asset_face : (M',) int64
        Asset face of each final sim face.
    stress_initial : (M, 3, 3)
        Stress per *initial* sim face before any crack.
    stress_final : (M', 3, 3)
        Stress per final sim face.
    separation : (N',) float64
        Largest separation eigenvalue per final node, relative to the toughness (>= 1 failed).
    separation_initial : (N,) float64 or None
        The same per *initial* node before any crack (the solver's own starting values).
    steps : int
        Solver steps taken.
    stats : dict
        Method-specific figures (counts, timings) for reports.
    origins : (K, 6) float64
        Each distinct crack, in the order they started: ``x, y, z`` where it started (mesh
        units), the solver step, 1 when it started on a crack or the mesh boundary (0 inside
        the material), and its total length (mesh units, all its branches).
    """

    cracks: list[CrackPath]
    vertices: np.ndarray
    faces: np.ndarray
    asset_face: np.ndarray
    stress_initial: np.ndarray
    stress_final: np.ndarray
    separation: np.ndarray
    steps: int
    stats: dict = field(default_factory=dict)
    origins: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    separation_initial: np.ndarray | None = None
