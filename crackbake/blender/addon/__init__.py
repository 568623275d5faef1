"""Crackbake for Blender: grow cracks on the active mesh and bake them into its material.

Installed from the zip ``crackbake blender-addon -o DIR`` writes.  The bpy modules are imported
in :func:`register` only, so ``runner`` and ``raycast`` load (and are tested) without Blender.
"""


def register() -> None:
    from . import ops, props, ui

    props.register()
    ops.register()
    ui.register()


def unregister() -> None:
    from . import ops, props, ui

    ui.unregister()
    ops.unregister()
    props.unregister()
