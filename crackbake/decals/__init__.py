"""Decals, the feature: a projected decal per impact (``--decal``) and decal libraries
(``crackbake decals``).

- ``projector.py``: the projector over an impact and the crack bake through it;
- ``apply.py``: a decal projected back onto its mesh (what an engine does; the check);
- ``files.py``: ``--decal``'s texture sets and ``decals.json``;
- ``library.py``: a library's variants on a flat plate (:class:`LibraryParams`,
  :func:`build_library`, :func:`plate_mesh`);
- ``atlas.py``: the library's mip-safe atlases, contact sheet, ``decals.json`` and manifest;
- ``command.py``: the ``crackbake decals`` command.
"""

from crackbake.decals.library import LibraryParams, build_library, plate_mesh

__all__ = ["LibraryParams", "build_library", "plate_mesh"]
