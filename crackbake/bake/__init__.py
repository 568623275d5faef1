"""Baking: UVs (kept or unwrapped), the headless GL context, the GPU raster of the crack maps.

Names are imported on first use (PEP 562), so ``python -m crackbake.bake.xatlas_worker`` starts
without loading the GL, scipy and mesh modules it does not need.
"""

from importlib import import_module

_EXPORTS = {
    "GLScope": "crackbake.bake.context",
    "create_context": "crackbake.bake.context",
    "renderer_info": "crackbake.bake.context",
    "CrackMaps": "crackbake.bake.raster",
    "bake_cracks": "crackbake.bake.raster",
    "FaceBins": "crackbake.bake.grid",
    "face_bins": "crackbake.bake.grid",
    "dilate": "crackbake.bake.dilation",
    "nearest_island": "crackbake.bake.dilation",
    "preview_direction": "crackbake.bake.preview",
    "render_preview": "crackbake.bake.preview",
    "UVCheck": "crackbake.bake.uv",
    "UVMesh": "crackbake.bake.uv",
    "check_uvs": "crackbake.bake.uv",
    "prepare_uvs": "crackbake.bake.uv",
    "unwrap": "crackbake.bake.uv",
    "uv_overlap_fraction": "crackbake.bake.uv",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'crackbake.bake' has no attribute {name!r}")
