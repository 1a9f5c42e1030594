"""The add-on's bpy layer in-process with the real pip bpy: registration, operators, panels, prefs."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import bpy
import numpy as np
import OpenImageIO as oiio
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import blender_addon  # noqa: E402
from blender_addon import nodes, preferences  # noqa: E402

addon_utils = importlib.import_module("addon_utils")  # importable only once bpy is imported
ADDON = "blender_addon"


@pytest.fixture()
def enabled():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mod = addon_utils.enable(ADDON, default_set=True, handle_error=None)
    assert mod is not None
    yield bpy.context.preferences.addons[ADDON].preferences
    addon_utils.disable(ADDON, default_set=True)


def test_register_and_unregister_cleanly():
    blender_addon.register()
    try:
        assert bpy.ops.spectral_skin.invert_albedo.get_rna_type().name == "Invert Skin Albedo"
        assert bpy.ops.spectral_skin.add_mixture.get_rna_type().name == "Add Skin SSS Mixture"
        assert bpy.types.SPECTRAL_SKIN_PT_shader_editor.bl_category == "Skin SSS"
        assert bpy.types.SPECTRAL_SKIN_PT_shader_editor.bl_space_type == "NODE_EDITOR"
        assert bpy.types.SPECTRAL_SKIN_PT_material.bl_context == "material"
        assert "UNDO" in bpy.types.SPECTRAL_SKIN_OT_add_mixture.bl_options
    finally:
        blender_addon.unregister()
    assert not hasattr(bpy.types, "SPECTRAL_SKIN_OT_invert_albedo")
    assert not hasattr(bpy.types, "SPECTRAL_SKIN_PT_material")
    blender_addon.register()  # registering again after a clean unregister must work
    blender_addon.unregister()


def test_preferences_defaults_and_model_path(enabled, tmp_path):
    assert enabled.threads == 0 and enabled.model_path == ""
    assert preferences.model_path(bpy.context) == preferences.DEFAULT_MODEL
    assert preferences.DEFAULT_MODEL.endswith(str(Path("blender_addon", "models", "skin_inversion.onnx")))
    enabled.model_path = str(tmp_path / "m.onnx")
    enabled.threads = 3
    assert preferences.model_path(bpy.context) == str(tmp_path / "m.onnx")
    assert preferences.threads(bpy.context) == 3


def test_invert_albedo_reports_missing_model(enabled, tmp_path):
    missing = tmp_path / "nowhere" / "skin_inversion.onnx"
    enabled.model_path = str(missing)
    with pytest.raises(RuntimeError, match=rf"model not found at {missing}: train/export it or set the path in "
                                           r"preferences"):
        bpy.ops.spectral_skin.invert_albedo(filepath=str(tmp_path / "albedo.png"))


def test_invert_albedo_checks_the_albedo_once_a_model_file_exists(enabled, tmp_path):
    model = tmp_path / "skin_inversion.onnx"
    model.write_bytes(b"not used before the albedo is read")
    enabled.model_path = str(model)
    with pytest.raises(RuntimeError, match="albedo image not found"):
        bpy.ops.spectral_skin.invert_albedo(filepath=str(tmp_path / "missing.png"))
    bad = tmp_path / "nan.exr"
    spec = oiio.ImageSpec(2, 1, 3, "float")
    out = oiio.ImageOutput.create(str(bad))
    out.open(str(bad), spec)
    out.write_image(np.array([[[0.5, np.nan, 0.5], [0.5, 0.5, 0.5]]], dtype=np.float32))
    out.close()
    with pytest.raises(RuntimeError, match="NaN"):
        bpy.ops.spectral_skin.invert_albedo(filepath=str(bad))


def test_add_mixture_operator_keeps_user_nodes(enabled):
    mesh = bpy.data.meshes.new("m")
    obj = bpy.data.objects.new("o", mesh)
    bpy.context.scene.collection.objects.link(obj)
    mat = bpy.data.materials.new("Skin")
    mesh.materials.append(mat)
    user = mat.node_tree.nodes.new("ShaderNodeTexNoise")  # an extra user node, unconnected
    before = {n.name for n in mat.node_tree.nodes}
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.add_mixture(components=2) == {"FINISHED"}
    names = {n.name for n in mat.node_tree.nodes}
    assert before < names and user.name in names
    group_nodes = [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]
    assert len(group_nodes) == 1 and group_nodes[0].node_tree.name == nodes.GROUP_NAME
    assert group_nodes[0].node_tree["spectral_skin_sss_k"] == 2
    closures = [n for n in group_nodes[0].node_tree.nodes if n.bl_idname == "ShaderNodeSubsurfaceScattering"]
    roughness = sorted(round(n.inputs["Roughness"].default_value, 9) for n in closures)
    # three nested closures per component, and a copy of each for the part of its weight above 1
    assert roughness == [nodes.ENTRY_ROUGHNESS] * 6 + [round(nodes.OVERFLOW_ROUGHNESS, 9)] * 6
    # the open closures read their smooth entry from the group's computed zero, the copies hold theirs
    linked = [n.inputs["Roughness"].is_linked for n in closures]
    assert sorted(linked) == [False] * 6 + [True] * 6
    assert all(n.inputs["Roughness"].links[0].from_node.operation == "SUBTRACT" for n in closures
               if n.inputs["Roughness"].is_linked)
    assert mat[nodes.PREVIOUS_SURFACE_PROP] == "Principled BSDF"
