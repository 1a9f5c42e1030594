"""Spectral Skin SSS: Blender add-on (bpy layer over the numpy core in ``exporters``).

Modules: ``preferences`` (model path, threads), ``operators`` (Invert Skin Albedo, Add Skin SSS
Mixture), ``baker`` (the bpy side of a bake: albedo source, images, wiring), ``panels`` (Shader Editor tab
"Skin SSS", Material properties, per-scene bake settings), ``nodes`` (the node group), ``osl`` (Script-node
helpers), ``probe`` (render-fidelity probe used by the tests); ``bake.py`` is the headless script.

As an extension the repository-root ``__init__.py`` calls :func:`register` with the extension's module
name, so that the preferences are found under it; imported directly (tests, scripts) the name is this
package's.
"""

from __future__ import annotations

import bpy

from . import operators, panels, preferences

_classes = (preferences.SpectralSkinPreferences, *operators.classes, *panels.classes)


def register(addon_name: str | None = None) -> None:
    """Register every class; ``addon_name`` is the module Blender enabled (for AddonPreferences)."""
    name = addon_name or __package__
    preferences.ADDON_NAME = name
    preferences.SpectralSkinPreferences.bl_idname = name
    for cls in _classes:
        bpy.utils.register_class(cls)
    panels.register_properties()


def unregister() -> None:
    panels.unregister_properties()
    for cls in reversed(_classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
