"""The crack network: polylines on the surface, what the solver produces and the bake consumes.

A :class:`CrackNetwork` is written as the ``cracks.json`` sidecar (:mod:`crackbake.io.sidecar`)
so it can be re-baked without solving again, and as OBJ polylines (:mod:`crackbake.io.obj_lines`).
The bake reads it flattened into :class:`Segments`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the network is the data contract; it needs no mesh code at run time
    from crackbake.io.mesh import Mesh

__all__ = ["Crack", "CrackNetwork", "Segments", "from_solver", "mesh_info", "segments"]


@dataclass(eq=False)
class Crack:
    """One crack: a polyline on the surface with per-point attributes.

    Attributes
    ----------
    id : int
        Unique within its network; baked into the ``crack.id`` channel.
    points : (N, 3) float64
        Positions on the surface, mesh units, N >= 2.
    faces : (N,) int64
        Output-mesh face holding each point.
    time : (N,) float64
        In [0, 1]: the order in which each point cracked (0 first).
    width : (N,) float64
        Opening width >= 0, mesh units.
    depth : (N,) float64
        Depth >= 0, mesh units.
    """

    id: int
    points: np.ndarray
    faces: np.ndarray
    time: np.ndarray
    width: np.ndarray
    depth: np.ndarray

    def __post_init__(self) -> None:
        # Coerce once here so every consumer can rely on the documented dtypes (callers often
        # pass lists or float32 arrays); no copy is made when the input already fits.
        self.id = int(self.id)
        self.points = np.asarray(self.points, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int64)
        self.time = np.asarray(self.time, dtype=np.float64)
        self.width = np.asarray(self.width, dtype=np.float64)
        self.depth = np.asarray(self.depth, dtype=np.float64)

    @property
    def length(self) -> float:
        """Polyline length, mesh units."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


@dataclass(eq=False)
class CrackNetwork:
    """All cracks on one mesh plus what made them.

    Attributes
    ----------
    cracks : list of Crack
    mesh : dict
        ``{"source", "vertices", "faces", "bbox_min", "bbox_max"}`` of the mesh the cracks lie on
        (see :func:`mesh_info`).
    params : dict
        Every effective parameter (JSON-compatible values).
    impacts : list of dict
        ``[{"point": [x, y, z], "radius": r, "strength": s}]``, mesh units.
    solver_steps : int
        Solver iterations that produced the network (0 when not solved).
    """

    cracks: list[Crack]
    mesh: dict
    params: dict = field(default_factory=dict)
    impacts: list[dict] = field(default_factory=list)
    solver_steps: int = 0

    def stats(self) -> dict:
        """Summary counts: ``{"cracks", "points", "total_length", "solver_steps"}``.

        ``total_length`` is the sum of all segment lengths, mesh units.
        """
        seg = segments(self)
        total = float(np.linalg.norm(seg.b - seg.a, axis=1).sum()) if len(seg.a) else 0.0
        return {
            "cracks": len(self.cracks),
            "points": int(sum(len(c.points) for c in self.cracks)),
            "total_length": total,
            "solver_steps": int(self.solver_steps),
        }


@dataclass(frozen=True, eq=False)
class Segments:
    """The network as flat per-segment arrays, the form the GPU bake consumes.

    Segment ``k`` joins ``a[k]`` to ``b[k]``; paired attributes hold the value at ``a`` in column
    0 and at ``b`` in column 1.

    Attributes
    ----------
    a, b : (S, 3) float64
        Start and end points, mesh units.
    width : (S, 2) float64
        Opening width at a and b, mesh units.
    depth : (S, 2) float64
        Depth at a and b, mesh units.
    time : (S, 2) float64
        Crack time at a and b, in [0, 1].
    crack_id : (S,) int64
        Id of the crack each segment belongs to.
    """

    a: np.ndarray
    b: np.ndarray
    width: np.ndarray
    depth: np.ndarray
    time: np.ndarray
    crack_id: np.ndarray


def segments(network: CrackNetwork) -> Segments:
    """Flatten the network into its segments (S = sum over cracks of N - 1).

    Parameters
    ----------
    network : CrackNetwork

    Returns
    -------
    Segments
        In crack order, then along each crack.
    """
    cracks = [c for c in network.cracks if len(c.points) >= 2]
    if not cracks:
        empty2 = np.zeros((0, 2), dtype=np.float64)
        return Segments(
            a=np.zeros((0, 3), dtype=np.float64),
            b=np.zeros((0, 3), dtype=np.float64),
            width=empty2,
            depth=empty2.copy(),
            time=empty2.copy(),
            crack_id=np.zeros(0, dtype=np.int64),
        )
    points = np.concatenate([c.points for c in cracks])
    counts = np.array([len(c.points) for c in cracks], dtype=np.int64)
    # Every point starts a segment except the last point of each crack.
    start = np.ones(len(points), dtype=bool)
    start[np.cumsum(counts) - 1] = False
    ia = np.flatnonzero(start)
    ib = ia + 1

    def pair(name: str) -> np.ndarray:
        values = np.concatenate([getattr(c, name) for c in cracks])
        return np.stack([values[ia], values[ib]], axis=1)

    ids = np.array([c.id for c in cracks], dtype=np.int64)
    return Segments(
        a=points[ia],
        b=points[ib],
        width=pair("width"),
        depth=pair("depth"),
        time=pair("time"),
        crack_id=np.repeat(ids, counts - 1),
    )


def mesh_info(mesh: Mesh) -> dict:
    """The sidecar's ``"mesh"`` block for a mesh.

    Returns
    -------
    dict
        ``{"source": str, "vertices": V, "faces": F, "bbox_min": [3], "bbox_max": [3]}``.
    """
    return {
        "source": str(mesh.source),
        "vertices": int(len(mesh.vertices)),
        "faces": int(len(mesh.faces)),
        "bbox_min": [float(x) for x in mesh.bbox_min],
        "bbox_max": [float(x) for x in mesh.bbox_max],
    }


def from_solver(
    paths: list,
    mesh: Mesh,
    params: dict | None = None,
    impacts: list[dict] | None = None,
    solver_steps: int = 0,
) -> CrackNetwork:
    """The crack network of a solver run.

    Parameters
    ----------
    paths : list of crackbake.simulate.solver.CrackPath
        Polylines with per-point asset faces, time, width and depth.
    mesh : Mesh
        The asset mesh the faces index.
    params : dict, optional
        Every effective parameter (stored in the sidecar).
    impacts : list of dict, optional
        Impacts as used (snapped points).
    solver_steps : int
        Steps the solver took.

    Returns
    -------
    CrackNetwork
        Cracks numbered 0.. in the solver's order; paths with fewer than 2 points are dropped.
    """
    cracks = []
    for path in paths:
        if len(path.points) < 2:
            continue
        cracks.append(
            Crack(
                id=len(cracks),
                points=np.asarray(path.points, np.float64),
                faces=np.asarray(path.asset_faces, np.int64),
                time=np.clip(np.asarray(path.time, np.float64), 0.0, 1.0),
                width=np.maximum(np.asarray(path.width, np.float64), 0.0),
                depth=np.maximum(np.asarray(path.depth, np.float64), 0.0),
            )
        )
    return CrackNetwork(
        cracks=cracks,
        mesh=mesh_info(mesh),
        params=dict(params or {}),
        impacts=list(impacts or []),
        solver_steps=int(solver_steps),
    )
