"""The operators: impacts, bake (in the background, or blocking for scripts), cancel."""

from __future__ import annotations

import json
import os
import random
import shutil
import tempfile
import time

import bpy
from bpy.props import BoolProperty, FloatProperty, FloatVectorProperty, IntProperty
from mathutils import Vector

from . import export, gltf, nodes, runner, status
from .raycast import object_scale, surface_hit

#: Seconds between two polls of a running bake.
POLL_SECONDS = 0.1
#: The longest poll so far (seconds), for the UI-responsiveness check.
TIMER_STATS = {"calls": 0, "max_s": 0.0}
#: Where the last bake's time went (seconds): export, the crackbake run, loading the result.
LAST_TIMINGS: dict[str, float] = {}
_VERSIONS: dict[str, str] = {}  # command -> version, checked once per session


class _State:
    job: runner.Job | None = None
    obj_name = ""
    out_dir = ""
    uv_name = ""
    unwrap = False


def _prefs(context):
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon else None


def _mesh_object(context, op):
    obj = context.active_object
    if obj is None or obj.type != "MESH":
        what = "no active object" if obj is None else f"the active object '{obj.name}' is a " \
            f"{obj.type.lower()}"
        op.report({"ERROR"}, f"Crackbake: {what}; select a mesh object")
        return None
    return obj


class CRACKBAKE_OT_check_command(bpy.types.Operator):
    """Run the crackbake command with --version"""

    bl_idname = "crackbake.check_command"
    bl_label = "Check the crackbake command"

    def execute(self, context):
        command = _prefs(context).command
        version, problem = runner.check_command(command)
        if problem:
            self.report({"ERROR"}, problem)
            return {"CANCELLED"}
        _VERSIONS[command] = version
        self.report({"INFO"}, f"crackbake {version}")
        return {"FINISHED"}


class CRACKBAKE_OT_add_impact(bpy.types.Operator):
    """Add an impact to the active mesh object (world coordinates and units)"""

    bl_idname = "crackbake.add_impact"
    bl_label = "Add Impact"
    bl_options = {"REGISTER", "UNDO"}

    location: FloatVectorProperty(name="Location", size=3, subtype="XYZ",
                                  description="World-space point on the surface")
    radius: FloatProperty(name="Radius", default=0.0, min=0.0,
                          description="World units; 0 = the preset's default")
    strength: FloatProperty(name="Strength", default=1.0, min=1e-6, max=1e6)
    at_cursor: BoolProperty(name="At the 3D cursor", default=False, options={"SKIP_SAVE"})

    def execute(self, context):
        obj = _mesh_object(context, self)
        if obj is None:
            return {"CANCELLED"}
        point = context.scene.cursor.location if self.at_cursor else self.location
        item = obj.crackbake.impacts.add()
        item.location = obj.matrix_world.inverted_safe() @ Vector(point)
        item.radius = self.radius / object_scale(obj) if self.radius > 0 else 0.0
        item.strength = self.strength
        obj.crackbake.active_impact = len(obj.crackbake.impacts) - 1
        return {"FINISHED"}


class CRACKBAKE_OT_remove_impact(bpy.types.Operator):
    """Remove the selected impact"""

    bl_idname = "crackbake.remove_impact"
    bl_label = "Remove Impact"
    bl_options = {"REGISTER", "UNDO"}

    index: IntProperty(default=-1)

    def execute(self, context):
        obj = _mesh_object(context, self)
        if obj is None:
            return {"CANCELLED"}
        s = obj.crackbake
        i = self.index if self.index >= 0 else s.active_impact
        if 0 <= i < len(s.impacts):
            s.impacts.remove(i)
            s.active_impact = max(0, min(s.active_impact, len(s.impacts) - 1))
        return {"FINISHED"}


class CRACKBAKE_OT_new_seed(bpy.types.Operator):
    """Pick a new random seed"""

    bl_idname = "crackbake.new_seed"
    bl_label = "New Seed"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        obj = _mesh_object(context, self)
        if obj is None:
            return {"CANCELLED"}
        obj.crackbake.seed = random.randrange(0, 2**31 - 1)
        return {"FINISHED"}


class CRACKBAKE_OT_place_impact(bpy.types.Operator):
    """Click on the mesh to add impacts (Esc or right-click ends; navigation passes through)"""

    bl_idname = "crackbake.place_impact"
    bl_label = "Place Impacts"
    bl_options = {"REGISTER", "UNDO"}

    def invoke(self, context, event):
        if context.area is None or context.area.type != "VIEW_3D":
            self.report({"ERROR"}, "Crackbake: place impacts in a 3D view")
            return {"CANCELLED"}
        if _mesh_object(context, self) is None:
            return {"CANCELLED"}
        context.window_manager.modal_handler_add(self)
        status.operator_text(True)
        context.workspace.status_text_set("Crackbake: click on the mesh to add an impact; "
                                          "Esc / right-click: done")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type in {"ESC", "RIGHTMOUSE"}:
            context.workspace.status_text_set(None)
            status.operator_text(False)
            return {"FINISHED"}
        if event.type == "LEFTMOUSE" and event.value == "PRESS":
            from bpy_extras import view3d_utils

            region, rv3d = context.region, context.region_data
            coord = (event.mouse_region_x, event.mouse_region_y)
            origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, coord)
            direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, coord)
            obj = context.active_object
            hit = surface_hit(obj, context.evaluated_depsgraph_get(), origin, direction)
            if hit is not None:
                bpy.ops.crackbake.add_impact(location=hit.world)
            return {"RUNNING_MODAL"}
        return {"PASS_THROUGH"}


def output_folder(obj) -> str:
    """``<output>/<object>/``; a ``//`` folder of an unsaved file goes to the temp folder."""
    base = obj.crackbake.output_dir or "//crackbake/"
    if base.startswith("//") and not bpy.data.filepath:
        base = os.path.join(tempfile.gettempdir(), "crackbake", base[2:])
    return os.path.join(bpy.path.abspath(base), bpy.path.clean_name(obj.name))


def _num(value: float) -> str:
    """A float property as typed (single precision: 0.1, not 0.10000000149011612)."""
    return f"{float(value):.7g}"


def command_line(command: str, obj, mesh_path: str, out_dir: str, cracks: str | None,
                 weight: bool, unwrap: bool = False) -> list[str]:
    s = obj.crackbake
    argv = [*runner.split_command(command), mesh_path, "-o", out_dir, "--target", "blender",
            "--formats", "png,glb" if unwrap else "png", "--res", str(s.res), "--seed",
            str(s.seed), "--min-px", _num(s.min_px), "--method", s.method,
            "--uv", "unwrap" if unwrap else "keep", "--progress", "jsonl"]
    if s.preset:  # with --cracks too: the preset's look draws the cracks
        argv += ["--preset", s.preset]
    if cracks:
        return [*argv, "--cracks", cracks]
    if s.sim_faces > 0:
        argv += ["--sim-faces", str(s.sim_faces)]
    for imp in s.impacts:
        argv += ["--impact", runner.impact_arg(imp.location, imp.radius, imp.strength)]
    if weight:
        argv += ["--weight-attribute", export.WEIGHT_ATTRIBUTE]
        if s.invert_weights:
            argv.append("--invert-weights")
    if s.direction_strength > 0 and any(s.direction):
        x, y, z = s.direction
        argv += ["--direction", f"{_num(x)},{_num(y)},{_num(z)}:{_num(s.direction_strength)}"]
    if s.curvature > 0:
        argv += ["--curvature", _num(s.curvature)]
    for name in ("shrink", "noise", "spacing"):
        if getattr(s, name) > 0:
            argv += [f"--{name}", _num(getattr(s, name))]
    return argv


class CRACKBAKE_OT_bake(bpy.types.Operator):
    """Grow cracks on the active mesh and bake them into its material"""

    bl_idname = "crackbake.bake"
    bl_label = "Bake Cracks"

    wait: BoolProperty(name="Wait", default=False, options={"SKIP_SAVE"},
                       description="Block until the bake ends (scripts)")
    reuse: BoolProperty(name="Re-bake only", default=False, options={"SKIP_SAVE"},
                        description="Re-bake the last crack network (cracks.json) at the "
                        "current resolution, without solving")

    def execute(self, context):
        obj = _mesh_object(context, self)
        if obj is None:
            return {"CANCELLED"}
        if _State.job is not None:
            self.report({"ERROR"}, "Crackbake: a bake is running; cancel it or wait")
            return {"CANCELLED"}
        command = _prefs(context).command
        if command not in _VERSIONS:
            version, problem = runner.check_command(command)
            if problem:
                self.report({"ERROR"}, problem)
                return {"CANCELLED"}
            _VERSIONS[command] = version
        t0 = time.perf_counter()
        s = obj.crackbake
        out_dir = output_folder(obj)
        workdir = tempfile.mkdtemp(prefix="crackbake-")
        try:
            unwrap = s.uv_mode == "UNWRAP"
            if unwrap:
                uv_name = export.UNWRAP_UV
            else:
                uv_name = s.uv_map or (obj.data.uv_layers.active.name
                                       if obj.data.uv_layers.active else "")
            arrays = export.mesh_arrays(obj, context.evaluated_depsgraph_get(),
                                        None if unwrap else uv_name, s.weight_group)
            if unwrap:
                obj.data.calc_loop_triangles()
                base = len(obj.data.loop_triangles)
                if base != arrays["triangles"]:
                    raise export.ExportError(
                        f"'{obj.name}': a new unwrap is stored on the mesh itself, and its "
                        f"modifiers change it ({base} -> {arrays['triangles']} triangles); "
                        "apply them, or bake with a UV map")
            mesh_path = os.path.join(workdir, bpy.path.clean_name(obj.name) + ".ply")
            export.write_ply(mesh_path, arrays)
            cracks = None
            if self.reuse:
                sidecar = os.path.join(out_dir, "cracks.json")
                if not os.path.isfile(sidecar):
                    raise export.ExportError(f"no earlier bake in {out_dir} to re-bake")
                cracks = shutil.copy(sidecar, os.path.join(workdir, "cracks.json"))
            argv = command_line(command, obj, mesh_path, out_dir, cracks, "weight" in arrays,
                                unwrap)
            LAST_TIMINGS.clear()
            LAST_TIMINGS["export"] = time.perf_counter() - t0
            job = runner.Job(argv, workdir).start()
        except (export.ExportError, OSError) as exc:
            shutil.rmtree(workdir, ignore_errors=True)
            self.report({"ERROR"}, f"Crackbake: {exc}")
            return {"CANCELLED"}
        _State.job, _State.obj_name, _State.out_dir, _State.uv_name = job, obj.name, out_dir, \
            uv_name
        _State.unwrap = unwrap
        s.status, s.progress = "starting", 0.0
        status.show("starting", 0.0)
        if self.wait:
            job.wait()
            return self._report(finish())
        bpy.app.timers.register(poll_job, first_interval=POLL_SECONDS)
        return {"FINISHED"}

    def _report(self, outcome: tuple[str, str]):
        level, text = outcome
        self.report({level}, text)
        return {"FINISHED"} if level != "ERROR" else {"CANCELLED"}


class CRACKBAKE_OT_cancel(bpy.types.Operator):
    """Stop the running bake (the last result stays)"""

    bl_idname = "crackbake.cancel"
    bl_label = "Cancel Bake"

    def execute(self, context):
        if _State.job is None:
            self.report({"INFO"}, "Crackbake: no bake is running")
            return {"CANCELLED"}
        _State.job.cancel()
        return {"FINISHED"}


def _settings():
    obj = bpy.data.objects.get(_State.obj_name)
    return obj, (obj.crackbake if obj is not None else None)


def _redraw() -> None:
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def poll_job():
    """The timer: take the bake's new events (never blocks); finish when it has ended."""
    t0 = time.perf_counter()
    job = _State.job
    if job is None:
        return None
    ended = job.poll()
    _obj, s = _settings()
    if s is not None:
        s.progress, s.status = job.fraction, job.message
    status.update(job.message, job.fraction)
    _redraw()
    TIMER_STATS["calls"] += 1
    TIMER_STATS["max_s"] = max(TIMER_STATS["max_s"], time.perf_counter() - t0)
    if not ended:
        return POLL_SECONDS
    level, text = finish()
    print(text)
    return None


def finish() -> tuple[str, str]:
    """Load the result into the scene (or say why not); the temporary folder goes in every
    case.  Returns a report level and line."""
    job, out_dir = _State.job, _State.out_dir
    _State.job = None
    t0 = time.perf_counter()
    obj, s = _settings()
    try:
        if job.summary is None:
            what = "cancelled; the previous result is kept" if job.cancelled else job.error
            if s is not None:
                s.status, s.progress = what, 0.0
            return ("WARNING" if job.cancelled else "ERROR"), f"Crackbake: {what}"
        if obj is None:
            return "ERROR", f"Crackbake: the object '{_State.obj_name}' is gone; the bake is " \
                f"in {out_dir}"
        try:
            with open(os.path.join(out_dir, "manifest.json"), encoding="utf-8") as fh:
                manifest = json.load(fh)
            if _State.unwrap:
                glb = next(f for f in job.summary.get("files", []) if f.endswith(".glb"))
                uv, faces = gltf.read_uv_triangles(os.path.join(out_dir, glb))
                export.store_unwrap(obj.data, uv, faces, export.UNWRAP_UV)
            images = nodes.load_images(obj.name, out_dir, manifest)
            look = manifest.get("params", {}).get("look", {})
            mats = nodes.apply(obj, images, look, _State.uv_name)
        except (OSError, ValueError, RuntimeError, StopIteration, export.ExportError) as exc:
            s.status = f"could not load the result: {exc}"
            return "ERROR", f"Crackbake: could not load the result from {out_dir}: {exc}"
        if not mats:
            s.status = "no Principled BSDF to add the cracks to"
            return "WARNING", (f"Crackbake: the bake is in {out_dir}, but no material of "
                               f"'{obj.name}' has a Principled BSDF to add the cracks to")
        cracks = job.summary.get("cracks", {}).get("cracks", 0)
        s.status, s.progress, s.last_out = f"{cracks} cracks", 1.0, out_dir
        warned = f"; {len(job.warnings)} warning(s): {job.warnings[0]}" if job.warnings else ""
        return ("WARNING" if job.warnings else "INFO"), (
            f"Crackbake: {cracks} cracks baked into {', '.join(mats)}{warned}")
    finally:
        status.hide()
        job.kill()
        job.cleanup()
        LAST_TIMINGS["run"] = job.ended - job.started
        LAST_TIMINGS["finish"] = time.perf_counter() - t0


CLASSES = (CRACKBAKE_OT_check_command, CRACKBAKE_OT_add_impact, CRACKBAKE_OT_remove_impact,
           CRACKBAKE_OT_new_seed, CRACKBAKE_OT_place_impact, CRACKBAKE_OT_bake,
           CRACKBAKE_OT_cancel)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    if _State.job is not None:  # Blender quits or the extension is disabled mid-bake
        job, _State.job = _State.job, None
        job.cancel()
        try:
            job.wait(10)
        except Exception:  # still running after 10 s: stop it outright
            job.kill()
        job.cleanup()
    status.hide()
    if bpy.app.timers.is_registered(poll_job):
        bpy.app.timers.unregister(poll_job)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
