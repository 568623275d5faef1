"""The ``iben`` crack solver: Iben & O'Brien, "Generating Surface Crack Patterns" (2006/2009).

Cracks cut through the triangles of the simulation mesh where the separation tensor of a node
exceeds the toughness, one node per event, most critical first; the stress relaxes near each
event and a world-scale shadow releases it along the cracks.  What the method does, the rules
that keep the pattern independent of the mesh, the measured limits and a map of the modules:
docs/solver.md.
"""

from crackbake.simulate.solver.iben.chain import crack_graph
from crackbake.simulate.solver.iben.constants import (
    LIGAMENT_CONE_DEG,
    LIGAMENT_REL,
    PROGRESS_SECONDS,
    RELAX_RINGS,
    RES_TOLERANCE,
    TIP_REF_FACES,
)
from crackbake.simulate.solver.iben.solve import solve_iben

__all__ = ["LIGAMENT_CONE_DEG", "LIGAMENT_REL", "PROGRESS_SECONDS", "RELAX_RINGS",
           "RES_TOLERANCE", "TIP_REF_FACES", "crack_graph", "solve_iben"]
