"""The state and scratch of the compiled loop as numba struct references.

The driver keeps :class:`~crackbake.simulate.solver.iben.state.State` and
:class:`~crackbake.simulate.solver.iben.state.Work` as named tuples; each compiled entry point
(:func:`.loop.run`, :func:`.update.rebuild`, :func:`.update.requeue_all`) turns them into the
struct references below (same field names, same arrays: nothing is copied) and every kernel
below it takes those.  A struct reference is passed as one pointer, a named tuple of 41 arrays
as some 290 values: with tuples, each kernel taking the state compiled several times slower and
each call cost more.  The field types are fixed here (``C``-contiguous arrays of one dtype
and rank each), so every kernel compiles once and its cache is reused across processes;
tests/test_iben.py checks them against a real state.
"""

from __future__ import annotations

from numba import njit, types
from numba.experimental import structref


@structref.register
class StateRef(types.StructRef):
    """numba type of the loop's state (the fields of ``State``)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@structref.register
class WorkRef(types.StructRef):
    """numba type of the loop's scratch (the fields of ``Work``)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


_F81, _F82, _F83, _F84 = (types.Array(types.float64, nd, "C") for nd in (1, 2, 3, 4))
_I81, _I82 = (types.Array(types.int64, nd, "C") for nd in (1, 2))
_B11 = types.Array(types.boolean, 1, "C")

STATE_FIELDS = (("X", _F82), ("F", _I82), ("S", _F83), ("AF", _I81), ("GR", _F83), ("area", _F81),
    ("nrm", _F82), ("grad", _F83), ("pr", _F82), ("fst", _I81), ("NF", _I82), ("NFc", _I81),
    ("rho", _F83), ("val", _F81), ("vec", _F82), ("taun", _F81), ("hn", _F81), ("pid", _I81),
    ("onb", _B11), ("crack_of", _I81), ("nver", _I81), ("dead", _B11), ("nonuc", _B11),
    ("nst", _I81), ("nevl", _I81), ("lchk", _I81), ("tipn", _F82), ("segof", _I81),
    ("pcid", _I81), ("pdir", _F82), ("mate", _I81), ("hk", _F81), ("hnode", _I81), ("hv", _I81),
    ("segp", _I82),
    ("seg_alive", _B11), ("seg_info", _F82), ("clen", _F81), ("corig", _F82), ("G", _F84),
    ("gp", _F81), ("cnt", _I81))
WORK_FIELDS = (("regf", _I81), ("regn", _I81), ("disp", _F82), ("buf", _I81), ("par", _I81),
    ("comp", _I81), ("fbuf", _I81), ("centers", _I81), ("sc", _F81), ("acc", _F83), ("ev", _F82),
    ("fr", _F82), ("r6", _F81), ("geo", _F82), ("sa", _I81), ("sb", _I81), ("st", _F81),
    ("sd", _F81), ("tip", _I81), ("split", _B11), ("free_tip", _B11), ("near_end", _B11),
    ("segl", _F81), ("vst", _I81), ("vstamp", _I81), ("queue", _I81))
STATE_T = StateRef(list(STATE_FIELDS))
WORK_T = WorkRef(list(WORK_FIELDS))


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def state_ref(s):
    """The struct reference of named tuple ``s`` (a State), sharing its arrays."""
    r = structref.new(STATE_T)
    r.X = s.X
    r.F = s.F
    r.S = s.S
    r.AF = s.AF
    r.GR = s.GR
    r.area = s.area
    r.nrm = s.nrm
    r.grad = s.grad
    r.pr = s.pr
    r.fst = s.fst
    r.NF = s.NF
    r.NFc = s.NFc
    r.rho = s.rho
    r.val = s.val
    r.vec = s.vec
    r.taun = s.taun
    r.hn = s.hn
    r.pid = s.pid
    r.onb = s.onb
    r.crack_of = s.crack_of
    r.nver = s.nver
    r.dead = s.dead
    r.nonuc = s.nonuc
    r.nst = s.nst
    r.nevl = s.nevl
    r.lchk = s.lchk
    r.tipn = s.tipn
    r.segof = s.segof
    r.pcid = s.pcid
    r.pdir = s.pdir
    r.mate = s.mate
    r.hk = s.hk
    r.hnode = s.hnode
    r.hv = s.hv
    r.segp = s.segp
    r.seg_alive = s.seg_alive
    r.seg_info = s.seg_info
    r.clen = s.clen
    r.corig = s.corig
    r.G = s.G
    r.gp = s.gp
    r.cnt = s.cnt
    return r


@njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)
def work_ref(w):
    """The struct reference of named tuple ``w`` (a Work), sharing its arrays."""
    r = structref.new(WORK_T)
    r.regf = w.regf
    r.regn = w.regn
    r.disp = w.disp
    r.buf = w.buf
    r.par = w.par
    r.comp = w.comp
    r.fbuf = w.fbuf
    r.centers = w.centers
    r.sc = w.sc
    r.acc = w.acc
    r.ev = w.ev
    r.fr = w.fr
    r.r6 = w.r6
    r.geo = w.geo
    r.sa = w.sa
    r.sb = w.sb
    r.st = w.st
    r.sd = w.sd
    r.tip = w.tip
    r.split = w.split
    r.free_tip = w.free_tip
    r.near_end = w.near_end
    r.segl = w.segl
    r.vst = w.vst
    r.vstamp = w.vstamp
    r.queue = w.queue
    return r
