"""Files for other tools: one module per format (EXR, PNG, GLB), the run's set of files and its
manifest.  The output folder they are written into is :mod:`crackbake.transaction`."""

from crackbake.exchange.bundle import write_outputs
from crackbake.exchange.exr import (
    LOSSLESS_COMPRESSIONS,
    LOSSY_COMPRESSIONS,
    read_exr,
    write_exr,
)
from crackbake.exchange.glb import write_glb
from crackbake.exchange.manifest import build_manifest, effective_params, write_manifest
from crackbake.exchange.materials import CRACK_RGB, GLB_TEXTURE_MAX, SURFACE_RGB, base_color
from crackbake.exchange.pngenc import png_bytes
from crackbake.exchange.targets import TARGETS, describe, pack

__all__ = [
    "CRACK_RGB",
    "GLB_TEXTURE_MAX",
    "LOSSLESS_COMPRESSIONS",
    "LOSSY_COMPRESSIONS",
    "SURFACE_RGB",
    "TARGETS",
    "base_color",
    "build_manifest",
    "describe",
    "effective_params",
    "pack",
    "png_bytes",
    "read_exr",
    "write_exr",
    "write_glb",
    "write_manifest",
    "write_outputs",
]
