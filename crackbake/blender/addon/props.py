"""The extension's settings: the preferences (the crackbake command) and, on each object and
saved in the .blend, its impacts and bake options."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from . import defaults


def _help(option: str, fallback: str = "") -> str:
    return defaults.HELP.get(option, fallback)


class CrackbakePreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    command: StringProperty(
        name="crackbake command",
        description="How to run crackbake: its path, or 'PYTHON -m crackbake' (filled in by "
        "crackbake blender-addon with the environment that built this extension)",
        default=defaults.COMMAND,
    )

    def draw(self, context):
        self.layout.prop(self, "command")
        self.layout.operator("crackbake.check_command")


class CrackbakeImpact(bpy.types.PropertyGroup):
    location: FloatVectorProperty(name="Location", size=3, subtype="XYZ",
                                  description="Impact point, object space")
    radius: FloatProperty(name="Radius", min=0.0, default=0.0, precision=4,
                          description="Impact radius, object units; 0 = the preset's ("
                          + _help("impacts") + ")")
    strength: FloatProperty(name="Strength", min=1e-6, max=1e6, default=1.0)


def _presets(_self, _context):
    return [("", "(none)", "No preset: the solver's defaults")] + [
        (p, p, f"the {p} preset (crackbake --preset {p})") for p in defaults.PRESETS]


class CrackbakeSettings(bpy.types.PropertyGroup):
    impacts: CollectionProperty(type=CrackbakeImpact)
    active_impact: IntProperty(default=0)
    preset: EnumProperty(name="Preset", items=_presets, description=_help("preset"))
    method: EnumProperty(name="Method", items=[(m, m, m) for m in defaults.METHODS],
                         description=_help("method"))
    seed: IntProperty(name="Seed", default=0, min=0, description=_help("seed"))
    res: IntProperty(name="Resolution", default=2048, min=64, max=16384,
                     description=_help("res"))
    min_px: FloatProperty(name="Min px", default=1.0, min=0.0, description=_help("min_px"))
    uv_mode: EnumProperty(name="UVs", items=[
        ("ACTIVE", "UV map", "Bake for the object's UV map (the one named below, or the "
         "active one)"),
        ("UNWRAP", "New unwrap", "Unwrap with xatlas (crackbake --uv unwrap) and store the "
         "result as the UV map 'crackbake'"),
    ], default="ACTIVE")
    uv_map: StringProperty(name="UV map", description="UV map the maps are baked for (empty: "
                           "the active one)")
    weight_group: StringProperty(name="Weights", description="Vertex group multiplying the "
                                 "stress field (" + _help("weight_attribute") + ")")
    shrink: FloatProperty(name="Shrink", default=0.0, min=0.0, description=_help("shrink"))
    noise: FloatProperty(name="Noise", default=0.0, min=0.0, description=_help("noise"))
    spacing: FloatProperty(name="Spacing", default=0.0, min=0.0, max=1.0,
                           description=_help("spacing") + " (0: the preset's)")
    invert_weights: BoolProperty(name="Invert weights", default=False,
                                 description=_help("invert_weights"))
    direction: FloatVectorProperty(name="Direction", size=3, subtype="XYZ",
                                   default=(0.0, 0.0, 1.0),
                                   description=_help("directions") + " Object space")
    direction_strength: FloatProperty(name="Direction strength", default=0.0, min=0.0,
                                      description="Strength of the directional tension "
                                      "(0: none)")
    curvature: FloatProperty(name="Curvature bias", default=0.0, min=0.0,
                             description=_help("curvature") + " (0: none)")
    sim_faces: IntProperty(name="Sim faces", default=0, min=0,
                           description=_help("sim_faces") + " (0: the default)")
    output_dir: StringProperty(name="Output", subtype="DIR_PATH", default="//crackbake/",
                               description="Folder of the bakes; each object's go in a "
                               "sub-folder named after it")
    # what the last bake said (shown in the panel)
    status: StringProperty(default="")
    progress: FloatProperty(default=0.0, min=0.0, max=1.0)
    last_out: StringProperty(default="")


CLASSES = (CrackbakePreferences, CrackbakeImpact, CrackbakeSettings)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.crackbake = PointerProperty(type=CrackbakeSettings)


def unregister() -> None:
    del bpy.types.Object.crackbake
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
