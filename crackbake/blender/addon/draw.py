"""Each impact of the active object drawn in the 3D view as a circle of its radius on the
surface."""

from __future__ import annotations

import bpy

from .raycast import impact_circles

COLOUR = (1.0, 0.45, 0.1, 1.0)
_handle = None
_cache: dict = {"key": None, "circles": []}


def _key(obj) -> tuple:
    # the circles change with the impacts, the object's placement and its mesh
    impacts = tuple((tuple(i.location), i.radius) for i in obj.crackbake.impacts)
    return (obj.name, impacts, tuple(map(tuple, obj.matrix_world)), len(obj.data.vertices))


def _draw() -> None:
    obj = bpy.context.active_object
    if obj is None or obj.type != "MESH" or not len(obj.crackbake.impacts):
        return
    try:
        import gpu
        from gpu_extras.batch import batch_for_shader

        key = _key(obj)
        if key != _cache["key"]:  # closest-point queries only when something moved
            _cache["key"], _cache["circles"] = key, impact_circles(obj)
        try:
            shader = gpu.shader.from_builtin("POLYLINE_UNIFORM_COLOR")
        except ValueError:  # Blender < 4.0's name
            shader = gpu.shader.from_builtin("3D_POLYLINE_UNIFORM_COLOR")
        region = bpy.context.region
        shader.uniform_float("viewportSize", (region.width, region.height))
        shader.uniform_float("lineWidth", 2.0)
        shader.uniform_float("color", COLOUR)
        for points in _cache["circles"]:
            batch_for_shader(shader, "LINE_STRIP", {"pos": points}).draw(shader)
    except Exception as exc:  # a drawing problem must not flood the console at every redraw
        print(f"Crackbake: cannot draw the impacts ({exc})")
        unregister()


def register() -> None:
    global _handle
    if _handle is None and not bpy.app.background:
        _handle = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW")


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
