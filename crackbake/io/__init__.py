"""Reading and writing the pipeline's own inputs and records: asset meshes (with their vertex
attributes, read once), weight images, the ``cracks.json`` sidecar and OBJ polylines."""

# mesh first: the sidecar modules import crackbake.network, which imports crackbake.io.mesh.
from crackbake.io.mesh import Mesh, load_mesh  # isort: skip
from crackbake.io.images import load_weight_map
from crackbake.io.obj_lines import write_obj
from crackbake.io.sidecar import from_dict, read_sidecar, to_dict, write_sidecar

__all__ = [
    "Mesh",
    "from_dict",
    "load_mesh",
    "load_weight_map",
    "read_sidecar",
    "to_dict",
    "write_obj",
    "write_sidecar",
]
