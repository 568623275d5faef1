"""Painted weights on the simulation mesh: per-vertex attributes and weight maps.

Both are sampled at each sim face's centroid through the asset face it lies in (barycentric
interpolation of vertex values, bilinear lookup of the image through the asset UVs) and multiply
the whole field, so a zero weight always means zero stress.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.images import LUMA
from crackbake.io.mesh import VERTEX_COLOURS, Mesh
from crackbake.simulate.simmesh import asset_barycentric
from crackbake.simulate.stress.sources import WeightSource


def _asset_barycentrics(sim, mesh: Mesh, centroid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Asset face (M,) and barycentrics (M, 3) of every sim face centroid."""
    af = np.asarray(sim.asset_face, dtype=np.int64)
    if af.shape != (len(centroid),) or af.min() < 0 or af.max() >= len(mesh.faces):
        raise CrackbakeError(
            "simulation mesh does not match the asset mesh (asset_face out of range); "
            "rebuild it from this mesh"
        )
    bary = np.clip(asset_barycentric(mesh, af, centroid), 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    return af, bary


def _sample_image(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear, repeat-wrapped lookup of an (H, W) image at (K, 2) UVs; row 0 is v = 1."""
    h, w = image.shape
    x = np.mod(uv[:, 0], 1.0) * w - 0.5
    y = (1.0 - np.mod(uv[:, 1], 1.0)) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa, xb = np.mod(x0, w), np.mod(x0 + 1, w)
    ya, yb = np.mod(y0, h), np.mod(y0 + 1, h)
    top = image[ya, xa] * (1 - fx) + image[ya, xb] * fx
    bottom = image[yb, xa] * (1 - fx) + image[yb, xb] * fx
    return top * (1 - fy) + bottom * fy


def weight_field(
    sim, mesh: Mesh, centroid: np.ndarray, src: WeightSource, bary_cache: list
) -> np.ndarray:
    """Per-sim-face multiplier (M,) of one weight source, sampled at the face centroids (M, 3).

    ``bary_cache`` (a list, empty at first) keeps the centroids' asset barycentrics between
    weight sources of one field.
    """
    if not bary_cache:
        bary_cache.append(_asset_barycentrics(sim, mesh, centroid))
    af, bary = bary_cache[0]
    corners = mesh.faces[af]
    weight = np.ones(len(centroid))
    if src.per_vertex is not None:
        pv = np.asarray(src.per_vertex, dtype=np.float64)
        if len(pv) != len(mesh.vertices):
            raise CrackbakeError(
                f"{len(pv)} per-vertex weights for a mesh of {len(mesh.vertices)} vertices; "
                "read them from the same mesh file"
            )
        pv = 1.0 - pv if src.invert else pv
        weight *= np.einsum("ek,ek->e", pv[corners], bary)
    if src.image is not None:
        if mesh.uv is None:
            raise CrackbakeError(
                f"{Path(mesh.source).name or 'the mesh'} has no UVs to sample the weight map "
                "through; give the mesh UVs or paint vertex weights instead"
            )
        uv = np.einsum("eka,ek->ea", mesh.uv[corners], bary)
        im = np.asarray(src.image, dtype=np.float64)
        im = 1.0 - im if src.invert else im
        weight *= _sample_image(im, uv)
    if (weight < 0).any():
        warnings.warn(
            "negative painted weights clipped to 0 (a weight of 1 is full strength)",
            CrackbakeWarning,
            stacklevel=3,
        )
        weight = np.maximum(weight, 0.0)
    return weight



def _attribute_names(attributes: dict) -> list[str]:
    return sorted(attributes)


def _attribute_values(attributes: dict, name: str) -> np.ndarray | None:
    # glTF requires custom attributes to start with '_'; accept the name with or without it.
    for key in (name, "_" + name, name.lstrip("_")):
        if key in attributes and key != VERTEX_COLOURS:
            return attributes[key]
    return None


def _to_scalar(values: np.ndarray, n: int, what: str, path: Path) -> np.ndarray:
    values = np.asarray(values)
    integer = np.issubdtype(values.dtype, np.integer)
    values = values.astype(np.float64).reshape(n, -1) if values.size % max(n, 1) == 0 else None
    if values is None:
        raise CrackbakeError(f"{path}: {what} does not hold one value per vertex; re-export it")
    if values.shape[1] >= 3:
        # Colour-like attribute: luminance; 8-bit colours scale to [0, 1].
        values = values[:, :3] @ LUMA
        return values / 255.0 if integer else values
    return values[:, 0]


def vertex_weights(mesh: Mesh, attribute: str | None = None) -> np.ndarray | None:
    """Per-asset-vertex weights painted in the mesh file, from the attributes read with it.

    Parameters
    ----------
    mesh : Mesh
        The asset as :func:`crackbake.io.mesh.load_mesh` returned it (its ``attributes`` hold the
        painted values; nothing is read again).
    attribute : str, optional
        Named vertex attribute (a PLY vertex property, or a glTF ``_NAME`` attribute; the
        leading underscore may be left out).  ``None`` reads the vertex colours' luminance.

    Returns
    -------
    (V,) float64 or None
        One weight per vertex of ``mesh``, used as is (1 = full strength; colours map to
        [0, 1]).  ``None`` only when ``attribute`` is ``None`` and the mesh has no vertex
        colours.

    Raises
    ------
    CrackbakeError
        No attribute of that name (the message lists those available), or values that are not
        one finite number per vertex.
    """
    path = Path(mesh.source)
    n = len(mesh.vertices)
    if attribute is None:
        colours = mesh.attributes.get(VERTEX_COLOURS)
        if colours is None:
            if mesh.objects == 1:
                return None
            raise CrackbakeError(
                f"{path}: some objects have no vertex colours; paint all of them or pick "
                "one with --object"
            )
        weights = _to_scalar(colours, n, "vertex colours", path)
    else:
        values = _attribute_values(mesh.attributes, attribute)
        if values is None:
            names = ", ".join(_attribute_names(mesh.attributes)) or "none"
            raise CrackbakeError(f"{path}: no vertex attribute '{attribute}'; available: {names}")
        weights = _to_scalar(values, n, f"attribute '{attribute}'", path)
    if not np.isfinite(weights).all():
        raise CrackbakeError(f"{path}: vertex weights hold NaN or infinite values; fix them")
    return weights
