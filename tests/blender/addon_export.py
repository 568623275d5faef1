"""The extension's mesh export (crackbake/blender/addon/export.py) of a moved, scaled cube with
a subdivision modifier and a vertex group: writes the PLY to the path given and prints what
Blender's evaluated mesh holds, for the test to compare with crackbake's own reading."""

import importlib.util
import json
import os
import sys

import bpy
from mathutils import Matrix

spec = importlib.util.spec_from_file_location("export", sys.argv[1])
export = importlib.util.module_from_spec(spec)
sys.modules["export"] = export
spec.loader.exec_module(export)
out_path = sys.argv[2]

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_cube_add(size=2.0, calc_uvs=True)
obj = bpy.context.active_object
obj.matrix_world = Matrix.Translation((5.0, 0.0, 1.0)) @ Matrix.Scale(3.0, 4)
group = obj.vertex_groups.new(name="paint")
group.add([v.index for v in obj.data.vertices if v.co.z > 0], 1.0, "REPLACE")
sub = obj.modifiers.new("subd", "SUBSURF")
sub.levels = 1
bpy.context.view_layer.update()
dg = bpy.context.evaluated_depsgraph_get()
arrays = export.mesh_arrays(obj, dg, "", "paint")
export.write_ply(out_path, arrays)
evaluated = obj.evaluated_get(dg).to_mesh()
evaluated.calc_loop_triangles()
result = {"triangles": len(evaluated.loop_triangles), "vertices": len(evaluated.vertices),
          "co": sorted(tuple(round(c, 5) for c in v.co) for v in evaluated.vertices),
          "written_vertices": len(arrays["vertices"])}
try:
    export.mesh_arrays(obj, dg, "no such map", "")
except export.ExportError as exc:
    result["bad_uv"] = str(exc)
try:
    export.mesh_arrays(obj, dg, "", "no such group")
except export.ExportError as exc:
    result["bad_group"] = str(exc)
print(json.dumps(result))
sys.stdout.flush()
os._exit(0)
