"""Blender extension entry point of Spectral Skin SSS (docs/contracts.md §5: the manifest is at the repository root).

Blender loads the repository root (as packaged by blender_manifest.toml: this file, blender_addon/ and
exporters/) as the module ``bl_ext.<repo>.spectral_skin_sss``.  ``exporters`` and ``blender_addon`` use
absolute imports of ``exporters``, so the extension folder is put on sys.path before importing them.
Imports are lazy so that nothing imports bpy when the repository is used as a plain Python checkout.
"""


def _put_extension_dir_on_path() -> None:
    import os
    import sys

    here = os.path.dirname(os.path.abspath(__file__))
    if here not in sys.path:
        sys.path.insert(0, here)


def register() -> None:
    _put_extension_dir_on_path()
    import blender_addon

    blender_addon.register(addon_name=__name__)


def unregister() -> None:
    import blender_addon

    blender_addon.unregister()
