"""The sidebar panel: 3D view, tab "Crackbake", for the active mesh object."""

from __future__ import annotations

import bpy

from .ops import _State


class CRACKBAKE_UL_impacts(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_prop, index=0,
                  flt_flag=0):
        # the point itself is the circle drawn in the viewport; the row keeps what is edited
        split = layout.split(factor=0.15, align=True)
        split.label(text=str(index + 1))
        row = split.row(align=True)
        row.prop(item, "radius", text="R")
        row.prop(item, "strength", text="S")


class CRACKBAKE_PT_panel(bpy.types.Panel):
    bl_label = "Crackbake"
    bl_idname = "CRACKBAKE_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Crackbake"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH"

    def draw(self, context):
        obj = context.active_object
        s = obj.crackbake
        layout = self.layout
        col = layout.column()
        # Blender's own panels' layout: labels in a column of their own, not cut short
        col.use_property_split, col.use_property_decorate = True, False
        col.prop(s, "preset")
        col.prop(s, "method")
        row = col.row(align=True)
        row.prop(s, "seed")
        row.operator("crackbake.new_seed", text="", icon="FILE_REFRESH")
        col.prop(s, "res")
        col.prop(s, "min_px")
        col.prop(s, "uv_mode")
        if s.uv_mode == "ACTIVE":
            col.prop_search(s, "uv_map", obj.data, "uv_layers")
        col.prop_search(s, "weight_group", obj, "vertex_groups")
        col.prop(s, "output_dir")

        layout.label(text="Impacts")
        row = layout.row()
        row.template_list("CRACKBAKE_UL_impacts", "", s, "impacts", s, "active_impact", rows=3)
        side = row.column(align=True)
        side.operator("crackbake.place_impact", text="", icon="RESTRICT_SELECT_OFF")
        side.operator("crackbake.add_impact", text="", icon="PIVOT_CURSOR").at_cursor = True
        side.operator("crackbake.remove_impact", text="", icon="REMOVE")

        running = _State.job is not None and _State.obj_name == obj.name
        if running:
            if hasattr(layout, "progress"):  # Blender 4.0+
                layout.progress(factor=s.progress, type="BAR", text=s.status or "baking")
            else:
                layout.prop(s, "progress", text=s.status or "baking", slider=True)
            layout.operator("crackbake.cancel", icon="CANCEL")
        else:
            row = layout.row(align=True)
            row.operator("crackbake.bake", text="Bake", icon="RENDER_STILL")
            row.operator("crackbake.bake", text="Re-bake", icon="FILE_REFRESH").reuse = True
            if s.status:
                layout.label(text=s.status)


class CRACKBAKE_PT_advanced(bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "CRACKBAKE_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Crackbake"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        s = context.active_object.crackbake
        col = self.layout.column()
        col.use_property_split, col.use_property_decorate = True, False
        for name in ("shrink", "noise", "spacing", "curvature", "direction",
                     "direction_strength", "invert_weights", "sim_faces"):
            col.prop(s, name)


CLASSES = (CRACKBAKE_UL_impacts, CRACKBAKE_PT_panel, CRACKBAKE_PT_advanced)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
