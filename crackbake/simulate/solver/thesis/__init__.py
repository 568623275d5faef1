"""``--method thesis``: the 2023 NCCA MSc variant (Tan-Mulligan) of Iben & O'Brien's cracks.

What it does (docs/method.md, "The thesis variant", with the published file's defects fixed):

1. Node forces and separation tensors are computed **once** from the initial stress
   (:mod:`crackbake.simulate.solver.fem`; the radial/hoop field and its unit vectors are the stress
   module's business, and the compressive terms of the separation tensor carry their correct
   signs there).  Each node gets its largest eigenvalue ``v+`` and eigenvector ``n+``.
2. A crack starts at the un-cracked node with the largest ``v+`` (if it exceeds the toughness
   ``tau``) and grows **both ends to the end**, alternating one step per end: each step moves to
   the neighbouring vertex (over the welded sim edges) best aligned with the crack heading; there
   is no remeshing, so cracks follow mesh edges and look jagged, as the thesis says.
3. The old tip's ``v+`` is reduced by ``tau``; the new tip's separation tensor gets
   ``tip_factor * (v+ - tau) * o o^T`` with ``o`` the crack's opening direction (the heading
   turned 90 degrees in the tangent plane, i.e. the tip's ``n+`` of Iben & O'Brien §A7), and its
   ``v+``/``n+`` are re-evaluated at once (the shipped file only refreshed them after the loop).
4. A tip stops at the mesh boundary, on reaching a node of an earlier crack (a T-junction: it
   steps there and ends), when its node's ``v+ <= tau``, or when the crack has used its step
   budget (``max_crack_length / edge_length`` steps, 25 like the thesis when unset).
5. Between cracks, scalar relaxation of ``v+``: each pass a node keeps ``(1 - relax_share) v+``
   and shares the rest equally with its neighbours, ``relax_steps`` passes, restricted to the
   nodes within ``relax_steps`` rings of the new crack so a crack costs O(its length), not
   O(mesh).  Eigenvectors are not relaxed (as in the thesis).
6. Up to ``max_cracks`` cracks, ``max_steps`` tip steps in all.

Two small deviations from the thesis, both to keep cracks on course without remeshing: the
heading is blended towards the local eigenvector's perpendicular in proportion to the tensor's
anisotropy (an isotropic tensor's eigenvector is noise), and the step choice corrects the
sideways drift that accumulates from snapping to edges (aim point back on the ideal line).

The stress field is unchanged by this method; ``separation`` is the final ``v+ / tau``.
"""

from crackbake.simulate.solver.thesis.driver import (
    DEFAULT_CRACK_STEPS,
    relative_toughness,
    solve_thesis,
    turning_angle_per_length,
)
from crackbake.simulate.solver.thesis.kernels import END_BOUNDARY, END_FREE, END_JUNCTION

__all__ = [
    "DEFAULT_CRACK_STEPS",
    "END_BOUNDARY",
    "END_FREE",
    "END_JUNCTION",
    "relative_toughness",
    "solve_thesis",
    "turning_angle_per_length",
]
