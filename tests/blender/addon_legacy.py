"""The extension zip as a legacy add-on in a Blender older than 4.2 (Debian's 3.4): install it
with Preferences > Add-ons > Install's operator, enable it, import spot, add an impact, bake
in the background as the panel does (the status bar's line meanwhile), and report the scene.
Run by tests/test_blender_addon.py as ``blender -b --factory-startup --python THIS -- ZIP SPOT
OUT_DIR RES`` with BLENDER_USER_SCRIPTS pointing at an empty folder; prints one JSON line."""

import json
import os
import sys
import time

import bpy

zip_path, spot, out_dir, res = sys.argv[sys.argv.index("--") + 1:][:4]
result = {"version": list(bpy.app.version)}

bpy.ops.wm.read_factory_settings(use_empty=True)
result["installed"] = sorted(bpy.ops.preferences.addon_install(filepath=zip_path))
result["enabled"] = sorted(bpy.ops.preferences.addon_enable(module="crackbake_blender"))
result["addon_dir"] = sorted(os.listdir(os.path.join(bpy.utils.user_resource("SCRIPTS"),
                                                     "addons", "crackbake_blender")))
ops_mod = sys.modules["crackbake_blender.ops"]
status_mod = sys.modules["crackbake_blender.status"]
result["bl_info"] = {k: list(v) if isinstance(v, tuple) else v for k, v in
                     sys.modules["crackbake_blender"].bl_info.items()}

bpy.ops.wm.obj_import(filepath=spot)
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
s = obj.crackbake
s.output_dir = out_dir + os.sep
s.res = int(res)
s.preset = "glass"
s.sim_faces = int(os.environ.get("CRACKBAKE_TEST_SIM_FACES", "0"))
point = obj.matrix_world @ min(obj.data.vertices, key=lambda v: v.co.x).co
result["impact_world"] = list(point)
result["add_impact"] = sorted(bpy.ops.crackbake.add_impact(location=point, radius=0.3))
result["impacts"] = [list(i.location) for i in s.impacts]

result["bake"] = sorted(bpy.ops.crackbake.bake())
lines = []
end = time.monotonic() + 500
while ops_mod._State.job is not None and time.monotonic() < end:
    job = ops_mod._State.job
    again = ops_mod.poll_job()
    if again is not None:
        lines.append({"line": status_mod.STATE["line"], "shown": status_mod.is_shown(),
                      "message": job.message, "fraction": job.fraction})
        time.sleep(ops_mod.POLL_SECONDS)
result["status_bar"] = lines
result["status_bar_after"] = [status_mod.STATE["line"], status_mod.is_shown()]
result["status"] = s.status

tree = obj.active_material.node_tree
node = tree.nodes.get("Crackbake Cracks")
bsdf = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
result["group"] = node.node_tree.name if node else None
result["linked"] = {k: bsdf.inputs[k].is_linked and bsdf.inputs[k].links[0].from_node == node
                    for k in ("Base Color", "Roughness", "Normal")}
result["images"] = {n.name: [n.image.colorspace_settings.name, list(n.image.size)]
                    for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage" and n.image}
with open(os.path.join(s.last_out, "cracks.json")) as fh:
    result["sidecar_impacts"] = [i["point"] for i in json.load(fh)["impacts"]]
print(json.dumps(result))
sys.stdout.flush()
os._exit(0)
