"""Blender's own exporters keep the artist's material after Invert Skin Albedo, in the oldest (bpy 4.2 LTS), the
project's (bpy 5.0.1) and the newest (bpy 5.3) Blender the manifest claims.

tests/export_check.py installs the
extension zip in each Blender, builds an artist's material (albedo, roughness, metallic and normal-map PNGs into a
Principled BSDF: the metallic map brings in the add-on's metal layer, a copy of the Principled BSDF the exporters
must not pick up), exports it with glTF 2.0, FBX, OBJ and USD, runs Invert Skin Albedo (the live group, then in a
fresh scene baked maps) and exports again; Remove Skin SSS then gives the material back (its nodes, values, links
and custom properties). Each exporter must write, after the operator, exactly what it wrote before: glTF's
materials, textures and images; OBJ's .mtl; the PNGs the FBX file names; USD's shader inputs. What this guards
against: with the group feeding the active Material Output instead of the per-target outputs (blender_addon.wiring),
glTF writes baseColorFactor [0, 0, 0, 1] with no texture, OBJ ``Kd 0.8`` with no ``map_Kd``, and the FBX file names
none of the images.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.blender_versions import BLENDERS, IDS, run_check

ROOT = Path(__file__).resolve().parents[1]
CHECK = ROOT / "tests" / "export_check.py"


@pytest.mark.parametrize("case,python,version,py_version", BLENDERS, ids=IDS)
def test_exporters_write_the_artists_material_after_invert(case, python, version, py_version, ext_zip, tmp_path):
    out = run_check(python, CHECK, ext_zip, tmp_path, timeout=300)
    assert out["blender"].startswith(version)
    for mode, group in (("LIVE", "Spectral Skin SSS Live"), ("BAKE", "Spectral Skin SSS Mixture")):
        run = out[mode]
        assert run["invert"] == ["FINISHED"] and any(g.startswith(group) for g in run["groups"]), (mode, run)
        # Blender's choice of output per target: the artist's Principled BSDF for All, the group for the renderers.
        assert run["renders"]["ALL"] == "ShaderNodeBsdfPrincipled", run["renders"]
        assert run["renders"]["CYCLES"].startswith(group) and run["renders"]["EEVEE"].startswith(group)
        before, after = run["before"], run["after"]
        # What each exporter writes for the artist's Principled BSDF: its three textures and its values.
        material = before["gltf"]["materials"][0]
        assert {"baseColorTexture", "metallicRoughnessTexture"} <= set(material["pbrMetallicRoughness"]), material
        assert "normalTexture" in material
        images = sorted(im["uri"] for im in before["gltf"]["images"])  # metallic and roughness: one image
        assert len(images) == 3 and {"albedo.png", "normal.png"} <= set(images), images
        assert any("metal" in uri and "rough" in uri for uri in images), images
        assert any(ln.startswith("map_Kd") and ln.endswith("albedo.png") for ln in before["mtl"]), before["mtl"]
        assert any(ln.startswith("map_Ns") and ln.endswith("rough.png") for ln in before["mtl"]), before["mtl"]
        assert any(ln.startswith("map_refl") and ln.endswith("metal.png") for ln in before["mtl"]), before["mtl"]
        assert any(ln.startswith("map_Bump") and ln.endswith("normal.png") for ln in before["mtl"]), before["mtl"]
        assert before["fbx"] == ["albedo.png", "metal.png", "normal.png", "rough.png"]
        assert sum("asset inputs:file" in ln for ln in before["usd"]) == 4, before["usd"]
        assert run["remove"] == ["FINISHED"] and run["restored"], (mode, run["remove"])  # Remove Skin SSS too
        # ... and the same after Invert Skin Albedo.
        for exporter in ("gltf", "mtl", "fbx", "usd"):
            assert after[exporter] == before[exporter], (mode, exporter, before[exporter], after[exporter])
