"""The Blender extension that drives crackbake (``crackbake blender-addon -o DIR``).

- ``addon/``: the extension's own sources, run inside Blender 4.2+ (pure Python: it runs the
  ``crackbake`` command as a subprocess and reads its ``--progress jsonl`` stream);
  ``addon/runner.py`` and ``addon/raycast.py``'s maths import no ``bpy``;
- ``build.py``: the ``crackbake blender-addon`` command, which zips ``addon/`` with its
  ``blender_manifest.toml`` (version = crackbake's) and a ``defaults.py`` pre-filling the
  preferences with this environment's command, the presets and the CLI's own help texts.
"""
