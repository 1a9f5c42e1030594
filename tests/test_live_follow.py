"""The live group follows what the artist changes on their Principled BSDF after Invert Skin Albedo
(blender_addon.follow), in real Cycles on the probe box (camera straight above, white world).

* A layer mixed into Base Color afterwards (a lipstick red over the medium skin texture) renders: the render is the
  new painted colour plus the coat (Blender's own Principled specular layer), within the non-skin colours' bounds,
  where the group left as wired renders the skin texture.
* Values and links made later on the Principled BSDF (Roughness, Coat Weight, a normal map) reach the group (the live
  group, and the mixture group of baked maps but for Base Color, which the maps hold); a value
  the artist set on the group node itself stays until the same input changes on the Principled BSDF; Remove Skin
  SSS leaves no record behind.
* The scene's Unit Scale reaches the live group's radii when it changes, or when a skin material is appended into a
  scene of other units; baked maps in other units than the scene's are reported stale.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import follow, live, probe, wiring  # noqa: E402
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode  # noqa: E402
from tests.addon_scene import principled_coat_reflectance, render_linear, run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SKIN = (180, 120, 95)  # medium skin, 8-bit sRGB
LIPSTICK = (190, 30, 45)
SIZE = 16  # texels and pixels per side
ROUGHNESS = 0.5  # the Principled BSDF's default, which the group takes


@pytest.fixture
def wired(tmp_path):
    """The probe scene with the artist's material (skin texture -> Principled BSDF), wired live; (scene, material,
    the Principled BSDF, the group node, the texture node)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    scene = probe.new_scene(samples=64, resolution=SIZE, seed=3)
    pixels = np.broadcast_to(np.array(SKIN, np.uint8), (SIZE, SIZE, 3))
    image = bpy.data.images.load(str(write_image(tmp_path / "skin.png", pixels, "uint8")))
    mat = box_material(image, "principled")
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    principled = mat.node_tree.nodes["Principled BSDF"]
    texture = principled.inputs["Base Color"].links[0].from_node
    yield scene, mat, principled, wiring.wired_group_node(mat), texture
    blender_addon.unregister()


def _render_delta_e(scene, tmp_path: Path, name: str, painted: np.ndarray) -> float:
    """ΔE76 of the probe's mean render (the coat's reflection taken off) from the ``painted`` linear colour."""
    rgb = render_linear(scene, tmp_path / f"{name}.exr")[2:-2, 2:-2].reshape(-1, 3).mean(axis=0)
    coat = principled_coat_reflectance(scene, [1.0], ROUGHNESS, live.nodes.DEFAULT_IOR)[0]
    return float(delta_e76(linear_srgb_to_lab((rgb - coat)[None]), linear_srgb_to_lab(painted[None]))[0])


@pytest.mark.slow
def test_a_layer_mixed_into_base_color_afterwards_renders(tmp_path, wired):
    scene, mat, principled, gnode, texture = wired
    tree = mat.node_tree
    layer = tree.nodes.new("ShaderNodeMix")  # lipstick over the skin, factor 1 (a painted layer's mask at full)
    layer.data_type = "RGBA"
    layer.inputs["Factor"].default_value = 1.0
    tree.links.new(texture.outputs["Color"], layer.inputs["A"])
    layer.inputs["B"].default_value = (*srgb_decode(np.array(LIPSTICK) / 255.0), 1.0)
    tree.links.new(layer.outputs["Result"], principled.inputs["Base Color"])
    lipstick = srgb_decode(np.array(LIPSTICK, np.float64) / 255.0)
    blender_addon.unregister()  # no handler: the group still reads the skin texture
    stale = _render_delta_e(scene, tmp_path, "stale", lipstick)
    blender_addon.register()
    bpy.context.view_layer.update()  # the depsgraph update the node editor's link makes
    assert gnode.inputs["Color"].links[0].from_node == layer
    followed = _render_delta_e(scene, tmp_path, "followed", lipstick)
    print(f"\nlipstick layer: ΔE76 {followed:.2f} with the group following, {stale:.2f} without")
    assert followed <= 2.0 and stale > 10.0


def test_values_and_links_follow_and_the_groups_own_values_stay(tmp_path, wired):
    _, mat, principled, gnode, _ = wired
    tree = mat.node_tree
    principled.inputs["Roughness"].default_value = 0.8
    principled.inputs["Coat Weight"].default_value = 0.4
    normal = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(normal.outputs["Normal"], principled.inputs["Normal"])
    bpy.context.view_layer.update()
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.8)
    assert gnode.inputs["Coat Weight"].default_value == pytest.approx(0.4)
    assert gnode.inputs["Normal"].links[0].from_node == normal
    gnode.inputs["Roughness"].default_value = 0.3  # the artist's own value on the group node
    principled.inputs["Coat Weight"].default_value = 0.1
    tree.links.remove(principled.inputs["Normal"].links[0])
    bpy.context.view_layer.update()
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.3)  # Roughness did not change on the Principled
    assert gnode.inputs["Coat Weight"].default_value == pytest.approx(0.1)
    assert not gnode.inputs["Normal"].is_linked
    taken = json.loads(mat[wiring.TAKEN_INPUTS_PROP])
    assert taken["Roughness"] == ["value", 0.8] and taken["Normal"][0] == "value"
    with bpy.context.temp_override(object=bpy.data.objects["ProbeSlab"], active_object=bpy.data.objects["ProbeSlab"]):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
    assert wiring.TAKEN_INPUTS_PROP not in mat


def test_baked_maps_follow_the_same_inputs_but_base_color(tmp_path, wired):
    """Mode Bake maps: the mixture group takes Roughness, Normal and the specular inputs, and follows them; Base
    Color is in the maps (a change there needs a new bake)."""
    _, mat, principled, _, _ = wired
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="BAKE") == {"FINISHED"}
    gnode = wiring.wired_group_node(mat)
    assert "spectral_skin_sss_k" in gnode.node_tree and "Color" not in gnode.inputs
    principled.inputs["Roughness"].default_value = 0.65
    principled.inputs["Sheen Weight"].default_value = 0.2
    bpy.context.view_layer.update()
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.65)
    assert gnode.inputs["Sheen Weight"].default_value == pytest.approx(0.2)
    assert "Color" not in json.loads(mat[wiring.TAKEN_INPUTS_PROP])
    assert follow.baked_unit_scale_stale(mat, bpy.context.scene) is None


def _set_units(scene: bpy.types.Scene, system: str, scale: float = 1.0) -> None:
    scene.unit_settings.system, scene.unit_settings.scale_length = system, scale
    bpy.context.view_layer.update()  # the depsgraph update Scene ▸ Units makes in the interface


def test_the_live_group_follows_the_scenes_unit_scale(tmp_path, wired):
    """Radii are in Blender units: a model set to centimetres after inverting (Unit Scale 0.01) has the live
    group's radii given in centimetres; a value the artist set on the group node stays until the scene's changes;
    unit system None is 1 metre per unit."""
    scene, mat, principled, gnode, _ = wired
    assert gnode.inputs["Unit Scale"].default_value == pytest.approx(follow.scene_unit_scale(scene))
    _set_units(scene, "METRIC", 0.01)
    assert gnode.inputs["Unit Scale"].default_value == pytest.approx(0.01)
    assert json.loads(mat[wiring.TAKEN_INPUTS_PROP])["Unit Scale"] == ["value", 0.01]
    gnode.inputs["Unit Scale"].default_value = 0.02  # the artist's own value on the group node
    principled.inputs["Roughness"].default_value = 0.7
    scene.render.resolution_percentage = 50  # another scene change: the units did not change
    bpy.context.view_layer.update()
    assert gnode.inputs["Unit Scale"].default_value == pytest.approx(0.02)
    _set_units(scene, "NONE", 0.01)
    assert gnode.inputs["Unit Scale"].default_value == pytest.approx(1.0)


def test_a_skin_material_appended_into_a_scene_of_other_units_takes_them(tmp_path, wired):
    """A skin material wired at Unit Scale 1 and saved to a library, appended into a scene in centimetres and
    given to an object there, renders with radii in centimetres; the operator on it is up to date."""
    scene, mat, _, _, _ = wired
    library = tmp_path / "library.blend"
    bpy.data.libraries.write(str(library), {mat}, fake_user=True)
    _set_units(scene, "METRIC", 0.01)
    with bpy.data.libraries.load(str(library), link=False) as (source, target):
        target.materials = [mat.name]
    (appended,) = target.materials
    assert wiring.wired_group_node(appended).inputs["Unit Scale"].default_value == pytest.approx(1.0)
    bpy.ops.mesh.primitive_plane_add(size=0.1)
    plane = bpy.context.object
    plane.data.materials.append(appended)
    bpy.context.view_layer.update()
    assert wiring.wired_group_node(appended).inputs["Unit Scale"].default_value == pytest.approx(0.01)


def test_baked_maps_in_other_units_than_the_scenes_are_reported(tmp_path, wired):
    """Baked radii are in the units of the bake: where the scene's Unit Scale changes afterwards the add-on says the
    maps are stale (the panel asks for another bake), and a bake in the new units is not."""
    scene, mat, _, _, _ = wired
    _set_units(scene, "METRIC", 1.0)
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="BAKE") == {"FINISHED"}
    assert follow.baked_unit_scale_stale(mat, scene) is None
    _set_units(scene, "METRIC", 0.01)
    assert follow.baked_unit_scale_stale(mat, scene) == pytest.approx(1.0)
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="BAKE") == {"FINISHED"}
    assert follow.baked_unit_scale_stale(mat, scene) is None


def test_a_file_opened_follows_what_changed_while_the_add_on_was_off(tmp_path, wired):
    """Changes made to the Principled BSDF with the add-on off (or in a Blender without it) reach the group when
    the file is opened with it on: a roughness, and a metallic value that brings in the metal layer."""
    _, mat, principled, _, _ = wired
    blender_addon.unregister()
    principled.inputs["Roughness"].default_value = 0.85
    principled.inputs["Metallic"].default_value = 1.0
    path, name = tmp_path / "changed.blend", mat.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    blender_addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    mat = bpy.data.materials[name]
    assert wiring.wired_group_node(mat).inputs["Roughness"].default_value == pytest.approx(0.85)
    assert any(node.get(wiring.BASE_LAYER_PROP) == "Metallic" for node in mat.node_tree.nodes)


def test_a_driven_input_drives_the_group(tmp_path, wired):
    """A driver on the Principled BSDF's Emission Strength (an empty's height, as a rig's control) drives the live
    group's Emission Strength the same way: the group's input carries a copy of the driver."""
    _, mat, principled, gnode, _ = wired
    control = bpy.data.objects.new("Glow control", None)
    bpy.context.scene.collection.objects.link(control)
    driver = principled.inputs["Emission Strength"].driver_add("default_value").driver
    driver.type = "SUM"
    variable = driver.variables.new()
    variable.type, variable.targets[0].id_type = "SINGLE_PROP", "OBJECT"
    variable.targets[0].id, variable.targets[0].data_path = control, "location.z"
    bpy.context.view_layer.update()
    for height in (0.0, 2.5):
        control.location.z = height
        bpy.context.view_layer.update()
        assert principled.inputs["Emission Strength"].default_value == pytest.approx(height)
        assert gnode.inputs["Emission Strength"].default_value == pytest.approx(height)
    assert json.loads(mat[wiring.TAKEN_INPUTS_PROP])["Emission Strength"][0] == "animated"


def test_a_material_wired_without_a_record_follows_after_the_file_is_opened(tmp_path, wired):
    """A material wired by a version that kept no record (the record dropped): opening the file records the
    Principled BSDF as it is, leaving the group as it is (a roughness set on the group node stays), and what
    changes afterwards follows."""
    _, mat, principled, gnode, _ = wired
    del mat[wiring.TAKEN_INPUTS_PROP]
    gnode.inputs["Roughness"].default_value = 0.3  # set on the group node
    path, name, principled_name = tmp_path / "older.blend", mat.name, principled.name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    mat = bpy.data.materials[name]
    principled, gnode = mat.node_tree.nodes[principled_name], wiring.wired_group_node(mat)
    assert wiring.TAKEN_INPUTS_PROP in mat and gnode.inputs["Roughness"].default_value == pytest.approx(0.3)
    principled.inputs["Coat Weight"].default_value = 0.25
    bpy.context.view_layer.update()
    assert gnode.inputs["Coat Weight"].default_value == pytest.approx(0.25)
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.3)
