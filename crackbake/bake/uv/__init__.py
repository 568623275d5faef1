"""The UVs the textures are baked for: checking the asset's own, measuring overlap, unwrapping.

Modules: :mod:`~crackbake.bake.uv.check` (usable? UDIM?), :mod:`~crackbake.bake.uv.overlap`
(GPU overlap fraction), :mod:`~crackbake.bake.uv.unwrap` (xatlas in a child process) with its
:mod:`~crackbake.bake.uv.cache`, and :mod:`~crackbake.bake.uv.prepare` choosing between them.
"""

from crackbake.bake.uv.cache import cache_dir
from crackbake.bake.uv.check import UVCheck, check_uvs
from crackbake.bake.uv.overlap import uv_overlap_fraction
from crackbake.bake.uv.prepare import prepare_uvs
from crackbake.bake.uv.unwrap import unwrap
from crackbake.bake.uv.uvmesh import UVMesh
from crackbake.params import default_padding

__all__ = [
    "UVCheck",
    "UVMesh",
    "cache_dir",
    "check_uvs",
    "default_padding",
    "prepare_uvs",
    "unwrap",
    "uv_overlap_fraction",
]
