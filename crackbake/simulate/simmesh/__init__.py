"""The simulation mesh: a conforming refinement inside each asset triangle.

The crack solver must not see the asset's triangulation (long thin game-asset triangles, or
millions of scan faces), so it runs on a mesh of well-shaped, slightly irregular triangles at a
target edge length (docs/method.md, "The simulation mesh contract").  It is built per asset face:

* asset edges are split into nearly equal pieces, about one target length each for big faces
  and fewer where the asset faces are small, so the point density (and face count) does not
  depend on how finely the asset is triangulated; the points are computed once per (welded)
  edge, so both faces of an edge share them exactly and the result is welded across UV seams;
* interior points come from a triangular lattice with a random orientation and offset per face,
  clipped to the face shrunk by a margin and jittered, so no global direction is preferred;
* each face is triangulated on its own plane by a constrained Delaunay triangulation with a
  20 degree quality bound (Shewchuk's Triangle) that may add interior points but never points on
  the face's edges (which would break the sharing).  All faces go to Triangle in one call, laid
  out side by side in 2-D, because one call per face costs ~100 us of overhead each;
* faces that get no point (asset already finer than the target) are kept as they are.

Every sim triangle lies inside exactly one asset triangle, so every sim node maps exactly to
(asset face, barycentric) and every sim triangle maps affinely into the asset's UV space.

An asset far denser than the wanted face count (over twice it, and over 200k faces) is first
decimated to a proxy surface and refined inside the proxy's faces instead (:mod:`.proxy`): the
mapping back to the asset is then the closest asset point, and crack points are projected onto
the asset after the solve.
"""

from crackbake.simulate.simmesh.build import (
    MAX_SIM_FACES,
    Local,
    SimMesh,
    asset_barycentric,
    build_simmesh,
    target_edge_length,
)
from crackbake.simulate.simmesh.proxy import Proxy, onto_asset

__all__ = [
    "MAX_SIM_FACES",
    "Local",
    "Proxy",
    "SimMesh",
    "asset_barycentric",
    "build_simmesh",
    "onto_asset",
    "target_edge_length",
]
