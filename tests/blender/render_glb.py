"""Render a crackbake GLB in Blender (Cycles, CPU) to check how its maps read in a real client.

Usage: ``python render_glb.py IN.glb OUT.png X Y Z [SIZE]`` under a Python with ``bpy``.
X, Y, Z is a point on the surface in the GLB's own (glTF, Y-up) coordinates; the camera looks
at it along its surface normal from a distance of SIZE (default 0.6) with a grazing sun, so
grooves from the normal map show.  Prints a JSON line with the material's bound inputs.
"""

import json
import sys

import bpy
from mathutils import Vector

glb, out = sys.argv[1], sys.argv[2]
x, y, z = map(float, sys.argv[3:6])
size = float(sys.argv[6]) if len(sys.argv) > 6 else 0.6

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=glb)
obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
target = Vector((x, -z, y))  # glTF Y-up -> Blender Z-up
mesh = obj.data
best = min(mesh.vertices, key=lambda v: (obj.matrix_world @ v.co - target).length)
normal = (obj.matrix_world.to_3x3() @ best.normal).normalized()

cam_data = bpy.data.cameras.new("cam")
cam_data.type = "ORTHO"
cam_data.ortho_scale = size
cam = bpy.data.objects.new("cam", cam_data)
bpy.context.scene.collection.objects.link(cam)
cam.location = target + normal * 2.0
cam.rotation_euler = (-normal).to_track_quat("-Z", "Y").to_euler()
bpy.context.scene.camera = cam

sun_data = bpy.data.lights.new("sun", "SUN")
sun_data.energy = 4.0
sun = bpy.data.objects.new("sun", sun_data)
bpy.context.scene.collection.objects.link(sun)
side = normal.cross(Vector((0, 0, 1)))
side = side.normalized() if side.length > 1e-6 else Vector((1, 0, 0))
sun.rotation_euler = (-(normal * 0.35 + side)).normalized().to_track_quat("-Z", "Y").to_euler()

world = bpy.data.worlds.new("w")
world.color = (0.05, 0.05, 0.06)
bpy.context.scene.world = world
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 16
scene.render.resolution_x = scene.render.resolution_y = 640
scene.render.filepath = out
bpy.ops.render.render(write_still=True)

bsdf = next(n for n in obj.active_material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
linked = sorted(i.name for i in bsdf.inputs if i.is_linked)
print(json.dumps({"linked": linked, "out": out}))
