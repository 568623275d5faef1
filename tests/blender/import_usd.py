"""Import a crackbake USD layer with Blender's USD importer and report what it bound.

Usage: ``python import_usd.py IN.usda [OUT.png]`` under a Python with ``bpy``.  Prints a JSON
line: for each Principled BSDF input that is linked, the image feeding it (through a Normal Map
or Separate Color node) with its colour space and the node's channel; the UV maps; the mesh's
world bounding box (Blender is Z-up: the importer converts a Y-up stage).  With OUT.png, renders
the object with Cycles (CPU, 16 samples) from a three-quarter view under a sun.
"""

import json
import sys

import bpy
from mathutils import Vector

path = sys.argv[1]
out = sys.argv[2] if len(sys.argv) > 2 else None

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=path)
obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
mat = obj.active_material
bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")


def upstream(socket):
    """The image node feeding ``socket`` (through normal-map / separate nodes), the output
    socket name and the nodes passed (``TYPE.output``)."""
    passed = []
    link = socket.links[0]
    while True:
        node = link.from_node
        if node.type == "TEX_IMAGE":
            return node, link.from_socket.name, passed
        passed.append(f"{node.type}.{link.from_socket.name}")
        inputs = [i for i in node.inputs if i.is_linked]
        if not inputs:
            return None, None, passed
        link = inputs[-1].links[0] if node.type == "NORMAL_MAP" else inputs[0].links[0]


bound = {}
for inp in bsdf.inputs:
    if not inp.is_linked:
        continue
    node, channel, passed = upstream(inp)
    bound[inp.name] = {
        "image": node.image.filepath if node else None,
        "colorspace": node.image.colorspace_settings.name if node else None,
        "socket": channel,
        "via": passed,
    }

corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box]
lo = [min(c[i] for c in corners) for i in range(3)]
hi = [max(c[i] for c in corners) for i in range(3)]
result = {
    "bound": bound,
    "uv_maps": [uv.name for uv in obj.data.uv_layers],
    "faces": len(obj.data.polygons),
    "bbox": [lo, hi],
    "images_found": {i.filepath: i.has_data or i.size[0] > 0 for i in bpy.data.images},
}

if out:
    centre = (Vector(lo) + Vector(hi)) / 2
    size = max((Vector(hi) - Vector(lo)).length, 1e-6)
    cam_data = bpy.data.cameras.new("cam")
    cam_data.lens = 50
    cam = bpy.data.objects.new("cam", cam_data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = centre + Vector((1.2, -1.6, 0.9)).normalized() * size * 1.5
    cam.rotation_euler = (centre - cam.location).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = cam
    sun_data = bpy.data.lights.new("sun", "SUN")
    sun_data.energy = 3.0
    sun = bpy.data.objects.new("sun", sun_data)
    bpy.context.scene.collection.objects.link(sun)
    sun.rotation_euler = Vector((-0.6, 0.5, -1.0)).to_track_quat("-Z", "Y").to_euler()
    world = bpy.data.worlds.new("w")
    world.color = (0.2, 0.2, 0.22)
    scene = bpy.context.scene
    scene.world = world
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.render.resolution_x = scene.render.resolution_y = 640
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    result["out"] = out

print(json.dumps(result))
