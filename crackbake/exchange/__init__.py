"""Files for other tools: one module per format (EXR, PNG, GLB), the run's set of files and its
manifest.  The output folder they are written into is :mod:`crackbake.transaction`.

The names below are imported from their modules on first use (PEP 562): ``crackbake inspect``
reads an EXR through :mod:`crackbake.exchange.inspect` without loading the bake that
:mod:`crackbake.exchange.bundle` needs (GL, numba kernels, scipy).
"""

from __future__ import annotations

import importlib

# name -> the module of this package that defines it
_SOURCES = {
    "write_outputs": "bundle",
    "LOSSLESS_COMPRESSIONS": "exr",
    "LOSSY_COMPRESSIONS": "exr",
    "read_exr": "exr",
    "write_exr": "exr",
    "write_glb": "glb",
    "build_manifest": "manifest",
    "effective_params": "manifest",
    "write_manifest": "manifest",
    "CRACK_RGB": "materials",
    "GLB_TEXTURE_MAX": "materials",
    "SURFACE_RGB": "materials",
    "base_color": "materials",
    "png_bytes": "pngenc",
    "TARGETS": "targets",
    "describe": "targets",
    "pack": "targets",
}

__all__ = sorted(_SOURCES)


def __getattr__(name: str):
    module = _SOURCES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
