"""Seamlessly tiling crack materials (``crackbake tile``): the solver on a periodic plate.

The plate is the square ``[0, size)²`` in z = 0 with its opposite edges identified (a flat
torus): the simulation mesh (:func:`periodic_simmesh`) is a jittered triangulated grid whose
nodes on opposite edges are one node, so it has no boundary, and the solver wraps every
vector between two nodes to its nearest image (``period`` on the sim mesh, docs/solver.md
"Periodic plates").  Cracks leaving one side continue from the other.  The stress field
(:func:`tile_field`) is periodic too: shrinkage is uniform, the noise is a sum of plane waves
whose wave vectors fit the period, and impacts (``--impacts N``, glass) are placed at random
with their distance measured to the nearest image.  :func:`split_at_border` cuts the
solver's unwrapped polylines at the tile border into pieces inside the tile; the bake
(:mod:`crackbake.tile.files`) sees every piece also shifted by one period each way.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.params import (
    EXR_COMPRESSION_DEFAULT,
    EXR_COMPRESSIONS,
    LENGTH_MAX,
    RES_MIN,
    TILE_DEFAULTS,
    RunParams,
    check_seed,
    check_sim_faces,
    is_length,
    load_preset,
)

logger = logging.getLogger(__name__)

#: Largest tile texture, texels per side.
TILE_RES_MAX = 8192
#: Simulation faces of a tile when ``--sim-faces`` is not given.
TILE_SIM_FACES = TILE_DEFAULTS["sim_faces"]
#: Most impacts on one glass tile.
IMPACTS_MAX = 64
#: Node jitter of the periodic grid, fraction of the cell (keeps every triangle positive).
JITTER = 0.2


@dataclass(frozen=True)
class TileParams:
    """Every parameter of one tile.

    Attributes
    ----------
    out : Path
        Output folder (replaced as a whole).
    preset : str
        Material preset.
    size : float
        Tile side, mesh units (the period).
    res : int
        Texels per side.
    seed : int
    impacts : int or None
        Random impacts on the tile (presets that need impacts, glass); ``None`` = 3 for those.
    sim_faces : int or None
        Simulation mesh size; ``None`` = :data:`TILE_SIM_FACES`.
    method : str or None
        ``iben`` (the only method on a periodic plate) or ``None`` (the preset's).
    exr_compression : str
        Lossless compression of ``tile_cracks.exr``, one of
        :data:`~crackbake.params.EXR_COMPRESSIONS` (as the bake's ``--exr-compression``).
    """

    out: Path
    preset: str = TILE_DEFAULTS["preset"]
    size: float = TILE_DEFAULTS["size"]
    res: int = TILE_DEFAULTS["res"]
    seed: int = TILE_DEFAULTS["seed"]
    impacts: int | None = None
    sim_faces: int | None = None
    method: str | None = None
    exr_compression: str = EXR_COMPRESSION_DEFAULT

    def validate(self) -> TileParams:
        """Check every value (one-line :class:`CrackbakeError`); return self."""
        if not str(self.out).strip():
            raise CrackbakeError("-o '' names no folder; give an output folder with -o")
        preset = load_preset(self.preset)
        method = self.method or preset.get("method", "iben")
        if method != "iben":
            raise CrackbakeError(
                f"--method {method} cannot run on a periodic tile; use --method iben"
            )
        if not is_length(self.size):
            raise CrackbakeError(
                f"--size {self.size} is not a tile size; use a number above 0 up to "
                f"{LENGTH_MAX:g} mesh units"
            )
        if not RES_MIN <= self.res <= TILE_RES_MAX:
            raise CrackbakeError(
                f"--res {self.res} is out of range; use {RES_MIN} to {TILE_RES_MAX} texels"
            )
        if self.impacts is not None and not 1 <= self.impacts <= IMPACTS_MAX:
            raise CrackbakeError(
                f"--impacts {self.impacts} is out of range; use 1 to {IMPACTS_MAX}"
            )
        if self.impacts is not None and not preset.get("needs_impact", False):
            raise CrackbakeError(
                f"--impacts is for impact presets (glass); preset {self.preset} has none"
            )
        if self.exr_compression not in EXR_COMPRESSIONS:
            raise CrackbakeError(
                f"--exr-compression {self.exr_compression} is not one of "
                f"{', '.join(EXR_COMPRESSIONS)}; use one of those (all lossless)"
            )
        check_sim_faces(self.sim_faces)
        check_seed(self.seed)
        return self


def periodic_simmesh(size: float, faces: int, seed: int, cells: int) -> SimpleNamespace:
    """A jittered triangulated grid on the flat torus ``[0, size)²``.

    Parameters
    ----------
    size : float
        Period, mesh units.
    faces : int
        About this many triangles (``2 n²`` for ``n`` cells per side).
    seed : int
        Seeds the jitter and the diagonals.
    cells : int
        Cells per side of the plate mesh the sim faces map to (``asset_face``).

    Returns
    -------
    SimpleNamespace
        ``vertices (n², 3)`` in ``[0, size)``, ``faces (2 n², 3)`` counter-clockwise in the
        nearest-image sense, ``asset_face``, ``boundary`` (all False), ``edge_length``,
        ``period`` = size.  Node ``(i, j)`` is ``i * n + j``; column ``n`` is column 0.
    """
    n = max(int(round(math.sqrt(faces / 2.0))), 8)
    h = size / n
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x711E]))
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    xy = np.stack([i, j], -1).reshape(-1, 2) + rng.uniform(-JITTER, JITTER, (n * n, 2))
    xy = np.mod(xy * h, size)
    node = lambda a, b: (a % n) * n + (b % n)  # noqa: E731
    a, b, c, d = node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)
    flip = rng.random((n, n)) < 0.5  # random diagonals: no preferred crack direction
    t1 = np.where(flip[..., None], np.stack([a, b, d], -1), np.stack([a, b, c], -1))
    t2 = np.where(flip[..., None], np.stack([b, c, d], -1), np.stack([a, c, d], -1))
    tris = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)]).astype(np.int64)
    vertices = np.column_stack([xy, np.zeros(n * n)])
    # Asset face: the plate cell (two triangles, lower-right first) holding the centroid.
    cent = lifted(vertices, tris, size).mean(1) % size
    ci = np.minimum((cent[:, :2] / size * cells).astype(np.int64), cells - 1)
    lower = (cent[:, 0] / size * cells - ci[:, 0]) >= (cent[:, 1] / size * cells - ci[:, 1])
    asset = np.where(lower, 0, cells * cells) + ci[:, 0] * cells + ci[:, 1]
    return SimpleNamespace(vertices=vertices, faces=tris, asset_face=asset.astype(np.int64),
                           boundary=np.zeros(n * n, bool), edge_length=h, period=float(size))


def lifted(vertices: np.ndarray, faces: np.ndarray, period: float) -> np.ndarray:
    """(M, 3, 3) corner positions of each face, corners 1 and 2 moved to the image nearest
    corner 0 (so each face is a small triangle, possibly reaching past the tile)."""
    p = vertices[faces].copy()
    d = p[:, 1:, :2] - p[:, :1, :2]
    p[:, 1:, :2] = p[:, :1, :2] + d - period * np.floor(d / period + 0.5)
    return p


def tile_impacts(params: TileParams, radius_rel: float) -> list[tuple[float, float, float]]:
    """``(x, y, radius)`` of the tile's random impacts (none for presets without impacts)."""
    if not load_preset(params.preset).get("needs_impact", False):
        return []
    n = TILE_DEFAULTS["impacts"] if params.impacts is None else int(params.impacts)
    rng = np.random.default_rng(np.random.SeedSequence([int(params.seed), 0x1A9AC7]))
    # Latin hypercube: one impact per row and per column of an n x n grid, so that impacts
    # spread over the tile instead of clumping (their fields would merge into one blob).
    xy = (np.column_stack([rng.permutation(n), rng.permutation(n)])
          + rng.uniform(0.0, 1.0, (n, 2))) * (params.size / n)
    # The preset's radius, at most a third of the mean spacing of the impacts.
    radius = min(radius_rel * params.size * math.sqrt(2.0), params.size / (3.0 * math.sqrt(n)))
    return [(float(x), float(y), float(radius)) for x, y in xy]


def tile_field(sim, run: RunParams, relative: dict, params: TileParams) -> SimpleNamespace:
    """The periodic stress field on ``sim``: ``stress``, ``growth`` (M, 3, 3), ``impacts``.

    The preset's shrinkage (uniform, hence periodic) and noise (plane waves with wave vectors
    on the period's lattice) are applied as :func:`crackbake.simulate.stress.stress_field`
    applies them; impacts add a radial/hoop field (:func:`_impact_stress`) of every impact's
    nearest image.
    """
    from crackbake.simulate.stress.fields import NOISE_SCALE_DIAGONAL, _outer

    m = len(sim.faces)
    plane = np.zeros((m, 3, 3))
    plane[:, 0, 0] = plane[:, 1, 1] = 1.0
    stress = np.zeros((m, 3, 3))
    growth = np.zeros((m, 3, 3))
    if run.shrink:
        stress += run.shrink * plane
        growth += run.shrink_rate * run.shrink * plane
    cent = lifted(sim.vertices, sim.faces, params.size).mean(1)
    impacts = tile_impacts(params, relative.get("impact_radius_rel", 0.15))
    for x, y, r in impacts:
        stress += _impact_stress(cent, x, y, r, params.size, run.hoop or 1.0)
    if run.noise:
        rng = np.random.default_rng(np.random.SeedSequence([int(run.seed), 0]))
        scale = NOISE_SCALE_DIAGONAL * params.size * math.sqrt(2.0)
        fields = _periodic_noise(cent, scale, params.size, rng, 4)
        factor = np.maximum(1.0 + run.noise * fields[0], 0.0)
        size = np.sqrt(np.einsum("eab,eab->e", stress, stress))
        if not size.any():
            size = np.ones_like(size)
        t = fields[1:].T.copy()
        t[:, 2] = 0.0  # in the plate's plane
        stress = factor[:, None, None] * stress + (0.5 * run.noise * size)[:, None, None] * _outer(
            t, t)
        growth *= factor[:, None, None]
    info = [{"point": [x, y, 0.0], "radius": r} for x, y, r in impacts]
    return SimpleNamespace(stress=stress, growth=growth if growth.any() else None, impacts=info)


def _periodic_noise(points, scale, period, rng, count, waves: int = 16) -> np.ndarray:
    """``count`` smooth unit-variance periodic fields at (M, 3) points, (count, M): plane
    waves of random direction and wavelength near ``scale``, wave vectors rounded to the
    lattice ``2 pi / period * Z²`` (so every wave fits the tile)."""
    k = rng.normal(size=(2, count * waves))
    k /= np.linalg.norm(k, axis=0, keepdims=True)
    k *= (2 * np.pi / scale) * rng.uniform(0.7, 1.4, size=count * waves)
    step = 2 * np.pi / period
    k = np.round(k / step) * step
    k[0, ~k.any(axis=0)] = step  # no constant wave
    phase = rng.uniform(0, 2 * np.pi, size=count * waves)
    arg = np.cos(points[:, :2] @ k + phase)
    return arg.reshape(len(points), count, waves).sum(axis=2).T * np.sqrt(2.0 / waves)


def _impact_stress(cent, x, y, radius, period, hoop) -> np.ndarray:
    """The impact field of :mod:`crackbake.simulate.stress.fields` on a flat plate (unit
    strength): ``2 cos(d / radius) (r r^T + hoop c c^T)`` within ``d <= pi/2 radius`` of the
    impact's nearest image, ``r`` the radial and ``c`` the hoop direction."""
    d = cent[:, :2] - np.array([x, y])
    d -= period * np.floor(d / period + 0.5)
    r = np.linalg.norm(d, axis=1)
    u = d / np.maximum(r, 1e-12)[:, None]
    u[r < 1e-12] = (1.0, 0.0)
    w = np.where(r <= 0.5 * np.pi * radius, 2.0 * np.cos(r / radius), 0.0)
    c = np.column_stack([-u[:, 1], u[:, 0]])
    s = np.zeros((len(cent), 3, 3))
    s[:, :2, :2] = w[:, None, None] * (np.einsum("ea,eb->eab", u, u)
                                       + hoop * np.einsum("ea,eb->eab", c, c))
    return s


def split_at_border(points: np.ndarray, values: np.ndarray, period: float) -> list:
    """Cut an unwrapped polyline where it crosses a tile border; each piece shifted into
    ``[0, period]²``.

    Parameters
    ----------
    points : (N, 3) float64
        Continuous polyline (may leave the tile).
    values : (N, K) float64
        Per-point attributes, interpolated linearly at the cuts.

    Returns
    -------
    list of (points (n, 3), values (n, K))
    """
    # Sub-segments between the grid lines each segment crosses strictly inside, each in the
    # cell of its midpoint; a piece ends where the cell changes.  (Points lying exactly on a
    # line belong to both sides, so they never decide a cell.)
    runs: list[tuple[list, list, np.ndarray]] = []
    for k in range(1, len(points)):
        a, b = points[k - 1], points[k]
        va, vb = values[k - 1], values[k]
        ts = [0.0, 1.0]
        for ax in (0, 1):
            lo, hi = sorted((a[ax], b[ax]))
            for g in range(int(np.floor(lo / period)) + 1, int(np.ceil(hi / period))):
                tt = (g * period - a[ax]) / (b[ax] - a[ax])
                if 0.0 < tt < 1.0:
                    ts.append(tt)
        ts.sort()
        for t0, t1 in zip(ts[:-1], ts[1:], strict=True):
            if t1 <= t0:
                continue
            cell = np.floor((a + 0.5 * (t0 + t1) * (b - a))[:2] / period)
            p1, v1 = a + t1 * (b - a), va + t1 * (vb - va)
            if runs and np.array_equal(runs[-1][2], cell):
                runs[-1][0].append(p1)
                runs[-1][1].append(v1)
            else:
                runs.append(([a + t0 * (b - a), p1], [va + t0 * (vb - va), v1], cell))
    pieces = []
    for ps, vs, c in runs:
        p = np.array(ps)
        p[:, :2] -= c * period
        # Rounding only: every point is in the closed cell of its piece.
        p[:, :2] = np.clip(p[:, :2], 0.0, period)
        pieces.append((p, np.array(vs)))
    return pieces


def solve_tile(params: TileParams, mesh, cells: int, timings: dict) -> SimpleNamespace:
    """Periodic sim mesh, field and the iben solver: the tile's pieces and figures."""
    from crackbake.simulate.setup import solver_params, with_spacing
    from crackbake.simulate.solver.iben import solve_iben

    run = RunParams(mesh=Path(mesh.source), preset=params.preset, seed=params.seed,
                    res=params.res, method=params.method).validate()
    run, relative = run.resolved()
    t = time.perf_counter()
    sim = periodic_simmesh(params.size, params.sim_faces or TILE_SIM_FACES, params.seed, cells)
    field = with_spacing(tile_field(sim, run, relative, params), run, np.hypot(params.size,
                                                                               params.size))
    timings["stress"] = time.perf_counter() - t
    sp = solver_params(run, mesh, relative)
    t = time.perf_counter()
    result = solve_iben(sim, field, sp)
    timings["solve"] = time.perf_counter() - t
    pieces = []
    for cid, path in enumerate(result.cracks):
        vals = np.column_stack([path.width, path.depth, path.time])
        for p, v in split_at_border(np.asarray(path.points), vals, params.size):
            pieces.append(SimpleNamespace(crack=cid, points=p, width=v[:, 0], depth=v[:, 1],
                                          time=v[:, 2]))
    logger.info("%d cracks, %d pieces in the tile", len(result.cracks), len(pieces))
    return SimpleNamespace(pieces=pieces, paths=result.cracks, run=run, sp=sp, sim=sim,
                           field=field, stats=result.stats, steps=result.steps)


def build_tile(params: TileParams) -> dict:
    """Solve, bake and write one tile into ``params.out`` atomically; the manifest written.

    Raises
    ------
    CrackbakeError
        Bad parameters or an unusable output folder (left unchanged).
    """
    from crackbake.transaction.interrupt import run_staged
    from crackbake.transaction.stage import OutputStage

    params = params.validate()
    stage = OutputStage(params.out)

    def body() -> dict:
        manifest = _build(params, stage)
        stage.commit()
        return manifest

    # SIGINT/SIGTERM leave the folder as it was and exit 128 + signal, like the other commands.
    return run_staged(stage, body)


def _build(params: TileParams, stage) -> dict:
    from crackbake.bake.context import create_context
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv import prepare_uvs
    from crackbake.decals.library import PLATE_CELLS, plate_mesh
    from crackbake.tile.files import bake_tile, write_tile

    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    mesh = plate_mesh(params.size, PLATE_CELLS)
    solved = solve_tile(params, mesh, PLATE_CELLS, timings)
    ctx = create_context()
    try:
        t = time.perf_counter()
        uvmesh = with_tangents(prepare_uvs(mesh, "keep", params.res, cache=False, ctx=ctx))
        maps = bake_tile(solved.pieces, uvmesh, params.size, params.res, solved.run.profile,
                         ctx, look=solved.run.crack_look())
        timings["bake"] = time.perf_counter() - t
    finally:
        ctx.release()
    stats = dict(solved.stats, pieces=len(solved.pieces))
    return write_tile(stage, params, maps, solved.pieces, stats, timings, t0)


__all__ = [
    "TILE_SIM_FACES",
    "TileParams",
    "build_tile",
    "lifted",
    "periodic_simmesh",
    "solve_tile",
    "split_at_border",
    "tile_field",
]
