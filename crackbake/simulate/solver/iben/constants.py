"""Tuning constants of the iben solver (see docs/solver.md for what they do and why)."""

SNAP_DEG = 10.0
"""Snap the cut to an existing vertex when it runs within this angle of an edge (degrees).
The paper's codes use 15; on a sim mesh whose vertices lie along long straight asset lines,
15 locked cracks within that angle onto the lines (fine 100x100 asset plate, 4 seeds:
largest 15-degree bin 0.16 at 15 degrees, 0.13 at 10, with the 2-triangle plate at 0.09-0.11)."""
SNAP_BOUNDARY_DEG = 25.0
"""Same, when the vertex lies on a crack or the mesh boundary (ends cracks cleanly there)."""
SNAP_T = 0.12
"""Snap when the crossing is this close (fraction of the edge) to an end: avoids slivers."""
BACK_DEG = 60.0
"""A cut within this angle of a crack or boundary edge at the node is not opened (no forks)."""
RELAX_RINGS = 3
"""Rings of faces around a crack event that the fine relaxation touches."""
RELAX_CAP = 0.1
"""Largest relative change of a face's stress in one relaxation pass."""
RELAX_TOL = 0.002
"""Stop the relaxation passes once no face's stress changes by more than this (relative)."""
SHADOW_REL = 0.1
"""Radius of a crack's world-scale stress shadow, relative to the bounding-box diagonal."""
SHADOW_GAIN = 2.0
"""Release on a crack's own line, in units of its normal stress (coarse level); above 1 the
clamp saturates it, widening the fully released strip to about half the radius."""
SHADOW_MAX_CELLS = 4_000_000
"""Largest shadow grid (cells); coarser cells are used on very elongated bounding boxes."""
RES_TOLERANCE = 0.25
"""Documented tolerance of the change of the number of cracks started and of the total crack
length when the sim edge length halves, from the default resolution (100k faces) upward."""
REF_PERCENTILE = 90.0
"""Percentile of the initial normalised separation that toughness 1 corresponds to."""
FLAW = 0.25
"""Relative spread of the seeded toughness (material flaws)."""
FLAW_WAVELENGTH = 0.1
"""Flaw wavelength relative to the bounding-box diagonal."""
FLAW_WAVES = 12
FOOTPRINT_REL = 0.01
"""World-scale footprint (relative to the bounding-box diagonal) over which the initial
normalised separation is compared with its local mean: a node's toughness follows its own
fluctuation below this scale (see :func:`.calibration.footprint_factor`)."""
FOOTPRINT_CLIP = 2.0
"""Largest factor (and smallest, inverted) that :func:`.calibration.footprint_factor` applies."""
FOOTPRINT_MIN_LOADED = 0.95
"""Least fraction of loaded interior nodes for which :func:`.calibration.footprint_factor`
applies."""
NUC_FOOTPRINT_REL = 0.0075
"""Localized fields: a new crack nucleates only where the mean v+/h over the nodes within this
(x bounding-box diagonal) exceeds their mean toughness (tips keep the per-node test)."""
GRAIN = 0.05
"""Weight of a node's seeded grain direction, relative to v+, in choosing the crack normal; it
only decides where the separation is nearly isotropic (see :func:`.separation.node_update`)."""
GROWTH_REF_STEPS = 20
"""With no initial stress, toughness 1 is the separation of this many growth steps."""
EXTRA_DEGREE = 24
"""Room for faces a node may gain by edge splits around it (node -> face table width, beyond
the initial largest degree); the table widens by as much again when an event needs more."""
TIP_FIRST = True
"""Grow every failing crack tip before a new crack starts (docs/solver.md)."""
TIP_PRIORITY = 1e6
"""Added to a free tip's heap key when ``TIP_FIRST``."""
INITIAL_ROOM = 4096
"""Crack events the state arrays first make room for (they double when full)."""
PROGRESS_SECONDS = 0.5
"""Least time between two progress messages."""
NEAR_REL = 0.12
"""Near-crack radius, a fraction of the shadow radius: a free tip of a localized field that
comes this close to another crack running alongside it (within ``NEAR_PAR_DEG``) is ended
there, and no new crack starts this close to one running its way (docs/solver.md)."""
NEAR_PAR_DEG = 60.0
"""Largest angle between a free tip's direction and a nearby crack's segment for that crack to
count as running alongside it."""
TIP_REF_FACES = 100_000
"""The tip factor is the share of the excess carried over one edge of a mesh of this many
equilateral faces covering the surface; shorter steps carry more (docs/solver.md)."""
DIR_SMOOTH = 0.5
"""Length of the crack direction's moving average, relative to the near-crack radius."""
LIGAMENT_REL = 0.25
"""A free tip arrested this close (x the shadow radius) to another crack or the boundary ahead
of it breaks through the ligament between them (:func:`.rules.bridge`)."""
LIGAMENT_CONE_DEG = 45.0
"""Half-angle of the cone ahead of an arrested tip in which :func:`.rules.bridge` looks."""
UPDATE_CHUNK = 4096
"""Faces or nodes per parallel work item of :func:`.update.update_all` (one set of scratch each)."""
CROSS_CLEAR = 3.0
"""A crack tip crosses to a touching shell (:func:`.loop.cross_shells`) only where no crack of
that shell runs within this many of the mate's edge lengths: there it cracked already."""
