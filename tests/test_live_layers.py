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
GLOW = (0.05, 0.2, 1.0)  # the emission layer's colour (linear), strength 1
FACTOR = 0.3
SIZE = 16
ROUGHNESS = 0.5


def _tree_state(material: bpy.types.Material) -> tuple:
    tree = material.node_tree
    return (sorted(n.name for n in tree.nodes),
            sorted((ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
                   for ln in tree.links))


@pytest.fixture
def glow(tmp_path):
    """The probe scene with the add-on registered and :func:`_glow_material`: (scene, material, its Mix Shader)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    scene = probe.new_scene(samples=64, resolution=SIZE, seed=5)
    yield (scene, *_glow_material(tmp_path))
    blender_addon.unregister()


def _glow_material(tmp_path: Path) -> tuple[bpy.types.Material, bpy.types.Node]:
    """The probe box's artist material: the medium skin texture into a Principled BSDF (Roughness 0.5), reaching
    the Material Output through a Mix Shader that mixes the blue glow in at :data:`FACTOR`; returns it and that
    Mix Shader."""
    pixels = np.broadcast_to(np.array(SKIN, np.uint8), (SIZE, SIZE, 3))
    mat = box_material(bpy.data.images.load(str(write_image(tmp_path / "skin.png", pixels, "uint8"))), "principled")
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    principled.inputs["Roughness"].default_value = ROUGHNESS
    glow, layer = tree.nodes.new("ShaderNodeEmission"), tree.nodes.new("ShaderNodeMixShader")
    glow.inputs["Color"].default_value = (*GLOW, 1.0)
    layer.inputs["Fac"].default_value = FACTOR
    tree.links.new(principled.outputs["BSDF"], layer.inputs[1])
    tree.links.new(glow.outputs["Emission"], layer.inputs[2])
    tree.links.new(layer.outputs["Shader"], wiring.active_output(tree).inputs["Surface"])
    return mat, layer


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["LIVE", "BAKE"])
def test_a_layer_over_the_principled_bsdf_renders_over_the_skin(tmp_path, glow, mode):
    scene, mat, layer = glow
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    output = wiring.active_output(tree)
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


def _copies(mat: bpy.types.Material, target: str) -> list[str]:
    """The names of the artist's nodes whose copies feed the ``target`` render output, output side first."""
    return [n[wiring.LAYER_OF_PROP] for n in wiring._copies_below(
        wiring.render_output(mat.node_tree, target).inputs["Surface"])[0]]


@pytest.mark.slow
def test_the_copied_layers_follow_the_artists(tmp_path, glow):
    """After Invert Skin Albedo the artist's layer keeps working: its factor raised from 0.3 to 0.6 renders 0.4 x the
    skin plus the coat + 0.6 x the glow (ΔE76 within 2, the same copy nodes), a mask linked to the factor feeds the
    copies, a layer added on top is copied over the skin (and its factor follows), a layer taken out leaves the
    copies, and Remove Skin SSS leaves the artist's tree as the artist left it."""
    scene, mat, layer = glow
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    output = wiring.active_output(tree)
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [layer.name]
    names = sorted(n.name for n in tree.nodes)
    layer.inputs["Fac"].default_value = 0.6
    bpy.context.view_layer.update()
    assert sorted(n.name for n in tree.nodes) == names  # the same copies took the factor
    rgb = render_linear(scene, tmp_path / "raised.exr")[2:-2, 2:-2].reshape(-1, 3).mean(axis=0)
    coat = principled_coat_reflectance(scene, [1.0], ROUGHNESS, live.nodes.DEFAULT_IOR)[0]
    skin = srgb_decode(np.array(SKIN, np.float64) / 255.0) + coat
    lab = linear_srgb_to_lab
    de = float(delta_e76(lab(rgb[None]), lab((0.4 * skin + 0.6 * np.array(GLOW))[None]))[0])
    stale = float(delta_e76(lab(rgb[None]), lab((0.7 * skin + 0.3 * np.array(GLOW))[None]))[0])
    print(f"\nfactor 0.6: ΔE76 {de:.2f} from 0.4 skin + 0.6 glow ({stale:.1f} from the factor as wired)")
    assert de <= 2.0 and stale > 10.0
    mask = tree.nodes.new("ShaderNodeValue")
    tree.links.new(mask.outputs[0], layer.inputs["Fac"])
    bpy.context.view_layer.update()
    for target in ("CYCLES", "EEVEE"):
        (copy,) = wiring._copies_below(wiring.render_output(tree, target).inputs["Surface"])[0]
        assert copy.inputs["Fac"].links[0].from_node == mask
    top, sweat = tree.nodes.new("ShaderNodeMixShader"), tree.nodes.new("ShaderNodeBsdfGlossy")
    tree.links.new(layer.outputs[0], top.inputs[1])
    tree.links.new(sweat.outputs[0], top.inputs[2])
    tree.links.new(top.outputs[0], output.inputs["Surface"])
    bpy.context.view_layer.update()
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [top.name, layer.name]
    top.inputs["Fac"].default_value = 0.25
    bpy.context.view_layer.update()
    for target in ("CYCLES", "EEVEE"):
        copy = wiring._copies_below(wiring.render_output(tree, target).inputs["Surface"])[0][0]
        assert copy.inputs["Fac"].default_value == pytest.approx(0.25)
        assert copy.inputs[2].links[0].from_node == sweat
    assert wiring.wired_group_node(mat) is not None
    tree.links.new(principled.outputs["BSDF"], top.inputs[1])  # the glow taken out: skin, then sweat
    bpy.context.view_layer.update()
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [top.name]
    assert wiring.wired_group_node(mat) is not None
    # a file wired before the copies were marked and followed: opening it copies the layers again, once
    for node in [n for n in tree.nodes if wiring.LAYER_OF_PROP in n]:
        del node[wiring.LAYER_OF_PROP], node[wiring.INNER_PROP]
    record = json.loads(mat[wiring.TAKEN_INPUTS_PROP])
    del record[follow.LAYERS]
    mat[wiring.TAKEN_INPUTS_PROP] = json.dumps(record)
    count = len(tree.nodes)
    follow.follow_on_load()
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [top.name] and len(tree.nodes) == count
    ours = {n.name for n in tree.nodes if wiring.is_added(n)}
    names, links = _tree_state(mat)
    artists = ([n for n in names if n not in ours], [ln for ln in links if ln[0] not in ours and ln[2] not in ours])
    with bpy.context.temp_override(object=bpy.data.objects["ProbeSlab"],
                                   active_object=bpy.data.objects["ProbeSlab"]):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
    assert _tree_state(mat) == artists


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["LIVE", "BAKE"])
def test_reroutes_and_muted_nodes_are_seen_through(tmp_path, glow, mode):
    """A tidy artist's tree: Reroute nodes between the Principled BSDF, its layer and the Material Output and on the
    albedo's link, and a muted Add Shader (it passes its first input through) under the output.  Invert Skin Albedo
    finds the Principled BSDF through them (the live group refused the material before, and baked maps left its
    inputs out), and the render is bit for bit that of the same material without them; Remove Skin SSS leaves them
    as they were."""
    scene, mat, layer = glow
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    output = wiring.active_output(tree)
    albedo = principled.inputs["Base Color"].links[0].from_node
    tree.nodes.active = albedo  # the albedo image, for the bake
    slab = bpy.data.objects["ProbeSlab"]

    def wired_render(name: str) -> np.ndarray:
        assert run_invert(slab, mode=mode) == {"FINISHED"}
        rgb = render_linear(scene, tmp_path / f"{name}.exr")
        with bpy.context.temp_override(object=slab, active_object=slab):
            assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
        return rgb

    plain = wired_render("plain")
    reroutes = [tree.nodes.new("NodeReroute") for _ in range(3)]
    muted, red = tree.nodes.new("ShaderNodeAddShader"), tree.nodes.new("ShaderNodeEmission")
    red.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
    muted.mute = True
    for source, reroute, target in ((principled.outputs["BSDF"], reroutes[0], layer.inputs[1]),
                                    (layer.outputs["Shader"], reroutes[1], muted.inputs[0]),
                                    (albedo.outputs["Color"], reroutes[2], principled.inputs["Base Color"])):
        tree.links.new(source, reroute.inputs[0])
        tree.links.new(reroute.outputs[0], target)
    tree.links.new(red.outputs["Emission"], muted.inputs[1])
    tree.links.new(muted.outputs["Shader"], output.inputs["Surface"])
    before = _tree_state(mat)
    assert np.array_equal(wired_render("tidy"), plain)
    assert _tree_state(mat) == before


def test_a_layer_muted_after_wiring_leaves_the_render_and_comes_back(glow):
    """Muting the artist's layer (M) takes its copy out of what the renderers render, as it takes the layer out of
    the artist's material; unmuting puts it back."""
    _, mat, layer = glow
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [layer.name]
    layer.mute = True
    bpy.context.view_layer.update()
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [] and wiring.wired_group_node(mat) is not None
    layer.mute = False
    bpy.context.view_layer.update()
    assert _copies(mat, "CYCLES") == _copies(mat, "EEVEE") == [layer.name]
