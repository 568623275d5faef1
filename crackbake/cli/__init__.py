"""The ``crackbake`` command line: :data:`main`, a group whose default command is the bake.

- ``group.py``: the group (routes ``crackbake NAME ...`` to a command, anything else to the bake);
- ``bake.py``: ``crackbake MESH``: parses the options into :class:`crackbake.params.RunParams`
  and calls :func:`crackbake.pipeline.run`;
- ``inspect.py``: ``crackbake inspect FILE.exr``;
- ``common.py``: what the commands share (one-line errors, reporting).

``crackbake decals`` and ``crackbake tile`` live with their features
(:mod:`crackbake.decals.command`, :mod:`crackbake.tile.command`).
"""

from crackbake.cli.group import main

__all__ = ["main"]
