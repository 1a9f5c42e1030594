"""make extension (blender_addon/package.py): the zip with the bundled wheels builds, validates
with Blender's own tool, installs into a sandboxed Blender user folder, and bakes with the *bundled*
onnxruntime (the venv's copy is hidden from the import system in that process)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

from tests.addon_scene import skin_codes, write_image

ROOT = Path(__file__).resolve().parents[1]


def test_zip_contents_and_manifest(ext_zip):
    with zipfile.ZipFile(ext_zip) as zf:
        names = zf.namelist()
        manifest = zf.read("blender_manifest.toml").decode()
    assert {n.split("/")[0] for n in names} == {"__init__.py", "blender_manifest.toml", "blender_addon", "exporters",
                                                "wheels"}
    wheels = sorted(n for n in names if n.startswith("wheels/"))
    # onnxruntime for both Pythons Blender ships (3.11: 4.2-5.0, 3.13: 5.1 on); never OpenImageIO, which would
    # replace Blender's own (the extensions' site-packages come first) and break Cycles' oslquery
    assert [w.split("-")[0] + "-" + w.split("-")[2] for w in wheels] == [
        "wheels/onnxruntime-cp311", "wheels/onnxruntime-cp313"]
    assert all("manylinux" in w and w.endswith("_x86_64.whl") for w in wheels), wheels
    assert 'platforms = ["linux-x64"]' in manifest and all(f'"./{w}"' in manifest for w in wheels)
    assert "blender_addon/models/skin_inversion.onnx" in names and "exporters/data/reflectance_tables.npz" in names
    assert "blender_addon/package.py" not in names and not any("__pycache__" in n for n in names)


def test_installed_extension_bakes_with_the_bundled_onnxruntime(ext_zip, tmp_path):
    png = write_image(tmp_path / "albedo.png", skin_codes(), "uint8")
    user = tmp_path / "blender_user"
    script = textwrap.dedent(
        f"""
        import importlib.machinery, json, sys
        from pathlib import Path
        SITE = Path({str(user)!r}) / "extensions" / ".local" / "lib" / "python3.11" / "site-packages"

        class OnlyBundledOnnxruntime:
            # The venv also has onnxruntime: resolve that package from the extension's wheel folder only.
            def find_spec(self, name, path=None, target=None):
                if name == "onnxruntime":
                    return importlib.machinery.PathFinder.find_spec(name, [str(SITE)])
                return None

        sys.meta_path.insert(0, OnlyBundledOnnxruntime())
        import bpy
        bpy.ops.extensions.package_install_files(filepath={str(ext_zip)!r}, repo="user_default",
                                                 enable_on_install=True)
        name = "bl_ext.user_default.spectral_skin_sss"
        bpy.context.preferences.addons[name].preferences.threads = 1
        bpy.ops.mesh.primitive_uv_sphere_add()
        obj = bpy.context.active_object
        mat = bpy.data.materials.new("Skin")
        obj.data.materials.append(mat)
        with bpy.context.temp_override(object=obj, active_object=obj):
            result = bpy.ops.spectral_skin.invert_albedo(filepath={str(png)!r}, backend="SVM")
        import onnxruntime
        groups = [n.node_tree.name for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]
        print("RESULT" + json.dumps({{"result": sorted(result), "onnxruntime": onnxruntime.__file__,
                                     "groups": groups, "images": len(bpy.data.images)}}))
        """
    )
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")]
    assert proc.returncode == 0 and lines, proc.stdout[-3000:] + proc.stderr[-3000:]
    out = json.loads(lines[-1][len("RESULT"):])
    assert out["result"] == ["FINISHED"]
    assert str(user) in out["onnxruntime"]  # the wheel from the zip, not the venv's
    assert out["groups"] and out["groups"][0].startswith("Spectral Skin SSS Mixture")
    assert out["images"] >= 12  # the K x 4 maps, packed
