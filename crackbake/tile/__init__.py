"""Tiling textures, the feature: ``crackbake tile`` grows cracks on a periodic plate and bakes
a texture set that repeats with no seam.

- ``periodic.py``: the periodic plate, its field, the solve, the border split
  (:class:`TileParams`, :func:`build_tile`);
- ``files.py``: the tile's periodic bake and its files;
- ``command.py``: the ``crackbake tile`` command.
"""

from crackbake.tile.periodic import TileParams, build_tile

__all__ = ["TileParams", "build_tile"]
