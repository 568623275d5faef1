"""Building the simulation mesh (the refinement recipe is in the package docstring)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.geometry import (
    SurfaceIndex,
    barycentric,
    corner_mean,
    face_cross,
    mesh_derived,
    remember_derived,
    weld_by_position,
)
from crackbake.io.mesh import Mesh
from crackbake.params import SIM_FACES_DEFAULT
from crackbake.params import SIM_FACES_MAX as MAX_SIM_FACES
from crackbake.simulate.simmesh.layout import edge_point_counts, face_frames_2d, lattice_points
from crackbake.simulate.simmesh.manifold import duplicate_faces, split_nonmanifold
from crackbake.simulate.simmesh.proxy import PROXY_MIN_FACES, Proxy, decimate, proxy_limit
from crackbake.simulate.simmesh.triangulate import FaceSet, Refined, refine_faces

# Area of an equilateral triangle of unit side: a triangular lattice of spacing h holds
# two such triangles (scaled by h^2) per point.
_EQUILATERAL = np.sqrt(3.0) / 4.0
# With the per-face point budget below, face counts land within ~1% of the request on spot,
# plates and tori of any resolution coarser than the target, so no correction is applied.



@dataclass(frozen=True, eq=False)
class SimMesh:
    """Simulation mesh with an exact map back to the asset mesh.

    Attributes
    ----------
    vertices : (N, 3) float64
        Welded node positions, mesh units.
    faces : (M, 3) int64
        Triangles indexing ``vertices``, oriented like the asset face each lies in.
    asset_face : (M,) int64
        Index into ``Mesh.faces`` (the asset/output mesh) of the face holding each sim face.
    node_face : (N,) int64
        One asset face holding each node.
    node_bary : (N, 3) float64
        Barycentric coordinates of each node in ``node_face``;
        ``(node_bary[:, :, None] * mesh.vertices[mesh.faces[node_face]]).sum(1) == vertices``
        up to rounding.
    boundary : (N,) bool
        Node lies on an open boundary of the welded asset surface.
    edge_length : float
        Target edge length used, mesh units.
    proxy : Proxy or None
        The decimated surface the mesh was refined in (:mod:`.proxy`), None when it was
        refined in the asset's own faces.  With a proxy the nodes lie near the asset surface,
        ``node_face``/``node_bary`` give the closest asset point and ``asset_face`` the asset
        face closest to each sim face's centroid.
    local : Local or None
        Balls refined to a finer edge length than ``edge_length`` (:func:`build_simmesh`'s
        ``local``), None when the whole mesh has one.
    """

    vertices: np.ndarray
    faces: np.ndarray
    asset_face: np.ndarray
    node_face: np.ndarray
    node_bary: np.ndarray
    boundary: np.ndarray
    edge_length: float
    proxy: Proxy | None = None
    local: Local | None = None

    def edge_at(self, point) -> float:
        """Target edge length at ``point`` (3,), mesh units: the finest of the refined balls
        holding it (:class:`Local`), else ``edge_length``."""
        return self.edge_length if self.local is None else self.local.edge_at(
            np.asarray(point, np.float64).reshape(1, 3), self.edge_length)[0]


@dataclass(frozen=True, eq=False)
class Local:
    """Balls of the surface refined finer than the rest of the sim mesh (an impact on a thin
    feature: docs/solver.md, "Several impacts").

    Attributes
    ----------
    centres : (K, 3) float64
        Ball centres, mesh units.
    radii : (K,) float64
        Ball radii (straight distance), mesh units.
    edges : (K,) float64
        Target edge length inside each ball, mesh units.
    """

    centres: np.ndarray
    radii: np.ndarray
    edges: np.ndarray

    def ball_of(self, points: np.ndarray, edge: float) -> np.ndarray:
        """The ball (index) whose edge length each of ``points`` (P, 3) takes, -1 where none
        is finer than ``edge``, (P,) int64."""
        best = np.full(len(points), float(edge))
        out = np.full(len(points), -1, np.int64)
        for k, (c, r, h) in enumerate(zip(self.centres, self.radii, self.edges, strict=True)):
            take = (np.linalg.norm(points - c, axis=1) <= r) & (h < best)
            best[take] = h
            out[take] = k
        return out

    def edge_at(self, points: np.ndarray, edge: float) -> np.ndarray:
        """Target edge length at each of ``points`` (P, 3): the smallest of ``edge`` and the
        edges of the balls holding the point, (P,)."""
        out = np.full(len(points), float(edge))
        for c, r, h in zip(self.centres, self.radii, self.edges, strict=True):
            inside = np.linalg.norm(points - c, axis=1) <= r
            out[inside] = np.minimum(out[inside], h)
        return out



def _total_area(mesh: Mesh) -> float:
    return 0.5 * float(np.linalg.norm(face_cross(mesh.vertices, mesh.faces), axis=1).sum())


def target_edge_length(mesh: Mesh, target_faces: int = SIM_FACES_DEFAULT) -> float:
    """Edge length giving about ``target_faces`` near-equilateral sim faces over the surface.

    Parameters
    ----------
    mesh : Mesh
        Asset mesh.
    target_faces : int
        Wanted number of simulation faces (at least 100).

    Returns
    -------
    float
        Target edge length, mesh units.
    """
    return _edge_for(_surface_area(mesh), target_faces)


def _surface_area(mesh: Mesh) -> float:
    area = _total_area(mesh)
    if not area > 0:
        raise CrackbakeError("the mesh has zero surface area; crackbake needs a surface")
    return area


def _edge_for(area: float, target_faces: int) -> float:
    if target_faces < 100:
        raise CrackbakeError(
            f"--sim-faces {target_faces} is too small for a crack simulation; use at least 100"
        )
    return float(np.sqrt(area / (_EQUILATERAL * target_faces)))


def asset_barycentric(mesh: Mesh, asset_faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points in given asset faces.

    Points off the face's plane are projected onto it first; points outside the triangle get
    coordinates outside [0, 1] (no clamping).

    Parameters
    ----------
    mesh : Mesh
        Asset mesh.
    asset_faces : (K,) int64
        Index into ``mesh.faces`` for each point.
    points : (K, 3) float64
        Positions, mesh units.

    Returns
    -------
    (K, 3) float64
        Barycentric coordinates summing to 1.
    """
    tri = mesh.vertices[mesh.faces[np.asarray(asset_faces, dtype=np.int64)]]
    return barycentric(tri, np.asarray(points, dtype=np.float64))


def _check_size(mesh: Mesh, detail: float | None, target_faces: int | None,
                jitter: float) -> tuple[float, float]:
    """The target edge length (mesh units) after the argument and size checks, and the face
    count it gives over the surface."""
    if detail is not None:
        if not np.isfinite(detail) or detail <= 0:
            raise CrackbakeError(
                f"--detail {detail} must be a positive edge length in mesh units; "
                f"try about {mesh.diagonal / 300:.4g} for this mesh"
            )
    if not 0.0 <= jitter <= 0.45:
        raise CrackbakeError(f"jitter {jitter} is out of range; use a value from 0 to 0.45")
    area = _surface_area(mesh)
    if detail is not None:
        h = float(detail)
    else:
        h = _edge_for(area, SIM_FACES_DEFAULT if target_faces is None else int(target_faces))
    estimate = area / (_EQUILATERAL * h * h)
    if estimate > MAX_SIM_FACES:
        suggest = np.sqrt(area / (_EQUILATERAL * MAX_SIM_FACES))
        raise CrackbakeError(
            f"the simulation mesh would have about {estimate:,.0f} faces (limit "
            f"{MAX_SIM_FACES:,}); use --detail {suggest:.4g} or larger, or fewer --sim-faces"
        )
    return h, estimate


def build_simmesh(
    mesh: Mesh,
    detail: float | None = None,
    target_faces: int | None = SIM_FACES_DEFAULT,
    seed: int = 0,
    jitter: float = 0.15,
    proxy_above: int | None = None,
    proxy: Proxy | None = None,
    local: Local | None = None,
    cache: bool = False,
) -> SimMesh:
    """Build the simulation mesh: a conforming, welded refinement inside each asset face, or
    inside the faces of a decimated proxy when the asset is far denser than wanted.

    Parameters
    ----------
    mesh : Mesh
        Asset mesh (UV seams are welded away here).
    detail : float, optional
        Target edge length, mesh units (``--detail``).  Takes precedence over ``target_faces``.
    target_faces : int, optional
        Wanted number of sim faces over the whole surface (``--sim-faces``), used when
        ``detail`` is None; None means the default 100,000.
    seed : int
        Seed for the lattice orientation and jitter; same seed, same mesh.
    jitter : float
        Random displacement of interior points, as a fraction of the edge length (0 to 0.45);
        edge points move half as much, along their edge.
    proxy_above : int, optional
        Asset face count above which the simulation runs on a decimated proxy
        (:mod:`.proxy`); default :func:`~.proxy.proxy_limit` of the wanted face count.
    proxy : Proxy, optional
        A proxy already decimated for this mesh (``SimMesh.proxy`` of an earlier build), to
        refine again at another edge length without decimating twice.
    local : Local, optional
        Balls meshed finer: an asset (or proxy) face whose centroid lies in a ball gets that
        ball's edge length (the faces' shared edges take the mean of their point requests and
        Triangle's quality bound grades the transition).
    cache : bool
        Read and store the mesh in the mesh cache (:mod:`crackbake.bake.mesh_cache`) with the
        warnings its build gave, which a read gives again, and its proxy (the proxy's asset
        tree is then built at its first query): the same arrays as a build.  A rebuild in a
        given ``proxy`` is not cached.

    Returns
    -------
    SimMesh

    Raises
    ------
    CrackbakeError
        ``detail`` <= 0, ``target_faces`` < 100, an estimated sim mesh above 20M faces, a bad
        jitter, or a mesh without area.
    """
    if not cache or proxy is not None:  # a rebuild in a given proxy: not cached
        return _build(mesh, detail, target_faces, seed, jitter, proxy_above, proxy, local)
    from crackbake.bake.mesh_cache import read_simmesh, simmesh_key, write_simmesh

    settings = {"detail": None if detail is None else float(detail),
                "target_faces": None if target_faces is None else int(target_faces),
                "default_faces": int(SIM_FACES_DEFAULT), "seed": int(seed),
                "jitter": float(jitter),
                "proxy_above": None if proxy_above is None else int(proxy_above),
                "proxy_min": int(PROXY_MIN_FACES)}  # fmt: skip
    key = simmesh_key(mesh.vertices, mesh.faces, settings, local)
    hit = read_simmesh(key, len(mesh.faces))
    if hit is not None:
        arrays, edge_length, said, parts, derived = hit
        # its edges, shells and centroids, which the field, the star check and the solver ask for
        remember_derived(arrays["vertices"], arrays["faces"], *derived)
        for category, message, filename, line in said:
            warnings.warn_explicit(message, category, filename, line)
        read_proxy = None
        if parts is not None:  # the asset's AABB tree is built when the solve starts
            # (crackbake.pipeline, SurfaceIndex.start_worker) or at the first query
            surface = SurfaceIndex(parts["surface_vertices"], parts["surface_faces"], lazy=True)
            read_proxy = Proxy(vertices=parts["proxy_vertices"], faces=parts["proxy_faces"],
                               surface=surface, rows=parts["proxy_rows"])  # fmt: skip
        return SimMesh(**arrays, edge_length=edge_length, proxy=read_proxy, local=local)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")  # every warning recorded, whatever the caller's filters
        sim = _build(mesh, detail, target_faces, seed, jitter, proxy_above, proxy, local)
    for w in said:  # the caller's filters decide now, as they would have
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    write_simmesh(key, sim, said, mesh_derived(sim.vertices, sim.faces))
    return sim


def _build(mesh: Mesh, detail: float | None, target_faces: int | None, seed: int,
           jitter: float, proxy_above: int | None, proxy: Proxy | None,
           local: Local | None) -> SimMesh:
    """:func:`build_simmesh` without the cache."""
    h, wanted = _check_size(mesh, detail, target_faces, jitter)
    rng = np.random.default_rng(seed)
    if proxy is None:
        wv, wf, keep = _welded_surface(mesh.vertices, mesh.faces, warn=True)
        if len(wf) <= (proxy_limit(wanted) if proxy_above is None else proxy_above):
            return _refine(wv, wf, keep, h, rng, jitter, local)
        proxy = decimate(wv, wf, keep, max(int(wanted), 100))
    pv, pf, pkeep = _welded_surface(proxy.vertices, proxy.faces, warn=False)
    sim = _refine(pv, pf, pkeep, h, rng, jitter, local)
    centroid = corner_mean(sim.vertices[sim.faces])
    asset_face = proxy.onto_asset(centroid)[0]
    node_face, node_bary, _ = proxy.onto_asset(sim.vertices)
    return replace(sim, asset_face=asset_face, node_face=node_face, node_bary=node_bary,
                   proxy=proxy)


def _welded_surface(vertices: np.ndarray, faces: np.ndarray, warn: bool):
    """Vertices welded by position, the non-degenerate faces made a 2-manifold and their rows
    in ``faces``: (W, 3), (R, 3), (R,).  ``warn`` names what was repaired (the asset's own
    faces; a proxy's repairs are not the user's business)."""
    from crackbake.geometry_kernels import solid_faces_kernel

    wv, wf_all, _ = weld_by_position(vertices, faces)
    wv = np.ascontiguousarray(wv, np.float64)
    wf_all = np.ascontiguousarray(wf_all, np.int64)
    # Zero-area faces carry no material and would give Triangle a collinear boundary: drop them
    # (twice the area at most 1e-12 of the longest edge squared).
    keep = np.flatnonzero(solid_faces_kernel(wv, wf_all, 1e-12))
    if warn:
        wf, keep, wv, _ = _manifold_copy(wv, wf_all, keep)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CrackbakeWarning)
            wf, keep, wv, _ = _manifold_copy(wv, wf_all, keep)
    return wv, wf, keep


def _refine(wv: np.ndarray, wf: np.ndarray, keep: np.ndarray, h: float,
            rng: np.random.Generator, jitter: float, local: Local | None = None) -> SimMesh:
    """The sim mesh refined at edge length ``h`` inside the welded faces ``wf`` (rows ``keep``
    of the mesh they came from), finer inside the balls of ``local``."""
    n_v = len(wv)
    face_edge, forward, ev0, ev1 = _welded_edges(wf, n_v)
    n_e = len(ev0)
    corners, pt_edge, t_edge, l_face, l_xy = _layout(wv[wf], face_edge, n_e, h, rng, jitter)
    h_face = h
    if local is not None:
        centroid = corner_mean(wv[wf])
        h_face = local.edge_at(centroid, h)
        ball = local.ball_of(centroid, h)
        base = int(rng.integers(1 << 62)) if (ball >= 0).any() else 0
        for k in np.unique(ball[ball >= 0]):
            # Faces outside the balls keep exactly the points the uniform layout gives them
            # (same draws), so a star far from a refined ball sees the same sim mesh as
            # without it; each ball's faces and their edges draw from a stream of their own,
            # seeded by its centre, so a ball is meshed the same whatever other balls exist.
            # The stream draws as if the ball were alone (every face in its sphere at its
            # edge): where a neighbouring ball takes some of those faces, the draws of the
            # faces after them in the stream must not shift (they did, and a star's sim mesh
            # changed when a second impact's ball overlapped the rim of its own).
            fine = ball == k
            alone = np.linalg.norm(centroid - local.centres[k], axis=1) <= local.radii[k]
            h_alone = np.where(alone, min(float(local.edges[k]), h), h)
            key = np.ascontiguousarray(local.centres[k], np.float64).view(np.uint32)
            sub = np.random.default_rng([base, *(int(x) for x in key)])
            f_corners, f_edge, f_t, f_face, f_xy = _layout(
                wv[wf], face_edge, n_e, h_alone, sub, jitter)
            touch = np.zeros(n_e, dtype=bool)
            touch[face_edge[fine].ravel()] = True
            corners = np.where(fine[:, None, None], f_corners, corners)
            old_pt, new_pt = ~touch[pt_edge], touch[f_edge]
            pt_edge = np.concatenate([pt_edge[old_pt], f_edge[new_pt]])
            t_edge = np.concatenate([t_edge[old_pt], f_t[new_pt]])
            old_l, new_l = ~fine[l_face], fine[f_face]
            l_face = np.concatenate([l_face[old_l], f_face[new_l]])
            l_xy = np.concatenate([l_xy[old_l], f_xy[new_l]])
    fs = FaceSet(wf, face_edge, forward, corners, l_face, l_xy,
                 np.linalg.norm(wv[ev1] - wv[ev0], axis=1), float(np.min(h_face)), n_v)
    # Triangulate every face that gets points; faces with none are kept as they are.
    has_pts = np.zeros(n_e, dtype=bool)
    has_pts[pt_edge] = True
    todo = np.flatnonzero(has_pts[face_edge].any(axis=1)
                          | (np.bincount(l_face, minlength=len(wf)) > 0))
    ref = refine_faces(fs, pt_edge, t_edge, todo)
    return replace(_assemble(fs, wv, ref, ev0, ev1, keep), edge_length=h, local=local)


def _layout(tri: np.ndarray, face_edge: np.ndarray, n_e: int, h, rng: np.random.Generator,
            jitter: float):
    """The points of a refinement at edge length ``h`` (one, or (R,) per face): the faces'
    2-D corners (R, 3, 2), the edge points' edges (Q,) and parameters along lo -> hi (Q,),
    the lattice points' faces (P,) and 2-D positions (P, 2).  Draws from ``rng`` in a fixed
    order: edge counts, edge jitter, lattice."""
    corners = face_frames_2d(tri, h)
    n_mid = edge_point_counts(corners, face_edge, n_e, rng)
    # Edge points, by parameter t along lo -> hi, lightly jittered along the edge.
    pt_edge = np.repeat(np.arange(n_e), n_mid)
    pt_k = np.arange(len(pt_edge)) - (np.cumsum(n_mid) - n_mid)[pt_edge] + 1
    t_edge = (pt_k + 0.5 * jitter * rng.uniform(-1.0, 1.0, len(pt_edge))) / (n_mid + 1)[pt_edge]
    # Interior points of every face (none where the inradius is below the margin).
    l_face, l_xy = lattice_points(corners, rng, jitter)
    return corners, pt_edge, t_edge, l_face, l_xy


def _manifold_copy(wv: np.ndarray, wf_all: np.ndarray, keep: np.ndarray):
    """The welded faces ``keep`` selects, made a 2-manifold (:mod:`.manifold`), with a warning
    naming what was changed.  Returns the faces (R, 3), their asset rows (R,), the vertices
    (W', 3) and W'.  A manifold mesh without duplicates comes back unchanged."""
    dup = duplicate_faces(wf_all[keep])
    if dup.any():
        keep = keep[~dup]
        warnings.warn(
            f"{int(dup.sum())} duplicated face(s) (same three vertices as another face) are left "
            "out of the crack simulation and still baked; remove them to silence this",
            CrackbakeWarning,
            stacklevel=6,
        )
    wf, origin, n_cut = split_nonmanifold(wf_all[keep], len(wv))
    n_split = len(origin) - len(wv)
    if n_split:
        what = []
        if n_cut:
            what.append(f"{n_cut} edge(s) shared by more than two faces")
        n_vert = len(np.unique(origin[len(wv):]))
        what.append(f"{n_vert} vertex/vertices joining separate sheets")
        warnings.warn(
            f"the mesh is not manifold ({' and '.join(what)}); each manifold patch is simulated "
            "on its own and cracks end where patches meet; repair the mesh to join them",
            CrackbakeWarning,
            stacklevel=6,
        )
        wv = wv[origin]
    return wf, keep, wv, len(wv)


def _welded_edges(wf: np.ndarray, n_v: int):
    """Welded edges as (lo, hi) vertex pairs, shared by every face using them.

    Returns the edge of each face side (R, 3), whether the side runs lo -> hi (R, 3) bool, and
    the edges' lo (E,) and hi (E,) vertices.
    """
    b_idx = wf[:, [1, 2, 0]]
    lo = np.minimum(wf, b_idx)
    hi = np.maximum(wf, b_idx)
    uniq, face_edge = np.unique((lo * n_v + hi).ravel(), return_inverse=True)
    return face_edge.reshape(len(wf), 3), wf == lo, uniq // n_v, uniq % n_v


def _assemble(fs: FaceSet, wv: np.ndarray, ref: Refined, ev0, ev1, keep) -> SimMesh:
    """Nodes, faces, the exact map back to the asset, boundary flags; unused nodes dropped."""
    wf, n_v, e_base = fs.wf, fs.n_v, fs.e_base
    n_lat = len(fs.l_face)
    pt_edge, t_edge = ref.pt_edge, ref.t_edge
    n_edge_pts = len(pt_edge)
    corners3 = wv[wf]
    edge_xyz = (1.0 - t_edge)[:, None] * wv[ev0[pt_edge]] + t_edge[:, None] * wv[ev1[pt_edge]]
    st_face_a = np.concatenate(ref.st_face) if ref.st_face else np.zeros(0, dtype=np.int64)
    st_bary_a = np.concatenate(ref.st_bary) if ref.st_bary else np.zeros((0, 3))
    tri_ids = np.where(ref.tri_ids < 0, e_base + n_edge_pts - 1 - ref.tri_ids, ref.tri_ids)
    kept = np.flatnonzero(~ref.refined)
    faces = np.concatenate([wf[kept], tri_ids]).astype(np.int64)
    owner = np.concatenate([kept, ref.tri_owner]).astype(np.int64)
    inner_face = np.concatenate([fs.l_face, st_face_a])
    inner_bary = np.concatenate([barycentric(fs.corners[fs.l_face], fs.l_xy), st_bary_a])
    inner_xyz = np.einsum("ij,ijk->ik", inner_bary, corners3[inner_face])
    vertices = np.concatenate([wv, inner_xyz[:n_lat], edge_xyz, inner_xyz[n_lat:]])

    inner_ids = np.r_[n_v + np.arange(n_lat), e_base + n_edge_pts + np.arange(len(st_face_a))]
    node_face, node_bary = _node_map(fs, len(vertices), inner_ids, inner_face, inner_bary,
                                     pt_edge, t_edge)
    face_count = np.bincount(fs.face_edge.ravel(), minlength=len(ev0))
    boundary = np.zeros(len(vertices), dtype=bool)
    open_e = np.flatnonzero(face_count == 1)
    boundary[ev0[open_e]] = True
    boundary[ev1[open_e]] = True
    boundary[e_base + np.flatnonzero(face_count[pt_edge] == 1)] = True

    # Drop nodes no face uses (loose asset vertices, corners of dropped zero-area faces,
    # lattice points of faces kept whole, points of faces meshed again).
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    if not used.all():
        remap = np.cumsum(used) - 1
        faces = remap[faces]
        vertices, node_face, node_bary, boundary = (
            vertices[used], node_face[used], node_bary[used], boundary[used])

    return SimMesh(
        vertices=vertices,
        faces=faces,
        asset_face=keep[owner],
        node_face=keep[node_face],
        node_bary=node_bary,
        boundary=boundary,
        edge_length=fs.h,
    )


def _node_map(fs: FaceSet, n_nodes: int, inner_ids, inner_face, inner_bary, pt_edge, t_edge):
    """Exact map back, (face row, barycentrics) per node: asset vertices by a corner of some
    face, edge points by a face of the edge, interior points by their own face."""
    node_face = np.zeros(n_nodes, dtype=np.int64)
    node_bary = np.zeros((n_nodes, 3))
    flat = fs.wf.ravel()
    node_ids, corner = np.unique(flat, return_index=True)  # first corner using each vertex
    node_face[node_ids] = corner // 3
    node_bary[node_ids, corner % 3] = 1.0
    node_face[inner_ids] = inner_face
    node_bary[inner_ids] = inner_bary
    if len(pt_edge):
        side = np.zeros(len(fs.e_len), dtype=np.int64)
        e_ids, e_side = np.unique(fs.face_edge.ravel(), return_index=True)  # first face side
        side[e_ids] = e_side
        s_of_pt = side[pt_edge]
        s = s_of_pt % 3
        t_s = np.where(fs.forward.ravel()[s_of_pt], t_edge, 1.0 - t_edge)
        ids = fs.e_base + np.arange(len(pt_edge))
        node_face[ids] = s_of_pt // 3
        node_bary[ids, s] = 1.0 - t_s
        node_bary[ids, (s + 1) % 3] = t_s
    return node_face, node_bary
