"""Child-process entry point building libigl's AABB tree of a surface while the run goes on:
``python -m crackbake.closest_worker``.

A cracked proxy run (an asset above about 200k faces, simulated on a decimated proxy) moves its
crack points onto the asset's surface once the solver is done: libigl's AABB tree of the
asset's faces, 2-3 s at 1.5M faces, all of it holding the GIL, so a thread would stall the
run's own thread instead of running beside it.  :class:`crackbake.geometry.SurfaceIndex` with
``ahead=True`` starts this worker as soon as the cached sim mesh is read: it builds the tree
on another core while the run builds the stress field and solves, then answers the one query.

Protocol (numpy's ``.npy`` format, on stdin and stdout): the parent writes ``vertices`` (V, 3)
float64 and ``faces`` (F, 3) int64, and later the query ``points`` (K, 3) float64; the worker
answers ``face`` (K,) int64 and ``position`` (K, 3) float64 (libigl's ``squared_distance``, as
:meth:`~crackbake.geometry.SurfaceIndex.closest` calls it in-process) and exits.  It dies with
its parent (:func:`crackbake.child.die_with_parent`); any failure is the parent's to recover
from (it builds the tree itself).
"""

from __future__ import annotations

#: Environment variable naming the parent's pid (set by ``SurfaceIndex``).
PARENT_ENV = "CRACKBAKE_CLOSEST_PARENT"

if __name__ == "__main__":
    from crackbake.child import die_with_parent

    die_with_parent(PARENT_ENV)

import sys  # noqa: E402  (after die_with_parent: the slow imports below run already guarded)

import numpy as np  # noqa: E402


class _Stream:
    """A pipe as numpy's ``.npy`` reader and writer see a plain stream: their path for real
    files asks the file for its position, which a pipe does not have."""

    def __init__(self, pipe) -> None:
        self.pipe = pipe

    def read(self, n: int = -1) -> bytes:
        return self.pipe.read(n)

    def write(self, data) -> int:
        return self.pipe.write(data)


def send(pipe, array: np.ndarray) -> None:
    """Write ``array`` to ``pipe`` in numpy's ``.npy`` format."""
    np.lib.format.write_array(_Stream(pipe), np.ascontiguousarray(array), allow_pickle=False)


def receive(pipe) -> np.ndarray:
    """The next ``.npy`` array on ``pipe`` (:func:`send`'s)."""
    return np.lib.format.read_array(_Stream(pipe), allow_pickle=False)


def serve(inp, out) -> None:
    """Read the surface from ``inp``, build its tree, answer one query on ``out``."""
    import igl

    vertices = receive(inp)
    faces = receive(inp)
    tree = igl.AABB()
    tree.init(vertices, faces)
    points = receive(inp)
    _, face, position = tree.squared_distance(vertices, faces, points)
    send(out, np.asarray(face, dtype=np.int64))
    send(out, np.asarray(position, dtype=np.float64))
    out.flush()


if __name__ == "__main__":
    serve(sys.stdin.buffer, sys.stdout.buffer)
