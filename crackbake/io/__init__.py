"""Reading and writing the pipeline's own inputs and records: asset meshes (with their vertex
attributes, read once), weight images, the ``cracks.json`` sidecar and OBJ polylines.

The names below are imported from their modules on first use (PEP 562): the command's start-up
(``--help``, the output folder's checks through :mod:`crackbake.io.safe_open`) does not load the
mesh readers and numpy.
"""

from __future__ import annotations

import importlib

# name -> the module of this package that defines it
_SOURCES = {
    "Mesh": "mesh",
    "load_mesh": "mesh",
    "load_weight_map": "images",
    "write_obj": "obj_lines",
    "from_dict": "sidecar",
    "read_sidecar": "sidecar",
    "to_dict": "sidecar",
    "write_sidecar": "sidecar",
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
