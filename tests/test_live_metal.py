"""Metal and glass on a skin material (blender_addon.wiring, "Metal and glass"): a character's texture set with a
metallic map (jewellery, armour, a piercing in the same material as the skin) keeps its metal after Invert Skin
Albedo, in real Cycles on the probe box (camera straight above, white world).

The reference is Blender's own Principled BSDF of the artist's material, rendered before the operator: where
Metallic is 1 the group's render is that render within the noise, where the metallic map is 0 it is the skin's,
and a Transmission Weight of 1 renders Blender's glass.  Layers come and go with the artist's Metallic, follow their
Principled BSDF's other inputs, and leave with Remove Skin SSS; a material without metal or glass gets none.
Baked maps, whose mixture group has no Subsurface Weight, Alpha or Emission inputs, get those as layers too.
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import probe, wiring  # noqa: E402
from tests.addon_scene import render_linear, run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SKIN = (180, 120, 95)  # medium skin, 8-bit sRGB
GOLD = (255, 200, 90)
SIZE = 16  # texels and pixels per side
SAMPLES = 64


@pytest.fixture
def scene(tmp_path):
    """The probe scene with the add-on registered."""
    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    yield probe.new_scene(samples=SAMPLES, resolution=SIZE, seed=5)
    blender_addon.unregister()


def _material(tmp_path: Path, left: tuple[int, int, int], right: tuple[int, int, int]) -> bpy.types.Material:
    """The probe box's artist material: a texture with colour ``left`` on the left half and ``right`` on the right
    (8-bit sRGB) into a Principled BSDF's Base Color."""
    pixels = np.empty((SIZE, SIZE, 3), np.uint8)
    pixels[:, : SIZE // 2], pixels[:, SIZE // 2:] = left, right
    image = bpy.data.images.load(str(write_image(tmp_path / "albedo.png", pixels, "uint8")))
    return box_material(image, "principled")


def _metallic_map(tmp_path: Path, mat: bpy.types.Material) -> bpy.types.Node:
    """A metallic map (1 on the left half, 0 on the right; Non-Color) through the box's texture coordinates into the
    Principled BSDF's Metallic; returns its Image Texture node."""
    tree = mat.node_tree
    pixels = np.zeros((SIZE, SIZE, 3), np.uint8)
    pixels[:, : SIZE // 2] = 255
    image = bpy.data.images.load(str(write_image(tmp_path / "metallic.png", pixels, "uint8")))
    image.colorspace_settings.name = "Non-Color"
    albedo = tree.nodes["Principled BSDF"].inputs["Base Color"].links[0].from_node
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = image, "Closest", "EXTEND"
    tree.links.new(albedo.inputs["Vector"].links[0].from_socket, tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Metallic"])
    return tex


def _halves(scene: bpy.types.Scene, path: Path) -> np.ndarray:
    """Mean linear RGB (2, 3) of the inner pixels of the left and right halves of the probe's render."""
    rgb = render_linear(scene, path)[2:-2]
    half = SIZE // 2
    return np.array([rgb[:, 2:half - 2].reshape(-1, 3).mean(axis=0), rgb[:, half + 2:-2].reshape(-1, 3).mean(axis=0)])


def _base_nodes(mat: bpy.types.Material) -> list[bpy.types.Node]:
    return [n for n in mat.node_tree.nodes if wiring.BASE_LAYER_PROP in n]


def _invert_live() -> None:
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}


@pytest.mark.slow
def test_a_metallic_map_keeps_its_metal_and_its_skin(tmp_path, scene):
    """Gold where the metallic map is 1 renders as the artist's Principled BSDF renders it (within 3 % per channel),
    skin where it is 0 as the live group renders skin without a metallic map (within 3 %)."""
    mat = _material(tmp_path, GOLD, SKIN)
    tex = _metallic_map(tmp_path, mat)
    principled = _halves(scene, tmp_path / "principled.exr")
    _invert_live()
    assert {n.bl_idname for n in _base_nodes(mat)} == {"ShaderNodeBsdfPrincipled", "ShaderNodeMixShader"}
    group = _halves(scene, tmp_path / "group.exr")
    mat.node_tree.links.remove(tex.outputs["Color"].links[0])  # no metallic map: the skin alone, and no layer
    bpy.context.view_layer.update()
    assert not _base_nodes(mat)
    skin = _halves(scene, tmp_path / "skin.exr")
    print(f"\nmetal: group {group[0].round(4)}, Principled {principled[0].round(4)}; "
          f"skin: group {group[1].round(4)}, without the map {skin[1].round(4)}, Principled {principled[1].round(4)}")
    np.testing.assert_allclose(group[0], principled[0], rtol=0.03)
    np.testing.assert_allclose(group[1], skin[1], rtol=0.03)
    assert np.max(np.abs(skin[0] / principled[0] - 1.0)) > 0.2  # the skin group alone does not render the gold


@pytest.mark.slow
def test_half_metallic_and_glass_mix_as_the_principled_bsdf_mixes_them(tmp_path, scene):
    """Metallic 0.5 renders half the Principled BSDF's metal and half the skin; Transmission Weight 1 renders the
    Principled BSDF's glass (within 3 % per channel, the references rendered by Blender's Principled BSDF and the
    group without the layer)."""
    mat = _material(tmp_path, GOLD, GOLD)
    principled = mat.node_tree.nodes["Principled BSDF"]
    principled.inputs["Metallic"].default_value = 1.0
    metal = _halves(scene, tmp_path / "metal.exr").mean(axis=0)
    principled.inputs["Metallic"].default_value, principled.inputs["Transmission Weight"].default_value = 0.0, 1.0
    glass = _halves(scene, tmp_path / "glass.exr").mean(axis=0)
    principled.inputs["Transmission Weight"].default_value = 0.0
    _invert_live()
    assert not _base_nodes(mat)  # neither metal nor glass: the material gets no layer
    skin = _halves(scene, tmp_path / "skin.exr").mean(axis=0)
    principled.inputs["Metallic"].default_value = 0.5
    bpy.context.view_layer.update()
    half = _halves(scene, tmp_path / "half.exr").mean(axis=0)
    principled.inputs["Metallic"].default_value, principled.inputs["Transmission Weight"].default_value = 0.0, 1.0
    bpy.context.view_layer.update()
    group_glass = _halves(scene, tmp_path / "group_glass.exr").mean(axis=0)
    print(f"\nhalf metal: {half.round(4)} against {(0.5 * (metal + skin)).round(4)}; "
          f"glass: {group_glass.round(4)} against {glass.round(4)}")
    np.testing.assert_allclose(half, 0.5 * (metal + skin), rtol=0.03)
    np.testing.assert_allclose(group_glass, glass, rtol=0.03)


def test_layers_follow_the_principled_bsdf_and_leave_with_remove(tmp_path, scene):
    """The metal layer's copy takes what the artist changes on their Principled BSDF afterwards; Metallic back at 0
    takes the layer out; a baked material gets it too; Remove Skin SSS leaves none of it."""
    mat = _material(tmp_path, SKIN, SKIN)
    principled = mat.node_tree.nodes["Principled BSDF"]
    _invert_live()
    principled.inputs["Metallic"].default_value = 1.0
    bpy.context.view_layer.update()
    copies = [n for n in _base_nodes(mat) if n.bl_idname == "ShaderNodeBsdfPrincipled"]
    assert len(copies) == 1 and len(_base_nodes(mat)) == 3  # one copy, a mix for each renderer's output
    assert copies[0].inputs["Base Color"].links[0].from_node == principled.inputs["Base Color"].links[0].from_node
    principled.inputs["Roughness"].default_value = 0.2
    bpy.context.view_layer.update()
    (copy,) = [n for n in _base_nodes(mat) if n.bl_idname == "ShaderNodeBsdfPrincipled"]
    assert copy.inputs["Roughness"].default_value == pytest.approx(0.2)
    assert copy.inputs["Metallic"].default_value == 1.0 and copy.inputs["Subsurface Weight"].default_value == 0.0
    for target in ("CYCLES", "EEVEE"):
        mix = wiring.render_output(mat.node_tree, target).inputs["Surface"].links[0].from_node
        assert mix[wiring.BASE_LAYER_PROP] == "Metallic" and mix.inputs["Fac"].default_value == pytest.approx(1.0)
    assert wiring.wired_group_node(mat) is not None
    for node in _base_nodes(mat):
        node.location.x += 1000.0  # moved by the artist
    moved = sorted((n.name, tuple(n.location)) for n in _base_nodes(mat))
    principled.inputs["Metallic"].default_value = 0.6  # a new value (a keyframe): the same nodes take it
    bpy.context.view_layer.update()
    assert sorted((n.name, tuple(n.location)) for n in _base_nodes(mat)) == moved
    mix = wiring.render_output(mat.node_tree, "CYCLES").inputs["Surface"].links[0].from_node
    assert mix.inputs["Fac"].default_value == pytest.approx(0.6)
    principled.inputs["Metallic"].default_value = 0.0
    bpy.context.view_layer.update()
    assert not _base_nodes(mat)
    assert wiring.render_output(mat.node_tree, "CYCLES").inputs["Surface"].links[0].from_node == \
        wiring.wired_group_node(mat)
    principled.inputs["Metallic"].default_value = 0.3
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="BAKE") == {"FINISHED"}
    assert len(_base_nodes(mat)) == 3 and "spectral_skin_sss_k" in wiring.wired_group_node(mat).node_tree
    with bpy.context.temp_override(object=bpy.data.objects["ProbeSlab"], active_object=bpy.data.objects["ProbeSlab"]):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
    assert not _base_nodes(mat) and not any(wiring.is_added(n) for n in mat.node_tree.nodes)
    assert wiring.active_output(mat.node_tree).inputs["Surface"].links[0].from_node == principled


def _mask(tmp_path: Path, mat: bpy.types.Material, name: str, left: float, right: float) -> bpy.types.Node:
    """A Non-Color mask texture (``left`` on the left half, ``right`` on the right) through the box's texture
    coordinates into the Principled BSDF's input ``name``; returns its Image Texture node."""
    tree = mat.node_tree
    pixels = np.empty((SIZE, SIZE, 3), np.uint8)
    pixels[:, : SIZE // 2], pixels[:, SIZE // 2:] = round(255 * left), round(255 * right)
    image = bpy.data.images.load(str(write_image(tmp_path / f"{name}.png", pixels, "uint8")))
    image.colorspace_settings.name = "Non-Color"
    principled = tree.nodes["Principled BSDF"]
    albedo = principled.inputs["Base Color"].links[0].from_node
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = image, "Closest", "EXTEND"
    tree.links.new(albedo.inputs["Vector"].links[0].from_socket, tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], principled.inputs[name])
    return tex


@pytest.mark.slow
def test_baked_maps_take_subsurface_weight_emission_and_alpha(tmp_path, scene):
    """Baked maps (whose mixture group has no such inputs) with a Subsurface Weight mask: where it is 0 the render is
    the artist's Principled BSDF at Subsurface Weight 0 (within 3 %), where it is 1 the skin of the maps; an
    Emission added afterwards adds its colour x strength to the render (Cycles' emission; within 0.01); Alpha 0
    renders as the artist's transparent Principled BSDF (within 3 %)."""
    mat = _material(tmp_path, SKIN, SKIN)
    principled = mat.node_tree.nodes["Principled BSDF"]
    _mask(tmp_path, mat, "Subsurface Weight", 0.0, 1.0)
    mat.node_tree.nodes.active = principled.inputs["Base Color"].links[0].from_node  # the albedo to bake
    reference = _halves(scene, tmp_path / "principled.exr")
    principled.inputs["Alpha"].default_value = 0.0
    transparent = _halves(scene, tmp_path / "transparent.exr")
    principled.inputs["Alpha"].default_value = 1.0
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="BAKE") == {"FINISHED"}
    assert "spectral_skin_sss_k" in wiring.wired_group_node(mat).node_tree
    assert {n[wiring.BASE_LAYER_PROP] for n in _base_nodes(mat)} == {"Subsurface Weight"}
    baked = _halves(scene, tmp_path / "baked.exr")
    glow = np.array([0.2, 0.05, 0.0])
    principled.inputs["Emission Color"].default_value = (*glow, 1.0)
    principled.inputs["Emission Strength"].default_value = 1.0
    bpy.context.view_layer.update()
    emitting = _halves(scene, tmp_path / "emitting.exr")
    principled.inputs["Emission Strength"].default_value = 0.0
    principled.inputs["Alpha"].default_value = 0.0
    bpy.context.view_layer.update()
    clear = _halves(scene, tmp_path / "clear.exr")
    print(f"\ndiffuse body: baked {baked[0].round(4)}, Principled {reference[0].round(4)}; skin: baked "
          f"{baked[1].round(4)}, Principled {reference[1].round(4)}; emission adds {(emitting - baked).round(4)}; "
          f"alpha 0: {clear.round(4)} against {transparent.round(4)}")
    np.testing.assert_allclose(baked[0], reference[0], rtol=0.03)
    assert np.max(np.abs(baked[1] / reference[1] - 1.0)) > 0.05  # the maps' skin, not the artist's Principled
    np.testing.assert_allclose(emitting - baked, np.stack([glow, glow]), atol=0.01)
    np.testing.assert_allclose(clear, transparent, rtol=0.03, atol=1e-3)


def test_keyframed_inputs_animate_the_group_and_its_layers(tmp_path, scene):
    """A keyframed Metallic (0 at frame 1, 1 at frame 11) and a keyframed Roughness on the artist's Principled BSDF
    animate the render: the metal layer's Fac and the live group's Roughness take the Principled BSDF's value at
    every frame (no handler runs on a frame change: they carry copies of its keyframes); keys moved afterwards
    follow; Remove Skin SSS leaves only the artist's own keyframes.  At frame 11 the gold renders as the Principled
    BSDF's metal (within 3 %)."""
    mat = _material(tmp_path, GOLD, GOLD)
    principled = mat.node_tree.nodes["Principled BSDF"]
    principled.inputs["Metallic"].default_value = 1.0
    metal = _halves(scene, tmp_path / "metal.exr").mean(axis=0)
    _invert_live()
    metallic, roughness = principled.inputs["Metallic"], principled.inputs["Roughness"]
    for frame, value, rough in ((1, 0.0, 0.2), (11, 1.0, 0.5)):  # at frame 11 the reference metal
        metallic.default_value, roughness.default_value = value, rough
        metallic.keyframe_insert("default_value", frame=frame)
        roughness.keyframe_insert("default_value", frame=frame)
    bpy.context.view_layer.update()
    gnode = wiring.wired_group_node(mat)
    mixes = [n for n in _base_nodes(mat) if n.bl_idname == "ShaderNodeMixShader"]
    assert len(mixes) == 2
    for frame in (1, 6, 11):
        scene.frame_set(frame)
        assert all(m.inputs["Fac"].default_value == pytest.approx(metallic.default_value) for m in mixes)
        assert gnode.inputs["Roughness"].default_value == pytest.approx(roughness.default_value)
    assert metallic.default_value == pytest.approx(1.0)
    animated = _halves(scene, tmp_path / "animated.exr").mean(axis=0)
    np.testing.assert_allclose(animated, metal, rtol=0.03)
    curve = wiring.animation(metallic)[0]
    curve.keyframe_points[1].co.x = 21.0  # the artist moves the last key to frame 21
    curve.update()
    bpy.context.view_layer.update()
    scene.frame_set(11)  # half-way between the keys: 0.5 by the curve's symmetry
    assert metallic.default_value == pytest.approx(0.5)
    assert all(m.inputs["Fac"].default_value == pytest.approx(0.5) for m in mixes)
    with bpy.context.temp_override(object=bpy.data.objects["ProbeSlab"], active_object=bpy.data.objects["ProbeSlab"]):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
    paths = sorted(fc.data_path for fc in wiring._action_fcurves(mat.node_tree))
    assert paths == sorted([metallic.path_from_id("default_value"), roughness.path_from_id("default_value")])
