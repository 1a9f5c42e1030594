"""Operators: Invert Skin Albedo (bake) and Add Skin SSS Mixture (node group into the active material)."""

from __future__ import annotations

import os

import bpy

from exporters import maps

from . import nodes, preferences


def _missing_model_message(path: str) -> str:
    return f"model not found at {path}: train/export it or set the path in preferences"


class SPECTRAL_SKIN_OT_invert_albedo(bpy.types.Operator):
    """Invert an RGB skin albedo texture into per-component subsurface maps (needs the trained model)"""

    bl_idname = "spectral_skin.invert_albedo"
    bl_label = "Invert Skin Albedo"
    bl_options = {"REGISTER"}

    filepath: bpy.props.StringProperty(name="Albedo image", subtype="FILE_PATH", default="")
    output_dir: bpy.props.StringProperty(name="Output folder", subtype="DIR_PATH", default="")
    colorspace: bpy.props.EnumProperty(
        name="Colour space",
        items=[("auto", "Auto", "sRGB unless the file says linear/Non-Color or stores floats"),
               ("srgb", "sRGB", "sRGB-encoded"), ("linear", "Linear", "Linear sRGB / Rec.709")],
        default="auto",
    )
    overwrite: bpy.props.BoolProperty(name="Overwrite", default=False)

    def execute(self, context):
        model = preferences.model_path(context)
        if not os.path.isfile(model):
            self.report({"ERROR"}, _missing_model_message(model))
            return {"CANCELLED"}
        if not self.filepath:
            self.report({"ERROR"}, "no albedo image given")
            return {"CANCELLED"}
        try:
            albedo = maps.read_albedo(bpy.path.abspath(self.filepath), colorspace=self.colorspace)
        except (OSError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        try:
            from exporters import inference  # written once a model exists (SPEC §3)
        except ImportError:
            self.report({"ERROR"}, "exporters.inference is not available in this build: cannot run the model")
            return {"CANCELLED"}
        result = inference.bake_cycles_maps(  # pragma: no cover - needs the trained model
            model, albedo, bpy.path.abspath(self.output_dir), unit_scale_m=context.scene.unit_settings.scale_length,
            threads=preferences.threads(context), overwrite=self.overwrite)
        self.report({"INFO"}, f"wrote {len(result)} maps")
        return {"FINISHED"}


class SPECTRAL_SKIN_OT_add_mixture(bpy.types.Operator):
    """Add the Spectral Skin SSS Mixture node group to the active material (existing nodes are kept)"""

    bl_idname = "spectral_skin.add_mixture"
    bl_label = "Add Skin SSS Mixture"
    bl_options = {"REGISTER", "UNDO"}

    components: bpy.props.IntProperty(name="Components (K)", default=3, min=1, max=7)
    backend: bpy.props.EnumProperty(
        name="Backend",
        items=[("SVM", "SVM (all devices)", "3K single-channel Subsurface Scattering nodes"),
               ("OSL", "OSL (CPU/OptiX)", "One OSL Script node with K bssrdf closures")],
        default="SVM",
    )

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.active_material is not None

    def execute(self, context):
        mat = context.object.active_material
        if self.backend == "OSL":
            group = nodes.build_osl_group(self.components)
            context.scene.cycles.shading_system = True
        else:
            group = nodes.build_svm_group(self.components)
        nodes.wire_into_material(mat, group)
        self.report({"INFO"}, f"added {group.name} (K={self.components}) to {mat.name}")
        return {"FINISHED"}


classes = (SPECTRAL_SKIN_OT_invert_albedo, SPECTRAL_SKIN_OT_add_mixture)
