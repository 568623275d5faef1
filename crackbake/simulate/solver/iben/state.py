"""The solver state (named arrays), the loop's parameters and scratch, and their growth.

Everything the compiled loop reads or writes travels in three named tuples: :class:`State`
(the mesh, the crack network and the heap, grown by :func:`grow` when full),
:class:`LoopParams` (scalars by name) and :class:`Work` (scratch rows of one
:func:`crackbake.simulate.solver.iben.loop.run` call).  Mutable scalars (counts, stamps) are
slots of the int array ``State.cnt`` named below.

The class bodies of ``State`` and ``Work`` are the one list of their fields: each annotation
names a field's dtype and rank (``F1`` ... ``B1`` below), and :mod:`.structs` generates from
them the numba struct references the kernels take.  The compiled entry points take the named
tuples and turn them into struct references, because (benchmarks/bench_state.py) a kernel
taking the 43-field ``State`` as a tuple (passed flattened, some 340 values) compiles about
1.6x slower than one taking its struct reference (one pointer); a field read costs the same
in either, and each call from Python unboxes the tuple's arrays one by one (some 16 µs), so
the entry points are called per chunk of work, never per item.
"""

from __future__ import annotations

from typing import Annotated, NamedTuple

import numpy as np

# The field types of State and Work: C-contiguous arrays of one dtype and rank.  The class
# bodies below are the one list of their fields; structs.py builds the numba struct types
# from them (a field is added in one place).
F1 = Annotated[np.ndarray, np.float64, 1]
F2 = Annotated[np.ndarray, np.float64, 2]
F3 = Annotated[np.ndarray, np.float64, 3]
F4 = Annotated[np.ndarray, np.float64, 4]
I1 = Annotated[np.ndarray, np.int64, 1]
I2 = Annotated[np.ndarray, np.int64, 2]
B1 = Annotated[np.ndarray, np.bool_, 1]

# Slots of State.cnt.  heap.py's kernels use the first (the heap size) by number.
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

    X: F2  #: (Ncap, 3) node positions
    F: I2  #: (Mcap, 3) faces
    S: F3  #: (Mcap, 3, 3) world in-plane stress per face (tension positive)
    AF: I1  #: (Mcap,) asset face
    GR: F3  #: (Mcap, 3, 3) growth per step, or (1, 3, 3) zeros without growth
    area: F1  #: (Mcap,)
    nrm: F2  #: (Mcap, 3) unit normals
    grad: F3  #: (Mcap, 3, 3) barycentric gradients
    pr: F2  #: (Mcap, 8) principal split of the effective stress: l1, l2, d1, d2
    fst: I1  #: (Mcap,) face stamp of the last event that touched it
    NF: I2  #: (Ncap, W) incident faces per node
    NFc: I1  #: (Ncap,) their count
    rho: F3  #: (Ncap, 3, 3) persistent residual
    val: F1  #: (Ncap,) largest separation eigenvalue
    vec: F2  #: (Ncap, 3) its eigenvector (crack normal)
    taun: F1  #: (Ncap,) toughness in separation units
    hn: F1  #: (Ncap,) mean edge length at the node
    pid: I1  #: (Ncap,) point of the node
    onb: B1  #: (Ncap,) on the mesh boundary
    crack_of: I1  #: (Ncap,) crack whose free tip the node is, else -1
    nver: I1  #: (Ncap,) heap version
    dead: B1  #: (Ncap,) never cut again
    nonuc: B1  #: (Ncap,) no crack may start here (beside an existing one)
    nst: I1  #: (Ncap,) node stamp of the last event that touched it
    nevl: I1  #: (Ncap,) shadow deposit count when last evaluated (lazy heap)
    lchk: I1  #: (Ncap,) event count + 1 when last checked for a ligament at rest
    tipn: F2  #: (Ncap, 3) crack normal of a free tip
    segof: I1  #: (Ncap,) per point: last live segment at it
    pcid: I1  #: (Ncap,) per point: crack it belongs to, else -1
    pdir: F2  #: (Ncap, 3) per point: smoothed crack direction
    mate: I1  #: (Ncap,) per point: nearest node of a touching shell, else -1
    hk: F1  #: (Hcap,) heap keys
    hnode: I1  #: (Hcap,) heap nodes
    hv: I1  #: (Hcap,) heap versions
    segp: I2  #: (Scap, 2) segment points
    seg_alive: B1  #: (Scap,)
    seg_info: F2  #: (Scap, 3) asset face, step, released v+/h
    clen: F1  #: (Ccap,) length per crack
    corig: F2  #: (Ccap, 5) origin per crack: x, y, z, step, on an edge
    G: F4  #: (nx, ny, nz, 6) shadow grid (or (1, 1, 1, 6) without)
    gp: F1  #: (5,) shadow grid origin (3), cell size, kernel radius; + impacts (shadow.py)
    period: float  #: tile period in x and y (plate [0, period)²), 0: not periodic
    gq: float  #: grain quantum: initial nodes hash their rest point in whole units of it
    gn0: int  #: initial node count: nodes from it on were made by splits (grain_angle)
    cnt: I1  #: (N_COUNTERS,) int64 counters, slots above


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

    regf: I1  #: (Mcap,) faces of the event's region
    regn: I1  #: (Ncap,) nodes of the event's region
    disp: F2  #: (Ncap, 3) relaxation displacements (zero between events)
    kinv: F2  #: (Ncap, 7) relaxation: inverse block stiffness per region node (relax.py)
    buf: I1  #: (W,) nodes made by a node split
    par: I1  #: (W,) union-find
    comp: I1  #: (W,) components
    fbuf: I1  #: (W,) faces
    centers: I1  #: (3 W + 3,) nodes whose 1-ring changed
    sc: F1  #: (14,) tip principal split
    acc: F3  #: (2, 3, 3) tensor accumulators
    ev: F2  #: (3, 3) eigenvectors
    fr: F2  #: (2, 3) face frame
    r6: F1  #: (6,) shadow sample
    geo: F2  #: (3, 3) the cut: centre, crack normal, direction along the crack
    sa: I1  #: (2,) per side: crossed edge start, else -1
    sb: I1  #: (2,) crossed edge end
    st: F1  #: (2,) crossing parameter on the edge
    sd: F1  #: (2,) crossing distance from the centre
    tip: I1  #: (2,) per side: tip node, else -1
    split: B1  #: (2,) the tip is a new node on the crossed edge
    free_tip: B1  #: (2,) the tip is free (did not meet a crack or the boundary)
    near_end: B1  #: (2,) the near-crack rule ends the tip
    segl: F1  #: (2,) segment length
    vst: I1  #: (Ncap,) visit stamps of the breadth-first searches
    vstamp: I1  #: (1,) current visit stamp
    queue: I1  #: (Ncap,) breadth-first queue


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
        kinv=np.empty((ncap, 7)),
        buf=np.empty(width, np.int64), par=np.empty(width, np.int64),
        comp=np.empty(width, np.int64), fbuf=np.empty(width, np.int64),
        centers=np.empty(3 * width + 3, np.int64), sc=np.empty(14), acc=np.empty((2, 3, 3)),
        ev=np.empty((3, 3)), fr=np.empty((2, 3)), r6=np.empty(6), geo=np.zeros((3, 3)),
        sa=np.empty(2, np.int64), sb=np.empty(2, np.int64), st=np.empty(2), sd=np.empty(2),
        tip=np.empty(2, np.int64), split=np.empty(2, np.bool_), free_tip=np.empty(2, np.bool_),
        near_end=np.empty(2, np.bool_), segl=np.empty(2), vst=np.zeros(ncap, np.int64),
        vstamp=np.zeros(1, np.int64), queue=np.empty(ncap, np.int64),
    )
