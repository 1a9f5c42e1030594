"""``exporters``, the add-on's numpy core, found beside this package wherever the add-on lives.

Installed as a Blender extension, the package tree is ``bl_ext.<repo>.spectral_skin_sss`` holding
``blender_addon`` and ``exporters``: the core is ``bl_ext.<repo>.spectral_skin_sss.exporters``, and no
top-level ``exporters`` (which another add-on could own) is imported or created.  In the repository
``blender_addon`` and ``exporters`` are top-level packages and the core is ``exporters``.

The add-on's modules import the core's modules from here, each on first use::

    from .core import bake, image_input

``exporters`` imports itself with relative imports only, so one copy serves both layouts.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: The package that holds ``blender_addon`` and ``exporters`` ("" in the repository: both are top level).
HOME = __package__.rpartition(".")[0]
#: The full name of the core package in this layout.
EXPORTERS = f"{HOME}.exporters" if HOME else "exporters"


def __getattr__(name: str) -> ModuleType:
    """``core.<module>``: the core's module ``<module>`` (``from .core import bake`` imports ``<EXPORTERS>.bake``)."""
    if name.startswith("__"):
        raise AttributeError(name)
    try:
        return importlib.import_module(f"{EXPORTERS}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{EXPORTERS}.{name}":
            raise
        raise AttributeError(f"{EXPORTERS} has no module {name!r}") from exc
