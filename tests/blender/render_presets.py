"""Render crackbake GLBs of one mesh in Blender (Cycles, CPU), each alone, same camera and light.

Usage: ``python render_presets.py OUT_DIR SIZE VX VY VZ TX TY TZ WIDTH GLB...`` under a Python
with ``bpy``.  Writes ``OUT_DIR/<glb stem>.png`` (SIZE pixels square) per GLB.  VX, VY, VZ is
the view direction in the GLB's own (glTF, Y-up) frame, from the camera towards the mesh; the
orthographic camera looks at TX, TY, TZ (glTF frame) and shows WIDTH mesh units across.  One
sun lights it from about 20 degrees above the surfaces the camera faces, from the side (a
grazing light: grooves show their lit and shadowed walls), with a dim world for the shadows.
Prints a JSON line with the files written.
"""

import json
import sys
from pathlib import Path

import bpy
from mathutils import Vector

out_dir = Path(sys.argv[1])
size = int(sys.argv[2])
gx, gy, gz = map(float, sys.argv[3:6])
tx, ty, tz = map(float, sys.argv[6:9])
width = float(sys.argv[9])
glbs = sys.argv[10:]
target = Vector((tx, -tz, ty))
view = Vector((gx, -gz, gy)).normalized()  # glTF Y-up -> Blender Z-up
written = []
for glb in glbs:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
    corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
    radius = max((c - target).length for c in corners)
    scene = bpy.context.scene
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = width
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    cam.location = target - view * 4 * radius
    cam.rotation_euler = view.to_track_quat("-Z", "Z").to_euler()
    scene.camera = cam
    # The sun: mostly across the view (from the camera's right, a little above), 20 degrees
    # above the surfaces that face the camera.
    right = view.cross(Vector((0, 0, 1))).normalized()
    to_light = (right * 0.8 + Vector((0, 0, 0.6))).normalized()
    to_light = (to_light * 0.94 - view * 0.34).normalized()
    sun_data = bpy.data.lights.new("sun", "SUN")
    sun_data.energy = 3.0
    sun_data.angle = 0.02
    sun = bpy.data.objects.new("sun", sun_data)
    scene.collection.objects.link(sun)
    sun.rotation_euler = (-to_light).to_track_quat("-Z", "Y").to_euler()
    world = bpy.data.worlds.new("w")
    world.color = (0.035, 0.037, 0.045)
    scene.world = world
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 24
    scene.cycles.use_denoising = True
    scene.render.film_transparent = False
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.view_settings.view_transform = "Standard"
    path = out_dir / f"{Path(glb).stem}.png"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    written.append(str(path))
print(json.dumps({"written": written}))
