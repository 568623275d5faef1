"""Whether an asset's own UVs can be baked into: range, UDIM tiles, degenerate faces, overlap."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crackbake.bake.uv.overlap import uv_overlap_fraction, wrap_conflicts
from crackbake.io.mesh import Mesh

# Kept UVs may stray this far outside [0, 1] (exporters round) and are clipped.
UV_TOLERANCE = 1e-6
# Twice the UV area below which a face counts as degenerate: far below one texel at 16384^2
# (3.7e-9), so only truly collapsed faces qualify.
DEGENERATE_AREA2 = 1e-12
# Kept UVs may stray outside [0, 1] by at most STRAY_MARGIN (exporters round, artists let an
# island hang over the edge; Keenan Crane's spot has 10 of 5,856 faces at u = -0.05).  Engines
# sample there with REPEAT, so the straying parts are also baked wrapped into the tile where
# they do not overlap another island.  They are kept, with a warning, when at most
# STRAY_FACE_FRACTION of the faces stray or when at most STRAY_LOST_FRACTION of the page's
# texels cannot be baked for them, rather than throwing away an artist's layout for a few texels.
STRAY_FACE_FRACTION = 0.01
STRAY_LOST_FRACTION = 0.01
STRAY_MARGIN = 0.25
# Resolution at which check_uvs measures overlap; 1024^2 resolves islands down to ~0.1 % of the
# page and costs well under a second even for 500k faces.
OVERLAP_RES = 1024


@dataclass(frozen=True)
class UVCheck:
    """Whether a mesh's own UVs can be baked into.

    Attributes
    ----------
    usable : bool
        UVs exist, are finite, lie in [0, 1] and not every face is degenerate in UV.
    reason : str
        ``""`` when usable, else a short why (no UVs / outside [0, 1] / UDIM tiles / degenerate).
    udim : bool
        The UVs are laid out in UDIM tiles (each face inside one integer tile, ``u`` in [0, 10)).
    overlap_fraction : float or None
        Overlapping / covered UV area for usable UVs, else ``None``.
    outside_fraction : float
        Fraction of faces reaching slightly outside [0, 1] in otherwise usable UVs (exporters
        and hand-made UVs often stray a little).
    wraps : (K, 3) int64
        Copies (face, du, dv) of the straying faces to bake at ``uv - (du, dv)``: where an
        engine sampling with REPEAT shows them, for every tile a face reaches that lands on
        no other face.  Empty when nothing strays.
    lost_fraction : float
        Share of the page (texels / all texels, measured at :data:`OVERLAP_RES`) that straying
        faces reach but cannot be baked for, because their wrapped place belongs to another
        face; their cracks do not show there.
    lost_faces : int
        Straying faces with at least one copy that could not be wrapped.
    tiles : (T, 2) int64 or None
        UDIM layouts only: the used tiles' integer (u, v) corners, in UDIM order (1001 first).
    """

    usable: bool
    reason: str
    udim: bool
    overlap_fraction: float | None
    outside_fraction: float = 0.0
    wraps: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    lost_fraction: float = 0.0
    lost_faces: int = 0
    tiles: np.ndarray | None = None


def uv_area2(corners: np.ndarray) -> np.ndarray:
    """Twice the unsigned UV area per face, (F,), from corners (F, 3, 2)."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    return np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def is_udim(corners: np.ndarray, faces: np.ndarray | None = None) -> bool:
    """True when every face lies inside one integer UV tile of a UDIM layout, not all in 0-1.

    With ``faces`` (F, 3), the UV vertex indices of the corners, a vertex shared by faces of
    two tiles (an island crossing a tile edge) rules UDIM out."""
    if corners.size == 0 or corners.ndim != 3 or corners.shape[-1] != 2:
        return False  # no UVs, or not two coordinates each (the caller says what they are)
    # Corner columns, not reductions along the (F, 3, 2) middle axis (numpy's are slow there:
    # 3 s a call at 1.5M faces); the centroid is the same sum, (c0 + c1) + c2, over 3.
    c0, c1, c2 = corners[:, 0], corners[:, 1], corners[:, 2]
    tile = np.floor((c0 + c1 + c2) / 3)  # (F, 2); a centroid is strictly inside its tile
    lo = np.minimum(np.minimum(c0, c1), c2)
    hi = np.maximum(np.maximum(c0, c1), c2)
    if not ((lo >= tile - UV_TOLERANCE) & (hi <= tile + 1.0 + UV_TOLERANCE)).all():
        return False
    # An island running on across a tile edge (a UV vertex shared by faces of two tiles) is one
    # layout straying past the page, not UDIM tiles (islands there never cross tiles).
    key = tile[:, 0] * 4096.0 + tile[:, 1]
    if faces is not None:
        # Each vertex keeps one of its corners' keys; a vertex of two tiles has a corner that
        # differs from it (np.minimum.at and np.maximum.at took a second).
        per_corner = np.repeat(key, 3)
        flat = faces.reshape(-1)
        vertex_key = np.empty(int(faces.max()) + 1)
        vertex_key[flat] = per_corner
        if (vertex_key[flat] != per_corner).any():
            return False
    tu, tv = tile[:, 0], tile[:, 1]
    # UDIM numbers tiles 1001 + u + 10 v: u in 0..9, v >= 0.
    if (tu < 0).any() or (tu > 9).any() or (tv < 0).any():
        return False
    return bool(((tu > 0) | (tv > 0)).any())


def udim_problem(corners: np.ndarray, faces: np.ndarray) -> str | None:
    """Why UVs spread over whole tiles are not a UDIM layout, or None when they do not look
    like one (most of the area outside the 0-1 tile, most faces inside one tile).

    Parameters
    ----------
    corners : (F, 3, 2) float
        UV corners per face.
    faces : (F, 3) int
        The UV vertex indices of the corners.

    Returns
    -------
    str or None
        A short why: faces straddling two tiles, islands running across a tile edge, tiles at
        negative ``u`` or ``v`` or at ``u >= 10`` (UDIM numbers none of them).
    """
    tile = np.floor(corners.mean(axis=1))
    inside = (
        (corners >= tile[:, None, :] - UV_TOLERANCE)
        & (corners <= tile[:, None, :] + 1.0 + UV_TOLERANCE)
    ).all(axis=(1, 2))
    off_page = (tile != 0).any(axis=1)
    # Tiles of their own: most faces inside one tile and a good share beyond the 0-1 tile.
    if inside.mean() < 0.9 or off_page.mean() < 0.05:
        return None
    why = []
    if (~inside).any():
        why.append(f"{int((~inside).sum())} faces straddle two tiles")
    else:
        key = tile[:, 0] * 4096.0 + tile[:, 1]
        per_corner = np.repeat(key, 3)
        n = int(faces.max()) + 1
        lo, hi = np.full(n, np.inf), np.full(n, -np.inf)
        np.minimum.at(lo, faces.reshape(-1), per_corner)
        np.maximum.at(hi, faces.reshape(-1), per_corner)
        crossing = int(np.count_nonzero(hi > lo))
        if crossing:
            why.append(f"islands run across a tile edge ({crossing} UV vertices shared by "
                       "faces of two tiles)")
    negative = int(np.count_nonzero((tile < 0).any(axis=1)))
    if negative:
        why.append(f"{negative} faces lie on negative tiles (u or v < 0)")
    beyond = int(np.count_nonzero(tile[:, 0] > 9))
    if beyond:
        why.append(f"{beyond} faces lie at u >= 10")
    if not why:
        return None
    return "UVs look like UDIM tiles but " + ", ".join(why) + " (UDIM numbers tiles u 0-9, v >= 0)"


def udim_tiles(corners: np.ndarray) -> np.ndarray:
    """The integer (u, v) tile of each face, (F, 2) int64: the tile holding its UV centroid."""
    return np.floor(np.asarray(corners, np.float64).mean(axis=1)).astype(np.int64)


def udim_number(tiles: np.ndarray) -> np.ndarray:
    """UDIM numbers ``1001 + u + 10 v`` of integer tiles (..., 2)."""
    tiles = np.asarray(tiles, np.int64)
    return 1001 + tiles[..., 0] + 10 * tiles[..., 1]


def check_uvs(mesh: Mesh, ctx=None) -> UVCheck:
    """Decide whether the mesh's own UVs can be baked into, and how much they overlap.

    Parameters
    ----------
    mesh : Mesh
        The asset mesh; only the UVs of vertices that faces use are looked at.
    ctx : moderngl.Context, optional
        GL context for the overlap measure; a temporary one when not given.

    Returns
    -------
    UVCheck
        ``overlap_fraction`` is measured (at 1024^2, see :func:`uv_overlap_fraction`) only when
        the UVs are usable.
    """
    if mesh.uv is None:
        return UVCheck(False, "the mesh has no UVs", False, None)
    uv = np.asarray(mesh.uv, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if uv.shape != (len(mesh.vertices), 2):
        return UVCheck(False, f"UV array has shape {uv.shape}, not one UV per vertex", False, None)
    if len(faces) == 0:
        return UVCheck(False, "the mesh has no faces", False, None)
    corners = uv[faces]
    if not np.isfinite(corners).all():
        return UVCheck(False, "UVs contain NaN or infinite values", False, None)
    lo, hi = corners.reshape(-1, 2).min(axis=0), corners.reshape(-1, 2).max(axis=0)
    outside_fraction = 0.0
    if (lo < -UV_TOLERANCE).any() or (hi > 1.0 + UV_TOLERANCE).any():
        if is_udim(corners, faces):
            return _udim_check(uv, faces, corners, ctx)
        stray = ((corners < -UV_TOLERANCE) | (corners > 1.0 + UV_TOLERANCE)).any(axis=(1, 2))
        outside_fraction = float(stray.mean())
        outside = UVCheck(
            False,
            f"UVs lie outside [0, 1] (u {lo[0]:.3g}..{hi[0]:.3g}, v {lo[1]:.3g}..{hi[1]:.3g})",
            False,
            None,
        )
        if (lo < -STRAY_MARGIN).any() or (hi > 1.0 + STRAY_MARGIN).any():
            return _not_udim(outside, corners, faces)
    if not (uv_area2(corners) > DEGENERATE_AREA2).any():
        return UVCheck(False, "every face has zero UV area", False, None)
    wraps = np.zeros((0, 3), np.int64)
    lost_fraction, lost_faces = 0.0, 0
    if outside_fraction > 0:
        copies = stray_copies(corners)
        keep, lost = wrap_conflicts(uv, faces, copies, OVERLAP_RES, ctx=ctx)
        wraps = copies[keep]
        lost_fraction = lost / OVERLAP_RES**2
        lost_faces = len(np.unique(copies[~keep, 0]))
        if outside_fraction > STRAY_FACE_FRACTION and lost_fraction > STRAY_LOST_FRACTION:
            return _not_udim(outside, corners, faces)
    overlap = uv_overlap_fraction(np.clip(uv, 0.0, 1.0), faces, OVERLAP_RES, ctx=ctx)
    return UVCheck(True, "", False, overlap, outside_fraction, wraps, lost_fraction, lost_faces)


def _not_udim(outside: UVCheck, corners: np.ndarray, faces: np.ndarray) -> UVCheck:
    """``outside``, or, for UVs that look like UDIM tiles, why they are not a UDIM layout."""
    problem = udim_problem(corners, faces)
    return outside if problem is None else UVCheck(False, problem, True, None)


def _udim_check(uv: np.ndarray, faces: np.ndarray, corners: np.ndarray, ctx) -> UVCheck:
    """A usable UDIM layout: its tiles and its overlap, measured tile by tile (each tile's
    faces moved onto the 0-1 page): texels covered twice over texels covered, on all tiles."""
    face_tile = udim_tiles(corners)
    numbers = udim_number(face_tile)
    used = np.unique(numbers)
    tiles = np.stack([(used - 1001) % 10, (used - 1001) // 10], axis=1).astype(np.int64)
    if not (uv_area2(corners) > DEGENERATE_AREA2).any():
        return UVCheck(False, "every face has zero UV area", False, None)
    twice = covered = 0
    for number, tile in zip(used, tiles, strict=True):
        own = np.flatnonzero(numbers == number)
        local = np.clip(uv - tile, 0.0, 1.0)
        t, c = uv_overlap_fraction(local, faces[own], OVERLAP_RES, ctx=ctx, texel_counts=True)
        twice += t
        covered += c
    overlap = twice / covered if covered > 0 else 0.0
    return UVCheck(True, "", True, overlap, tiles=tiles)


def stray_copies(corners: np.ndarray) -> np.ndarray:
    """Every (face, du, dv) with (du, dv) != (0, 0) a face's UV box reaches into, (K, 3).

    Parameters
    ----------
    corners : (F, 3, 2) float
        UV corners per face.

    Returns
    -------
    (K, 3) int64
        Face index and the whole-tile offset its copy is drawn at (``uv - (du, dv)``), faces
        in order; a face straddling a page edge gets one copy per tile it reaches past it.
    """
    c0, c1, c2 = corners[:, 0], corners[:, 1], corners[:, 2]  # not min/max along axis 1: slow
    first = np.floor(np.minimum(np.minimum(c0, c1), c2) + UV_TOLERANCE).astype(np.int64)  # (F, 2)
    last = np.floor(np.maximum(np.maximum(c0, c1), c2) - UV_TOLERANCE).astype(np.int64)
    out = []
    for du in range(int(first[:, 0].min()), int(last[:, 0].max()) + 1):
        for dv in range(int(first[:, 1].min()), int(last[:, 1].max()) + 1):
            if du == 0 and dv == 0:
                continue
            hit = np.flatnonzero(
                (first[:, 0] <= du) & (du <= last[:, 0]) & (first[:, 1] <= dv) & (dv <= last[:, 1])
            )
            out.append(np.c_[hit, np.full(len(hit), du), np.full(len(hit), dv)])
    if not out:
        return np.zeros((0, 3), np.int64)
    copies = np.concatenate(out).astype(np.int64)
    return copies[np.lexsort((copies[:, 2], copies[:, 1], copies[:, 0]))]
