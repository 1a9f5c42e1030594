"""Blender extension entry point of Spectral Skin SSS (docs/contracts.md §5: the manifest is at the repository root).

Blender loads the repository root (as packaged by blender_manifest.toml: this file, blender_addon/ and
exporters/) as the package ``bl_ext.<repo>.spectral_skin_sss``; ``blender_addon`` and ``exporters`` are its
subpackages, imported relative to it (blender_addon.core), so nothing is added to ``sys.path`` and no
top-level module of another add-on can collide with them.  Imports are lazy so that nothing imports bpy when
the repository is used as a plain Python checkout.
"""


def register() -> None:
    from . import blender_addon

    blender_addon.register(addon_name=__name__)


def unregister() -> None:
    from . import blender_addon

    blender_addon.unregister()
