"""Benchmark: the solver state passed to numba kernels as a named tuple or a struct reference.

Run: ``python benchmarks/bench_state.py [--calls 2000000] [--kernels 8]``.  Settles what
``iben/state.py`` and ``iben/structs.py`` say about the cost of each (both docstrings quote the
result).  On the real ``State`` of a small plate (43 fields) it measures, for the same kernels
written once and compiled twice (state as the named tuple, or as its struct reference):

* *compile s*: numba compiling ``--kernels`` distinct inner kernels (each reads four fields
  and is called from one outer kernel), first call minus a warm call;
* *call ns*: one call of an inner kernel from compiled code (the outer kernel calls it
  ``--calls`` times; numba leaves these calls to LLVM, which may inline them);
* *read ns*: one read of a field and an element inside a loop (``s.val[i]``);
* *entry us*: one call from Python of a kernel taking the state (numba unboxes the tuple's
  arrays one by one on every call; the struct reference is built inside, from the tuple).

Nothing is cached (fresh functions each run).  Times are wall clock, best of ``--repeat``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

from crackbake.simulate.solver import SolverParams
from crackbake.simulate.solver.iben.solve import _setup
from crackbake.simulate.solver.iben.structs import state_ref


def _state():
    """The real State of a 20 x 20 plate under uniform tension."""
    from types import SimpleNamespace

    n = 20
    h = 1.0 / n
    x, y = np.meshgrid(np.arange(n + 1) * h, np.arange(n + 1) * h, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    i = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    f = np.concatenate([np.stack([i, i + n + 1, i + n + 2], 1),
                        np.stack([i, i + n + 2, i + 1], 1)]).astype(np.int64)
    st = np.zeros((len(f), 3, 3))
    st[:, 0, 0] = st[:, 1, 1] = 1.0
    sim = SimpleNamespace(vertices=v, faces=f, asset_face=np.arange(len(f)), edge_length=h)
    s, _mesh = _setup(sim, SimpleNamespace(stress=st, growth=None), SolverParams(max_steps=10))
    return s


def _inner_kernels(count: int) -> list:
    """``count`` distinct kernels ``k(s, n)`` reading four fields of state ``s``."""
    out = []
    for j in range(count):
        def inner(s, n, j=j):
            m = s.val.shape[0]
            i = (n + j) % m
            return s.val[i] + s.X[i, 0] + s.hn[i] + float(s.cnt[1])
        out.append(njit(no_cpython_wrapper=True)(inner))
    return out


def _outer(kernels: list, as_struct: bool):
    """A kernel calling each of ``kernels`` ``calls // len(kernels)`` times on the state."""
    ks = tuple(kernels)
    k0, k1, k2, k3, k4, k5, k6, k7 = (ks * 8)[:8]

    def outer(t, calls):
        s = state_ref(t) if as_struct else t
        acc = 0.0
        for n in range(calls // 8):
            acc += k0(s, n) + k1(s, n) + k2(s, n) + k3(s, n)
            acc += k4(s, n) + k5(s, n) + k6(s, n) + k7(s, n)
        return acc
    return njit(outer)


def _reader(as_struct: bool):
    def read(t, calls):
        s = state_ref(t) if as_struct else t
        m = s.val.shape[0]
        acc = 0.0
        for n in range(calls):
            acc += s.val[n % m]
        return acc
    return njit(read)


def _entry(as_struct: bool):
    def entry(t):
        s = state_ref(t) if as_struct else t
        return s.cnt[1]
    return njit(entry)


_ENTRIES = 20_000


def _best(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=2_000_000)
    ap.add_argument("--kernels", type=int, default=8, choices=range(1, 9))
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    s = _state()
    print(f"State: {len(s)} fields; {args.kernels} inner kernels, {args.calls} calls")
    print("| state as | compile s | call ns | read ns | entry us |")
    print("|---|---:|---:|---:|---:|")
    for as_struct in (False, True):
        outer = _outer(_inner_kernels(args.kernels), as_struct)
        t0 = time.perf_counter()
        outer(s, 8)
        first = time.perf_counter() - t0
        warm = _best(lambda outer=outer: outer(s, 8), 1)
        call = _best(lambda outer=outer: outer(s, args.calls), args.repeat) / args.calls
        read = _reader(as_struct)
        read(s, 8)
        per_read = _best(lambda read=read: read(s, args.calls), args.repeat) / args.calls
        entry = _entry(as_struct)
        entry(s)
        def entries(entry=entry):
            for _ in range(_ENTRIES):
                entry(s)
        per_entry = _best(entries, args.repeat) / _ENTRIES
        print(f"| {'struct ref' if as_struct else 'named tuple'} | {first - warm:.2f} "
              f"| {1e9 * call:.1f} | {1e9 * per_read:.2f} | {1e6 * per_entry:.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
