"""Add-on preferences: model path and inference threads."""

from __future__ import annotations

import os

import bpy

from .models import INVERSION_MODEL

#: The model shipped with the add-on (``models.INVERSION_MODEL``; `python -m training export` writes it), as a str.
DEFAULT_MODEL = str(INVERSION_MODEL)

#: Module name Blender registered the add-on under (set by register(); the extension id when installed).
ADDON_NAME = __package__


class SpectralSkinPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    model_path: bpy.props.StringProperty(
        name="Model",
        description="skin_inversion.onnx exported by `python -m training export` (empty: the bundled one)",
        subtype="FILE_PATH",
        default="",
    )
    threads: bpy.props.IntProperty(
        name="Threads",
        description="CPU threads for ONNX inference (0: all cores)",
        default=0,
        min=0,
        max=256,
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "model_path")
        layout.prop(self, "threads")
        layout.label(text=f"Resolved model: {model_path(context)}")


def preferences(context) -> SpectralSkinPreferences | None:
    """This add-on's preferences, or None when it was imported without being enabled (tests, scripts)."""
    addon = context.preferences.addons.get(ADDON_NAME)
    return addon.preferences if addon is not None else None


def model_path(context) -> str:
    """Absolute model path from the preferences (Blender-relative '//' paths resolved), else the default."""
    prefs = preferences(context)
    path = prefs.model_path if prefs is not None and prefs.model_path else DEFAULT_MODEL
    return os.path.abspath(bpy.path.abspath(path))


def threads(context) -> int:
    prefs = preferences(context)
    return prefs.threads if prefs is not None else 0
