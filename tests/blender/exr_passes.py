"""Blender's view of a multilayer EXR: every render layer's passes, their types and pixels.

Usage: ``python exr_passes.py FILE.exr OUTDIR`` under an interpreter with ``bpy``.  Loads the
file as an image, lists the render layers and passes the compositor's Image node offers (with
the socket type Blender gives each pass: VALUE, VECTOR or RGBA) and writes each pass through its
own File Output node as a 32-bit float multilayer EXR ``OUTDIR/<layer>__<pass>.exr``, so the
caller can compare the values Blender decoded with the values written.  Prints one JSON object.
"""

import ast
import json
import re
import sys
from pathlib import Path

import bpy

SOCKET = {"VALUE": "FLOAT", "VECTOR": "VECTOR", "RGBA": "RGBA"}


def _layer_names(node) -> list[str]:
    """The render layers the Image node offers for its multilayer image.

    The ``layer`` enum is filled at run time, so ``enum_items`` shows only a placeholder; the
    error for an impossible value lists the real items.
    """
    try:
        node.layer = "\x01 no such layer"
    except TypeError as exc:
        found = re.search(r"not found in \((.*)\)", str(exc))
        if found:
            return [ast.literal_eval(x.strip()) for x in found.group(1).split(",") if x.strip()]
    raise RuntimeError("could not list the image's render layers")


def main(src: str, out_dir: str) -> dict:
    image = bpy.data.images.load(src)
    scene = bpy.context.scene
    tree = bpy.data.node_groups.new("exr_passes", "CompositorNodeTree")
    scene.compositing_node_group = tree
    probe = tree.nodes.new("CompositorNodeImage")
    probe.image = image
    layers = _layer_names(probe)
    result = {"image_type": image.type, "layers": layers, "passes": []}
    # The passes are written at the image's own size (the render size only matters to nodes
    # without an image input), so it is left alone.
    for layer in layers:
        node = tree.nodes.new("CompositorNodeImage")
        node.image = image
        node.layer = layer
        for socket in node.outputs:
            if not socket.enabled:
                continue
            # One File Output node per pass: a node with several inputs wrote only its first
            # input to the multilayer file (measured with bpy 5.0.1).
            out = tree.nodes.new("CompositorNodeOutputFile")
            out.directory = out_dir + "/"
            out.file_name = f"{layer}__{socket.name}"
            out.format.media_type = "MULTI_LAYER_IMAGE"
            out.format.file_format = "OPEN_EXR_MULTILAYER"
            out.format.color_depth = "32"
            out.format.exr_codec = "ZIP"
            item = out.file_output_items.new(SOCKET[socket.type], socket.name)
            tree.links.new(socket, out.inputs[item.name])
            result["passes"].append(
                {
                    "layer": layer,
                    "pass": socket.name,
                    "type": socket.type,
                    "file": str(Path(out_dir) / f"{layer}__{socket.name}.exr"),
                }
            )
    # No Render Layers node: the render runs only the compositor.
    bpy.ops.render.render(write_still=False)
    return result


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], sys.argv[2])))
