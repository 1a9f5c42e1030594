"""Make a virtual environment's bpy module see what Blender's own Python sees: ``python tests/blender_env.py``.

A Blender binary has its bundled ``python/lib/python3.x/site-packages`` (OpenImageIO, oslquery, ... from 4.5 on;
Blender 4.2 bundles none of them) on ``sys.path``; the bpy wheel ships that folder but leaves it off.  This writes
``blender_bundled.pth`` into the running interpreter's site-packages naming that folder (none on 4.2, where there
is nothing to add), so the add-on meets the same modules as in Blender.  The Makefile runs it in the
.venv-blender* environments that tests/test_addon_versions.py uses; it imports nothing but the standard library.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import sysconfig


def main() -> None:
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("blender_env.py: the bpy module is not installed in this Python")
    base = list(spec.submodule_search_locations)[0]
    bundled = sorted(glob.glob(os.path.join(base, "*", "python", "lib", "python3*", "site-packages")))
    pth = os.path.join(sysconfig.get_paths()["purelib"], "blender_bundled.pth")
    if bundled:
        with open(pth, "w") as f:
            f.write("\n".join(bundled) + "\n")
    elif os.path.exists(pth):
        os.remove(pth)
    print(f"blender_env.py: {pth}: {bundled or 'nothing bundled (Blender 4.2)'}")


if __name__ == "__main__":
    main()
