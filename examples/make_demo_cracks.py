"""Make a plausible-looking demo crack network for a mesh (a stand-in until the solver lands).

    python examples/make_demo_cracks.py examples/spot.obj -o cracks.json [--seed N]

Radial cracks walk across the surface from an impact point on the mesh's +x side; a few
concentric links join neighbouring radial cracks.  Every point is projected onto the surface, so
it lies on the face recorded for it.  Same mesh and seed give a byte-identical file.
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from trimesh.triangles import closest_point

from crackbake.io.mesh import load_mesh
from crackbake.io.sidecar import write_sidecar
from crackbake.network import Crack, CrackNetwork, mesh_info

MAX_WIDTH = 0.004  # mesh units; spot is about 2 units tall


class Surface:
    """Nearest-point queries without trimesh.nearest (which needs the optional rtree package)."""

    def __init__(self, mesh, k: int = 24):
        self.tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)  # keep face order
        self.face_normals = self.tm.face_normals
        self.tree = cKDTree(self.tm.triangles_center)
        self.k = min(k, len(mesh.faces))

    def project(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest surface points (K, 3) among nearby faces, and the faces (K,) holding them."""
        p = np.atleast_2d(p)
        _, cand = self.tree.query(p, k=self.k)
        cand = cand.reshape(len(p), -1)
        tri = self.tm.triangles[cand.ravel()]
        q = closest_point(tri, np.repeat(p, cand.shape[1], axis=0)).reshape(len(p), -1, 3)
        best = np.linalg.norm(q - p[:, None], axis=2).argmin(axis=1)
        return q[np.arange(len(p)), best], cand[np.arange(len(p)), best].astype(np.int64)


def walk(surface, start, direction, n_steps, step, rng, wobble=0.35):
    """Step along the surface from ``start``; returns points (N, 3) and faces (N,)."""
    pts, faces = surface.project(start)
    pts, faces = [pts[0]], [faces[0]]
    d = direction / np.linalg.norm(direction)
    for _ in range(n_steps):
        normal = surface.face_normals[faces[-1]]
        d = d - normal * (d @ normal)  # keep the heading tangent to the current face
        d = d + wobble * rng.normal() * np.cross(normal, d)
        d /= np.linalg.norm(d)
        p, f = surface.project(pts[-1] + step * d)
        if np.linalg.norm(p[0] - pts[-1]) < 0.2 * step:  # stuck in a crease: stop here
            break
        d = p[0] - pts[-1]  # follow the surface, so the heading bends over curvature
        pts.append(p[0])
        faces.append(f[0])
    return np.array(pts), np.array(faces, dtype=np.int64)


def arc01(points: np.ndarray) -> np.ndarray:
    """Arc length along a polyline (N, 3), normalised to [0, 1]."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    return s / s[-1]


def make_network(mesh, seed: int) -> CrackNetwork:
    rng = np.random.default_rng(seed)
    surface = Surface(mesh)
    centre = 0.5 * (mesh.bbox_min + mesh.bbox_max)
    # Just outside the +x side, so the nearest centroids surround the true nearest point.
    aim = centre + 0.05 * rng.normal(size=3) * mesh.diagonal
    aim[0] = mesh.bbox_max[0] + 0.05 * mesh.diagonal
    impact, impact_face = surface.project(aim)
    impact, normal = impact[0], surface.face_normals[impact_face[0]]
    u = np.cross(normal, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)

    step = 0.01 * mesh.diagonal
    n_radial = 7
    angles = 2 * np.pi * (np.arange(n_radial) + 0.3 * rng.uniform(-1, 1, n_radial)) / n_radial
    radial = []
    for a in angles:
        n_steps = int(rng.integers(18, 40))
        radial.append(walk(surface, impact, np.cos(a) * u + np.sin(a) * v, n_steps, step, rng))
    longest = max(len(p) for p, _ in radial)

    cracks = []
    for p, f in radial:  # radial cracks run first, outwards, widest at the impact
        t = 0.7 * np.arange(len(p)) / (longest - 1)
        cracks.append((p, f, t, MAX_WIDTH * (1.0 - arc01(p)) ** 0.7))
    for ring, frac in enumerate((0.35, 0.6)):
        for i in range(0, n_radial, 2):  # every other gap, so the rings look broken, not drawn
            pa, pb = radial[i][0], radial[(i + 1) % n_radial][0]
            ka, kb = int(frac * (len(pa) - 1)), int(frac * (len(pb) - 1))
            gap = pb[kb] - pa[ka]
            n = max(int(np.linalg.norm(gap) / step), 2)
            p, f = walk(surface, pa[ka], gap, n, np.linalg.norm(gap) / n, rng, wobble=0.15)
            s = arc01(p)  # links open last and taper to zero at both ends
            cracks.append((p, f, 0.75 + 0.1 * ring + 0.15 * s, 0.5 * MAX_WIDTH * np.sin(np.pi * s)))

    network_cracks = [
        Crack(id=k, points=p, faces=f, time=np.clip(t, 0, 1), width=w, depth=0.5 * w)
        for k, (p, f, t, w) in enumerate(cracks)
        if len(p) >= 2
    ]
    return CrackNetwork(
        cracks=network_cracks,
        mesh=mesh_info(mesh),
        params={"method": "demo", "preset": "demo", "seed": seed, "step": step},
        impacts=[{"point": impact.tolist(), "radius": 0.05, "strength": 1.0}],
        solver_steps=0,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", help="mesh file, e.g. examples/spot.obj")
    parser.add_argument("-o", "--output", default="cracks.json", help="sidecar to write")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    args = parser.parse_args()
    mesh = load_mesh(args.mesh)
    network = make_network(mesh, args.seed)
    write_sidecar(network, args.output)
    print(f"{args.output}: {network.stats()}")


if __name__ == "__main__":
    main()
