"""Panels: Shader Editor sidebar tab "Skin SSS" and Material properties."""

from __future__ import annotations

import os

import bpy

from . import preferences


def _draw(layout, context) -> None:
    model = preferences.model_path(context)
    box = layout.box()
    if os.path.isfile(model):
        box.label(text=f"Model: {os.path.basename(model)}", icon="CHECKMARK")
    else:
        box.label(text="Model not found: train/export it", icon="ERROR")
        box.label(text=model)
    layout.operator("spectral_skin.invert_albedo", icon="IMAGE_DATA")
    layout.operator("spectral_skin.add_mixture", icon="NODETREE")


class SPECTRAL_SKIN_PT_shader_editor(bpy.types.Panel):
    bl_label = "Spectral Skin SSS"
    bl_space_type = "NODE_EDITOR"
    bl_region_type = "UI"
    bl_category = "Skin SSS"

    @classmethod
    def poll(cls, context):
        return getattr(context.space_data, "tree_type", "") == "ShaderNodeTree"

    def draw(self, context):
        _draw(self.layout, context)


class SPECTRAL_SKIN_PT_material(bpy.types.Panel):
    bl_label = "Spectral Skin SSS"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw(self, context):
        _draw(self.layout, context)


classes = (SPECTRAL_SKIN_PT_shader_editor, SPECTRAL_SKIN_PT_material)
