"""Load the I&O solver's compiled kernels ahead of the solve, on a thread.

A fresh process pays for importing the solver and loading each of its numba kernels from the
disk cache on its first call: about 0.3 CPU-s on a 2-core machine, in the ``solve`` stage of
every run (docs/solver.md, "Implementation notes").  :func:`start` solves a small plate on a daemon
thread while the sim mesh and the stress field are built, with the argument types a real run
uses, so the real solve finds every kernel loaded.  numba's compiler lock makes a real call
that arrives first wait for the load, as it would have loaded it itself; the plate shares no
state with the run, and its result is dropped.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from types import SimpleNamespace

import numpy as np

#: Squares per side of the warm-up plate (two triangles each).
PLATE_CELLS = 6


def plate(cells: int = PLATE_CELLS) -> tuple[SimpleNamespace, SimpleNamespace]:
    """A flat unit plate of ``cells`` x ``cells`` squares (two triangles each) and an impact
    stress on it (radial tension falling off from the middle): the sim mesh and field types
    :func:`~crackbake.simulate.solver.iben.solve_iben` reads, (N, 3) float64 vertices,
    (M, 3) int64 faces, (M,) int64 asset faces and (M, 3, 3) float64 stress."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, cells + 1), np.linspace(0.0, 1.0, cells + 1))
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    i = (np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]).ravel()
    faces = np.concatenate([np.column_stack([i, i + 1, i + cells + 2]),
                            np.column_stack([i, i + cells + 2, i + cells + 1])]).astype(np.int64)
    centre = vertices[faces].mean(axis=1) - [0.5, 0.5, 0.0]
    r = np.linalg.norm(centre, axis=1)
    radial = centre / np.maximum(r, 1e-9)[:, None]
    hoop = np.cross([0.0, 0.0, 1.0], radial)
    w = np.cos(np.minimum(r, 0.7) / 0.7 * np.pi / 2)[:, None, None]
    stress = w * (radial[:, :, None] * radial[:, None, :] + hoop[:, :, None] * hoop[:, None, :])
    sim = SimpleNamespace(vertices=vertices, faces=faces,
                          asset_face=np.arange(len(faces), dtype=np.int64),
                          edge_length=1.0 / cells)
    field = SimpleNamespace(stress=stress, growth=np.zeros_like(stress), shadow_radius=None)
    return sim, field


def warm() -> None:
    """Solve :func:`plate` (a few steps): every kernel of the I&O loop loaded or compiled."""
    from crackbake.simulate.solver import SolverParams
    from crackbake.simulate.solver.iben.solve import solve_iben

    sim, field = plate()
    solve_iben(sim, field, SolverParams(max_steps=50, max_cracks=4))


#: How long the thread waits for ``after`` at most (seconds): a run that never sets it (it
#: failed first) still gets a thread that ends.
AFTER_WAIT_S = 30.0


def start(later: Sequence = (), stop: threading.Event | None = None,
          after: threading.Event | None = None, plate: bool = True) -> threading.Thread:
    """:func:`warm` on a daemon thread, started; join it or let it run out.

    ``later``: numba dispatchers of the stages after the solve (the bake's, the stress bake's,
    the writers'), loaded from the disk cache next (:func:`crackbake.jit.preload`) while the
    run's thread builds the field and solves, until ``stop`` is set (before the join): each a
    dispatcher, or named as ``"module:kernel"`` (its module imported there, not on the run's
    thread); a string without a colon is a module's name, imported there (the writers'
    modules: the solver's loop runs without the GIL, so an import beside it is not on the
    run's path).

    ``after``: the thread imports the solver's modules, then waits for this event before it
    loads any kernel (the run's thread loads its own first, :func:`crackbake.jit.preload`:
    numba loads one kernel at a time, under one lock).  ``plate=False``: no :func:`warm`, only
    ``later`` (a re-bake, which has no solver)."""
    thread = threading.Thread(target=_quiet_warm, args=(tuple(later), stop, after, plate),
                              name="crackbake-iben-warm" if plate else "crackbake-kernels",
                              daemon=True)  # fmt: skip
    thread.start()
    return thread


def _quiet_warm(later: tuple = (), stop: threading.Event | None = None,
                after: threading.Event | None = None, plate: bool = True) -> None:
    # Only a head start: a failure here is the real solve's to report, with its own inputs.
    try:
        if after is not None:
            if plate:
                import crackbake.simulate.solver.iben.solve  # noqa: F401 - imports, no loads
            after.wait(AFTER_WAIT_S)
        if plate and (stop is None or not stop.is_set()):
            warm()
    except Exception:  # noqa: BLE001
        pass
    if later:
        from importlib import import_module

        from crackbake.jit import preload

        for item in later:
            if stop is not None and stop.is_set():
                break
            if not isinstance(item, str):
                preload(item)
                continue
            module, _, name = item.partition(":")
            try:
                imported = import_module(module)
                kernel = getattr(imported, name) if name else None
            except Exception:  # noqa: BLE001 - the run's own import reports it
                continue
            if kernel is not None:
                preload(kernel)
