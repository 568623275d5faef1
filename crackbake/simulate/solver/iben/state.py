"""The solver state (named arrays), the loop's parameters and scratch, and their growth.

Everything the compiled loop reads or writes travels in three named tuples (numba passes them
as heterogeneous tuples, so field access costs nothing): :class:`State` (the mesh, the crack
network and the heap, grown by :func:`grow` when full), :class:`LoopParams` (scalars by name)
and :class:`Work` (scratch rows of one :func:`crackbake.simulate.solver.iben.loop.run` call).
Mutable scalars (counts, stamps) are slots of the int array ``State.cnt`` named below.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# Slots of State.cnt.  topology.py's kernels use the first four by number (heap size, nodes,
# faces, segments), so their order is fixed.
(HEAP, NODES, FACES, SEGS, STEP, EVENTS, STAMP, CRACKS, ABORTED, GROWTH_STEPS, DEPOSITS,
 REFRESHED, NUC_EDGE, NUC_VETOED, NUC_NEAR, TIPS_NEAR, IDLE, FIRST_CRACK, SATURATED,
 BRIDGED, CROSSED) = range(21)
N_COUNTERS = 21

# Return codes of the loop: chunk done, finished, state full (grow and call again), node ->
# face table too narrow for the next event (widen it and call again), a drying step grew the
# stress (recompute and re-queue on threads, call again).
MORE, DONE, FULL, WIDEN, DRIED = 0, 1, 2, 3, 4


class State(NamedTuple):
    """The solver state; capacities ``Ncap`` nodes, ``Mcap`` faces, ``Scap`` segments.

    Nodes never move; a node split copies its position.  ``pid`` maps a node to its *point*
    (the node it was split from, recursively): crack segments join points.
    """

    X: np.ndarray  #: (Ncap, 3) node positions
    F: np.ndarray  #: (Mcap, 3) faces
    S: np.ndarray  #: (Mcap, 3, 3) world in-plane stress per face (tension positive)
    AF: np.ndarray  #: (Mcap,) asset face
    GR: np.ndarray  #: (Mcap, 3, 3) growth per step, or (1, 3, 3) zeros without growth
    area: np.ndarray  #: (Mcap,)
    nrm: np.ndarray  #: (Mcap, 3) unit normals
    grad: np.ndarray  #: (Mcap, 3, 3) barycentric gradients
    pr: np.ndarray  #: (Mcap, 8) principal split of the effective stress: l1, l2, d1, d2
    fst: np.ndarray  #: (Mcap,) face stamp of the last event that touched it
    NF: np.ndarray  #: (Ncap, W) incident faces per node
    NFc: np.ndarray  #: (Ncap,) their count
    rho: np.ndarray  #: (Ncap, 3, 3) persistent residual
    val: np.ndarray  #: (Ncap,) largest separation eigenvalue
    vec: np.ndarray  #: (Ncap, 3) its eigenvector (crack normal)
    taun: np.ndarray  #: (Ncap,) toughness in separation units
    hn: np.ndarray  #: (Ncap,) mean edge length at the node
    pid: np.ndarray  #: (Ncap,) point of the node
    onb: np.ndarray  #: (Ncap,) on the mesh boundary
    crack_of: np.ndarray  #: (Ncap,) crack whose free tip the node is, else -1
    nver: np.ndarray  #: (Ncap,) heap version
    dead: np.ndarray  #: (Ncap,) never cut again
    nonuc: np.ndarray  #: (Ncap,) no crack may start here (beside an existing one)
    nst: np.ndarray  #: (Ncap,) node stamp of the last event that touched it
    nevl: np.ndarray  #: (Ncap,) shadow deposit count when last evaluated (lazy heap)
    lchk: np.ndarray  #: (Ncap,) event count + 1 when last checked for a ligament at rest
    tipn: np.ndarray  #: (Ncap, 3) crack normal of a free tip
    segof: np.ndarray  #: (Ncap,) per point: last live segment at it
    pcid: np.ndarray  #: (Ncap,) per point: crack it belongs to, else -1
    pdir: np.ndarray  #: (Ncap, 3) per point: smoothed crack direction
    mate: np.ndarray  #: (Ncap,) per point: nearest node of a touching shell, else -1
    hk: np.ndarray  #: (Hcap,) heap keys
    hnode: np.ndarray  #: (Hcap,) heap nodes
    hv: np.ndarray  #: (Hcap,) heap versions
    segp: np.ndarray  #: (Scap, 2) segment points
    seg_alive: np.ndarray  #: (Scap,)
    seg_info: np.ndarray  #: (Scap, 3) asset face, step, released v+/h
    clen: np.ndarray  #: (Ccap,) length per crack
    corig: np.ndarray  #: (Ccap, 5) origin per crack: x, y, z, step, on an edge
    G: np.ndarray  #: (nx, ny, nz, 6) shadow grid (or (1, 1, 1, 6) without)
    gp: np.ndarray  #: (5,) shadow grid origin (3), cell size, kernel radius
    cnt: np.ndarray  #: (N_COUNTERS,) int64 counters, slots above


class LoopParams(NamedTuple):
    """Scalars of the loop (see :mod:`crackbake.simulate.solver.iben.constants`)."""

    alpha: float  #: tip factor
    rate: float  #: relaxation rate
    nrelax: int  #: relaxation passes
    max_len: float  #: longest crack (inf: unlimited)
    snap: float  #: snap angle, radians
    snap_b: float  #: snap angle at a crack or the boundary, radians
    snap_t: float  #: snap fraction of the edge
    rings: int  #: fine relaxation rings
    gain: float  #: shadow gain
    back: float  #: back-cut angle, radians
    tip_first: bool  #: tips before nucleations
    grain: float  #: grain weight
    seed: int  #: grain seed
    near_rad: float  #: near-crack radius (0: rule off)
    near_cos: float  #: cosine of the near-crack parallel angle
    nuc_rad: float  #: footprint radius of nucleation (0: per-node test)
    dir_len: float  #: length of the direction's moving average
    tip_len: float  #: reference step of the tip factor
    tip_near: bool  #: near-crack rule ends tips (localized fields)
    lig_rad: float  #: ligament radius (0: rule off)
    lig_cos: float  #: cosine of the ligament cone half-angle
    nuc_any: float  #: no nucleation within this of any crack
    max_cracks: int
    max_steps: int


class Work(NamedTuple):
    """Scratch of one loop call; sized so that nothing can overflow (see :func:`work`)."""

    regf: np.ndarray  #: (Mcap,) faces of the event's region
    regn: np.ndarray  #: (Ncap,) nodes of the event's region
    disp: np.ndarray  #: (Ncap, 3) relaxation displacements (zero between events)
    buf: np.ndarray  #: (W,) nodes made by a node split
    par: np.ndarray  #: (W,) union-find
    comp: np.ndarray  #: (W,) components
    fbuf: np.ndarray  #: (W,) faces
    centers: np.ndarray  #: (3 W + 3,) nodes whose 1-ring changed
    sc: np.ndarray  #: (14,) tip principal split
    acc: np.ndarray  #: (2, 3, 3) tensor accumulators
    ev: np.ndarray  #: (3, 3) eigenvectors
    fr: np.ndarray  #: (2, 3) face frame
    r6: np.ndarray  #: (6,) shadow sample
    geo: np.ndarray  #: (3, 3) the cut: centre, crack normal, direction along the crack
    sa: np.ndarray  #: (2,) per side: crossed edge start, else -1
    sb: np.ndarray  #: (2,) crossed edge end
    st: np.ndarray  #: (2,) crossing parameter on the edge
    sd: np.ndarray  #: (2,) crossing distance from the centre
    tip: np.ndarray  #: (2,) per side: tip node, else -1
    split: np.ndarray  #: (2,) the tip is a new node on the crossed edge
    free_tip: np.ndarray  #: (2,) the tip is free (did not meet a crack or the boundary)
    near_end: np.ndarray  #: (2,) the near-crack rule ends the tip
    segl: np.ndarray  #: (2,) segment length
    vst: np.ndarray  #: (Ncap,) visit stamps of the breadth-first searches
    vstamp: np.ndarray  #: (1,) current visit stamp
    queue: np.ndarray  #: (Ncap,) breadth-first queue


def grown(a: np.ndarray, size: int) -> np.ndarray:
    """``a`` zero-padded (or cut) to ``size`` rows."""
    out = np.zeros((size,) + a.shape[1:], a.dtype)
    out[: len(a)] = a
    return out


_NODE_FIELDS = ("X", "NF", "NFc", "rho", "val", "vec", "taun", "hn", "pid", "onb", "crack_of",
                "nver", "dead", "nonuc", "nst", "nevl", "segof", "pcid", "pdir", "tipn", "lchk",
                "mate")
_FACE_FIELDS = ("F", "S", "AF", "area", "nrm", "grad", "pr", "fst")
_SEG_FIELDS = ("segp", "seg_alive", "seg_info")


def grow(s: State, has_growth: bool) -> State:
    """Double whichever capacity ran short (nodes, faces, segments, cracks)."""
    cnt = s.cnt
    ncap, mcap = len(s.X), len(s.F)
    new: dict[str, np.ndarray] = {}
    if cnt[NODES] + 32 > ncap:
        new.update({k: grown(getattr(s, k), 2 * ncap) for k in _NODE_FIELDS})
        new["pid"][ncap:] = np.arange(ncap, 2 * ncap)
        new["crack_of"][ncap:] = -1
        new["segof"][ncap:] = -1
        new["pcid"][ncap:] = -1
        new["mate"][ncap:] = -1
        hcap = 2 * ncap + 65536
        new.update({k: grown(getattr(s, k), hcap) for k in ("hk", "hnode", "hv")})
    if cnt[FACES] + 16 > mcap:
        new.update({k: grown(getattr(s, k), 2 * mcap) for k in _FACE_FIELDS})
        if has_growth:
            new["GR"] = grown(s.GR, 2 * mcap)
    if cnt[SEGS] + 16 > len(s.segp):
        new.update({k: grown(getattr(s, k), 2 * len(s.segp)) for k in _SEG_FIELDS})
    if cnt[CRACKS] + 2 > len(s.clen):
        new["corig"] = grown(s.corig, 2 * len(s.clen))
        new["clen"] = grown(s.clen, 2 * len(s.clen))
    return s._replace(**new)


def widen(s: State, extra: int) -> State:
    """Widen the node -> face table by ``extra`` columns."""
    NF = np.zeros((len(s.NF), s.NF.shape[1] + extra), np.int64)
    NF[:, : s.NF.shape[1]] = s.NF
    return s._replace(NF=NF)


def work(s: State) -> Work:
    """Scratch for the loop on state ``s``: every row is as long as it can ever need to be
    (a region holds each face or node once, a node splits into at most W nodes)."""
    ncap, mcap, width = len(s.X), len(s.F), s.NF.shape[1]
    return Work(
        regf=np.empty(mcap, np.int64), regn=np.empty(ncap, np.int64), disp=np.zeros((ncap, 3)),
        buf=np.empty(width, np.int64), par=np.empty(width, np.int64),
        comp=np.empty(width, np.int64), fbuf=np.empty(width, np.int64),
        centers=np.empty(3 * width + 3, np.int64), sc=np.empty(14), acc=np.empty((2, 3, 3)),
        ev=np.empty((3, 3)), fr=np.empty((2, 3)), r6=np.empty(6), geo=np.zeros((3, 3)),
        sa=np.empty(2, np.int64), sb=np.empty(2, np.int64), st=np.empty(2), sd=np.empty(2),
        tip=np.empty(2, np.int64), split=np.empty(2, np.bool_), free_tip=np.empty(2, np.bool_),
        near_end=np.empty(2, np.bool_), segl=np.empty(2), vst=np.zeros(ncap, np.int64),
        vstamp=np.zeros(1, np.int64), queue=np.empty(ncap, np.int64),
    )
