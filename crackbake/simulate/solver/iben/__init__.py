"""The ``iben`` crack solver: Iben & O'Brien, "Generating Surface Crack Patterns" (2006/2009).

What the method does, its rules and their measured limits: docs/solver.md.
"""

from crackbake.simulate.solver.iben.chain import crack_graph
from crackbake.simulate.solver.iben.constants import (
    LIGAMENT_CONE_DEG,
    LIGAMENT_REL,
    RELAX_RINGS,
    RES_TOLERANCE,
    TIP_REF_FACES,
)
from crackbake.simulate.solver.iben.solve import solve_iben

__all__ = ["LIGAMENT_CONE_DEG", "LIGAMENT_REL", "RELAX_RINGS", "RES_TOLERANCE",
           "TIP_REF_FACES", "crack_graph", "solve_iben"]
