"""The solver state: allocation and growth."""

from __future__ import annotations

import numpy as np

from crackbake.simulate.solver.iben.constants import _NCRACK, _NF, _NN, _NS

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
