"""The click operator's ray-cast helper (crackbake/blender/addon/raycast.py) on a moved,
rotated, scaled cube: a hit from outside, a miss, a back face from inside.  Prints JSON."""

import importlib.util
import json
import os
import sys

import bpy
from mathutils import Matrix, Vector

spec = importlib.util.spec_from_file_location("raycast", sys.argv[1])
raycast = importlib.util.module_from_spec(spec)
sys.modules["raycast"] = raycast  # dataclasses look their module up
spec.loader.exec_module(raycast)

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_cube_add(size=2.0)  # object space: [-1, 1]^3
obj = bpy.context.active_object
obj.matrix_world = (Matrix.Translation((3.0, 1.0, -2.0)) @ Matrix.Rotation(0.5, 4, "Z")
                    @ Matrix.Scale(0.5, 4))
bpy.context.view_layer.update()
dg = bpy.context.evaluated_depsgraph_get()
centre = obj.matrix_world.translation
out = {"scale": raycast.object_scale(obj)}
# from +X of the cube's own frame towards its centre: hits the +X face at object x = 1
axis = obj.matrix_world.to_3x3() @ Vector((1.0, 0.0, 0.0))
origin = centre + 5.0 * axis.normalized()
hit = raycast.surface_hit(obj, dg, origin, -axis)
out["hit"] = None if hit is None else {"world": list(hit.world), "local": list(hit.local),
                                       "normal": list(hit.normal), "face": hit.face}
out["expected_world"] = list(obj.matrix_world @ Vector((1.0, 0.0, 0.0)))
out["expected_normal"] = list(axis.normalized())
# a ray passing beside the cube
out["miss"] = raycast.surface_hit(obj, dg, origin + 10.0 * (obj.matrix_world.to_3x3()
                                  @ Vector((0.0, 0.0, 1.0))), -axis)
# from the centre outwards: the first face is seen from inside (a back face)
out["inside"] = raycast.surface_hit(obj, dg, centre, axis)
# an impact's circle: every point at the radius from the centre, in the plane normal to n
n = Vector((1.0, 2.0, 2.0)) / 3.0
pts = [Vector(p) for p in raycast.circle_points((1.0, -1.0, 0.5), n, 0.3, segments=16)]
out["circle"] = {"count": len(pts), "closed": (pts[0] - pts[-1]).length,
                 "radii": [(p - Vector((1.0, -1.0, 0.5))).length for p in pts],
                 "along_normal": [(p - Vector((1.0, -1.0, 0.5))).dot(n) for p in pts]}
print(json.dumps(out, default=str))
sys.stdout.flush()
os._exit(0)
