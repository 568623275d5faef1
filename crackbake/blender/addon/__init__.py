"""Crackbake for Blender: grow cracks on the active mesh and bake them into its material.

Installed from the zip ``crackbake blender-addon -o DIR`` writes.  The bpy modules are imported
in :func:`register` only, so ``runner`` and ``raycast`` load (and are tested) without Blender.

The same zip is an extension for Blender 4.2+ (``blender_manifest.toml``, which makes 4.2+
ignore ``bl_info``) and a legacy add-on for older Blenders (``bl_info``; tested with 3.4):
Preferences > Add-ons > Install.  ``crackbake blender-addon`` writes crackbake's version into
both.
"""

bl_info = {
    "name": "Crackbake",
    "author": "crackbake developers",
    "version": (0, 0, 0),
    "blender": (3, 4, 0),
    "location": "3D View > Sidebar > Crackbake",
    "description": "Grow cracks on a mesh and bake them into its material",
    "category": "Material",
}


def register() -> None:
    try:
        import numpy  # noqa: F401  (the mesh export's arrays)
    except ImportError:
        raise ImportError("Crackbake needs numpy in Blender's Python: blender.org's builds "
                          "have it; Debian's blender package needs 'apt install python3-numpy'"
                          ) from None
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
