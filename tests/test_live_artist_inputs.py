"""The artist's Principled inputs through the live group, in real Cycles (probe box: camera straight above, white
world; two stripes, medium skin and a lipstick red, 8-bit).

* At their defaults the new inputs change nothing: the render is bit for bit that of the same group with the
  Subsurface Weight scaling, the diffuse body, the Emission and Alpha shaders and the Translucency division taken
  out of it.
* Subsurface Weight, painted as a mask (0 on the left half, 1 on the right) on the Principled BSDF and linked into
  the group by Invert Skin Albedo: where it is 0 the render is a Diffuse BSDF of the painted colour plus Blender's
  own Principled specular layer (black base, the material's roughness, IOR 1.4), where it is 1 the skin (painted
  colour plus coat, as tests/test_bake_painted_colour.py).
* Alpha 0 renders what a Transparent BSDF renders (the white world through the box); Emission adds its colour
  times its strength.
* Translucency scales every radius the mixture gets.
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
from blender_addon import nodes, panels, probe  # noqa: E402
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode  # noqa: E402
from tests.addon_scene import principled_coat_reflectance, render_linear, run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

CODES = np.array([(180, 120, 95), (190, 30, 45)], np.uint8)  # medium skin, lipstick red
STRIPE, EDGE = 8, 2
ROUGHNESS = 0.5


@pytest.fixture
def addon():
    blender_addon.register()
    yield
    blender_addon.unregister()


def _scene(tmp: Path, columns: int = 2, samples: int = 64) -> tuple[bpy.types.Scene, bpy.types.Material]:
    """Probe scene showing ``columns`` stripes (CODES repeated) and the artist's material (texture -> Principled)."""
    scene = probe.new_scene(samples=samples, resolution=columns * STRIPE, seed=7)
    scene.render.resolution_y = STRIPE
    codes = np.resize(CODES, (columns, 3))
    pixels = np.repeat(np.repeat(codes[None], STRIPE, axis=0), STRIPE, axis=1)
    image = bpy.data.images.load(str(write_image(tmp / "paint.png", pixels, "uint8")))
    return scene, box_material(image, "principled")


def _render(scene: bpy.types.Scene, tmp: Path, name: str) -> np.ndarray:
    return render_linear(scene, tmp / f"{name}.exr")


def _stripes(rgb: np.ndarray) -> np.ndarray:
    n = rgb.shape[1] // STRIPE
    return np.array([rgb[:, i * STRIPE + EDGE:(i + 1) * STRIPE - EDGE].reshape(-1, 3).mean(axis=0) for i in range(n)])


def _live(material: bpy.types.Material) -> tuple[bpy.types.Node, bpy.types.NodeTree]:
    node = panels.live_node(material)
    assert node is not None
    return node, node.node_tree


def test_defaults_render_bit_for_bit_without_the_new_inputs(tmp_path, addon):
    scene, mat = _scene(tmp_path, samples=16)
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    node, group = _live(mat)
    assert node.inputs["Subsurface Weight"].default_value == 1.0  # the Principled's default 0: never switched on
    with_inputs = _render(scene, tmp_path, "defaults")
    gin = next(n for n in group.nodes if n.bl_idname == "NodeGroupInput")
    gout = next(n for n in group.nodes if n.bl_idname == "NodeGroupOutput")
    mixture = next(n for n in group.nodes if n.bl_idname == "ShaderNodeGroup" and "k1 Color" in n.inputs)
    group.links.new(group.nodes["Subsurface Weight"].inputs[0].links[0].from_socket,  # the grazing factors alone
                    mixture.inputs["Weight Scale"])
    group.links.remove(mixture.inputs["Body"].links[0])  # no diffuse body
    group.links.new(mixture.outputs["BSSRDF"], gout.inputs["Cycles"])  # no Emission, no Alpha
    per_metre = group.nodes.new("ShaderNodeMath")  # radii from the Unit Scale itself: 1 / Unit Scale
    per_metre.operation = "DIVIDE"
    per_metre.inputs[0].default_value = 1.0
    group.links.new(gin.outputs["Unit Scale"], per_metre.inputs[1])
    for link in list(group.nodes["Translucency"].outputs[0].links):
        group.links.new(per_metre.outputs[0], link.to_socket)
    without = _render(scene, tmp_path, "without")
    np.testing.assert_array_equal(with_inputs, without)


@pytest.mark.slow
def test_subsurface_weight_mask_gives_a_diffuse_body_where_it_is_0(tmp_path, addon):
    scene, mat = _scene(tmp_path, columns=4, samples=256)
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    coords = tree.nodes.new("ShaderNodeTexCoord")
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    mask = tree.nodes.new("ShaderNodeMath")
    mask.operation = "GREATER_THAN"  # the right half of the view (object x > 0): skin; the left: none
    mask.inputs[1].default_value = 0.0
    tree.links.new(coords.outputs["Object"], split.inputs[0])
    tree.links.new(split.outputs["X"], mask.inputs[0])
    tree.links.new(mask.outputs[0], principled.inputs["Subsurface Weight"])
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    node, _ = _live(mat)
    assert node.inputs["Subsurface Weight"].links[0].from_node == mask  # the mask, linked
    skin = _render(scene, tmp_path, "mask")
    body = _stripes(skin)
    coat = principled_coat_reflectance(scene, [1.0], ROUGHNESS, nodes.DEFAULT_IOR)[0]
    painted = srgb_decode(np.resize(CODES, (4, 3)) / 255.0)
    de = delta_e76(linear_srgb_to_lab(body - coat), linear_srgb_to_lab(painted))
    print(f"\nSubsurface Weight 0 | 1: ΔE76 {np.round(de, 2).tolist()}")
    assert de[:2].max() <= 0.5, de  # a diffuse body of the painted colour under the coat
    assert de[2:].max() <= 1.5, de  # the skin (its accuracy at low noise: tests/test_live_colours.py)
    # the diffuse half is not the skin: its render has no light bleeding, so it is nearly noiseless
    assert skin[:, :STRIPE].std(axis=0).mean() < 0.5 * skin[:, 2 * STRIPE:3 * STRIPE].std(axis=0).mean()


def test_alpha_and_emission_keep_their_effect(tmp_path, addon):
    scene, mat = _scene(tmp_path, samples=32)
    principled = mat.node_tree.nodes["Principled BSDF"]
    principled.inputs["Emission Color"].default_value = (0.2, 0.5, 0.9, 1.0)
    principled.inputs["Emission Strength"].default_value = 0.5
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    node, _ = _live(mat)
    emitting = _stripes(_render(scene, tmp_path, "emission"))
    node.inputs["Emission Strength"].default_value = 0.0
    plain = _stripes(_render(scene, tmp_path, "plain"))
    np.testing.assert_allclose(emitting - plain, np.tile([0.1, 0.25, 0.45], (2, 1)), atol=0.015)
    node.inputs["Alpha"].default_value = 0.0
    transparent = _render(scene, tmp_path, "alpha")
    mat.node_tree.links.new(mat.node_tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0],
                            mat.node_tree.get_output_node("CYCLES").inputs["Surface"])
    np.testing.assert_allclose(transparent, _render(scene, tmp_path, "transparent"), atol=1e-6)


def test_translucency_scales_every_radius(tmp_path, addon):
    scene, mat = _scene(tmp_path, samples=1)
    scene.cycles.filter_width = 0.01
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    node, group = _live(mat)
    mixture = next(n for n in group.nodes if n.bl_idname == "ShaderNodeGroup" and "k1 Color" in n.inputs)
    gout = next(n for n in group.nodes if n.bl_idname == "NodeGroupOutput")
    group.interface.new_socket("Check Radius", in_out="OUTPUT", socket_type="NodeSocketColor")
    emission = mat.node_tree.nodes.new("ShaderNodeEmission")
    mat.node_tree.links.new(emission.outputs[0], mat.node_tree.get_output_node("CYCLES").inputs["Surface"])
    radii = []
    for translucency in (1.0, 2.5):
        node.inputs["Translucency"].default_value = translucency
        for k in range(1, group["spectral_skin_sss_k"] + 1):
            group.links.new(mixture.inputs[f"k{k} Radius"].links[0].from_socket, gout.inputs["Check Radius"])
            mat.node_tree.links.new(node.outputs["Check Radius"], emission.inputs["Color"])
            radii.append(_stripes(_render(scene, tmp_path, f"radius{k}")))
    radii = np.array(radii).reshape(2, -1)
    assert np.all(radii[0] > 0.0)
    np.testing.assert_allclose(radii[1], 2.5 * radii[0], rtol=1e-5)
