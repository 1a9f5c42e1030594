"""The extension package: Blender's own extension tool builds and validates it; it installs and runs.

blender_ext.py is the back-end of `blender --command extension build|validate` (shipped in the bpy wheel);
installation runs in a separate interpreter with BLENDER_USER_RESOURCES pointing to a temporary folder, so
nothing is written to the user's Blender configuration.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import bpy
import pytest

ROOT = Path(__file__).resolve().parents[1]
BLENDER_EXT = Path(bpy.utils.resource_path("LOCAL")) / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


def run(*args: str, env: dict | None = None, timeout: int = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ext")
    proc = run(str(BLENDER_EXT), "build", "--source-dir", str(ROOT), "--output-dir", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    zips = list(out.glob("spectral_skin_sss-*.zip"))
    assert len(zips) == 1, proc.stdout
    return zips[0]


def test_manifest_validates_and_zip_holds_only_the_addon(built_zip):
    for target in (str(ROOT), str(built_zip)):
        proc = run(str(BLENDER_EXT), "validate", target)
        assert proc.returncode == 0 and "Success" in proc.stdout, proc.stdout + proc.stderr
    with zipfile.ZipFile(built_zip) as zf:
        names = zf.namelist()
    top = {n.split("/")[0] for n in names}
    assert top == {"__init__.py", "blender_manifest.toml", "blender_addon", "exporters"}, top
    assert "blender_addon/nodes.py" in names and "exporters/cycles.py" in names
    assert not any("__pycache__" in n for n in names)


def test_installs_enables_and_reports_missing_model(built_zip, tmp_path):
    script = textwrap.dedent(
        f"""
        import json, bpy
        bpy.ops.extensions.package_install_files(filepath={str(built_zip)!r}, repo="user_default",
                                                 enable_on_install=True)
        name = "bl_ext.user_default.spectral_skin_sss"
        prefs = bpy.context.preferences.addons[name].preferences
        prefs.model_path = {str(tmp_path / "absent.onnx")!r}
        try:
            bpy.ops.spectral_skin.invert_albedo(filepath="x.png")
            error = None
        except RuntimeError as exc:
            error = str(exc)
        print("RESULT" + json.dumps({{"enabled": name in bpy.context.preferences.addons,
                                     "label": bpy.ops.spectral_skin.invert_albedo.get_rna_type().name,
                                     "error": error}}))
        """
    )
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    proc = run("-c", script, env=env, timeout=120)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")]
    assert proc.returncode == 0 and lines, proc.stdout[-2000:] + proc.stderr[-2000:]
    result = json.loads(lines[-1][len("RESULT"):])
    assert result["enabled"] and result["label"] == "Invert Skin Albedo"
    assert "model not found at" in result["error"] and "absent.onnx" in result["error"]
    assert (tmp_path / "blender_user" / "extensions" / "user_default" / "spectral_skin_sss").is_dir()
