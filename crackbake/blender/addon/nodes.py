"""The result in the scene: the baked images (right colour spaces) and the "Crackbake Cracks"
node group spliced into the object's own material(s) between their inputs and the BSDF.

The group is one shared function of its inputs (no images inside): each material holds its own
image nodes feeding it, so several objects share one group and re-baking only reloads images.
"""

from __future__ import annotations

import os

import bpy

GROUP = "Crackbake Cracks"
NODE = "Crackbake Cracks"  # the group node's name in a material
#: The PNGs of ``--target blender`` the material reads: content -> (file suffix, node name).
IMAGES = {"data": "_data.png", "normal": "_normal.png", "occlusion": "_ao.png"}
SPACES = {"linear": "Non-Color", "sRGB": "sRGB"}

_IN = [("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat"),
       ("Normal", "NodeSocketVector"), ("Growth", "NodeSocketFloat"),
       ("Crack Data", "NodeSocketColor"), ("Crack Time", "NodeSocketFloat"),
       ("Crack Normal", "NodeSocketVector"), ("Crack Occlusion", "NodeSocketColor"),
       ("Crack Color", "NodeSocketColor"), ("Crack Roughness", "NodeSocketFloat"),
       ("Multiply", "NodeSocketFloat")]
_OUT = [("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat"),
        ("Normal", "NodeSocketVector")]


def srgb_to_linear(c: float) -> float:
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def _sock(sockets, identifier: str):
    return next(s for s in sockets if s.identifier == identifier)


def _mix(nodes, kind: str, blend: str = "MIX"):
    node = nodes.new("ShaderNodeMix")
    node.data_type = kind
    if kind == "RGBA":
        node.blend_type = blend
    return node


def _math(nodes, op: str, b: float | None = None):
    node = nodes.new("ShaderNodeMath")
    node.operation = op
    if b is not None:
        node.inputs[1].default_value = b
    return node


def _new_socket(group, name: str, in_out: str, kind: str):
    """A group input or output socket (Blender 4.0+'s interface, or 3.x's inputs/outputs)."""
    if hasattr(group, "interface"):
        return group.interface.new_socket(name, in_out=in_out, socket_type=kind)
    return (group.inputs if in_out == "INPUT" else group.outputs).new(kind, name)


def crack_group() -> bpy.types.ShaderNodeTree:
    """The shared "Crackbake Cracks" group, built on first use.

    ``visible = mask * (time < Growth) * (Growth > 0)``: the cracks grow out of the impacts as
    ``Growth`` goes 0 -> 1, the rule of ``examples/shaders/``.  Base colour is mixed towards
    Crack Color (or multiplied by it, Multiply = 1) by ``visible`` and multiplied by the baked
    occlusion where grown; roughness is mixed towards Crack Roughness, the normal towards the
    crack normal (the material's own normal elsewhere)."""
    group = bpy.data.node_groups.get(GROUP)
    if group is not None and group.bl_idname == "ShaderNodeTree":
        return group
    group = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
    for name, kind in _IN:
        sock = _new_socket(group, name, "INPUT", kind)
        if name in ("Growth", "Multiply"):
            sock.min_value, sock.max_value = 0.0, 1.0
        if name == "Growth":
            sock.default_value = 1.0
    for name, kind in _OUT:
        _new_socket(group, name, "OUTPUT", kind)
    nodes, link = group.nodes, group.links.new
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-900, 0), (700, 0)

    split = nodes.new("ShaderNodeSeparateColor")
    link(gin.outputs["Crack Data"], split.inputs["Color"])
    lead = _math(nodes, "ADD", 1e-4)  # the last texels (time 1) show at Growth 1
    link(gin.outputs["Growth"], lead.inputs[0])
    before = _math(nodes, "LESS_THAN")
    link(gin.outputs["Crack Time"], before.inputs[0])
    link(lead.outputs[0], before.inputs[1])
    started = _math(nodes, "GREATER_THAN", 0.0)
    link(gin.outputs["Growth"], started.inputs[0])
    grown = _math(nodes, "MULTIPLY")
    link(before.outputs[0], grown.inputs[0])
    link(started.outputs[0], grown.inputs[1])
    visible = _math(nodes, "MULTIPLY")
    link(split.outputs["Red"], visible.inputs[0])
    link(grown.outputs[0], visible.inputs[1])

    tinted = _mix(nodes, "RGBA")
    multiplied = _mix(nodes, "RGBA", "MULTIPLY")
    for node in (tinted, multiplied):
        link(visible.outputs[0], _sock(node.inputs, "Factor_Float"))
        link(gin.outputs["Base Color"], _sock(node.inputs, "A_Color"))
        link(gin.outputs["Crack Color"], _sock(node.inputs, "B_Color"))
    mode = _mix(nodes, "RGBA")
    link(gin.outputs["Multiply"], _sock(mode.inputs, "Factor_Float"))
    link(_sock(tinted.outputs, "Result_Color"), _sock(mode.inputs, "A_Color"))
    link(_sock(multiplied.outputs, "Result_Color"), _sock(mode.inputs, "B_Color"))
    shade = _mix(nodes, "RGBA", "MULTIPLY")
    link(grown.outputs[0], _sock(shade.inputs, "Factor_Float"))
    link(_sock(mode.outputs, "Result_Color"), _sock(shade.inputs, "A_Color"))
    link(gin.outputs["Crack Occlusion"], _sock(shade.inputs, "B_Color"))
    link(_sock(shade.outputs, "Result_Color"), gout.inputs["Base Color"])

    rough = _mix(nodes, "FLOAT")
    link(visible.outputs[0], _sock(rough.inputs, "Factor_Float"))
    link(gin.outputs["Roughness"], _sock(rough.inputs, "A_Float"))
    link(gin.outputs["Crack Roughness"], _sock(rough.inputs, "B_Float"))
    link(_sock(rough.outputs, "Result_Float"), gout.inputs["Roughness"])

    normal = _mix(nodes, "VECTOR")
    link(visible.outputs[0], _sock(normal.inputs, "Factor_Float"))
    link(gin.outputs["Normal"], _sock(normal.inputs, "A_Vector"))
    link(gin.outputs["Crack Normal"], _sock(normal.inputs, "B_Vector"))
    unit = nodes.new("ShaderNodeVectorMath")
    unit.operation = "NORMALIZE"
    link(_sock(normal.outputs, "Result_Vector"), unit.inputs[0])
    link(unit.outputs["Vector"], gout.inputs["Normal"])
    for i, node in enumerate(n for n in nodes if n not in (gin, gout)):
        node.location = (-600 + 220 * (i // 4), 300 - 200 * (i % 4))
    return group


def load_images(obj_name: str, out_dir: str, manifest: dict) -> dict[str, bpy.types.Image]:
    """The bake's images, each in the colour space the manifest names (data maps Non-Color).

    An image of an earlier bake of the object is pointed at the new file and reloaded: no
    ``.001`` duplicates."""
    textures = manifest.get("maps", {}).get("textures", {}).get("files", {})
    images = {}
    for content, suffix in IMAGES.items():
        name = next((f for f, t in textures.items() if t.get("content") == content), None)
        if name is None:
            raise RuntimeError(f"the bake wrote no {content} map (files: {sorted(textures)})")
        path = os.path.join(out_dir, name)
        key = f"{obj_name}{suffix}"
        image = bpy.data.images.get(key)
        if image is None:
            image = bpy.data.images.load(path)
            image.name = key
        else:
            image.filepath = path
            image.reload()
        image.colorspace_settings.name = SPACES.get(textures[name].get("colorspace"), "Non-Color")
        if content == "data":
            image.alpha_mode = "CHANNEL_PACKED"  # A is crack time, not coverage
        images[content] = image
    return images


def _principled(tree) -> list:
    return [n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"]


def materials_of(obj) -> list[bpy.types.Material]:
    """The object's materials; an object without one gets a Principled material."""
    mats = [s.material for s in obj.material_slots if s.material is not None]
    if mats:
        return mats
    mat = bpy.data.materials.new(f"{obj.name} Crackbake")
    mat.use_nodes = True
    obj.data.materials.append(mat)
    return [mat]


def _source(tree, socket):
    """What feeds ``socket`` (then unlinked), or None."""
    if not socket.is_linked:
        return None
    link = socket.links[0]
    src = link.from_socket
    tree.links.remove(link)
    return src


def apply(obj, images: dict, look: dict, uv_name: str) -> list[str]:
    """Splice the group into every Principled BSDF of the object's materials (once: a later
    call only updates the look and images); the names of the materials touched (one without a
    Principled BSDF is left as it is)."""
    group = crack_group()
    colour = [srgb_to_linear(c / 255.0) for c in look.get("color", (40, 36, 32))] + [1.0]
    done = []
    for mat in materials_of(obj):
        if mat.node_tree is None:
            mat.use_nodes = True
        tree = mat.node_tree
        for i, bsdf in enumerate(_principled(tree)):
            suffix = "" if i == 0 else f".{i}"
            node = tree.nodes.get(NODE + suffix)
            if node is None:
                for stale in [n for n in tree.nodes if n.name.startswith(f"{NODE}{suffix} ")]:
                    tree.nodes.remove(stale)  # helpers left when the group node was deleted
                node = _splice(tree, bsdf, group, NODE + suffix, uv_name)
            node.inputs["Crack Color"].default_value = colour
            node.inputs["Crack Roughness"].default_value = float(look.get("roughness", 1.0))
            node.inputs["Multiply"].default_value = float(look.get("mode") == "multiply")
            for content, image in images.items():
                tree.nodes[f"{NODE}{suffix} {content}"].image = image
            uvmap = tree.nodes[f"{NODE}{suffix} uv"]
            uvmap.uv_map = uv_name
            tree.nodes[f"{NODE}{suffix} normal map"].uv_map = uv_name
            if mat.name not in done:
                done.append(mat.name)
    return done


def _splice(tree, bsdf, group, name: str, uv_name: str):
    nodes, link = tree.nodes, tree.links.new
    node = nodes.new("ShaderNodeGroup")
    node.node_tree, node.name, node.label = group, name, GROUP
    x, y = bsdf.location
    node.location = (x - 260, y)
    for sock in ("Base Color", "Roughness"):
        src = _source(tree, bsdf.inputs[sock])
        if src is not None:
            link(src, node.inputs[sock])
        else:
            value = bsdf.inputs[sock].default_value
            node.inputs[sock].default_value = value[:] if hasattr(value, "__len__") else value
    src = _source(tree, bsdf.inputs["Normal"])
    if src is None:  # an unlinked group input is (0, 0, 0): feed the shading normal
        geometry = nodes.new("ShaderNodeNewGeometry")
        geometry.location = (x - 520, y + 300)
        src = geometry.outputs["Normal"]
    link(src, node.inputs["Normal"])
    for sock in ("Base Color", "Roughness", "Normal"):
        link(node.outputs[sock], bsdf.inputs[sock])

    uv = nodes.new("ShaderNodeUVMap")
    uv.name, uv.location = f"{name} uv", (x - 1000, y - 300)
    textures = {}
    for i, content in enumerate(IMAGES):
        tex = nodes.new("ShaderNodeTexImage")
        tex.name, tex.label = f"{name} {content}", f"crack {content}"
        tex.location = (x - 780, y - 250 - 280 * i)
        link(uv.outputs["UV"], tex.inputs["Vector"])
        textures[content] = tex
    nmap = nodes.new("ShaderNodeNormalMap")
    nmap.name, nmap.space, nmap.uv_map = f"{name} normal map", "TANGENT", uv_name
    nmap.location = (x - 520, y - 520)
    link(textures["data"].outputs["Color"], node.inputs["Crack Data"])
    link(textures["data"].outputs["Alpha"], node.inputs["Crack Time"])
    link(textures["normal"].outputs["Color"], nmap.inputs["Color"])
    link(nmap.outputs["Normal"], node.inputs["Crack Normal"])
    link(textures["occlusion"].outputs["Color"], node.inputs["Crack Occlusion"])
    return node
