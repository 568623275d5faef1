"""The README's screenshot of the panel (benchmarks/blender_screenshot.py runs this in a real
Blender window under Xvfb): install the zip as a legacy add-on (Blender < 4.2), import spot, add
an impact with the operator, bake in the background as the panel does (screenshots during it:
the status bar's line), then the panel and the result in material preview (final.png).

argv after ``--``: ZIP SPOT OUT_DIR SHOTS_DIR RES.  XDO: ';'-separated xdotool commands run one
per timer step before the bake (the click on the sidebar's Crackbake tab: Blender 3.4 has no
Python API for the active tab).  Progress in SHOTS_DIR/log.json."""
import json
import os
import sys
import time

import bpy

zip_path, spot, out_dir, shots, res = sys.argv[sys.argv.index("--") + 1:]
log = {"blender": bpy.app.version_string}


def say(**kw):
    log.update(kw)
    with open(os.path.join(shots, "log.json"), "w") as fh:
        json.dump(log, fh, indent=1, default=str)


r = bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
say(installed=sorted(r))
r = bpy.ops.preferences.addon_enable(module="crackbake_blender")
say(enabled=sorted(r), addons=sorted(a.module for a in bpy.context.preferences.addons))
ops_mod = sys.modules["crackbake_blender.ops"]
status_mod = sys.modules["crackbake_blender.status"]

for o in list(bpy.data.objects):
    bpy.data.objects.remove(o)
bpy.ops.wm.obj_import(filepath=spot)
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
bpy.ops.object.shade_smooth()
mat = bpy.data.materials.new("spot paint")
mat.use_nodes = True
bsdf = mat.node_tree.nodes["Principled BSDF"]
bsdf.inputs["Base Color"].default_value = (0.55, 0.42, 0.30, 1.0)
bsdf.inputs["Roughness"].default_value = 0.5
obj.data.materials.clear()
obj.data.materials.append(mat)
s = obj.crackbake
s.output_dir = out_dir + os.sep
s.res = int(res)
s.preset = os.environ.get("PRESET", "crackle")
s.seed = 7
say(bbox=[list(obj.matrix_world @ __import__("mathutils").Vector(c)) for c in obj.bound_box])

win = bpy.context.window_manager.windows[0]
area = next(a for a in win.screen.areas if a.type == "VIEW_3D")
space = area.spaces.active
region = next(rg for rg in area.regions if rg.type == "WINDOW")
space.show_region_ui = True
space.shading.type = "MATERIAL"
space.overlay.show_floor = True
space.overlay.show_cursor = False


def frame():
    with bpy.context.temp_override(window=win, area=area, region=region):
        bpy.ops.view3d.view_selected()


# an impact on spot's side facing the viewer: the surface point nearest a point in front
def impact():
    from mathutils import Vector
    rv3d = space.region_3d
    view_dir = rv3d.view_rotation @ Vector((0.0, 0.0, -1.0))
    centre = sum((obj.matrix_world @ Vector(c) for c in obj.bound_box), Vector()) / 8
    origin = centre - 10.0 * view_dir + Vector((0.0, 0.0, 0.15))
    hit = sys.modules["crackbake_blender.raycast"].surface_hit(
        obj, bpy.context.evaluated_depsgraph_get(), origin, view_dir)
    say(hit=None if hit is None else hit.world)
    with bpy.context.temp_override(window=win, area=area, region=region):
        r = bpy.ops.crackbake.add_impact(location=hit.world, radius=0.0, strength=1.0)
    say(add_impact=sorted(r), impacts=[list(i.location) for i in s.impacts])


steps = {"n": 0, "t0": 0.0, "during": []}


def shot(name):
    path = os.path.join(shots, name)
    with bpy.context.temp_override(window=win, area=area):
        bpy.ops.screen.screenshot(filepath=path)
    return path


def step():
    n = steps["n"]
    steps["n"] += 1
    try:
        if n == 0:
            frame()
            return 1.0
        if n == 1:
            shot("pre.png")
            say(regions=[[rg.type, rg.x, rg.y, rg.width, rg.height] for rg in area.regions],
                area=[area.x, area.y, area.width, area.height])
        actions = [a.split() for a in os.environ.get("XDO", "").split(";") if a.strip()]
        if 1 <= n <= len(actions):
            import subprocess
            r = subprocess.run(["xdotool", *actions[n - 1]], capture_output=True, text=True)
            say(**{f"xdo{n}": [actions[n - 1], r.returncode, r.stderr]})
            return 0.7
        if n == len(actions) + 1:
            obj.select_set(False)
            shot("pre2.png")
        if n == max(2, len(actions) + 1):
            impact()
            for rg in area.regions:
                if rg.type == "UI":
                    try:
                        rg.active_panel_category = "Crackbake"
                        say(tab="set")
                    except Exception as exc:  # noqa
                        say(tab=str(exc))
            with bpy.context.temp_override(window=win, area=area, region=region):
                r = bpy.ops.crackbake.bake()
            steps["t0"] = time.time()
            say(bake=sorted(r), job=ops_mod._State.job is not None,
                status_line=status_mod.STATE["line"], shown=status_mod.is_shown())
            return 1.5
        if ops_mod._State.job is not None:
            k = len(steps["during"])
            if k < 4:
                steps["during"].append({"line": status_mod.STATE["line"],
                                        "shown": status_mod.is_shown(),
                                        "shot": shot(f"during{k}.png")})
                say(during=steps["during"])
            return 2.0
        if "done" not in log:
            say(done=time.time() - steps["t0"], status=s.status, shown_after=status_mod.is_shown(),
                line_after=status_mod.STATE["line"], timer=ops_mod.TIMER_STATS)
            frame()
            from mathutils import Vector
            rv3d = space.region_3d
            hit = Vector(log["hit"])
            rv3d.view_location = rv3d.view_location.lerp(hit, 0.5)
            rv3d.view_distance *= float(os.environ.get("ZOOM", "0.95"))
            return 30.0
        if "final0" not in log:
            say(final0=shot("final0.png"))
            return 30.0
        shot("final.png")
        say(final=True)
        bpy.ops.wm.quit_blender()
        return None
    except Exception as exc:  # noqa
        import traceback
        say(error=traceback.format_exc())
        bpy.ops.wm.quit_blender()
        return None


bpy.app.timers.register(step, first_interval=2.0)
