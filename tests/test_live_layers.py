"""A layered material keeps its layers: where the artist's Principled BSDF reaches the Material Output through a Mix
Shader (a glow, a sweat or oil layer), the renderers render the add-on's group under the same layer
(blender_addon.wiring.shader_chain, feed_render_outputs), in real Cycles on the probe box (camera straight above,
white world), live and baked.

The layer is an Emission of a saturated blue mixed in at factor 0.3, so the render must be 0.7 x (the painted skin
plus the coat, Blender's own Principled specular layer) + 0.3 x the emission; with the layer dropped (the group
alone on the outputs, as the operator wired such a material before) it is the skin alone, ΔE76 over 20 away.
Remove Skin SSS takes the copied layer away with the rest and the artist's tree is as it was.
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
from blender_addon import live, probe, wiring  # noqa: E402
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode  # noqa: E402
from tests.addon_scene import principled_coat_reflectance, render_linear, run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SKIN = (180, 120, 95)  # medium skin, 8-bit sRGB
GLOW = (0.05, 0.2, 1.0)  # the emission layer's colour (linear), strength 1
FACTOR = 0.3
SIZE = 16
ROUGHNESS = 0.5


def _tree_state(material: bpy.types.Material) -> tuple:
    tree = material.node_tree
    return (sorted(n.name for n in tree.nodes),
            sorted((ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
                   for ln in tree.links))


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["LIVE", "BAKE"])
def test_a_layer_over_the_principled_bsdf_renders_over_the_skin(tmp_path, mode):
    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    try:
        scene = probe.new_scene(samples=64, resolution=SIZE, seed=5)
        pixels = np.broadcast_to(np.array(SKIN, np.uint8), (SIZE, SIZE, 3))
        image = bpy.data.images.load(str(write_image(tmp_path / "skin.png", pixels, "uint8")))
        mat = box_material(image, "principled")
        tree = mat.node_tree
        principled = tree.nodes["Principled BSDF"]
        output = wiring.active_output(tree)
        glow, layer = tree.nodes.new("ShaderNodeEmission"), tree.nodes.new("ShaderNodeMixShader")
        glow.inputs["Color"].default_value = (*GLOW, 1.0)
        layer.inputs["Fac"].default_value = FACTOR
        tree.links.new(principled.outputs["BSDF"], layer.inputs[1])
        tree.links.new(glow.outputs["Emission"], layer.inputs[2])
        tree.links.new(layer.outputs["Shader"], output.inputs["Surface"])
        tree.nodes.active = principled.inputs["Base Color"].links[0].from_node  # the albedo image, for the bake
        before = _tree_state(mat)
        assert run_invert(bpy.data.objects["ProbeSlab"], mode=mode) == {"FINISHED"}
        gnode = wiring.wired_group_node(mat)
        assert gnode is not None and wiring.is_added(gnode)
        assert output.inputs["Surface"].links[0].from_node == layer  # the exporters' view: the artist's layer
        backends = sorted(n.node_tree.get("spectral_skin_sss_backend", "") for n in tree.nodes
                          if n.bl_idname == "ShaderNodeGroup" and wiring.is_added(n))
        assert "GRAZING" in backends or mode == "LIVE"  # baked maps get the grazing-light correction, layered or not
        rgb = render_linear(scene, tmp_path / f"{mode}.exr")[2:-2, 2:-2].reshape(-1, 3).mean(axis=0)
        coat = principled_coat_reflectance(scene, [1.0], ROUGHNESS, live.nodes.DEFAULT_IOR)[0]
        skin = srgb_decode(np.array(SKIN, np.float64) / 255.0) + coat
        expected = (1.0 - FACTOR) * skin + FACTOR * np.array(GLOW)
        lab = linear_srgb_to_lab
        de = float(delta_e76(lab(rgb[None]), lab(expected[None]))[0])
        dropped = float(delta_e76(lab(skin[None]), lab(expected[None]))[0])
        print(f"\n{mode}: ΔE76 {de:.2f} from 0.7 skin + 0.3 glow (the skin alone is {dropped:.1f} from it)")
        assert de <= 2.0 and dropped > 20.0
        with bpy.context.temp_override(object=bpy.data.objects["ProbeSlab"],
                                       active_object=bpy.data.objects["ProbeSlab"]):
            assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
        assert _tree_state(mat) == before
    finally:
        blender_addon.unregister()
