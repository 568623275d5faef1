"""crackbake: grow crack patterns on a triangle mesh and bake them into textures.

The pipeline is a chain of small stages with plain data between them::

    io.mesh.load_mesh -> simulate (sim mesh, stress, solver) or io.sidecar.read_sidecar
      -> network.CrackNetwork -> bake.uv.prepare_uvs -> bake.raster.bake_cracks
      -> exchange (EXR, PNG, GLB, sidecar, manifest)

``crackbake.pipeline.run`` chains them exactly as the ``crackbake`` command does.
"""

__version__ = "0.1.0"

from crackbake.errors import CrackbakeError  # noqa: E402

__all__ = ["CrackbakeError", "__version__"]
