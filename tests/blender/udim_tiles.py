"""Open a crackbake UDIM set in Blender: as a tiled image, and through the USD importer.

Usage: ``python udim_tiles.py TILE.1001.png [IN.usda]`` under a Python with ``bpy``.  Prints a
JSON line: the tiled image's tiles (number, size); with IN.usda, the images the imported
material's nodes read, with their source (``TILED`` for a UDIM set) and tile numbers, and the
largest imported UV.
"""

import json
import sys

import bpy

path = sys.argv[1]
usd = sys.argv[2] if len(sys.argv) > 2 else None

bpy.ops.wm.read_factory_settings(use_empty=True)
image = bpy.data.images.load(path)
image.source = "TILED"  # Blender finds the set's other tiles from the .1001 name
tiles = [{"number": t.number, "size": list(t.size)} for t in image.tiles]
result = {"tiles": tiles, "filepath": image.filepath}

if usd:
    bpy.ops.wm.usd_import(filepath=usd)
    obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
    nodes = obj.active_material.node_tree.nodes
    result["usd_images"] = {
        n.image.filepath.rsplit("/", 1)[-1]: {
            "source": n.image.source,
            "tiles": sorted(t.number for t in n.image.tiles),
        }
        for n in nodes
        if n.type == "TEX_IMAGE" and n.image is not None
    }
    uv = obj.data.uv_layers[0].data
    result["uv_max"] = [max(p.uv[0] for p in uv), max(p.uv[1] for p in uv)]

print(json.dumps(result))
