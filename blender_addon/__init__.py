"""Spectral Skin SSS: Blender add-on (bpy layer over the numpy core in ``exporters``, reached through ``core``).

Modules: ``preferences`` (model path, threads), ``operators`` (Invert Skin Albedo, Add Skin SSS
Mixture, Remove Skin SSS), ``baker`` (the bpy side of a bake: albedo source, images, wiring), ``panels`` (Shader
Editor tab "Skin SSS", Material properties, per-scene bake settings), ``nodes`` (the node group), ``wiring`` (where
the add-on's nodes sit in a material, and how they leave it), ``follow`` (the live group follows the artist's
Principled BSDF), ``merge`` (one copy of the add-on's groups and tables per file), ``osl`` (Script-node helpers),
``probe`` (render-fidelity probe used by the tests), ``core`` (``exporters`` beside this package); ``bake.py`` is the
headless script.

As an extension the repository-root ``__init__.py`` calls :func:`register` with the extension's module
name, so that the preferences are found under it; imported directly (tests, scripts) the name is this
package's.

A process that ends with the classes still registered crashes in Blender 4.2's bpy module (segmentation fault
while freeing the RNA types) and hangs in 4.5's; 5.0 and later clean up by themselves.  Blender disables the
add-ons it enabled before it exits, but a script that calls :func:`register` itself often never calls
:func:`unregister`, so :func:`register` also schedules :func:`unregister` at interpreter exit (``atexit``
handlers run last-registered first, so before bpy's own exit handler).
"""

from __future__ import annotations

import atexit

import bpy

from . import follow, live_edits, merge, operators, panels, preferences

_classes = (preferences.SpectralSkinPreferences, *operators.classes, *live_edits.classes, *panels.classes)


def register(addon_name: str | None = None) -> None:
    """Register every class; ``addon_name`` is the module Blender enabled (for AddonPreferences)."""
    name = addon_name or __package__
    preferences.ADDON_NAME = name
    preferences.SpectralSkinPreferences.bl_idname = name
    for cls in _classes:
        bpy.utils.register_class(cls)
    panels.register_properties()
    merge.register_handlers()
    live_edits.register_handlers()
    follow.register_handlers()
    atexit.unregister(unregister)
    atexit.register(unregister)


def unregister() -> None:
    """Unregister every class and property this add-on registered; safe to call again."""
    atexit.unregister(unregister)
    merge.unregister_handlers()
    live_edits.unregister_handlers()
    follow.unregister_handlers()
    panels.unregister_properties()
    for cls in reversed(_classes):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
