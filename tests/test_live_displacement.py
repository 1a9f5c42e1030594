"""The artist's displacement, volume and thickness keep working after Invert Skin Albedo (blender_addon.wiring,
OUTPUT_INPUTS): the Material Outputs the add-on adds for Cycles and EEVEE take what the artist's Material Output has
at Displacement (a pore or wrinkle map, bump or true displacement), Volume and Thickness, and follow it.

A Coat Normal of the artist's turns the clear coat, and Anisotropic along a Tangent stretches the specular highlight,
as they do the Principled BSDF's (the same scene).

The render check is real Cycles on the probe box (camera straight above, white world) with a sun from the side and
a height that rises along x (a bump tilting the shading normal away from the sun): the reference is the artist's own
Principled BSDF at Subsurface Weight 1, rendered with and without the height before the operator.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import follow, nodes, probe, wiring  # noqa: E402
from tests.addon_scene import render_linear, run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SKIN = (180, 120, 95)  # medium skin, 8-bit sRGB
SIZE = 16  # texels and pixels per side
SLOPE = 0.7  # the height's rise per Blender unit along x: the shading normal tilts by atan(0.7) = 35 degrees


@pytest.fixture
def scene(tmp_path):
    """The probe scene with a sun 50 degrees off the vertical, towards +x, and the add-on registered."""
    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    scene = probe.new_scene(samples=32, resolution=SIZE, seed=5)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (0.0, math.radians(50.0), 0.0)
    scene.collection.objects.link(sun)
    yield scene
    blender_addon.unregister()


def _material(tmp_path: Path) -> bpy.types.Material:
    """The probe box's artist material: a medium skin texture into a Principled BSDF at Subsurface Weight 1, and a
    Displacement node whose height rises along the object's x (not linked yet)."""
    pixels = np.empty((SIZE, SIZE, 3), np.uint8)
    pixels[:] = SKIN
    mat = box_material(bpy.data.images.load(str(write_image(tmp_path / "albedo.png", pixels, "uint8"))), "principled")
    tree = mat.node_tree
    tree.nodes["Principled BSDF"].inputs["Subsurface Weight"].default_value = 1.0
    coords, separate = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeSeparateXYZ")
    displacement = tree.nodes.new("ShaderNodeDisplacement")
    displacement.inputs["Scale"].default_value = SLOPE
    tree.links.new(coords.outputs["Object"], separate.inputs[0])
    tree.links.new(separate.outputs["X"], displacement.inputs["Height"])
    return mat


def _mean(scene: bpy.types.Scene, path: Path) -> np.ndarray:
    """Mean linear RGB of the render's inner pixels."""
    return render_linear(scene, path)[2:-2, 2:-2].reshape(-1, 3).mean(axis=0)


def _added_outputs(mat: bpy.types.Material) -> list[bpy.types.Node]:
    return [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and wiring.is_added(n)]


@pytest.mark.slow
def test_a_displacement_map_still_bumps_the_skin(tmp_path, scene):
    """With the artist's height linked to their Material Output's Displacement (Blender's default: bump only), the
    group's render darkens by the same factor as the artist's Principled BSDF's (within 6 % per channel; about 0.6
    here, the surface tilted away from the sun); unlinked afterwards, the group renders flat again."""
    mat = _material(tmp_path)
    tree = mat.node_tree
    out = wiring.active_output(tree)
    height = tree.nodes["Displacement"].outputs[0]
    flat = _mean(scene, tmp_path / "flat.exr")
    tree.links.new(height, out.inputs["Displacement"])
    bumped = _mean(scene, tmp_path / "bumped.exr")
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    group_bumped = _mean(scene, tmp_path / "group_bumped.exr")
    tree.links.remove(out.inputs["Displacement"].links[0])
    bpy.context.view_layer.update()
    group_flat = _mean(scene, tmp_path / "group_flat.exr")
    print(f"\nPrincipled BSDF bumped / flat {(bumped / flat).round(4)}, "
          f"group {(group_bumped / group_flat).round(4)}")
    assert np.all(bumped / flat < 0.8)  # the bump is there to see
    np.testing.assert_allclose(group_bumped / group_flat, bumped / flat, rtol=0.06)


def test_outputs_take_and_follow_displacement_volume_and_thickness(tmp_path, scene):
    """Both outputs the add-on adds take the artist's Displacement link, Volume link and Thickness value at wiring,
    and what the artist changes there afterwards; an output of the artist's own for a renderer keeps its own;
    Remove Skin SSS leaves the artist's output as it was; a file wired before the outputs took these (a record
    without them) gets them when it is opened."""
    mat = _material(tmp_path)
    tree = mat.node_tree
    out = wiring.active_output(tree)
    height = tree.nodes["Displacement"].outputs[0]
    tree.links.new(height, out.inputs["Displacement"])
    out.inputs["Thickness"].default_value = 0.25
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    added = _added_outputs(mat)
    assert sorted(n.target for n in added) == ["CYCLES", "EEVEE"]
    for node in added:
        assert node.inputs["Displacement"].links[0].from_socket == height
        assert node.inputs["Thickness"].default_value == pytest.approx(0.25)
        assert not node.inputs["Volume"].is_linked
    absorption = tree.nodes.new("ShaderNodeVolumeAbsorption")
    tree.links.new(absorption.outputs[0], out.inputs["Volume"])
    out.inputs["Thickness"].default_value = 0.5
    tree.links.remove(out.inputs["Displacement"].links[0])
    bpy.context.view_layer.update()
    for node in _added_outputs(mat):
        assert node.inputs["Volume"].links[0].from_node == absorption
        assert node.inputs["Thickness"].default_value == pytest.approx(0.5)
        assert not node.inputs["Displacement"].is_linked
    # a record made before the outputs took these: opening the file gives them
    record = json.loads(mat[wiring.TAKEN_INPUTS_PROP])
    record.pop(follow.OUTPUT)
    mat[wiring.TAKEN_INPUTS_PROP] = json.dumps(record)
    tree.links.new(height, out.inputs["Displacement"])
    follow.follow_on_load()
    assert all(n.inputs["Displacement"].links[0].from_socket == height for n in _added_outputs(mat))
    with bpy.context.temp_override(object=bpy.data.objects["ProbeSlab"], active_object=bpy.data.objects["ProbeSlab"]):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
    assert not _added_outputs(mat)
    assert out.inputs["Displacement"].links[0].from_socket == height
    assert out.inputs["Volume"].links[0].from_node == absorption
    assert out.inputs["Thickness"].default_value == pytest.approx(0.5)
    # the artist's own Cycles output: its Surface is the group's, its displacement stays the artist's
    own = tree.nodes.new("ShaderNodeOutputMaterial")
    own.target, own.is_active_output = "CYCLES", False
    tree.links.new(tree.nodes["Principled BSDF"].outputs[0], own.inputs["Surface"])
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    assert not own.inputs["Displacement"].is_linked
    assert wiring.render_output(tree, "CYCLES") == own
    assert [n.target for n in _added_outputs(mat)] == ["EEVEE"]
    assert _added_outputs(mat)[0].inputs["Displacement"].links[0].from_socket == height


def _tilted(tree: bpy.types.NodeTree, degrees: float) -> bpy.types.Node:
    """A Combine XYZ node giving the unit vector ``degrees`` off the vertical towards the sun (+x)."""
    node = tree.nodes.new("ShaderNodeCombineXYZ")
    node.inputs[0].default_value = math.sin(math.radians(degrees))
    node.inputs[2].default_value = math.cos(math.radians(degrees))
    return node


def _principled_then_group(scene: bpy.types.Scene, tmp_path: Path, on, off) -> tuple[np.ndarray, np.ndarray]:
    """The change of the render between ``on()`` and ``off()`` (each changing the artist's material) with the
    artist's Principled BSDF, then after Invert Skin Albedo: (the Principled BSDF's, the live group's)."""

    def change(name: str) -> np.ndarray:
        on()
        bpy.context.view_layer.update()
        changed = _mean(scene, tmp_path / f"{name}_on.exr")
        off()
        bpy.context.view_layer.update()
        return changed - _mean(scene, tmp_path / f"{name}_off.exr")

    reference = change("principled")
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    return reference, change("group")


@pytest.mark.slow
def test_a_coat_normal_turns_the_coat_as_the_principled_bsdfs(tmp_path, scene):
    """A clear coat (Coat Weight 1, Roughness 0.1) whose Coat Normal is tilted 25 degrees towards the side sun
    mirrors the sun into the camera straight above: the render gains what the artist's Principled BSDF gains with the
    same Coat Normal (within 10 % per channel, and that gain is large), where the coat took the base Normal before."""
    mat = _material(tmp_path)
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    principled.inputs["Coat Weight"].default_value, principled.inputs["Coat Roughness"].default_value = 1.0, 0.1
    tilted = _tilted(tree, 25.0)
    reference, group = _principled_then_group(
        scene, tmp_path, lambda: tree.links.new(tilted.outputs[0], principled.inputs["Coat Normal"]),
        lambda: tree.links.remove(principled.inputs["Coat Normal"].links[0]))
    print(f"\ncoat normal: the group gains {group.round(4)}, the Principled BSDF {reference.round(4)}")
    assert np.all(reference > 0.1)
    np.testing.assert_allclose(group, reference, rtol=0.1)


@pytest.mark.slow
def test_anisotropy_shapes_the_highlight_as_the_principled_bsdfs(tmp_path, scene):
    """The side sun's specular highlight seen straight above, 10 degrees off its peak (the Normal tilted 15 degrees
    towards the sun, Roughness 0.3, the skin's IOR), brightens with Anisotropic 0.9 along a Tangent towards the sun
    (the lobe stretched that way) by what the artist's Principled BSDF's brightens (within 10 % per channel; at the
    peak the stretch changes nothing)."""
    mat = _material(tmp_path)
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    principled.inputs["Roughness"].default_value = 0.3
    principled.inputs["IOR"].default_value = nodes.DEFAULT_IOR  # the skin's, which the group's specular keeps
    tree.links.new(_tilted(tree, 15.0).outputs[0], principled.inputs["Normal"])
    tree.links.new(_tilted(tree, 90.0).outputs[0], principled.inputs["Tangent"])  # along x, towards the sun
    anisotropic = principled.inputs["Anisotropic"]
    reference, group = _principled_then_group(scene, tmp_path, lambda: setattr(anisotropic, "default_value", 0.9),
                                              lambda: setattr(anisotropic, "default_value", 0.0))
    print(f"\nanisotropy: the group changes by {group.round(4)}, the Principled BSDF by {reference.round(4)}")
    assert np.all(reference > 0.05)
    np.testing.assert_allclose(group, reference, rtol=0.1)
