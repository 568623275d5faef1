"""The UVs the textures are baked for: the asset's own when usable, else an xatlas unwrap.

Most game assets come with good UVs, and xatlas is slow (10-25 s of CPU for 100k faces) and
can crash, so :func:`prepare_uvs` keeps the asset's UVs whenever :func:`check_uvs` finds them
usable.
"""

from __future__ import annotations

import warnings

import numpy as np

from crackbake.bake.uv.check import DEGENERATE_AREA2, UVCheck, check_uvs, uv_area2
from crackbake.bake.uv.unwrap import unwrap
from crackbake.bake.uv.uvmesh import UVMesh, mesh_label, uv_area_coverage
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh
from crackbake.params import UV_MODES

# Above this overlap fraction kept UVs get a warning: mirrored/stacked islands repeat cracks.
OVERLAP_WARN_FRACTION = 0.01
#: Kept UVs covering less of the page than this get a warning: the maps have few texels for the
#: cracks (a 4096² page then gives the asset under 920 texels across).  Lower than an unwrap's
#: (:data:`crackbake.bake.uv.unwrap.COVERAGE_WARN`): a prop's share of a shared atlas is often
#: a tenth of it, and an artist chose that layout.
KEPT_COVERAGE_WARN = 0.05


def kept_uvmesh(mesh: Mesh, check: UVCheck, res: int = 2048) -> UVMesh:
    """The asset's own UVs as a :class:`UVMesh`, warning about overlap, strays and zero area.

    ``res`` is the texture size the stray warning counts lost texels at."""
    label = mesh_label(mesh)
    overlap = float(check.overlap_fraction or 0.0)
    if overlap > OVERLAP_WARN_FRACTION:
        warnings.warn(
            f"{label}: {overlap:.1%} of the UV area overlaps (stacked or mirrored islands), so "
            "cracks will show twice there; use --uv unwrap for unique UVs",
            CrackbakeWarning,
            stacklevel=3,
        )
    if check.outside_fraction > 0:
        warnings.warn(stray_message(label, mesh, check, res), CrackbakeWarning, stacklevel=3)
    uv = np.asarray(mesh.uv, dtype=np.float64)
    if check.tiles is None:  # a UDIM set has a page per tile
        # The summed triangle area counts stacked islands twice: an upper bound of the page's
        # share, so the warning never comes from overlap.
        coverage = uv_area_coverage(uv, mesh.faces)
        if coverage < KEPT_COVERAGE_WARN:
            warnings.warn(
                f"{label}: its own UVs cover only {coverage:.1%} of the {res}px texture (about "
                f"{np.sqrt(coverage) * res:.0f} px across), so cracks get few texels; raise "
                "--res, or use --uv unwrap for a page of the asset's own",
                CrackbakeWarning,
                stacklevel=3,
            )
    # Not clipped: clipping would distort the straying faces.  The GLB keeps the artist's UVs
    # and the bake draws the straying parts again where REPEAT sampling shows them (wraps).
    n_degenerate = int(np.count_nonzero(uv_area2(uv[mesh.faces]) <= DEGENERATE_AREA2))
    if n_degenerate > OVERLAP_WARN_FRACTION * len(mesh.faces):
        warnings.warn(
            f"{label}: {n_degenerate} faces have zero UV area and get no texels; "
            "use --uv unwrap if cracks go missing there",
            CrackbakeWarning,
            stacklevel=3,
        )
    return UVMesh(
        vertices=np.asarray(mesh.vertices, dtype=np.float64),
        faces=np.asarray(mesh.faces, dtype=np.int64),
        uv=uv,
        normals=np.asarray(mesh.normals, dtype=np.float64),
        vertex_map=np.arange(len(mesh.vertices), dtype=np.int64),
        method="kept",
        overlap_fraction=overlap,
        padding_px=0,
        wraps=np.asarray(check.wraps, np.int64),
        udim=None if check.tiles is None else np.asarray(check.tiles, np.int64),
    )


def stray_message(label: str, mesh: Mesh, check: UVCheck, res: int) -> str:
    """The one-line warning about faces straying past the UV page: how many, how many were
    baked wrapped into the tile, and how many texels could not be."""
    n = int(round(check.outside_fraction * len(mesh.faces)))
    wrapped = len(np.unique(np.asarray(check.wraps)[:, 0])) if len(check.wraps) else 0
    msg = (
        f"{label}: {n} faces reach slightly outside the 0-1 UV square; engines repeat the "
        f"texture there, so {wrapped} are also baked wrapped into the tile"
    )
    if check.lost_faces:
        texels = int(round(check.lost_fraction * res * res))
        msg += (
            f"; {check.lost_faces} could not be (their wrapped place belongs to another island): "
            f"about {texels} texels at {res}x{res} show another island's cracks there "
            "(use --uv unwrap to avoid it)"
        )
    return msg


def prepare_uvs(
    mesh: Mesh,
    mode: str = "auto",
    res: int = 2048,
    padding: int | None = None,
    timeout: float = 300.0,
    cache: bool = True,
    ctx=None,
) -> UVMesh:
    """The UVs to bake into: keep the asset's, or unwrap with xatlas.

    Parameters
    ----------
    mesh : Mesh
        The asset mesh.
    mode : {"auto", "keep", "unwrap"}
        ``"keep"`` uses the mesh's UVs (error when unusable), ``"unwrap"`` always runs xatlas,
        ``"auto"`` keeps usable UVs and unwraps otherwise (warning why when the mesh had UVs).
        UVs on UDIM tiles are usable: the :class:`UVMesh` lists the tiles (``udim``).
    res : int
        Texture resolution an unwrap packs for, texels per side.
    padding : int, optional
        Unwrap gutter in texels; default :func:`default_padding`.
    timeout : float
        Seconds xatlas may run.
    cache : bool
        Use the unwrap cache.
    ctx : moderngl.Context, optional
        The run's GL context (overlap measure); a temporary one when not given.

    Returns
    -------
    UVMesh

    Raises
    ------
    CrackbakeError
        Unknown mode, unusable UVs in ``"keep"`` mode, or a failed unwrap.

    Warns
    -----
    CrackbakeWarning
        Kept UVs overlapping by more than 1 % or covering under 5 % of the page, or ``"auto"``
        falling back to an unwrap.
    """
    if mode not in UV_MODES:
        raise CrackbakeError(f"unknown UV mode '{mode}'; use one of {', '.join(UV_MODES)}")
    if mode == "unwrap":
        return unwrap(mesh, res, padding=padding, timeout=timeout, cache=cache, ctx=ctx)

    label = mesh_label(mesh)
    check = _checked_uvs(mesh, ctx, cache)
    if check.usable:
        return kept_uvmesh(mesh, check, res)
    if mode == "keep":
        if check.udim:
            raise CrackbakeError(
                f"{label}: cannot keep the UVs: {check.reason}; move each face inside one tile "
                "or use --uv unwrap"
            )
        raise CrackbakeError(f"{label}: cannot keep the UVs: {check.reason}; use --uv unwrap")
    if mesh.uv is not None:
        fix = "; move each face inside one tile to keep the layout" if check.udim else ""
        warnings.warn(
            f"{label}: {check.reason}; unwrapping with xatlas instead{fix}",
            CrackbakeWarning,
            stacklevel=2,
        )
    return unwrap(mesh, res, padding=padding, timeout=timeout, cache=cache, ctx=ctx)


def _checked_uvs(mesh: Mesh, ctx, cache: bool) -> UVCheck:
    """:func:`check_uvs`, read from the mesh cache (:mod:`crackbake.bake.mesh_cache`) when an
    earlier run of the same UVs on the same renderer stored it (a re-bake's UV stage: the
    overlap and wrap measures are GL draws), else measured and stored."""
    if not cache or ctx is None or mesh.uv is None:
        return check_uvs(mesh, ctx=ctx)
    from crackbake.bake.context import renderer_info
    from crackbake.bake.mesh_cache import read_uvcheck, uvcheck_key, write_uvcheck

    uv = np.asarray(mesh.uv)
    if uv.ndim != 2 or len(uv) != len(mesh.vertices):
        return check_uvs(mesh, ctx=ctx)
    key = uvcheck_key(uv, mesh.faces, len(mesh.vertices), renderer_info(ctx))
    check = read_uvcheck(key, len(mesh.faces))
    if check is None:
        check = check_uvs(mesh, ctx=ctx)
        write_uvcheck(key, check)
    return check
