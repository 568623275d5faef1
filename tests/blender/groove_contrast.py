"""Measure how the grooves of a crackbake GLB read under one grazing light in Cycles.

Usage: ``python groove_contrast.py IN.glb OUT.png X Y Z [SIZE] [RES]`` under a Python with
``bpy``.  X, Y, Z is a point on the surface in the GLB's own (glTF, Y-up) coordinates; an
orthographic camera looks at it along its surface normal (view SIZE mesh units wide, default
0.35; RES pixels square, default 256) and one sun lights it from 19 degrees above the surface.

Three renders of the same view: the picture (Cycles, 16 samples, Standard view transform,
written to OUT.png), the shading normal with the GLB's normal map, and the smooth normal without
it (both as emission, 1 sample).  A pixel is a groove wall when the normal map tilts it by more
than 6 degrees; it faces the light when that tilt points towards the sun (tangential
components), away when it points the other way.  Prints one JSON line: ``contrast`` = mean
display brightness (Rec. 709 luma of the 8-bit sRGB picture, 0..1) of the lit walls minus that
of the shadowed walls, the two means, the open surface's mean (no tilt) and the pixel counts.
"""

import json
import sys
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector

glb, out = sys.argv[1], sys.argv[2]
x, y, z = map(float, sys.argv[3:6])
size = float(sys.argv[6]) if len(sys.argv) > 6 else 0.35
res = int(sys.argv[7]) if len(sys.argv) > 7 else 256

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=glb)
obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
target = Vector((x, -z, y))  # glTF Y-up -> Blender Z-up
best = min(obj.data.vertices, key=lambda v: (obj.matrix_world @ v.co - target).length)
target = obj.matrix_world @ best.co
normal = (obj.matrix_world.to_3x3() @ best.normal).normalized()

scene = bpy.context.scene
cam_data = bpy.data.cameras.new("cam")
cam_data.type = "ORTHO"
cam_data.ortho_scale = size
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
cam.location = target + normal * 2.0
cam.rotation_euler = (-normal).to_track_quat("-Z", "Y").to_euler()
scene.camera = cam

side = normal.cross(Vector((0, 0, 1)))
side = side.normalized() if side.length > 1e-6 else Vector((1, 0, 0))
to_light = (normal * 0.35 + side).normalized()
sun_data = bpy.data.lights.new("sun", "SUN")
sun_data.energy = 4.0
sun_data.angle = 0.01
sun = bpy.data.objects.new("sun", sun_data)
scene.collection.objects.link(sun)
sun.rotation_euler = (-to_light).to_track_quat("-Z", "Y").to_euler()

world = bpy.data.worlds.new("w")
world.color = (0.05, 0.05, 0.06)
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.render.resolution_x = scene.render.resolution_y = res
scene.view_settings.view_transform = "Standard"
scene.view_settings.look = "None"


def render(path: str, samples: int) -> np.ndarray:
    scene.cycles.samples = samples
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(res, res, 4)[..., :3]


scene.render.image_settings.file_format = "PNG"
scene.render.image_settings.color_depth = "8"
picture = render(out, 16)
luma = picture @ np.array([0.2126, 0.7152, 0.0722], np.float32)

# The normal passes: the material's output replaced by an emission of n * 0.5 + 0.5.
mat = obj.active_material
nodes, links = mat.node_tree.nodes, mat.node_tree.links
bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
mapped = bsdf.inputs["Normal"].links[0].from_socket if bsdf.inputs["Normal"].is_linked else None
geometry = nodes.new("ShaderNodeNewGeometry")
encode = nodes.new("ShaderNodeVectorMath")
encode.operation = "MULTIPLY_ADD"
encode.inputs[1].default_value = (0.5, 0.5, 0.5)
encode.inputs[2].default_value = (0.5, 0.5, 0.5)
emit = nodes.new("ShaderNodeEmission")
links.new(encode.outputs[0], emit.inputs["Color"])
links.new(emit.outputs[0], output.inputs["Surface"])
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filter_size = 0.01
tmp = Path(out).with_suffix("")
normals = {}
for name, socket in (("mapped", mapped or geometry.outputs["Normal"]),
                     ("smooth", geometry.outputs["Normal"])):
    links.new(socket, encode.inputs[0])
    normals[name] = render(f"{tmp}_{name}.exr", 1) * 2.0 - 1.0
    Path(f"{tmp}_{name}.exr").unlink()

n, s = normals["mapped"], normals["smooth"]
covered = np.linalg.norm(s, axis=-1) > 0.5
s = s / np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-9)
tilt = n - s * np.sum(n * s, axis=-1, keepdims=True)
light = np.array(to_light, np.float32)
light_t = light - s * (s @ light)[..., None]
light_t /= np.maximum(np.linalg.norm(light_t, axis=-1, keepdims=True), 1e-9)
toward = np.sum(tilt * light_t, axis=-1)
sin_tilt = np.linalg.norm(tilt, axis=-1)
wall = covered & (sin_tilt > np.sin(np.radians(6.0)))
lit, shadowed = wall & (toward > 0), wall & (toward < 0)
flat = covered & (sin_tilt < np.sin(np.radians(0.5)))


def mean(sel):
    return float(luma[sel].mean()) if sel.any() else float("nan")


print(json.dumps({
    "contrast": mean(lit) - mean(shadowed), "lit": mean(lit), "shadowed": mean(shadowed),
    "open": mean(flat), "lit_px": int(lit.sum()), "shadowed_px": int(shadowed.sum()),
    "open_px": int(flat.sum()), "out": out,
}))
