"""crackbake: grow crack patterns on a triangle mesh and bake them into textures.

The pipeline is a chain of small stages with plain data between them::

    mesh.load_mesh -> uv.prepare_uvs -> network (sidecar / solver) -> bake.bake_cracks -> export

``crackbake.pipeline.run`` chains them exactly as the ``crackbake`` command does.
"""

__version__ = "0.1.0"

from crackbake.errors import CrackbakeError  # noqa: E402

__all__ = ["CrackbakeError", "__version__"]
