"""Install the crackbake extension zip into a clean user profile, bake spot through it, and
report what the scene holds.  Run by tests/test_blender_addon.py under Blender's Python with
BLENDER_USER_RESOURCES pointing at an empty folder.

Arguments: ZIP SPOT OUT_DIR RES MODE, MODE one of
``bake`` (transform spot, two impacts, a vertex group, bake, re-bake at another resolution),
``cancel`` (bake in the background, poll as Blender's timer does, cancel mid-run),
``errors`` (a non-mesh active object, a wrong crackbake command).
"""

import json
import os
import sys
import time

import bpy
from mathutils import Matrix, Vector

zip_path, spot, out_dir, res, mode = sys.argv[1:6]
result = {}

bpy.ops.wm.read_factory_settings(use_empty=True)
installed = bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True)
result["installed"] = sorted(installed)
module = "bl_ext.user_default.crackbake"
result["enabled"] = module in bpy.context.preferences.addons
ops_mod = sys.modules[module + ".ops"]
status_mod = sys.modules[module + ".status"]
prefs = bpy.context.preferences.addons[module].preferences
result["command"] = prefs.command

bpy.ops.wm.obj_import(filepath=spot, forward_axis="NEGATIVE_Z", up_axis="Y")
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
# the importer's axis change, then a rotation, a scale and a move
obj.matrix_world = (Matrix.Translation((1.5, -2.0, 0.25)) @ Matrix.Rotation(0.7, 4, "Z")
                    @ Matrix.Scale(2.0, 4) @ obj.matrix_world)
bpy.context.view_layer.update()
s = obj.crackbake
s.output_dir = out_dir + os.sep
s.res = int(res)
s.preset = "glass"
s.seed = 3
s.sim_faces = int(os.environ.get("CRACKBAKE_TEST_SIM_FACES", "0"))
# the artist's own material: a blue, fairly smooth Principled BSDF
mat = bpy.data.materials.new("artist")
mat.use_nodes = True
bsdf = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
bsdf.inputs["Base Color"].default_value = (0.2, 0.4, 0.8, 1.0)
bsdf.inputs["Roughness"].default_value = 0.35
obj.data.materials.clear()
obj.data.materials.append(mat)

# two impacts on the surface, clicked in world space: vertices of spot's flank and back
local = [Vector((0.334, 0.044, 0.287)), Vector((-0.25, 0.35, -0.05))]
me = obj.data
picked = []
for p in local:
    v = min(me.vertices, key=lambda v: (v.co - p).length)
    picked.append(v.co.copy())
result["impacts_local"] = [list(p) for p in picked]
for p in picked:
    bpy.ops.crackbake.add_impact(location=obj.matrix_world @ p, radius=2.0 * 0.12, strength=1.0)
result["stored"] = [list(i.location) for i in s.impacts]
result["stored_radius"] = [i.radius for i in s.impacts]
result["impacts_world"] = [list(obj.matrix_world @ p) for p in picked]
result["circles"] = sys.modules[module + ".raycast"].impact_circles(obj)


def material_state():
    mat = obj.active_material
    tree = mat.node_tree
    node = tree.nodes.get("Crackbake Cracks")
    bsdf = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    linked = {sock: bsdf.inputs[sock].is_linked and
              bsdf.inputs[sock].links[0].from_node == node for sock in
              ("Base Color", "Roughness", "Normal")}
    images = {n.name: {"image": n.image.name, "space": n.image.colorspace_settings.name,
                       "file": os.path.basename(n.image.filepath),
                       "size": list(n.image.size)}
              for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage" and n.image}
    kept = {k: list(node.inputs[k].default_value)[:3] if k == "Base Color"
            else node.inputs[k].default_value for k in ("Base Color", "Roughness")}
    return {"material": mat.name, "group": node.node_tree.name if node else None,
            "kept": kept, "materials": sorted(m.name for m in bpy.data.materials),
            "linked": linked, "images": images,
            "groups": sorted(g.name for g in bpy.data.node_groups),
            "all_images": sorted(i.name for i in bpy.data.images)}


def cycles_albedo(size):
    """Mean albedo luminance Cycles bakes on the texels where the crack mask (box-filtered to
    ``size``) is > 0.25 and where it is 0 (inside the UV islands)."""
    import numpy as np

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1
    tree = obj.active_material.node_tree
    image = bpy.data.images.new("albedo check", size, size, float_buffer=True)
    target = tree.nodes.new("ShaderNodeTexImage")
    target.image = image
    tree.nodes.active = target  # Cycles bakes into the material's active image node
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.ops.object.bake(type="DIFFUSE", pass_filter={"COLOR"}, margin=0, use_clear=True)
    albedo = np.array(image.pixels[:]).reshape(size, size, 4)
    tree.nodes.remove(target)
    bpy.data.images.remove(image)
    data = tree.nodes["Crackbake Cracks data"].image
    w, h = data.size
    mask = np.array(data.pixels[:]).reshape(h, w, 4)[..., 0]
    mask = mask.reshape(size, h // size, size, w // size).mean(axis=(1, 3))
    lum = albedo[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    inside = albedo[..., :3].sum(axis=-1) > 0
    crack, intact = inside & (mask > 0.25), inside & (mask == 0)
    return {"crack": float(lum[crack].mean()), "intact": float(lum[intact].mean()),
            "crack_texels": int(crack.sum()), "intact_texels": int(intact.sum()),
            "intact_rgb": albedo[intact][:, :3].mean(axis=0).tolist()}


def poll_until_done(cancel_at=None):
    """Call the extension's timer function as Blender's timer would, timing each call; what
    the status bar showed at each call, and after the bake."""
    job = ops_mod._State.job
    times, cancelled_at, lines = [], None, []
    end = time.monotonic() + 500
    while ops_mod._State.job is not None and time.monotonic() < end:
        t = time.perf_counter()
        again = ops_mod.poll_job()
        times.append(time.perf_counter() - t)
        if again is not None:
            lines.append({"line": status_mod.STATE["line"], "shown": status_mod.is_shown(),
                          "message": job.message, "fraction": job.fraction})
        if cancel_at and cancelled_at is None and job.message.startswith(cancel_at):
            cancelled_at = job.message
            bpy.ops.crackbake.cancel()
        if again is None:
            break
        time.sleep(ops_mod.POLL_SECONDS)
    # the last call loads the result (the bake has ended); the others ran beside it
    return {"polls": len(times), "max_poll_s": max(times[:-1]), "finish_s": times[-1],
            "slowest": sorted(times[:-1])[-5:], "cancelled_at": cancelled_at,
            "workdir_left": os.path.exists(job.workdir), "status": s.status,
            "status_bar": lines, "final_fraction": job.fraction,
            "summary_read": job.summary is not None, "status_bar_after": {
                "line": status_mod.STATE["line"], "shown": status_mod.is_shown(),
                "in_header": status_mod.draw in bpy.types.STATUSBAR_HT_header._dyn_ui_initialize()}}


if mode == "bake":
    group = obj.vertex_groups.new(name="stress")
    group.add([v.index for v in me.vertices if v.co.z > 0], 1.0, "REPLACE")
    s.weight_group = "stress"
    t = time.perf_counter()
    r = bpy.ops.crackbake.bake(wait=True)
    result["bake"] = sorted(r)
    result["bake_s"] = time.perf_counter() - t
    result["status"] = s.status
    result["out"] = s.last_out
    result["first"] = material_state()
    with open(os.path.join(s.last_out, "cracks.json")) as fh:
        result["sidecar_impacts"] = json.load(fh)["impacts"]
    with open(os.path.join(s.last_out, "manifest.json")) as fh:
        result["params"] = json.load(fh)["params"]
    # Cycles' own evaluation of the material: the albedo baked into a 128² image, compared on
    # the mask's crack texels and off them, fully grown and at Growth 0
    node = obj.active_material.node_tree.nodes["Crackbake Cracks"]
    result["albedo_grown"] = cycles_albedo(128)
    node.inputs["Growth"].default_value = 0.0
    result["albedo_ungrown"] = cycles_albedo(128)
    node.inputs["Growth"].default_value = 1.0
    # growth is animatable
    result["keyframed"] = node.inputs["Growth"].keyframe_insert("default_value", frame=1)
    result["status_bar_after_wait"] = [status_mod.STATE["line"], status_mod.is_shown()]
    # re-bake the same network at another resolution, in the background as the panel does
    # (the status bar shows it meanwhile): the images are replaced in place
    s.res = int(res) // 2
    r = bpy.ops.crackbake.bake(reuse=True)
    result["rebake_started"] = [status_mod.STATE["line"], status_mod.is_shown()]
    result["rebake_run"] = poll_until_done()
    result["rebake"] = sorted(r)
    result["rebake_status"] = s.status
    result["second"] = material_state()
    with open(os.path.join(s.last_out, "manifest.json")) as fh:
        result["rebake_params"] = json.load(fh)["params"]
elif mode == "unwrap":
    import numpy as np
    from mathutils.geometry import barycentric_transform

    s.uv_mode = "UNWRAP"
    # a mesh with a subdivision modifier cannot keep a new unwrap: refused, with the fix
    sub = obj.modifiers.new("subd", "SUBSURF")
    try:
        bpy.ops.crackbake.bake(wait=True)
        result["modifier"] = "no error"
    except RuntimeError as exc:
        result["modifier"] = str(exc)
    obj.modifiers.remove(sub)
    while me.uv_layers:  # spot without UVs: unwrapped by crackbake
        me.uv_layers.remove(me.uv_layers[0])
    result["bake"] = sorted(bpy.ops.crackbake.bake(wait=True))
    result["uv_layers"] = [layer.name for layer in me.uv_layers]
    tree = obj.active_material.node_tree
    result["uv_nodes"] = sorted({n.uv_map for n in tree.nodes
                                 if n.bl_idname in ("ShaderNodeUVMap", "ShaderNodeNormalMap")})
    # each crack point of the sidecar, through its face's "crackbake" UVs, onto the mask: it
    # lands on a crack (and with v flipped it would not)
    with open(os.path.join(s.last_out, "cracks.json")) as fh:
        cracks = json.load(fh)["cracks"]
    data = tree.nodes["Crackbake Cracks data"].image
    w, h = data.size
    mask = np.array(data.pixels[:]).reshape(h, w, 4)[..., 0]
    layer = me.uv_layers["crackbake"]
    me.calc_loop_triangles()
    on, flipped, total = 0, 0, 0
    for crack in cracks:
        for point, face in zip(crack["points"], crack["faces"], strict=True):
            tri = me.loop_triangles[face]
            corners = [me.vertices[i].co for i in tri.vertices]
            uvs = [Vector((*layer.uv[i].vector, 0.0)) for i in tri.loops]
            uv = barycentric_transform(Vector(point), *corners, *uvs)
            x = min(max(int(uv.x * w), 0), w - 1)
            y = min(max(int(uv.y * h), 0), h - 1)
            on += mask[y, x] > 0.1
            flipped += mask[h - 1 - y, x] > 0.1
            total += 1
    result["on_crack"], result["on_flipped"], result["points"] = int(on), int(flipped), total
    result["state"] = material_state()
elif mode in ("cancel", "background"):
    if mode == "cancel":
        result["first"] = sorted(bpy.ops.crackbake.bake(wait=True))
        with open(os.path.join(s.last_out, "manifest.json")) as fh:
            before = fh.read()
        s.sim_faces, s.seed = 0, 4  # a longer solve, to cancel
        result["bake"] = sorted(bpy.ops.crackbake.bake())
        result["run"] = poll_until_done(cancel_at="growing cracks")
        with open(os.path.join(s.last_out, "manifest.json")) as fh:
            result["manifest_kept"] = fh.read() == before
    else:
        result["bake"] = sorted(bpy.ops.crackbake.bake())
        t = time.perf_counter()
        result["run"] = poll_until_done()
        result["bake_s"] = time.perf_counter() - t
    result["state"] = material_state()
elif mode == "errors":
    bpy.ops.object.camera_add()
    camera = bpy.context.active_object
    try:
        bpy.ops.crackbake.bake(wait=True)
        result["camera"] = "no error"
    except RuntimeError as exc:
        result["camera"] = str(exc)
    bpy.context.view_layer.objects.active = obj
    # crackbake's own one-line error, as the operator's report; the scene is left as it was
    bpy.ops.crackbake.add_impact(location=obj.matrix_world @ Vector((100.0, 100.0, 100.0)))
    try:
        bpy.ops.crackbake.bake(wait=True)
        result["crackbake_error"] = "no error"
    except RuntimeError as exc:
        result["crackbake_error"] = str(exc)
    result["groups_after_error"] = sorted(g.name for g in bpy.data.node_groups)
    s.impacts.remove(len(s.impacts) - 1)
    # every panel setting reaches the command line
    s.weight_group, s.invert_weights = "", True
    s.direction, s.direction_strength, s.curvature = (0.0, 1.0, 0.0), 1.5, 0.5
    s.shrink, s.noise, s.spacing, s.sim_faces, s.method = 0.25, 0.1, 0.05, 5000, "thesis"
    result["argv"] = ops_mod.command_line("crackbake", obj, "m.ply", "out", None, True)
    prefs.command = "/nonexistent/crackbake"
    try:
        bpy.ops.crackbake.bake(wait=True)
        result["wrong_command"] = "no error"
    except RuntimeError as exc:
        result["wrong_command"] = str(exc)

result["tmp_left"] = sorted(n for n in os.listdir(os.environ.get("TMPDIR", "/tmp"))
                            if n.startswith("crackbake-"))
print(json.dumps(result))
sys.stdout.flush()
os._exit(0)  # bpy's atexit handlers can hang a headless interpreter
