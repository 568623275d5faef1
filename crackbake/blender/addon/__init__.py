"""Crackbake for Blender: grow cracks on the active mesh and bake them into its material.

Installed from the zip ``crackbake blender-addon -o DIR`` writes.  The bpy modules are imported
in :func:`register` only, so ``runner`` and ``raycast`` load (and are tested) without Blender.
"""


def register() -> None:
    from . import draw, ops, props, ui

    props.register()
    ops.register()
    ui.register()
    draw.register()


def unregister() -> None:
    from . import draw, ops, props, ui

    draw.unregister()
    ui.unregister()
    ops.unregister()
    props.unregister()
