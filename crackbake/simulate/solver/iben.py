"""The ``iben`` crack solver: Iben & O'Brien, "Generating Surface Crack Patterns" (2006/2009).

Algorithm (../shared/research/method.md §A, gaps resolved as in §B):

1. Setup (once, compiled loops over all faces / nodes): per-face geometry, the principal split of
   the world in-plane stress into tension and compression, per-corner forces
   ``f = -A S± g`` and per-node separation tensors
   ``ς = ½(−m(Σf⁺) + Σm(f⁺) + m(Σf⁻) − Σm(f⁻)) + ρ`` (ρ a persistent residual), their largest
   eigenpair ``(v⁺, n̂⁺)``; failing nodes go into a max-heap with lazy invalidation.  The
   crack normal ``n̂⁺`` comes from a *direction-averaged* tensor (each corner's ``m(f)``
   replaced by its mean over the opposite edge's direction, plus a seeded per-node grain
   where that is isotropic), and ``v⁺`` mostly from it, so that neither sees how the mesh is
   laid out (see :func:`crackbake.simulate.solver.topology.node_update`): on a sim mesh refining a
   regular asset grid the paper's tensor steered cracks along the asset's straight edge lines.
2. Loop (compiled, sequential): pop the node with the largest ``v⁺/τ``; cut the plane through it
   normal to ``n̂⁺`` (projected on the tangent plane) through its triangle fan, splitting the two
   crossed opposite edges or snapping to a vertex when the cut runs within ``SNAP_DEG`` of an edge
   (``SNAP_BOUNDARY_DEG`` when that vertex lies on a crack or the boundary, or ``t`` within
   ``SNAP_T`` of an end); split the node along the cut; recompute forces and ``ς`` of the changed
   1-ring; push ``α(v⁺ − τ) n̂n̂ᵀ`` to the new free tips (not to tips that met a crack or the
   boundary: those cracks are finished); relax the stress (fine level, below); cast the crack's
   stress shadow (coarse level, below); re-queue the changed nodes.  The work per step does not
   grow with the mesh.
3. Shrinkage growth (``field.growth``) is applied quasi-statically: whenever no node fails, the
   growth is added to every face (one solver step), and the loop resumes; once ``max_cracks``
   cracks have started and no node fails, the run ends, and so it does once the material has
   dried ``GROWTH_REF_STEPS`` steps longer without a crack event than the fresh material took
   to crack (saturated: no place is left where a crack may start or grow).  Drying is slow
   compared with cracking, so cracks run until the field is at rest before it grows again.

Stress relief works on two levels, so that the pattern has a world scale rather than the scale
of the simulation mesh:

* **Fine (near the crack, in rings).**  Method.md §A8 with the stability fix of §B5: per pass,
  each node within ``RELAX_RINGS`` rings of the change moves by ``d = relax_rate · K⁻¹ F_net``
  with ``K = ⅔ Σ A(|g|² I + g gᵀ)`` the node's diagonal stiffness block (a damped block-Jacobi
  step of the equilibrium; on a fan with edges in all directions it is the scalar
  ``Σ A|g|²``, and it does not over-relax across the dominant edge direction of an
  anisotropic fan), and each
  face adds ``sym(Σ_i d_i g_iᵀ)``, capped at ``RELAX_CAP`` of its stress norm per pass; passes
  stop early once no face changes by more than ``RELAX_TOL``.  This shapes tips and junctions.
* **Coarse (world-scale stress shadow).**  Global relaxation, as in the paper, would cost O(n) a
  step.  Instead each new crack segment (length ℓ, normal n̂) deposits ``ℓ (n̂·S·n̂) n̂n̂ᵀ`` with a
  compact kernel of radius ``R = SHADOW_REL ×`` bounding-box diagonal into a uniform grid of
  cell size R/3 (O(1) cells per event).  A face's *effective* stress is its stress minus the
  grid's release interpolated at its centroid, projected on its plane and never pushed into new
  compression.  A long crack thus releases its normal stress fully along itself, fading to zero
  at distance R, while stress parallel to it is untouched: parallel cracks keep a world spacing,
  and perpendicular ones still form T-junctions.  Free crack tips see the shadow without its
  component along their own crack normal (:func:`crackbake.simulate.solver.topology.tip_principal`):
  their own crack's shadow (and that of cracks parallel to it) would otherwise stall them, so
  their opening stress stays raw, but the release of other cracks across their path counts.
  Before, tips read the raw stress: a concentric link started between two radial impact
  cracks, in a wedge whose hoop stress they had released, then saw the raw hoop stress and
  turned back into a radial crack (plate glass, tangential share of the crack length 0.35-0.65
  reaches from the centre at 100k / 400k / 1M faces: 0.11 / 0.07 / 0.06, now 0.18 / 0.17 /
  0.16).  The heap is lazy: a popped node is re-evaluated against the current shadow and
  re-queued if it no longer is the most critical, so nodes far from the last event are never
  touched.

Toughness is resolution independent: a node's separation scales with its edge length h, so the
failure test compares ``v⁺ / h_n`` with ``τ = toughness × P90`` where ``P90`` is the 90th
percentile of the initial ``v⁺ / h_n`` over interior nodes with positive separation.  Each node
also gets a seeded flaw factor (±``FLAW`` relative, a smooth world-space field), the material's
imperfections.

Crack order: with ``TIP_FIRST`` every failing free tip is grown before a new crack may start
(tips get ``TIP_PRIORITY`` on their heap key).  Propagation is fast compared with nucleation, and
without this the number of nucleations between two tip steps would grow as the mesh refines
(a tip advances one edge length per event), which made the crack count resolution dependent.
Cutting back along an existing crack edge at the node (within ``BACK_DEG``) is not opened, so a
crack grows forward from its tip instead of forking behind it.

Resolution independence.  Whatever the simulation edge length h, the pattern should be the
same, so the rules that decide where cracks start, how far they run and where they stop work
at world lengths, not at "one node" or "one step".  Only the fine relaxation stays a few rings
wide (a world-wide one would make a step's cost grow with the mesh), and what remains of the
drift comes from it: at 400k faces 2 / 3 / 5 rings give 19.3 / 16.7 / 16.0 glass cracks.
``RES_TOLERANCE`` (25 %) is the documented bound on the change of the number of cracks started
and of the total length when h halves, from the default 100k sim faces upward
(tests/test_resolution.py; coarser meshes are previews and drift more: cracks there cannot
come closer than a few edges to each other).

* Toughness is relative to the field's initial normalised separation ``v+/h`` (above), and
  the flaws are a world-space field.
* Tip momentum: ``alpha`` (the tip factor) is the share of the excess carried over a step of
  ``tip_len``, the edge of a ``TIP_REF_FACES``-face equilateral mesh of the surface; a shorter
  step carries ``alpha^(step / tip_len)``.  With a fixed share per step a crack coasted a
  fixed number of steps into sub-critical stress, i.e. a shorter distance the finer the mesh,
  and the stress it left started more cracks (plate glass 100k -> 1M: 15 -> 25 cracks).
  Steps longer than ``tip_len`` keep ``alpha``.
* Crack directions for the rules below are moving averages over ``DIR_SMOOTH`` x the
  near-crack radius of path (``pdir`` per crack point, :func:`_smooth_dir`): one segment's
  direction zig-zags across the sim triangles, more so the finer the mesh.
* A new crack may not start within ``RELAX_RINGS x tip_len`` of an existing crack (the reach
  of the fine relaxation at the default resolution, which on finer meshes shrinks with h), nor
  within the near-crack radius ``NEAR_REL x`` the shadow radius of a crack running within
  ``NEAR_PAR_DEG`` of its direction: finer meshes otherwise started ever more short cracks
  right beside existing ones (plate shrinkage 1M: clusters of 0.003-0.01 long cracks at the
  boundary; plate glass: stubs whose tips the near-crack rule ended at once).

Near-crack rule (localized fields only). Free tips do not see the shadow of cracks parallel to
their own, so nothing kept a radial impact crack from running alongside an existing one: at
finer resolution tips ran ~0.03-0.05 units from a neighbour over long stretches (glass on spot:
33 -> 52 cracks, length +45 % from 100k to 400k faces, before this rule). After each crack event
a breadth-first search over the nodes within the near-crack radius of each free tip
(:func:`_near_other`) looks for another crack's point whose direction runs within
``NEAR_PAR_DEG`` of the tip's; if found the tip is ended like a tip that met a crack, once its
own crack is at least that radius long (a younger one would stay a stub). The rule applies only
when fewer than ``FOOTPRINT_MIN_LOADED`` of the interior nodes are loaded (the criterion of
:func:`_footprint_factor`): on surface-wide fields (shrinkage, crackle, mud) the shadow keeps
parallel cracks apart.

Ligament failure (all fields). A free tip that stops short of another crack or the mesh boundary
ahead of it (within ``LIGAMENT_REL`` x the shadow radius, inside ``LIGAMENT_CONE_DEG`` of its
smoothed direction) breaks through the thin ligament between them (:func:`_bridge`): it is made
to fail with its cut aimed at the nearest such point, step after step, until it meets it. This
covers tips arrested below the toughness and tips the near-crack rule would end while converging
on the crack they run into. The boundary counts once the tip's crack is that radius long (short
cracks beside an open boundary otherwise curled back onto it). Before, such tips stopped a few
edges short and left a gap that shows in the textures: on 60-cell plates (3 seeds, glass and
shrinkage) 15 free ends had a crack ahead within that reach, now 1; the radial cracks of a glass
impact now run into the first cracks at the centre instead of stopping beside them.

Footprint nucleation (localized fields only).  Single fine-mesh stress peaks next to existing
cracks kept starting tiny new cracks.  A node starts a *new* crack only when the summed
``v+/h`` of the nodes within ``NUC_FOOTPRINT_REL`` x the bounding-box diagonal exceeds their
summed toughness (current values, so peaks beside cracks are averaged away); crack tips keep
the per-node test.

Measured (``origins`` of the result, means over 3 seeds; benchmarks/bench_solver.py plates):
glass impact 14.0 / 14.0 / 13.7 cracks started at 100k / 400k / 1M faces (length 3.10 / 3.18 /
3.05), shrinkage 86.7 / 91.0 / 91.7 (length 16.3 / 16.5 / 16.8); before these rules glass
went 18 / 22 / 53.  Spot through the real stages (3 seeds): glass 10.3 / 12.0 / 12.7 cracks,
length 3.96 / 4.43 / 4.63.

Concentric links in a glass impact.  After the radial cracks, a wedge between two of them
loses its hoop stress and keeps its radial tension, which opens the concentric links; the tip
view (above) keeps a link running along the wedge and ligament failure joins it to the radial
crack it reaches.  Links can only form where the radial stress left exceeds the toughness:
with ``w = 2cos(d/r)`` and hoop 1.25, radial stress alone reaches the glass toughness at
``w`` about 1.5 (1.1 at the weakest flaws), i.e. within about 0.6 of the impact's reach
``pi r / 2``.  Measured on plates (tests/test_resolution.py, 2 seeds): the tangential share
of the crack length 0.35-0.65 reaches from the centre is 0.18 / 0.17 / 0.16 at 100k / 400k /
1M faces (0.39 and 0.29 in the two halves of that annulus on 7k-face plates, where the fine
relaxation spans a wider world distance).  The shadow still sums each crack's release
``n̂n̂ᵀ`` with its own normal, so radial cracks one wedge away leak some radial release into a
wedge (final radial stress 0.4-0.7 at 0.1-0.25 from the impact, initially 1.8-1.0), and a
link's release is not confined to its wedge; a crack-aware (shielded) coarse level would
give denser rings.  Tried and not kept: releasing along the shadow cell's principal axes
(no clear gain), a shadow radius growing with the crack length (links 0.28 but shrinkage
crack counts +75 %).

Independence from the asset triangulation (tests/test_quality.py): a 2-triangle and a
20,000-triangle plate at 100k sim faces under shrinkage give crack lengths within 3-8 %,
crack counts within 12-17 % and no preferred direction (largest 15-degree bin <= 0.15).

Budgets: ``max_cracks`` bounds the distinct cracks started (nucleations; existing cracks keep
growing), ``max_steps`` the solver steps (crack events plus growth steps).
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable

import numpy as np
from numba import njit, prange

from crackbake.errors import CrackbakeError
from crackbake.simulate.solver import CrackPath, SolverParams, SolverResult
from crackbake.simulate.solver.topology import (
    face_update,
    heap_pop,
    heap_push,
    node_update,
    on_boundary,
    separate,
    shadow_add,
    split_edge,
    spoke_count,
)

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
fluctuation below this scale (see :func:`_footprint_factor`)."""
FOOTPRINT_CLIP = 2.0
"""Largest factor (and smallest, inverted) that :func:`_footprint_factor` applies."""
FOOTPRINT_MIN_LOADED = 0.95
"""Least fraction of loaded interior nodes for which :func:`_footprint_factor` applies."""
NUC_FOOTPRINT_REL = 0.0075
"""Localized fields: a new crack nucleates only where the mean v+/h over the nodes within this
(x bounding-box diagonal) exceeds their mean toughness (tips keep the per-node test)."""
GRAIN = 0.05
"""Weight of a node's seeded grain direction, relative to v+, in choosing the crack normal; it
only decides where the separation is nearly isotropic (see topology.node_update)."""
GROWTH_REF_STEPS = 20
"""With no initial stress, toughness 1 is the separation of this many growth steps."""
EXTRA_DEGREE = 24
"""Room for faces a node may gain by edge splits around it (node -> face table width)."""
TIP_FIRST = True
"""Grow every failing crack tip before a new crack starts (see the module docstring)."""
TIP_PRIORITY = 1e6
"""Added to a free tip's heap key when ``TIP_FIRST``."""
INITIAL_ROOM = 4096
"""Crack events the state arrays first make room for (they double when full)."""
PROGRESS_SECONDS = 0.5
"""Least time between two progress messages."""
NEAR_REL = 0.12
"""Near-crack radius, a fraction of the shadow radius: a free tip of a localized field that
comes this close to another crack running alongside it (within ``NEAR_PAR_DEG``) is ended
there, and no new crack starts this close to one running its way (module docstring)."""
NEAR_PAR_DEG = 60.0
"""Largest angle between a free tip's direction and a nearby crack's segment for that crack to
count as running alongside it."""
TIP_REF_FACES = 100_000
"""The tip factor is the share of the excess carried over one edge of a mesh of this many
equilateral faces covering the surface; shorter steps carry more (see the module docstring)."""
DIR_SMOOTH = 0.5
"""Length of the crack direction's moving average, relative to the near-crack radius."""
LIGAMENT_REL = 0.25
"""A free tip arrested this close (x the shadow radius) to another crack or the boundary ahead
of it breaks through the ligament between them (:func:`_bridge`)."""
LIGAMENT_CONE_DEG = 45.0
"""Half-angle of the cone ahead of an arrested tip in which :func:`_bridge` looks."""
NEAR_QUEUE = 8192
"""Most nodes the near-crack search around one tip visits."""

# Indices into the counter array shared by the kernels.
(_HEAP, _NN, _NF, _NS, _STEP, _EVENTS, _STAMP, _NCRACK, _ABORT, _GROW, _DEP,
 _REFRESH, _NUC_EDGE, _NUC_VETO, _NUC_NEAR, _TIP_NEAR, _IDLE, _FIRST, _SATURATED,
 _BRIDGE) = range(20)
# Return codes of _run.
_MORE, _DONE, _FULL = 0, 1, 2


@njit(cache=True)
def _scratch():
    return np.empty(14), np.empty((2, 3, 3)), np.empty((3, 3)), np.empty((2, 3)), np.empty(6)


UPDATE_CHUNK = 4096
"""Faces or nodes per parallel work item of :func:`_update_all` (one set of scratch each)."""


@njit(cache=True, parallel=True)
def _update_all(nn, nf, X, F, S, area, nrm, grad, pr, NF, NFc, rho, val, vec, crack_of, G, gp,
                grain, seed, tipn):
    """Recompute every face and every node (setup, growth steps, the final state).

    Each face and each node writes only its own entries, so the chunks run in parallel and
    the result does not depend on the thread count.  A growth step on a 1M-face sim mesh
    costs about a second on one core, and drying runs take tens of them.
    """
    for ch in prange((nf + UPDATE_CHUNK - 1) // UPDATE_CHUNK):
        _sc, _acc, _ev, fr, r6 = _scratch()
        for f in range(ch * UPDATE_CHUNK, min(nf, (ch + 1) * UPDATE_CHUNK)):
            face_update(f, X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
    for ch in prange((nn + UPDATE_CHUNK - 1) // UPDATE_CHUNK):
        sc, acc, ev, _fr, _r6 = _scratch()
        for n in range(ch * UPDATE_CHUNK, min(nn, (ch + 1) * UPDATE_CHUNK)):
            node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec,
                        crack_of[n] >= 0, grain, seed, sc, acc, ev, G, gp, tipn)


@njit(cache=True)
def _incidence(nf, F, NF, NFc):
    for f in range(nf):
        for k in range(3):
            n = F[f, k]
            NF[n, NFc[n]] = f
            NFc[n] += 1


@njit(cache=True)
def _key(n, val, taun, crack_of, tip_first):
    """Heap key: v+/tau, plus TIP_PRIORITY for free crack tips when ``tip_first``."""
    k = val[n] / taun[n]
    if tip_first and crack_of[n] >= 0:
        k += TIP_PRIORITY
    return k


@njit(cache=True)
def _rebuild_heap(hk, hn, hv, cnt, val, taun, nver, dead, crack_of, tip_first):
    cnt[_HEAP] = 0
    for n in range(cnt[_NN]):
        if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
            heap_push(hk, hn, hv, cnt, _key(n, val, taun, crack_of, tip_first), n, nver[n])


@njit(cache=True)
def _push(n, hk, hn, hv, cnt, val, taun, nver, dead, crack_of, tip_first):
    nver[n] += 1
    if not dead[n] and taun[n] > 0 and val[n] > taun[n]:
        if not heap_push(hk, hn, hv, cnt, _key(n, val, taun, crack_of, tip_first), n, nver[n]):
            _rebuild_heap(hk, hn, hv, cnt, val, taun, nver, dead, crack_of, tip_first)


@njit(cache=True)
def _angle(u0, u1, u2, v0, v1, v2):
    nu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    nv = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if nu == 0.0 or nv == 0.0:
        return 0.0
    return np.arccos(min(1.0, max(-1.0, (u0 * v0 + u1 * v1 + u2 * v2) / (nu * nv))))


@njit(cache=True)
def _relax(nrelax, rate, regf, nrf, regn, nrn, stamp, fst, F, S, NF, NFc, area, nrm, grad, disp):
    """Fine relaxation of the region's stress (raw S), damped Jacobi passes; see module doc."""
    for _pass in range(nrelax):
        for i in range(nrn):
            n = regn[i]
            free = True
            f0 = f1 = f2 = 0.0
            # Block stiffness of the node, (2/3) sum A (|g|^2 I + g g^T) (upper triangle): the
            # exact diagonal block of the strain operator, scaled so that a fan with edges in
            # all directions gets the scalar sum A |g|^2.  A scalar alone over-relaxes across
            # the dominant edge direction of an anisotropic fan (rows of sim edges along the
            # asset's edges), which steered crack tips along them.
            k00 = k01 = k02 = k11 = k12 = k22 = 0.0
            for j in range(NFc[n]):
                f = NF[n, j]
                if fst[f] != stamp:
                    free = False
                    break
                k = 0
                while F[f, k] != n:
                    k += 1
                g = grad[f, k]
                s = S[f]
                A = area[f]
                f0 -= A * (s[0, 0] * g[0] + s[0, 1] * g[1] + s[0, 2] * g[2])
                f1 -= A * (s[1, 0] * g[0] + s[1, 1] * g[1] + s[1, 2] * g[2])
                f2 -= A * (s[2, 0] * g[0] + s[2, 1] * g[1] + s[2, 2] * g[2])
                gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2]
                k00 += A * (gg + g[0] * g[0])
                k01 += A * g[0] * g[1]
                k02 += A * g[0] * g[2]
                k11 += A * (gg + g[1] * g[1])
                k12 += A * g[1] * g[2]
                k22 += A * (gg + g[2] * g[2])
            # Inverse by cofactors (the block is symmetric positive definite).
            c00 = k11 * k22 - k12 * k12
            c01 = k02 * k12 - k01 * k22
            c02 = k01 * k12 - k02 * k11
            det = k00 * c00 + k01 * c01 + k02 * c02
            if free and det > 0:
                c11 = k00 * k22 - k02 * k02
                c12 = k01 * k02 - k00 * k12
                c22 = k00 * k11 - k01 * k01
                r = 1.5 * rate / det
                disp[n, 0] = r * (c00 * f0 + c01 * f1 + c02 * f2)
                disp[n, 1] = r * (c01 * f0 + c11 * f1 + c12 * f2)
                disp[n, 2] = r * (c02 * f0 + c12 * f1 + c22 * f2)
            else:
                disp[n, 0] = disp[n, 1] = disp[n, 2] = 0.0
        worst = 0.0
        for i in range(nrf):
            f = regf[i]
            nf_ = nrm[f]
            m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
            for q in range(3):
                d = disp[F[f, q]]
                dn = d[0] * nf_[0] + d[1] * nf_[1] + d[2] * nf_[2]
                d0 = d[0] - dn * nf_[0]
                d1 = d[1] - dn * nf_[1]
                d2 = d[2] - dn * nf_[2]
                g = grad[f, q]
                m00 += d0 * g[0]
                m01 += d0 * g[1]
                m02 += d0 * g[2]
                m10 += d1 * g[0]
                m11 += d1 * g[1]
                m12 += d1 * g[2]
                m20 += d2 * g[0]
                m21 += d2 * g[1]
                m22 += d2 * g[2]
            a01 = 0.5 * (m01 + m10)
            a02 = 0.5 * (m02 + m20)
            a12 = 0.5 * (m12 + m21)
            nds = np.sqrt(m00 * m00 + m11 * m11 + m22 * m22
                          + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12))
            s = S[f]
            ns = 0.0
            for a in range(3):
                for b in range(3):
                    ns += s[a, b] * s[a, b]
            ns = np.sqrt(ns)
            scale = 1.0
            if nds > RELAX_CAP * ns:
                scale = RELAX_CAP * ns / nds
            if ns > 0.0:
                worst = max(worst, scale * nds / ns)
            s[0, 0] += scale * m00
            s[1, 1] += scale * m11
            s[2, 2] += scale * m22
            s[0, 1] += scale * a01
            s[1, 0] += scale * a01
            s[0, 2] += scale * a02
            s[2, 0] += scale * a02
            s[1, 2] += scale * a12
            s[2, 1] += scale * a12
        if worst < RELAX_TOL:
            break
    for i in range(nrn):
        disp[regn[i], 0] = disp[regn[i], 1] = disp[regn[i], 2] = 0.0


@njit(cache=True)
def _enqueue_near(n, x0, x1, x2, r2, X, F, NF, NFc, vst, vstamp, queue, tail):
    """Breadth-first step: queue the unvisited neighbours of ``n`` within ``sqrt(r2)`` of
    ``(x0, x1, x2)``; returns the new queue tail."""
    for j in range(NFc[n]):
        f = NF[n, j]
        for q in range(3):
            y = F[f, q]
            if vst[y] == vstamp:
                continue
            vst[y] = vstamp
            e0 = X[y, 0] - x0
            e1 = X[y, 1] - x1
            e2 = X[y, 2] - x2
            if e0 * e0 + e1 * e1 + e2 * e2 <= r2 and tail < queue.shape[0]:
                queue[tail] = y
                tail += 1
    return tail


@njit(cache=True)
def _ball(c, rad, X, F, NF, NFc, vst, vstamp, queue):
    """The nodes connected to ``c`` over the mesh within ``rad`` of it (breadth-first; cracks
    separate): ``queue[:count]``, ``c`` first; returns ``count``."""
    r2 = rad * rad
    x0, x1, x2 = X[c, 0], X[c, 1], X[c, 2]
    vst[c] = vstamp
    queue[0] = c
    head = 0
    tail = 1
    while head < tail:
        tail = _enqueue_near(queue[head], x0, x1, x2, r2, X, F, NF, NFc, vst, vstamp, queue,
                             tail)
        head += 1
    return tail


@njit(cache=True)
def _bridge(t, cid, rad, coscone, X, F, NF, NFc, nrm, area, pid, pcid, pdir, onb, val, vec,
            taun, vst, vstamp, queue, own_len):
    """Ligament failure: when the free tip ``t`` is arrested (its separation is below the
    toughness) and another crack or the mesh boundary lies ahead of it within ``rad`` (inside
    the cone ``acos(coscone)`` around its smoothed direction), the thin ligament between them
    breaks: the tip is made to fail (``val`` just above ``taun``) with its cut aimed at the
    nearest such point.  Returns whether it did.  Without this a crack stopped a few edges
    short of the crack it was running into, a gap that shows in the textures.  The boundary
    counts only once the tip's crack (``own_len`` long) is at least ``rad`` long: short cracks
    starting beside an open boundary otherwise curled back onto it at both ends (hooks).
    """
    to_boundary = own_len >= rad
    p = pid[t]
    d0, d1, d2 = pdir[p, 0], pdir[p, 1], pdir[p, 2]
    ld = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if ld == 0.0 or rad <= 0.0:
        return False
    x0, x1, x2 = X[t, 0], X[t, 1], X[t, 2]
    best = -1
    bd = np.inf
    for i in range(1, _ball(t, rad, X, F, NF, NFc, vst, vstamp, queue)):
        n = queue[i]
        if (pcid[pid[n]] >= 0 and pcid[pid[n]] != cid) or (onb[n] and to_boundary):
            e0 = X[n, 0] - x0
            e1 = X[n, 1] - x1
            e2 = X[n, 2] - x2
            le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            if 0.0 < le < bd and (e0 * d0 + e1 * d1 + e2 * d2) >= coscone * le * ld:
                best = n
                bd = le
    if best < 0:
        return False
    vn0 = vn1 = vn2 = 0.0
    for j in range(NFc[t]):
        f = NF[t, j]
        vn0 += area[f] * nrm[f, 0]
        vn1 += area[f] * nrm[f, 1]
        vn2 += area[f] * nrm[f, 2]
    e0 = X[best, 0] - x0
    e1 = X[best, 1] - x1
    e2 = X[best, 2] - x2
    # Cut normal: in the tangent plane, perpendicular to the way to the target.
    c0 = vn1 * e2 - vn2 * e1
    c1 = vn2 * e0 - vn0 * e2
    c2 = vn0 * e1 - vn1 * e0
    lc = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    if lc == 0.0:
        return False
    vec[t, 0], vec[t, 1], vec[t, 2] = c0 / lc, c1 / lc, c2 / lc
    val[t] = taun[t] * (1.0 + 1e-9)
    return True


@njit(cache=True)
def _near_other(t, cid, d0, d1, d2, rad, cospar, rad_any, X, F, NF, NFc, pid, pcid, pdir, vst,
                vstamp, queue):
    """Whether another crack comes near node ``t`` (breadth-first over the mesh).

    Returns 1 when a point of another crack lies within ``rad_any`` of ``t``, 2 when one lies
    within ``rad`` and that crack's smoothed direction there (``pdir``) runs within
    ``acos(cospar)`` of ``d``, else 0.
    """
    ld = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    r2 = max(rad, rad_any) ** 2
    ra2 = rad_any * rad_any
    x0, x1, x2 = X[t, 0], X[t, 1], X[t, 2]
    vst[t] = vstamp
    queue[0] = t
    head = 0
    tail = 1
    found = 0
    while head < tail:
        n = queue[head]
        head += 1
        p = pid[n]
        o = pcid[p]
        if o >= 0 and o != cid:
            e0 = X[n, 0] - x0
            e1 = X[n, 1] - x1
            e2 = X[n, 2] - x2
            if e0 * e0 + e1 * e1 + e2 * e2 <= ra2:
                return 1
            u0, u1, u2 = pdir[p, 0], pdir[p, 1], pdir[p, 2]
            lu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            if lu > 0.0 and ld > 0.0 and abs(u0 * d0 + u1 * d1 + u2 * d2) >= cospar * lu * ld:
                if rad_any == 0.0:
                    return 2
                found = 2
        tail = _enqueue_near(n, x0, x1, x2, r2, X, F, NF, NFc, vst, vstamp, queue, tail)
    return found


@njit(cache=True)
def _smooth_dir(pc, pt, d0, d1, d2, length, pdir):
    """Direction of a crack at its new point ``pt``: an exponential moving average over the
    last ``length`` (mesh units) of its path, from the one at ``pc`` and the new segment ``d``.

    A world-scale memory: a single segment's direction zig-zags across the sim triangles, and
    the finer the mesh the more it does, so tests on it would depend on the resolution.
    """
    ld = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if ld == 0.0:
        return
    u0, u1, u2 = pdir[pc, 0], pdir[pc, 1], pdir[pc, 2]
    w = np.exp(-ld / length) if length > 0.0 else 0.0
    if u0 * d0 + u1 * d1 + u2 * d2 < 0.0:
        w = -w
    e0 = w * u0 + (1.0 - abs(w)) * d0 / ld
    e1 = w * u1 + (1.0 - abs(w)) * d1 / ld
    e2 = w * u2 + (1.0 - abs(w)) * d2 / ld
    le = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if le > 0.0:
        pdir[pt, 0], pdir[pt, 1], pdir[pt, 2] = e0 / le, e1 / le, e2 / le


@njit(cache=True)
def _footprint_fails(c, rad, X, F, NF, NFc, val, taun, hn, dead, vst, vstamp, queue):
    """Whether the mean normalised separation ``v+ / h`` over the nodes within ``rad`` of node
    ``c`` (breadth-first over the mesh) exceeds their mean normalised toughness."""
    sv = 0.0
    st = 0.0
    for i in range(_ball(c, rad, X, F, NF, NFc, vst, vstamp, queue)):
        n = queue[i]
        if not dead[n] and taun[n] > 0.0 and hn[n] > 0.0:
            sv += val[n] / hn[n]
            st += taun[n] / hn[n]
    return sv > st


@njit(cache=True)
def _run(X, F, S, AF, GR, area, nrm, grad, pr, NF, NFc, rho, val, vec, taun, hn, pid, onb,
         crack_of, nver, dead, nonuc, fst, nst, nevl, segof, pcid, pdir, tipn, lchk, hk, hn_, hv,
         segp, seg_alive, seg_info, clen, corig, G, gp, cnt, prm, max_cracks, max_steps, chunk):
    """Advance the crack loop by at most ``chunk`` steps.

    Returns ``_MORE`` (chunk done), ``_DONE`` (finished) or ``_FULL`` (the state arrays need more
    room: grow them and call again).
    """
    alpha, rate, nrelax, max_len = prm[0], prm[1], int(prm[2]), prm[3]
    snap, snap_b, snap_t, rings = prm[4], prm[5], prm[6], int(prm[7])
    gain, back, tip_first = prm[8], prm[9], prm[10] > 0
    grain, seed = prm[11], int(prm[12])
    near_rad, near_cos = prm[13], prm[14]
    nuc_rad = prm[15]
    dir_len = prm[16]
    tip_len = prm[17]
    tip_near = prm[18] > 0
    lig_rad, lig_cos = prm[19], prm[20]
    nuc_any = RELAX_RINGS * tip_len
    shadow = G.shape[0] >= 2
    W = NF.shape[1]
    ncap = X.shape[0]
    mcap = F.shape[0]
    regf = np.empty(65536, np.int64)
    regn = np.empty(65536, np.int64)
    disp = np.zeros((ncap, 3))
    buf = np.empty(8, np.int64)
    par = np.empty(W, np.int64)
    comp = np.empty(W, np.int64)
    fbuf = np.empty(W, np.int64)
    centers = np.empty(24, np.int64)
    sc, acc, ev, fr, r6 = _scratch()
    sa = np.empty(2, np.int64)
    sb = np.empty(2, np.int64)
    st = np.empty(2)
    sd = np.empty(2)
    tip = np.empty(2, np.int64)
    split = np.empty(2, np.bool_)
    free_tip = np.empty(2, np.bool_)
    near_end = np.empty(2, np.bool_)
    segl = np.empty(2)
    vst = np.zeros(ncap if near_rad > 0 or nuc_rad > 0 or lig_rad > 0 else 1, np.int64)
    vstamp = 0
    queue = np.empty(NEAR_QUEUE, np.int64)
    done = 0
    while True:
        if cnt[_STEP] >= max_steps:
            return _DONE
        if done >= chunk:
            return _MORE
        if (cnt[_NN] + 32 > ncap or cnt[_NF] + 16 > mcap or cnt[_NS] + 16 > segp.shape[0]
                or cnt[_NCRACK] + 2 > clen.shape[0]):
            return _FULL
        if cnt[_HEAP] == 0 and lig_rad > 0:
            # At rest: before the material dries further (or the run ends), tips that were
            # arrested short of a crack another crack has since approached may break through.
            for n in range(cnt[_NN]):
                if crack_of[n] >= 0 and not dead[n] and lchk[n] != cnt[_EVENTS] + 1:
                    lchk[n] = cnt[_EVENTS] + 1
                    vstamp += 1
                    if _bridge(n, crack_of[n], lig_rad, lig_cos, X, F, NF, NFc, nrm, area, pid,
                               pcid, pdir, onb, val, vec, taun, vst, vstamp, queue,
                               clen[crack_of[n]]):
                        cnt[_BRIDGE] += 1
                        nevl[n] = cnt[_DEP]
                        _push(n, hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
        if cnt[_HEAP] == 0:
            # With the crack budget spent and the field at rest, more drying would only lengthen
            # existing cracks step after step: stop (otherwise only max_steps would end the run).
            if GR.shape[0] > 1 and cnt[_NCRACK] < max_cracks:
                # Quasi-static shrinkage: nothing fails, so the material dries a step further;
                # unless it has dried longer without a crack event than the fresh material took
                # to crack, plus GROWTH_REF_STEPS: then no place is left where a crack may
                # start or grow (saturated), and only max_steps would end the run.
                if cnt[_IDLE] > max(cnt[_FIRST], 0) + GROWTH_REF_STEPS:
                    cnt[_SATURATED] = 1
                    return _DONE
                cnt[_IDLE] += 1
                nn, nf = cnt[_NN], cnt[_NF]
                for f in range(nf):
                    S[f] += GR[f]
                _update_all(nn, nf, X, F, S, area, nrm, grad, pr, NF, NFc, rho, val, vec,
                            crack_of, G, gp, grain, seed, tipn)
                for n in range(nn):
                    nver[n] += 1
                    nevl[n] = cnt[_DEP]
                _rebuild_heap(hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
                cnt[_STEP] += 1
                cnt[_GROW] += 1
                done += 1
                continue
            return _DONE
        _top, c, ver = heap_pop(hk, hn_, hv, cnt)
        if ver != nver[c] or dead[c] or not val[c] > taun[c]:
            continue
        nucleate = crack_of[c] < 0
        if nucleate and (cnt[_NCRACK] >= max_cracks or nonuc[c]):
            # The crack budget is spent (only existing cracks may grow), or c lies beside one.
            continue
        if shadow and nevl[c] != cnt[_DEP]:
            # Lazy heap: the shadow grew since this node was evaluated; refresh and re-check.
            for j in range(NFc[c]):
                face_update(NF[c, j], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
            node_update(c, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec, not nucleate,
                        grain, seed, sc, acc, ev, G, gp, tipn)
            nevl[c] = cnt[_DEP]
            cnt[_REFRESH] += 1
            if not nucleate and not val[c] > taun[c] and lig_rad > 0:
                vstamp += 1
                if _bridge(c, crack_of[c], lig_rad, lig_cos, X, F, NF, NFc, nrm, area, pid, pcid,
                           pdir, onb, val, vec, taun, vst, vstamp, queue, clen[crack_of[c]]):
                    cnt[_BRIDGE] += 1
            if not val[c] > taun[c]:
                nver[c] += 1
                continue
            if cnt[_HEAP] > 0 and _key(c, val, taun, crack_of, tip_first) < hk[0]:
                _push(c, hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
                continue
        if nucleate and nuc_rad > 0:
            vstamp += 1
            if not _footprint_fails(c, nuc_rad, X, F, NF, NFc, val, taun, hn, dead, vst,
                                    vstamp, queue):
                nver[c] += 1
                cnt[_NUC_VETO] += 1
                continue
        # ---- crack plane: n-hat projected on the tangent plane; t runs along the crack.
        xc0, xc1, xc2 = X[c, 0], X[c, 1], X[c, 2]
        vn0 = vn1 = vn2 = 0.0
        asum = 0.0
        for j in range(NFc[c]):
            f = NF[c, j]
            vn0 += area[f] * nrm[f, 0]
            vn1 += area[f] * nrm[f, 1]
            vn2 += area[f] * nrm[f, 2]
            asum += area[f]
        lvn = np.sqrt(vn0 * vn0 + vn1 * vn1 + vn2 * vn2)
        if lvn == 0.0:
            dead[c] = True
            continue
        vn0 /= lvn
        vn1 /= lvn
        vn2 /= lvn
        e0, e1, e2 = vec[c, 0], vec[c, 1], vec[c, 2]
        en = e0 * vn0 + e1 * vn1 + e2 * vn2
        nc0 = e0 - en * vn0
        nc1 = e1 - en * vn1
        nc2 = e2 - en * vn2
        lnc = np.sqrt(nc0 * nc0 + nc1 * nc1 + nc2 * nc2)
        if lnc < 1e-6:
            dead[c] = True
            continue
        nc0 /= lnc
        nc1 /= lnc
        nc2 /= lnc
        tc0 = vn1 * nc2 - vn2 * nc1
        tc1 = vn2 * nc0 - vn0 * nc2
        tc2 = vn0 * nc1 - vn1 * nc0
        if nucleate and near_rad > 0:
            # No new crack right beside an existing one (permanently: cracks never heal), nor
            # where the near-crack rule would end both its tips at once (see the module
            # docstring); such starts only multiplied short cracks as the mesh refined.
            vstamp += 1
            near = _near_other(c, -1, tc0, tc1, tc2, near_rad, near_cos, nuc_any, X, F, NF,
                               NFc, pid, pcid, pdir, vst, vstamp, queue)
            if near > 0:
                nver[c] += 1
                cnt[_NUC_NEAR] += 1
                if near == 1:
                    nonuc[c] = True
                continue
        # Normal stress across the cut (effective, so overlapping shadows do not double count).
        sig_n = 0.0
        for j in range(NFc[c]):
            f = NF[c, j]
            p = pr[f]
            a1 = p[2] * nc0 + p[3] * nc1 + p[4] * nc2
            a2 = p[5] * nc0 + p[6] * nc1 + p[7] * nc2
            sig_n += area[f] * (p[0] * a1 * a1 + p[1] * a2 * a2)
        sig_n = max(sig_n / asum, 0.0) if asum > 0 else 0.0
        # ---- the crossed opposite edge on each side (+t, -t).
        for side in range(2):
            sa[side] = -1
            sb[side] = -1
            st[side] = 0.0
            sd[side] = np.inf
        for j in range(NFc[c]):
            f = NF[c, j]
            k = 0
            while F[f, k] != c:
                k += 1
            a = F[f, (k + 1) % 3]
            b = F[f, (k + 2) % 3]
            da = (X[a, 0] - xc0) * nc0 + (X[a, 1] - xc1) * nc1 + (X[a, 2] - xc2) * nc2
            db = (X[b, 0] - xc0) * nc0 + (X[b, 1] - xc1) * nc1 + (X[b, 2] - xc2) * nc2
            if da == db or da * db > 0:
                continue
            tt = da / (da - db)
            p0 = X[a, 0] + tt * (X[b, 0] - X[a, 0]) - xc0
            p1 = X[a, 1] + tt * (X[b, 1] - X[a, 1]) - xc1
            p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
            along = p0 * tc0 + p1 * tc1 + p2 * tc2
            side = 0 if along > 0 else 1
            dist = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            if dist < sd[side]:
                sd[side] = dist
                sa[side] = a
                sb[side] = b
                st[side] = tt
        # ---- snap or split, per side.
        for side in range(2):
            tip[side] = -1
            split[side] = False
            if sa[side] < 0:
                continue
            a, b, tt = sa[side], sb[side], st[side]
            p0 = X[a, 0] + tt * (X[b, 0] - X[a, 0]) - xc0
            p1 = X[a, 1] + tt * (X[b, 1] - X[a, 1]) - xc1
            p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
            ang_a = _angle(p0, p1, p2, X[a, 0] - xc0, X[a, 1] - xc1, X[a, 2] - xc2)
            ang_b = _angle(p0, p1, p2, X[b, 0] - xc0, X[b, 1] - xc1, X[b, 2] - xc2)
            thr_a = snap_b if on_boundary(F, NF, NFc, a) else snap
            thr_b = snap_b if on_boundary(F, NF, NFc, b) else snap
            snap_a = ang_a < thr_a or tt < snap_t
            snap_bb = ang_b < thr_b or tt > 1.0 - snap_t
            if snap_a and (not snap_bb or ang_a <= ang_b):
                x = a
            elif snap_bb:
                x = b
            else:
                x = -1
            if x >= 0:
                # Cutting along an edge that is already a crack side or boundary adds nothing.
                if spoke_count(F, NF, NFc, c, x) == 2:
                    tip[side] = x
            else:
                tip[side] = a
                split[side] = True
        if tip[0] >= 0 and tip[1] >= 0 and not split[0] and not split[1] and tip[0] == tip[1]:
            tip[1] = -1
        # A cut that runs back along a crack or boundary edge at c would fork the crack behind
        # its tip (a stub); cracks only grow forward from there.
        for side in range(2):
            if tip[side] < 0 or sa[side] < 0:
                continue
            a, b, tt = sa[side], sb[side], st[side]
            p0 = X[a, 0] + tt * (X[b, 0] - X[a, 0]) - xc0
            p1 = X[a, 1] + tt * (X[b, 1] - X[a, 1]) - xc1
            p2 = X[a, 2] + tt * (X[b, 2] - X[a, 2]) - xc2
            for j in range(NFc[c]):
                f = NF[c, j]
                for q in range(3):
                    y = F[f, q]
                    if y != c and y != tip[side] and spoke_count(F, NF, NFc, c, y) == 1:
                        if _angle(p0, p1, p2, X[y, 0] - xc0, X[y, 1] - xc1,
                                  X[y, 2] - xc2) < back:
                            tip[side] = -1
                            split[side] = False
        nt = (tip[0] >= 0) + (tip[1] >= 0)
        interior = not on_boundary(F, NF, NFc, c)
        ok = nt >= (2 if interior else 1)
        # Room in the node -> face table for the faces the splits add.
        if NFc[c] + 2 > W:
            ok = False
        for side in range(2):
            if split[side]:
                a, b = sa[side], sb[side]
                for j in range(NFc[a]):
                    f = NF[a, j]
                    if F[f, 0] == b or F[f, 1] == b or F[f, 2] == b:
                        for q in range(3):
                            if NFc[F[f, q]] + 2 > W:
                                ok = False
        if not ok:
            dead[c] = True
            cnt[_ABORT] += 1
            continue
        for side in range(2):
            if split[side]:
                tip[side] = split_edge(sa[side], sb[side], st[side], X, F, S, AF, GR, NF, NFc,
                                       pid, onb, hn, taun, rho, crack_of, nver, segp,
                                       seg_alive, seg_info, segof, cnt)
                nevl[tip[side]] = -1
        for side in range(2):
            if split[side]:
                # The separation of a node scales with its own edge lengths: measure the new
                # node's, or its fan (smaller than its parents') would make it artificially tough.
                p = tip[side]
                hsum = 0.0
                hcnt = 0
                for j in range(NFc[p]):
                    f = NF[p, j]
                    for q in range(3):
                        y = F[f, q]
                        if y != p:
                            hsum += np.sqrt((X[y, 0] - X[p, 0]) ** 2 + (X[y, 1] - X[p, 1]) ** 2
                                            + (X[y, 2] - X[p, 2]) ** 2)
                            hcnt += 1
                if hcnt > 0:
                    scale = (hsum / hcnt) / hn[p]
                    hn[p] *= scale
                    taun[p] *= scale
        # ---- open the crack: split the node along the cut edges.
        nsplit = separate(c, tip[0], tip[1], X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of,
                          nver, cnt, buf, par, comp, fbuf)
        if nsplit == 0:
            dead[c] = True
            cnt[_ABORT] += 1
            continue
        cnt[_STAMP] += 1
        stamp = cnt[_STAMP]
        ncen = 0
        centers[ncen] = c
        ncen += 1
        for q in range(nsplit):
            centers[ncen] = buf[q]
            ncen += 1
        for side in range(2):
            free_tip[side] = False
            if tip[side] < 0:
                continue
            centers[ncen] = tip[side]
            ncen += 1
            # A tip that lay on a boundary is pinched by the cut: mend it; its crack is finished.
            m = separate(tip[side], -1, -1, X, F, NF, NFc, pid, onb, hn, taun, rho, crack_of,
                         nver, cnt, buf, par, comp, fbuf)
            free_tip[side] = m == 0
            for q in range(m):
                if ncen < centers.shape[0]:
                    centers[ncen] = buf[q]
                    ncen += 1
        # ---- record the segments and the crack they extend; cast their stress shadow.
        cid = crack_of[c]
        if cid < 0:
            cid = cnt[_NCRACK]
            cnt[_NCRACK] += 1
            if not interior:
                cnt[_NUC_EDGE] += 1
            corig[cid, 0] = xc0
            corig[cid, 1] = xc1
            corig[cid, 2] = xc2
            corig[cid, 3] = cnt[_STEP]
            corig[cid, 4] = 0.0 if interior else 1.0
        release = val[c] / hn[c]
        excess = val[c] - taun[c]
        crack_of[c] = -1
        for side in range(2):
            t = tip[side]
            if t < 0:
                continue
            af = -1
            for j in range(NFc[t]):
                f = NF[t, j]
                for q in range(3):
                    if pid[F[f, q]] == pid[c]:
                        af = AF[f]
            s = cnt[_NS]
            cnt[_NS] += 1
            segp[s, 0] = pid[c]
            segp[s, 1] = pid[t]
            seg_alive[s] = True
            seg_info[s, 0] = af
            seg_info[s, 1] = cnt[_STEP]
            seg_info[s, 2] = release
            segof[pid[c]] = s
            segof[pid[t]] = s
            pcid[pid[c]] = cid
            pcid[pid[t]] = cid
            # A new crack's first segments start its direction afresh (c may lie on another).
            _smooth_dir(pid[c], pid[t], X[t, 0] - xc0, X[t, 1] - xc1, X[t, 2] - xc2,
                        0.0 if nucleate else dir_len, pdir)
            d0 = X[t, 0] - xc0
            d1 = X[t, 1] - xc1
            d2 = X[t, 2] - xc2
            seglen = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            segl[side] = seglen
            clen[cid] += seglen
            if shadow and sig_n > 0.0:
                shadow_add(xc0 + 0.5 * d0, xc1 + 0.5 * d1, xc2 + 0.5 * d2,
                           gain * seglen * sig_n, nc0, nc1, nc2, G, gp)
                cnt[_DEP] += 1
        pc = pid[c]
        if pdir[pc, 0] == 0.0 and pdir[pc, 1] == 0.0 and pdir[pc, 2] == 0.0:
            pdir[pc, 0], pdir[pc, 1], pdir[pc, 2] = tc0, tc1, tc2
        # ---- recompute the changed faces and nodes (1-ring of the centres).
        nrf = 0
        for q in range(ncen):
            n = centers[q]
            if q <= nsplit:
                rho[n] = 0.0
            for j in range(NFc[n]):
                f = NF[n, j]
                if fst[f] != stamp:
                    fst[f] = stamp
                    regf[nrf] = f
                    nrf += 1
        for i in range(nrf):
            face_update(regf[i], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
        near_end[0] = False
        near_end[1] = False
        if tip_near and clen[cid] >= near_rad:
            # Localized fields: a free tip running alongside another crack ends there (once
            # its crack is a world length long: a younger one would stay a resolution-sized
            # stub).
            for side in range(2):
                t = tip[side]
                if t >= 0 and free_tip[side]:
                    vstamp += 1
                    p = pid[t]
                    if _near_other(t, cid, pdir[p, 0], pdir[p, 1], pdir[p, 2], near_rad,
                                   near_cos, 0.0, X, F, NF, NFc, pid, pcid, pdir, vst, vstamp,
                                   queue) > 0:
                        # Ended, unless it is converging on that crack: then it breaks
                        # through to it (decided below, after the region's update).
                        near_end[side] = True
        for side in range(2):
            t = tip[side]
            if t >= 0 and free_tip[side]:
                crack_of[t] = cid
                tipn[t, 0], tipn[t, 1], tipn[t, 2] = nc0, nc1, nc2
                if clen[cid] < max_len:
                    # alpha is the share carried over a step of tip_len: per step it is
                    # alpha^(step / tip_len), so the momentum lasts a world distance.
                    a_eff = (alpha ** min(segl[side] / tip_len, 1.0) if tip_len > 0.0
                             else alpha)
                    for i in range(3):
                        ni = nc0 if i == 0 else (nc1 if i == 1 else nc2)
                        for j in range(3):
                            nj = nc0 if j == 0 else (nc1 if j == 1 else nc2)
                            rho[t, i, j] += a_eff * excess * ni * nj
        # ---- fine relaxation: grow the region by rings, then damped Jacobi passes.
        lo = 0
        hi = nrf
        for _ring in range(rings):
            for i in range(lo, hi):
                f = regf[i]
                for q in range(3):
                    n = F[f, q]
                    for j in range(NFc[n]):
                        g = NF[n, j]
                        if fst[g] != stamp and nrf < regf.shape[0]:
                            fst[g] = stamp
                            regf[nrf] = g
                            nrf += 1
            lo = hi
            hi = nrf
        nrn = 0
        for i in range(nrf):
            f = regf[i]
            for q in range(3):
                n = F[f, q]
                if nst[n] != stamp and nrn < regn.shape[0]:
                    nst[n] = stamp
                    regn[nrn] = n
                    nrn += 1
        if nrelax > 0 and rate > 0:
            _relax(nrelax, rate, regf, nrf, regn, nrn, stamp, fst, F, S, NF, NFc, area, nrm,
                   grad, disp)
            for i in range(nrf):
                face_update(regf[i], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
        elif shadow:
            # The new shadow reaches the whole region: refresh its faces.
            for i in range(nrf):
                face_update(regf[i], X, F, S, area, nrm, grad, pr, G, gp, fr, r6)
        for i in range(nrn):
            n = regn[i]
            node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec,
                        crack_of[n] >= 0, grain, seed, sc, acc, ev, G, gp, tipn)
            nevl[n] = cnt[_DEP]
            # Only this event's tips: an older arrested tip was looked at when it stopped, and
            # looking again at every nearby event would cost a search per event.
            mine = n == tip[0] or n == tip[1]
            ended = (n == tip[0] and near_end[0]) or (n == tip[1] and near_end[1])
            if mine and crack_of[n] >= 0 and (ended or not val[n] > taun[n]) and lig_rad > 0:
                vstamp += 1
                if _bridge(n, crack_of[n], lig_rad, lig_cos, X, F, NF, NFc, nrm, area, pid,
                           pcid, pdir, onb, val, vec, taun, vst, vstamp, queue,
                           clen[crack_of[n]]):
                    cnt[_BRIDGE] += 1
                    ended = False
            if ended:
                # The near-crack rule ends this tip like one that met a crack.
                crack_of[n] = -1
                for i in range(3):
                    for j in range(3):
                        rho[n, i, j] = 0.0
                node_update(n, X, F, S, NF, NFc, area, nrm, grad, pr, rho, val, vec, False,
                            grain, seed, sc, acc, ev, G, gp, tipn)
                cnt[_TIP_NEAR] += 1
            _push(n, hk, hn_, hv, cnt, val, taun, nver, dead, crack_of, tip_first)
        cnt[_STEP] += 1
        cnt[_EVENTS] += 1
        if cnt[_FIRST] < 0:
            cnt[_FIRST] = cnt[_GROW]
        cnt[_IDLE] = 0
        done += 1


def _edges_boundary(faces: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Boundary flag per node (N,) and the unique undirected edges (E, 2)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    # One int64 key per edge: a 1-D unique is far faster than np.unique(axis=0).
    key = e[:, 0] * np.int64(n_nodes) + e[:, 1]
    uniq, counts = np.unique(key, return_counts=True)
    edges = np.stack([uniq // n_nodes, uniq % n_nodes], axis=1)
    bnd = np.zeros(n_nodes, bool)
    bnd[edges[counts == 1].ravel()] = True
    return bnd, edges


def _flaw(seed: int, points: np.ndarray) -> np.ndarray:
    """Seeded toughness factors per node, a smooth world-space field in [1 - FLAW, 1 + FLAW].

    The flaws live in world space (a sum of plane waves of wavelength ``FLAW_WAVELENGTH`` x the
    bounding-box diagonal), not per node: cracks then start at the same weak spots whatever the
    simulation resolution, which keeps the crack count resolution independent.
    """
    rng = np.random.default_rng(seed)
    diag = float(np.linalg.norm(points.max(0) - points.min(0))) or 1.0
    k = 2 * np.pi / (FLAW_WAVELENGTH * diag)
    dirs = rng.normal(size=(FLAW_WAVES, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, FLAW_WAVES)
    noise = np.cos(k * points @ dirs.T + phase).sum(1) / np.sqrt(FLAW_WAVES / 2)
    return 1.0 + FLAW * np.tanh(noise)


def _surface_wide(norm_sep: np.ndarray, bnd: np.ndarray) -> bool:
    """Whether at least ``FOOTPRINT_MIN_LOADED`` of the interior nodes are loaded."""
    use = (~bnd) & (norm_sep > 0)
    return bool(use.any()) and not use.sum() < FOOTPRINT_MIN_LOADED * max(int((~bnd).sum()), 1)


def _footprint_factor(points: np.ndarray, norm_sep: np.ndarray, bnd: np.ndarray) -> np.ndarray:
    """Per-node toughness factor that hides sub-footprint fluctuations of the initial field.

    The initial normalised separation ``v+ / h`` of interior nodes is averaged over a world grid
    of cell ``FOOTPRINT_REL`` x the bounding-box diagonal (trilinear splat and read-back); a
    node's factor is its value over that local mean (clipped to ``FOOTPRINT_CLIP``), so it fails
    when the *footprint's* separation, not its own, exceeds the toughness.  Fluctuations finer
    than the footprint (stress noise, mesh irregularity) are resolved ever better as the sim
    mesh refines and put ever higher peaks in the field: without this the number of cracks
    nucleated grew with the resolution (spot, crackle: +28 % from 100k to 400k faces).
    Boundary nodes and nodes without separation get 1, and so do all nodes when fewer than
    ``FOOTPRINT_MIN_LOADED`` of the interior nodes are loaded (a localized field such as an
    impact, whose own structure would be flattened: tests/test_iben.py radial density).
    """
    n = len(points)
    fac = np.ones(n)
    use = (~bnd) & (norm_sep > 0)
    if not _surface_wide(norm_sep, bnd):
        return fac
    lo = points.min(0)
    diag = float(np.linalg.norm(points.max(0) - lo)) or 1.0
    cell = FOOTPRINT_REL * diag
    u = (points - lo) / cell
    dims = np.floor(u.max(0)).astype(np.int64) + 2
    i0 = np.minimum(np.floor(u).astype(np.int64), dims - 2)
    w = u - i0
    acc = np.zeros(int(np.prod(dims)))
    wsum = np.zeros_like(acc)
    corners = []
    for a in (0, 1):
        for b in (0, 1):
            for c in (0, 1):
                idx = np.ravel_multi_index(((i0[:, 0] + a), (i0[:, 1] + b), (i0[:, 2] + c)),
                                           dims)
                wt = ((w[:, 0] if a else 1 - w[:, 0]) * (w[:, 1] if b else 1 - w[:, 1])
                      * (w[:, 2] if c else 1 - w[:, 2]))
                corners.append((idx, wt))
                acc += np.bincount(idx[use], wt[use] * norm_sep[use], minlength=len(acc))
                wsum += np.bincount(idx[use], wt[use], minlength=len(acc))
    mean = np.divide(acc, wsum, out=np.zeros_like(acc), where=wsum > 0)
    num = np.zeros(n)
    den = np.zeros(n)
    for idx, wt in corners:
        wt = wt * (wsum[idx] > 0)
        num += wt * mean[idx]
        den += wt
    local = np.divide(num, den, out=np.zeros(n), where=den > 0)
    ok = use & (local > 0)
    fac[ok] = np.clip(norm_sep[ok] / local[ok], 1.0 / FOOTPRINT_CLIP, FOOTPRINT_CLIP)
    return fac


def _percentile_ref(norm_sep: np.ndarray, bnd: np.ndarray) -> float:
    """REF_PERCENTILE of the positive normalised separations ``v+ / h`` of interior nodes.

    Falls back to all nodes when no interior node has a positive separation; 0 when none has.
    """
    pool = norm_sep[(~bnd) & (norm_sep > 0)]
    if len(pool) == 0:
        pool = norm_sep[norm_sep > 0]
    return float(np.percentile(pool, REF_PERCENTILE)) if len(pool) else 0.0


def _check(params: SolverParams) -> None:
    if not params.toughness > 0:
        raise CrackbakeError(f"toughness is {params.toughness}; it must be > 0 (try 1.0)")
    if not 0 <= params.tip_factor <= 1:
        raise CrackbakeError(f"tip factor is {params.tip_factor}; it must be in [0, 1] (try 0.75)")
    if params.relax_steps < 0 or not params.relax_rate >= 0:
        raise CrackbakeError("relax steps and relax rate must be >= 0 (try 3 and 0.1)")
    if params.max_cracks < 0 or params.max_steps < 0:
        raise CrackbakeError("max cracks and max steps must be >= 0")
    if params.max_crack_length is not None and not params.max_crack_length > 0:
        raise CrackbakeError(
            f"max crack length is {params.max_crack_length}; it must be > 0 mesh units"
        )
    if params.crack_width is not None and not params.crack_width > 0:
        raise CrackbakeError(f"crack width is {params.crack_width}; it must be > 0 mesh units")
    if not params.depth_ratio >= 0:
        raise CrackbakeError(f"depth ratio is {params.depth_ratio}; it must be >= 0")


def _shadow_grid(X0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Empty shadow grid over the bounding box and its parameters ``origin, cell, radius``."""
    lo, hi = X0.min(0), X0.max(0)
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    radius = SHADOW_REL * diag
    cell = radius / 3.0
    pad = 2
    while True:
        dims = np.floor((hi - lo) / cell).astype(np.int64) + 1 + 2 * pad
        if int(np.prod(dims)) <= SHADOW_MAX_CELLS:
            break
        cell *= 1.25
    origin = lo - pad * cell
    G = np.zeros((int(dims[0]), int(dims[1]), int(dims[2]), 6))
    return G, np.array([origin[0], origin[1], origin[2], cell, radius])


# State arrays, in _run's argument order, and the capacity each is sized by.
_NODE_ARRAYS = ("X", "NF", "NFc", "rho", "val", "vec", "taun", "hn", "pid", "onb", "crack_of",
                "nver", "dead", "nonuc", "nst", "nevl", "segof", "pcid", "pdir", "tipn", "lchk")
_FACE_ARRAYS = ("F", "S", "AF", "area", "nrm", "grad", "pr", "fst")
_SEG_ARRAYS = ("segp", "seg_alive", "seg_info")
_RUN_ORDER = ("X", "F", "S", "AF", "GR", "area", "nrm", "grad", "pr", "NF", "NFc", "rho", "val",
              "vec", "taun", "hn", "pid", "onb", "crack_of", "nver", "dead", "nonuc", "fst", "nst",
              "nevl", "segof", "pcid", "pdir", "tipn", "lchk", "hk", "hnode", "hv", "segp",
              "seg_alive", "seg_info", "clen", "corig", "G", "gp", "cnt", "prm")


def _grown(a: np.ndarray, size: int) -> np.ndarray:
    out = np.zeros((size,) + a.shape[1:], a.dtype)
    out[: len(a)] = a
    return out


def _grow(state: dict, has_growth: bool) -> None:
    """Double whichever capacity ran short (nodes, faces, segments, cracks)."""
    cnt = state["cnt"]
    ncap, mcap = len(state["X"]), len(state["F"])
    if cnt[_NN] + 32 > ncap:
        for k in _NODE_ARRAYS:
            state[k] = _grown(state[k], 2 * ncap)
        state["pid"][ncap:] = np.arange(ncap, 2 * ncap)
        state["crack_of"][ncap:] = -1
        state["segof"][ncap:] = -1
        state["pcid"][ncap:] = -1
        hcap = 2 * ncap + 65536
        for k in ("hk", "hnode", "hv"):
            state[k] = _grown(state[k], hcap)
    if cnt[_NF] + 16 > mcap:
        for k in _FACE_ARRAYS:
            state[k] = _grown(state[k], 2 * mcap)
        if has_growth:
            state["GR"] = _grown(state["GR"], 2 * mcap)
    if cnt[_NS] + 16 > len(state["segp"]):
        for k in _SEG_ARRAYS:
            state[k] = _grown(state[k], 2 * len(state["segp"]))
    if cnt[_NCRACK] + 2 > len(state["clen"]):
        state["corig"] = _grown(state["corig"], 2 * len(state["clen"]))
        state["clen"] = _grown(state["clen"], 2 * len(state["clen"]))


def solve_iben(
    sim, field, params: SolverParams, progress: Callable[[str], None] | None = None
) -> SolverResult:
    """Grow cracks with the Iben & O'Brien hybrid method (see the module docstring).

    Parameters
    ----------
    sim : SimMesh-like
        ``vertices (N, 3)`` float64, ``faces (M, 3)`` int64, ``asset_face (M,)`` int64; a
        triangulated 2-manifold surface, possibly with boundary.
    field : StressField-like
        ``stress (M, 3, 3)`` world in-plane stress per face (tension positive); ``growth``
        ``(M, 3, 3)`` or None, added per quasi-static growth step.
    params : SolverParams
        ``max_cracks`` bounds the distinct cracks started, ``max_steps`` the solver steps.
    progress : callable(str), optional
        Receives a one-line status at most every ``PROGRESS_SECONDS``.

    Returns
    -------
    SolverResult
        ``stats`` holds ``tau`` (separation per unit edge length at toughness 1 x toughness),
        ``events``, ``cracks`` (distinct cracks started), ``aborted``, ``growth_steps``,
        ``refreshed`` (lazy heap re-evaluations), ``edge_starts`` (cracks started on a crack
        or the boundary), ``nucleations_vetoed`` (refused by the footprint test),
        ``nucleations_near`` (refused beside an existing crack), ``tips_ended_near`` (by the
        near-crack rule), ``ligaments_broken`` (steps a tip took through a ligament,
        :func:`_bridge`), ``tips_arrested`` (free tips left below the toughness),
        ``shadow_radius``, ``stopped`` (why the run ended: ``max steps``, ``max cracks``,
        ``saturated`` or ``at rest``), ``loop_seconds`` (the crack loop alone),
        ``seconds``; and
        ``origins``, where and when each crack started and its length.
    """
    _check(params)
    t0 = _time.perf_counter()
    X0 = np.ascontiguousarray(sim.vertices, dtype=np.float64)
    F0 = np.ascontiguousarray(sim.faces, dtype=np.int64)
    S0 = np.ascontiguousarray(field.stress, dtype=np.float64)
    n0, m0 = len(X0), len(F0)
    if m0 == 0 or S0.shape != (m0, 3, 3):
        raise CrackbakeError(
            f"stress field has shape {S0.shape} for {m0} simulation faces; rebuild the field"
        )
    growth = getattr(field, "growth", None)
    has_growth = growth is not None and bool(np.any(growth))
    # Initial room for a few thousand events; _grow doubles it on demand.
    room = int(min(params.max_steps, INITIAL_ROOM)) + 16
    ncap = n0 + 10 * room
    mcap = m0 + 4 * room
    scap = 6 * room

    bnd, edges = _edges_boundary(F0, n0)
    elen = np.linalg.norm(X0[edges[:, 0]] - X0[edges[:, 1]], axis=1)
    hsum = np.bincount(edges.ravel(), np.repeat(elen, 2), minlength=n0)
    hcnt = np.bincount(edges.ravel(), minlength=n0)
    h_node = hsum / np.maximum(hcnt, 1)
    deg = np.bincount(F0.ravel(), minlength=n0)
    width = int(deg.max()) + EXTRA_DEGREE

    st: dict = {}
    st["X"] = _grown(X0, ncap)
    st["F"] = _grown(F0, mcap)
    st["S"] = _grown(S0, mcap)
    st["AF"] = _grown(np.asarray(sim.asset_face, dtype=np.int64), mcap)
    st["GR"] = (_grown(np.asarray(growth, dtype=np.float64), mcap) if has_growth
                else np.zeros((1, 3, 3)))
    st["area"] = np.zeros(mcap)
    st["nrm"] = np.zeros((mcap, 3))
    st["grad"] = np.zeros((mcap, 3, 3))
    st["pr"] = np.zeros((mcap, 8))
    st["fst"] = np.zeros(mcap, np.int64)
    st["NF"] = np.zeros((ncap, width), np.int64)
    st["NFc"] = np.zeros(ncap, np.int64)
    st["rho"] = np.zeros((ncap, 3, 3))
    st["val"] = np.zeros(ncap)
    st["vec"] = np.zeros((ncap, 3))
    st["crack_of"] = np.full(ncap, -1, np.int64)
    st["tipn"] = np.zeros((ncap, 3))
    G, gp = _shadow_grid(X0)
    st["G"], st["gp"] = G, gp
    _incidence(m0, st["F"], st["NF"], st["NFc"])
    gseed = params.seed % (1 << 52)

    def update_all(nn: int, nf: int, stress: np.ndarray) -> None:
        _update_all(nn, nf, st["X"], st["F"], stress, st["area"], st["nrm"], st["grad"],
                    st["pr"], st["NF"], st["NFc"], st["rho"], st["val"], st["vec"],
                    st["crack_of"], G, gp, GRAIN, gseed, st["tipn"])

    update_all(n0, m0, st["S"])
    if np.any(st["area"][:m0] <= 0):
        raise CrackbakeError("the simulation mesh has zero-area faces; clean the mesh first")

    val = st["val"]
    st["hn"] = _grown(h_node, ncap)
    ref = _percentile_ref(val[:n0] / np.maximum(h_node, 1e-300), bnd)
    if ref == 0.0 and has_growth:
        # No initial stress: toughness is relative to GROWTH_REF_STEPS steps of growth.
        # The compiled kernels measure it, so the reference is the separation the loop sees.
        update_all(n0, m0, st["GR"])
        ref = GROWTH_REF_STEPS * _percentile_ref(val[:n0] / np.maximum(h_node, 1e-300), bnd)
        update_all(n0, m0, st["S"])
    tau = params.toughness * ref
    norm0 = val[:n0] / np.maximum(h_node, 1e-300)
    if ref == 0.0 and has_growth:
        update_all(n0, m0, st["GR"])
        norm0 = val[:n0] / np.maximum(h_node, 1e-300)
        update_all(n0, m0, st["S"])
    fac = _flaw(params.seed, X0) * _footprint_factor(X0, norm0, bnd)
    # The near-crack rule is for localized fields only (the footprint factor's criterion).
    localized = not _surface_wide(norm0, bnd)
    near_rad = NEAR_REL * float(gp[4])
    nuc_rad = 0.0 if not localized else NUC_FOOTPRINT_REL * float(
        np.linalg.norm(X0.max(0) - X0.min(0)))
    st["taun"] = _grown(tau * h_node * fac, ncap)
    # The tip factor's reference step: the edge of an equilateral triangle of a
    # TIP_REF_FACES-face mesh of this surface (about the default simulation's edge length).
    total_area = 0.5 * float(np.linalg.norm(
        np.cross(X0[F0[:, 1]] - X0[F0[:, 0]], X0[F0[:, 2]] - X0[F0[:, 0]]), axis=1).sum())
    tip_len = (float(np.sqrt(4.0 * total_area / (np.sqrt(3.0) * TIP_REF_FACES)))
               if TIP_REF_FACES else 0.0)
    st["pid"] = np.arange(ncap, dtype=np.int64)
    st["onb"] = _grown(bnd, ncap)
    for k in ("nver", "nst", "nevl", "lchk"):
        st[k] = np.zeros(ncap, np.int64)
    st["dead"] = np.zeros(ncap, bool)
    st["nonuc"] = np.zeros(ncap, bool)
    st["segof"] = np.full(ncap, -1, np.int64)
    st["pcid"] = np.full(ncap, -1, np.int64)
    st["pdir"] = np.zeros((ncap, 3))
    hcap = ncap + 65536
    st["hk"] = np.zeros(hcap)
    st["hnode"] = np.zeros(hcap, np.int64)
    st["hv"] = np.zeros(hcap, np.int64)
    st["segp"] = np.zeros((scap, 2), np.int64)
    st["seg_alive"] = np.zeros(scap, bool)
    st["seg_info"] = np.zeros((scap, 3))
    st["clen"] = np.zeros(min(1024, room))
    st["corig"] = np.zeros((len(st["clen"]), 5))
    cnt = np.zeros(20, np.int64)
    cnt[_FIRST] = -1
    cnt[_NN], cnt[_NF] = n0, m0
    st["cnt"] = cnt
    max_len = np.inf if params.max_crack_length is None else float(params.max_crack_length)
    st["prm"] = np.array([
        params.tip_factor, params.relax_rate, params.relax_steps, max_len,
        np.radians(SNAP_DEG), np.radians(SNAP_BOUNDARY_DEG), SNAP_T, RELAX_RINGS, SHADOW_GAIN,
        np.radians(BACK_DEG), float(TIP_FIRST), GRAIN, float(gseed),
        near_rad, np.cos(np.radians(NEAR_PAR_DEG)), nuc_rad, DIR_SMOOTH * near_rad,
        tip_len, float(localized), LIGAMENT_REL * float(gp[4]),
        np.cos(np.radians(LIGAMENT_CONE_DEG)),
    ], dtype=np.float64)
    if tau > 0:
        _rebuild_heap(st["hk"], st["hnode"], st["hv"], cnt, val, st["taun"], st["nver"],
                      st["dead"], st["crack_of"], TIP_FIRST)
    # Chunks are sized so a call takes about a tenth of a second: progress stays responsive
    # without a clock inside the compiled loop.
    chunk = 64
    last_msg = t_loop = _time.perf_counter()
    while tau > 0:
        t_call = _time.perf_counter()
        code = _run(*(st[k] for k in _RUN_ORDER), int(params.max_cracks),
                    int(params.max_steps), chunk)
        now = _time.perf_counter()
        if code == _FULL:
            _grow(st, has_growth)
            continue
        if now - t_call < 0.05:
            chunk = min(chunk * 2, 1 << 20)
        elif now - t_call > 0.2:
            chunk = max(chunk // 2, 16)
        if progress is not None and now - last_msg >= PROGRESS_SECONDS and code == _MORE:
            progress(f"iben: {int(cnt[_EVENTS])} crack events, {int(cnt[_NCRACK])} cracks, "
                     f"{int(cnt[_STEP])}/{params.max_steps} steps")
            last_msg = now
        if code == _DONE:
            break

    loop_seconds = _time.perf_counter() - t_loop
    nn, nf, ns = int(cnt[_NN]), int(cnt[_NF]), int(cnt[_NS])
    # Bring every face and node up to date with the final shadow (the heap was lazy).
    update_all(nn, nf, st["S"])
    steps = int(cnt[_STEP])
    alive = st["seg_alive"][:ns]
    X, taun, val = st["X"], st["taun"], st["val"]
    cracks = _chain(st["segp"][:ns][alive], st["seg_info"][:ns][alive], X, st["onb"], steps,
                    params, X0)
    sep = np.where(taun[:nn] > 0, val[:nn] / np.where(taun[:nn] > 0, taun[:nn], 1.0), 0.0)
    pr = st["pr"][:nf]
    # Effective stress (what the cracks left): l1 d1 d1^T + l2 d2 d2^T.
    s_final = (pr[:, 0, None, None] * np.einsum("ea,eb->eab", pr[:, 2:5], pr[:, 2:5])
               + pr[:, 1, None, None] * np.einsum("ea,eb->eab", pr[:, 5:8], pr[:, 5:8]))
    return SolverResult(
        cracks=cracks,
        vertices=X[:nn].copy(),
        faces=st["F"][:nf].copy(),
        asset_face=st["AF"][:nf].copy(),
        stress_initial=S0.copy(),
        stress_final=s_final,
        separation=sep,
        steps=steps,
        origins=np.column_stack([st["corig"][: int(cnt[_NCRACK])],
                                 st["clen"][: int(cnt[_NCRACK])]]),
        stats={
            "tau": float(tau),
            "events": int(cnt[_EVENTS]),
            "cracks": int(cnt[_NCRACK]),
            "paths": len(cracks),
            "aborted": int(cnt[_ABORT]),
            "growth_steps": int(cnt[_GROW]),
            "stopped": ("max steps" if steps >= params.max_steps
                        else "saturated" if cnt[_SATURATED]
                        else "max cracks" if cnt[_NCRACK] >= params.max_cracks
                        else "at rest"),
            "refreshed": int(cnt[_REFRESH]),
            "edge_starts": int(cnt[_NUC_EDGE]),
            "nucleations_vetoed": int(cnt[_NUC_VETO]),
            "nucleations_near": int(cnt[_NUC_NEAR]),
            "tips_ended_near": int(cnt[_TIP_NEAR]),
            "ligaments_broken": int(cnt[_BRIDGE]),
            "tips_arrested": int(np.count_nonzero(st["crack_of"][:nn] >= 0)),
            "shadow_radius": float(gp[4]),
            "loop_seconds": loop_seconds,
            "seconds": _time.perf_counter() - t0,
        },
    )


def crack_graph(segp: np.ndarray) -> dict[int, list[int]]:
    """Point id -> indices of the segments touching it."""
    adj: dict[int, list[int]] = {}
    for s, (a, b) in enumerate(segp.tolist()):
        adj.setdefault(a, []).append(s)
        adj.setdefault(b, []).append(s)
    return adj


def _chain(segp, info, X, onb, steps, params: SolverParams, X0) -> list[CrackPath]:
    """Chain crack segments into polylines between junctions and ends; width, depth, time.

    Point ``i`` of a path takes the asset face of segment ``i`` (the last point that of the last
    segment): every segment lies in one sim triangle, hence in one asset face, and its start point
    is in that face's closure.
    """
    if len(segp) == 0:
        return []
    adj = crack_graph(segp)
    used = np.zeros(len(segp), bool)
    chains: list[tuple[list[int], list[int]]] = []  # (point ids, segment ids)

    def walk(start_pt: int, s: int) -> tuple[list[int], list[int]]:
        pts, segs = [start_pt], []
        pt = start_pt
        while True:
            used[s] = True
            segs.append(s)
            a, b = segp[s]
            pt = b if a == pt else a
            pts.append(int(pt))
            nxt = [q for q in adj[pt] if not used[q]]
            if len(adj[pt]) != 2 or not nxt:
                return pts, segs
            s = nxt[0]

    for pt in sorted(adj):
        if len(adj[pt]) != 2:
            for s in adj[pt]:
                if not used[s]:
                    chains.append(walk(pt, s))
    for s in range(len(segp)):  # closed loops
        if not used[s]:
            chains.append(walk(int(segp[s][0]), s))

    rel = info[:, 2]
    wmax = float(rel.max()) if len(rel) and rel.max() > 0 else 1.0
    diag = float(np.linalg.norm(X0.max(0) - X0.min(0)))
    width = params.crack_width if params.crack_width is not None else 1e-3 * diag
    total = max(steps, 1)
    out = []
    for pts, segs in chains:
        p = X[np.asarray(pts)]
        sr = rel[segs] / wmax
        w = np.empty(len(pts))
        w[0], w[-1] = sr[0], sr[-1]
        w[1:-1] = 0.5 * (sr[:-1] + sr[1:])
        st = info[segs, 1]
        t = np.empty(len(pts))
        t[0], t[-1] = st[0], st[-1]
        t[1:-1] = np.minimum(st[:-1], st[1:])
        seglen = np.linalg.norm(np.diff(p, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seglen)])
        length = arc[-1]
        taper = max(0.25 * length, 1e-300)
        # Free tips (ends that are neither junctions nor on the mesh boundary) close to zero.
        for end, dist in ((pts[0], arc), (pts[-1], length - arc)):
            if len(adj[end]) == 1 and not onb[end]:
                w = w * np.clip(dist / taper, 0.0, 1.0)
        af = np.empty(len(pts), np.int64)
        af[:-1] = info[segs, 0].astype(np.int64)
        af[-1] = af[-2]
        out.append(CrackPath(points=p, asset_faces=af, time=t / total, width=w, depth=w))
    # The widest point opens exactly crack_width.
    top = max(float(c.width.max()) for c in out)
    scale = width / top if top > 0 else 0.0
    for c in out:
        c.width = c.width * scale
        c.depth = params.depth_ratio * c.width
    return out
