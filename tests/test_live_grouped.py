"""A grouped skin shader: the artist's Principled BSDF inside a node group (an asset's or a character pipeline's skin
shader), in real Cycles on the probe box.

The same material is built twice, flat and grouped: the albedo texture and a roughness value fed in, a Metallic of
0.3 (a layer of the artist's Principled BSDF over the group), an emission added over the Principled BSDF inside the
group and a glow mixed over its output in the material.  Cycles flattens node groups, so the live group wired into
the grouped material must render bit for bit what it renders in the flat one, with a skin edit too.  The group
node goes inside the artist's node group and feeds two outputs added to its interface; Remove Skin SSS gives back
the node group as the artist made it, once no material renders through it."""

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
from blender_addon import edit_masks, follow, live_edits, oblique, probe, wiring  # noqa: E402
from tests.addon_scene import cycles_memory_mb, render_linear, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SKIN = (180, 120, 95)
SIZE = 16
ROUGHNESS = 0.35
METALLIC = 0.3


@pytest.fixture
def scene(tmp_path):
    bpy.ops.wm.read_homefile(use_empty=True)
    blender_addon.register()
    scene = probe.new_scene(samples=32, resolution=SIZE, seed=3)
    yield scene
    blender_addon.unregister()


def _skin_image(tmp_path: Path) -> bpy.types.Image:
    pixels = np.broadcast_to(np.array(SKIN, np.uint8), (SIZE, SIZE, 3))
    return bpy.data.images.load(str(write_image(tmp_path / "skin.png", pixels, "uint8")))


def _principled_with_emission(tree: bpy.types.NodeTree) -> tuple[bpy.types.Node, bpy.types.Node]:
    """A Principled BSDF (Metallic 0.3) with a faint blue emission added over it, in ``tree``: (it, the Add Shader)."""
    principled = tree.nodes.new("ShaderNodeBsdfPrincipled")
    principled.inputs["Metallic"].default_value = METALLIC
    emission, add = tree.nodes.new("ShaderNodeEmission"), tree.nodes.new("ShaderNodeAddShader")
    emission.inputs["Color"].default_value = (0.1, 0.2, 1.0, 1.0)
    emission.inputs["Strength"].default_value = 0.2
    tree.links.new(principled.outputs[0], add.inputs[0])
    tree.links.new(emission.outputs[0], add.inputs[1])
    return principled, add


def _glow_over(tree: bpy.types.NodeTree, socket: bpy.types.NodeSocket) -> bpy.types.Node:
    """``socket`` under a Mix Shader mixing a green glow in at 0.3, into the active Material Output."""
    glow, mix = tree.nodes.new("ShaderNodeEmission"), tree.nodes.new("ShaderNodeMixShader")
    glow.inputs["Color"].default_value = (0.1, 1.0, 0.2, 1.0)
    mix.inputs["Fac"].default_value = 0.3
    tree.links.new(socket, mix.inputs[1])
    tree.links.new(glow.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], wiring.active_output(tree).inputs["Surface"])
    return mix


def _flat(image: bpy.types.Image) -> bpy.types.Material:
    mat = box_material(image, "principled")
    tree = mat.node_tree
    tex = tree.nodes.active
    tree.nodes.remove(next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"))
    principled, add = _principled_with_emission(tree)
    rough = tree.nodes.new("ShaderNodeValue")
    rough.outputs[0].default_value = ROUGHNESS
    tree.links.new(tex.outputs["Color"], principled.inputs["Base Color"])
    tree.links.new(rough.outputs[0], principled.inputs["Roughness"])
    _glow_over(tree, add.outputs[0])
    return mat


def skin_group(name: str = "Skin Shader") -> tuple[bpy.types.NodeTree, bpy.types.Node]:
    """The artist's node group: inputs Albedo and Roughness into a Principled BSDF, an emission added over it, out
    as BSDF; returns it and its Principled BSDF."""
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group.interface.new_socket("Albedo", in_out="INPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("Roughness", in_out="INPUT", socket_type="NodeSocketFloat")
    group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    gin, gout = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    principled, add = _principled_with_emission(group)
    group.links.new(gin.outputs["Albedo"], principled.inputs["Base Color"])
    group.links.new(gin.outputs["Roughness"], principled.inputs["Roughness"])
    group.links.new(add.outputs[0], gout.inputs["BSDF"])
    return group, principled


def grouped_material(image: bpy.types.Image, group: bpy.types.NodeTree) -> bpy.types.Material:
    """The probe box's material with ``group``'s node fed by the texture and a roughness value, under the glow."""
    mat = box_material(image, "principled")
    tree = mat.node_tree
    tex = tree.nodes.active
    tree.nodes.remove(next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"))
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    rough = tree.nodes.new("ShaderNodeValue")
    rough.outputs[0].default_value = ROUGHNESS
    tree.links.new(tex.outputs["Color"], node.inputs["Albedo"])
    tree.links.new(rough.outputs[0], node.inputs["Roughness"])
    _glow_over(tree, node.outputs["BSDF"])
    return mat


def _invert(material: bpy.types.Material) -> None:
    slab = bpy.data.objects["ProbeSlab"]
    slab.active_material = material
    with bpy.context.temp_override(object=slab, active_object=slab):
        assert bpy.ops.spectral_skin.invert_albedo(mode="LIVE") == {"FINISHED"}


def _remove(material: bpy.types.Material) -> None:
    slab = bpy.data.objects["ProbeSlab"]
    slab.active_material = material
    with bpy.context.temp_override(object=slab, active_object=slab):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}


def _state(tree: bpy.types.NodeTree) -> tuple:
    return (sorted(n.name for n in tree.nodes),
            sorted((ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
                   for ln in tree.links),
            [(item.name, item.in_out) for item in tree.interface.items_tree if item.item_type == "SOCKET"])


def test_a_grouped_principled_bsdf_renders_as_a_flat_one(tmp_path, scene):
    image = _skin_image(tmp_path)
    flat = _flat(image)
    _invert(flat)
    expected = render_linear(scene, tmp_path / "flat.exr")
    assert len(wiring.present_layers(flat.node_tree)) > 0  # the metal layer is there to compare

    group, principled = skin_group()
    mat = grouped_material(image, group)
    before_group, before_material = _state(group), _state(mat.node_tree)
    _invert(mat)
    gnode = wiring.wired_group_node(mat)
    assert gnode is not None and gnode.id_data == group  # inside the artist's node group
    assert wiring.artist_principled(mat) == principled
    assert wiring.active_output(mat.node_tree).inputs["Surface"].links[0].from_node.bl_idname == "ShaderNodeMixShader"
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree == group)
    for target, name in wiring.GROUP_OUTPUTS.items():  # each renderer: the glow's copy over the added output
        copy = wiring.render_output(mat.node_tree, target).inputs["Surface"].links[0].from_node
        assert wiring.is_added(copy) and copy.inputs[1].links[0].from_socket == node.outputs[name]
    rgb = render_linear(scene, tmp_path / "grouped.exr")
    assert rgb.mean() > 0.05
    np.testing.assert_array_equal(rgb, expected)
    edited = []  # a skin edit (tan and flush) on each: the same again
    for material in (mat, flat):
        bpy.data.objects["ProbeSlab"].active_material = material
        live_edits.set_edit(wiring.wired_group_node(material), (1.5, 2.0, 0.0))
        bpy.context.view_layer.update()
        edited.append(render_linear(scene, tmp_path / f"edited_{material.name}.exr"))
    assert np.abs(edited[0] - rgb).mean() > 0.01
    np.testing.assert_array_equal(edited[0], edited[1])

    _remove(mat)
    assert _state(group) == before_group and _state(mat.node_tree) == before_material


def test_a_principled_bsdf_two_node_groups_deep_renders_as_a_flat_one(tmp_path, scene):
    """The artist's node group inside another (a character pipeline's skin shader wrapping an asset's), the glow
    mixed over it inside the outer one: the group node goes in the inner one, the outer one passes its outputs up,
    and the render is bit for bit the flat material's; the layers in both groups follow; Remove Skin SSS gives back
    both node groups as they were."""
    image = _skin_image(tmp_path)
    flat = _flat(image)
    _invert(flat)
    expected = render_linear(scene, tmp_path / "flat.exr")

    group, principled = skin_group()
    outer = bpy.data.node_groups.new("Character Skin", "ShaderNodeTree")
    outer.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")  # first: its identifier
    for name, kind in (("Albedo", "NodeSocketColor"), ("Roughness", "NodeSocketFloat")):  # is not the inner one's
        outer.interface.new_socket(name, in_out="INPUT", socket_type=kind)
    gin, gout, core = (outer.nodes.new(kind) for kind in ("NodeGroupInput", "NodeGroupOutput", "ShaderNodeGroup"))
    core.node_tree = group
    for name in ("Albedo", "Roughness"):
        outer.links.new(gin.outputs[name], core.inputs[name])
    glow, mix = outer.nodes.new("ShaderNodeEmission"), outer.nodes.new("ShaderNodeMixShader")
    glow.inputs["Color"].default_value = (0.1, 1.0, 0.2, 1.0)
    mix.inputs["Fac"].default_value = 0.3
    outer.links.new(core.outputs["BSDF"], mix.inputs[1])
    outer.links.new(glow.outputs[0], mix.inputs[2])
    outer.links.new(mix.outputs[0], gout.inputs["Shader"])
    mat = box_material(image, "principled")
    tree = mat.node_tree
    tex = tree.nodes.active
    tree.nodes.remove(next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"))
    node, rough = tree.nodes.new("ShaderNodeGroup"), tree.nodes.new("ShaderNodeValue")
    node.node_tree = outer
    rough.outputs[0].default_value = ROUGHNESS
    tree.links.new(tex.outputs["Color"], node.inputs["Albedo"])
    tree.links.new(rough.outputs[0], node.inputs["Roughness"])
    tree.links.new(node.outputs["Shader"], wiring.active_output(tree).inputs["Surface"])
    before = _state(group), _state(outer), _state(tree)
    _invert(mat)
    gnode = wiring.wired_group_node(mat)
    assert gnode is not None and gnode.id_data == group and wiring.artist_principled(mat) == principled
    assert len(wiring.chain_copies(outer)) == 2  # the glow's copies over what each renderer renders
    np.testing.assert_array_equal(render_linear(scene, tmp_path / "nested.exr"), expected)
    mix.inputs["Fac"].default_value = 0.6  # the outer group's layer, and the inner group's, follow
    emission = next(n for n in group.nodes if n.bl_idname == "ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 0.7
    bpy.context.view_layer.update()
    assert [c.inputs["Fac"].default_value for c in wiring.chain_copies(outer)] == pytest.approx([0.6, 0.6])
    assert all(c.inputs[1].links[0].from_node == emission for c in wiring.chain_copies(group))
    assert set(json.loads(mat[wiring.TAKEN_INPUTS_PROP])[follow.GROUP_LAYERS]) == {group.name, outer.name}
    _remove(mat)
    assert (_state(group), _state(outer), _state(tree)) == before


def test_the_grouped_skin_follows_the_artist_and_is_shared(tmp_path, scene, capfd):
    """Inputs changed inside the node group reach the group node there (roughness, the emission layer's strength,
    Metallic up to 0 and back); a second material using the same node group is wired through the same group node,
    and the report says with which material it shares it;
    removing one keeps the other rendering, removing both gives back the node group as it was."""
    image = _skin_image(tmp_path)
    group, principled = skin_group()
    first, second = grouped_material(image, group), grouped_material(image, group)
    before_group = _state(group)
    _invert(first)
    gnode = wiring.wired_group_node(first)
    counts = len(group.nodes), len(first.node_tree.nodes)
    _invert(first)  # up to date: nothing made again
    assert wiring.wired_group_node(first) == gnode and (len(group.nodes), len(first.node_tree.nodes)) == counts
    rough = group.nodes.new("ShaderNodeValue")
    group.links.new(rough.outputs[0], principled.inputs["Roughness"])
    bpy.context.view_layer.update()
    assert gnode.inputs["Roughness"].links[0].from_node == rough
    add = next(n for n in group.nodes if n.bl_idname == "ShaderNodeAddShader" and not wiring.is_added(n))
    emission = add.inputs[1].links[0].from_node
    emission.inputs["Strength"].default_value = 0.7
    bpy.context.view_layer.update()
    copies = wiring.chain_copies(group)
    assert len(copies) == 2 and all(c.inputs[1].links[0].from_node == emission for c in copies)
    principled.inputs["Metallic"].default_value = 0.0
    bpy.context.view_layer.update()
    assert not wiring.present_layers(group)
    principled.inputs["Metallic"].default_value = METALLIC
    bpy.context.view_layer.update()
    assert wiring.present_layers(group) == {"Metallic"}
    record = json.loads(first[wiring.TAKEN_INPUTS_PROP])
    assert record[follow.GROUP_LAYERS][group.name][0][0] == add.name

    capfd.readouterr()
    _invert(second)
    assert wiring.wired_group_node(second) == gnode  # one group node for every material using the node group
    assert f"wired into '{second.name}' inside its node group 'Skin Shader', shared with '{first.name}'" \
        in capfd.readouterr().out
    alone = render_linear(scene, tmp_path / "second.exr")
    _remove(first)
    assert wiring.wired_group_node(second) == gnode
    bpy.data.objects["ProbeSlab"].active_material = second
    np.testing.assert_array_equal(render_linear(scene, tmp_path / "second_after.exr"), alone)
    _remove(second)
    group.nodes.remove(rough)
    group.links.new(next(n for n in group.nodes if n.bl_idname == "NodeGroupInput").outputs["Roughness"],
                    principled.inputs["Roughness"])
    assert _state(group) == before_group


def test_a_node_group_linked_from_a_library_is_refused(tmp_path, scene):
    """A node group whose nodes cannot be kept (linked from a library) is named, and nothing changes."""
    group, _ = skin_group("Library Skin")
    path = tmp_path / "library.blend"
    bpy.data.libraries.write(str(path), {group})
    bpy.data.node_groups.remove(group)
    with bpy.data.libraries.load(str(path), link=True) as (_, data):
        data.node_groups = ["Library Skin"]
    linked = bpy.data.node_groups["Library Skin"]
    assert linked.library is not None
    mat = grouped_material(_skin_image(tmp_path), linked)
    before = _state(mat.node_tree)
    slab = bpy.data.objects["ProbeSlab"]
    slab.active_material = mat
    with bpy.context.temp_override(object=slab, active_object=slab):
        with pytest.raises(RuntimeError, match="node group 'Library Skin' is linked from a library"):
            bpy.ops.spectral_skin.invert_albedo(mode="LIVE")
    assert _state(mat.node_tree) == before


EEVEE_SCRIPT = """
import json, sys, tempfile
from pathlib import Path
sys.path.insert(0, {root!r})
import bpy
import blender_addon
from blender_addon import probe
import tests.test_live_grouped as t
tmp = Path(tempfile.mkdtemp())
scene = probe.new_scene(samples=1, resolution=t.SIZE, seed=1)
scene.render.engine = "BLENDER_EEVEE"
scene.eevee.taa_render_samples = 4
blender_addon.register()
image = t._skin_image(tmp)
renders = []
for material in (t._flat(image), t.grouped_material(image, t.skin_group()[0])):
    t._invert(material)
    renders.append(t.render_linear(scene, tmp / (material.name + ".exr")).tolist())
print("RESULT" + json.dumps(renders))
"""


@pytest.mark.slow
def test_eevee_renders_a_grouped_principled_bsdf_as_a_flat_one(tmp_path):
    """EEVEE (and Material Preview) renders the node group's added EEVEE output: bit for bit what it renders for the
    flat material (one process, software OpenGL where there is no GPU)."""
    import os
    import subprocess

    env = dict(os.environ, EGL_PLATFORM=os.environ.get("EGL_PLATFORM", "surfaceless"),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-c", EEVEE_SCRIPT.format(root=str(ROOT))], capture_output=True, text=True,
                          env=env, timeout=600)
    line = next((ln for ln in done.stdout.splitlines() if ln.startswith("RESULT")), None)
    assert line is not None, done.stdout[-2000:] + done.stderr[-2000:]
    flat, grouped = (np.array(r) for r in json.loads(line[len("RESULT"):]))
    assert flat.mean() > 0.05
    np.testing.assert_array_equal(grouped, flat)


def test_exporters_write_the_grouped_material_as_before(tmp_path, scene):
    """Blender's exporters after Invert Skin Albedo on a grouped material write what they wrote before (glTF reads
    the Principled BSDF through the node group's own output, which the add-on leaves alone)."""
    from tests.export_check import export_all

    group, _ = skin_group()
    mat = grouped_material(_skin_image(tmp_path), group)
    bpy.data.objects["ProbeSlab"].active_material = mat
    before = export_all(str(tmp_path / "before"))
    assert before["gltf"]["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] is not None
    _invert(mat)
    assert export_all(str(tmp_path / "after")) == before


def test_a_saved_file_and_a_single_user_copy_of_the_node_group(tmp_path, scene):
    """The wiring inside the node group lasts through save and reopen (what changes there afterwards still
    follows), and a material given its own copy of the node group (Blender's user-count button copies the group with
    the add-on's nodes in it) renders through the copy's group node; removing it gives back that copy as the
    artist's, the other material keeping the original."""
    image = _skin_image(tmp_path)
    group, _ = skin_group()
    first, second = grouped_material(image, group), grouped_material(image, group)
    before_group = _state(group)
    _invert(first)
    _invert(second)
    first.use_fake_user = second.use_fake_user = True  # the probe box shows one of them: keep both in the file
    path, names = tmp_path / "grouped.blend", (first.name, second.name)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    first, second = (bpy.data.materials[name] for name in names)
    group = bpy.data.node_groups["Skin Shader"]
    principled = next(n for n in group.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled" and not wiring.is_added(n))
    gnode = wiring.wired_group_node(first)
    assert gnode is not None and gnode.id_data == group and wiring.wired_group_node(second) == gnode
    principled.inputs["Specular Tint"].default_value = (1.0, 0.5, 0.5, 1.0)
    bpy.context.view_layer.update()
    assert tuple(gnode.inputs["Specular Tint"].default_value) == (1.0, 0.5, 0.5, 1.0)

    node = next(n for n in first.node_tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree == group)
    node.node_tree = group.copy()
    own = wiring.wired_group_node(first)
    assert own is not None and own.id_data == node.node_tree and wiring.wired_group_node(second) == gnode
    _remove(first)
    assert _state(node.node_tree) == before_group  # the copy is the artist's node group again
    assert wiring.wired_group_node(second) == gnode
    _remove(second)
    assert _state(group) == before_group


def _uv_mapped(material: bpy.types.Material) -> None:
    """The albedo's Image Texture read through a UV Map node (the probe box's object coordinates taken out; the
    texture is one colour, so the render is the same)."""
    tree = material.node_tree
    tex = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage")
    tree.links.new(tree.nodes.new("ShaderNodeUVMap").outputs["UV"], tex.inputs["Vector"])
    tree.nodes.active = tex


def test_baked_maps_go_inside_a_grouped_skin_and_render_as_flat(tmp_path, scene):
    """Bake maps on a grouped material whose node group is its own and whose albedo reads a UV map: the mixture group,
    its maps (reading the same UV map through a UV Map node of their own), the grazing-light correction and the
    metal layer go inside the node group, and the render is bit for bit that of the same material built flat and
    baked; Remove Skin SSS gives back the node group and the material as they were."""
    image = _skin_image(tmp_path)
    flat = _flat(image)
    _uv_mapped(flat)
    slab = bpy.data.objects["ProbeSlab"]
    slab.active_material = flat
    with bpy.context.temp_override(object=slab, active_object=slab):
        assert bpy.ops.spectral_skin.invert_albedo(mode="BAKE") == {"FINISHED"}
    expected = render_linear(scene, tmp_path / "flat_baked.exr")

    group, principled = skin_group()
    mat = grouped_material(image, group)
    _uv_mapped(mat)
    before = _state(group), _state(mat.node_tree)
    slab.active_material = mat
    with bpy.context.temp_override(object=slab, active_object=slab):
        assert bpy.ops.spectral_skin.invert_albedo(mode="BAKE") == {"FINISHED"}
    gnode = wiring.wired_group_node(mat)
    assert gnode is not None and gnode.id_data == group and "k1 Color" in gnode.inputs
    uv = next(n for n in group.nodes if n.bl_idname == "ShaderNodeUVMap")
    maps = [oblique.map_node(s) for s in gnode.inputs if s.name.startswith("k")]
    assert maps and all(m.id_data == group and m.inputs["Vector"].links[0].from_node == uv for m in maps)
    assert wiring.present_layers(group) == {"Metallic"}
    np.testing.assert_array_equal(render_linear(scene, tmp_path / "grouped_baked.exr"), expected)
    _remove(mat)
    assert (_state(group), _state(mat.node_tree)) == before


def test_a_control_exposed_on_the_artists_node_group_renders_from_a_cache(tmp_path, scene):
    """Melanin exposed as an input of the artist's node group (the live group node inside, fed by the Group Input)
    and set on the material's group node: Cycles folds the group node's unlinked input as it does the live node's
    own, so the edit is a constant one (live_edits.input_value), cached by the handler and rendered bit for bit as
    the same value set on the live node, the compiled shader holding the cache's images, not the table's (Cycles'
    memory); a bake takes it (edit_masks.live_bake_edit); keyed on the group node, it holds its line in the mask
    cache (live_edits.hold_line).  A second material giving the node group's input another
    value makes it vary: the edit reads the table, and the panel says why."""
    image = _skin_image(tmp_path)
    group, _ = skin_group()
    mat = grouped_material(image, group)
    _invert(mat)
    inner = wiring.wired_group_node(mat)
    live_edits.set_edit(inner, (1.5, 2.5, -0.2))  # every control on: the table's path reads all six images
    bpy.context.view_layer.update()
    assert live_edits.cache_status(inner).startswith("Rendered from edit cache")
    direct = render_linear(scene, tmp_path / "direct.exr")
    cached_mb = cycles_memory_mb(lambda: render_linear(scene, tmp_path / "direct.exr"))
    inner.inputs["Melanin"].default_value = 1.0
    group.interface.new_socket("Melanin", in_out="INPUT", socket_type="NodeSocketFloat")
    group.links.new(next(n for n in group.nodes if n.bl_idname == "NodeGroupInput").outputs["Melanin"],
                    inner.inputs["Melanin"])
    outer = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree == group)
    outer.inputs["Melanin"].default_value = 1.5
    bpy.context.view_layer.update()  # the handler caches it
    assert live_edits.input_value(inner, "Melanin") == 1.5 and live_edits.linked_flags(inner) == 0
    assert live_edits.cache_status(inner).startswith("Rendered from edit cache"), live_edits.cache_status(inner)
    np.testing.assert_array_equal(render_linear(scene, tmp_path / "exposed.exr"), direct)
    assert cycles_memory_mb(lambda: render_linear(scene, tmp_path / "exposed.exr")) - cached_mb <= 0.5
    live_edits.unregister_handlers()  # which would cache it again
    try:
        live_edits.set_edit(inner, (1.0, 2.5, -0.2), cache=False)  # the table's path, which the memory tells apart
        assert cycles_memory_mb(lambda: render_linear(scene, tmp_path / "table.exr")) - cached_mb >= 4.0
    finally:
        live_edits.register_handlers()
    tex = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeTexImage")
    assert edit_masks.live_bake_edit(mat, tex, (SIZE, SIZE)) == ((1.5, 2.5, float(np.float32(-0.2))), {})
    live_edits.set_edit(inner, (1.0, 1.0, 0.0))  # Melanin alone, keyframed on the material's group node: its line
    scene.frame_start, scene.frame_end = 1, 24
    for frame, melanin in ((1, 1.0), (21, 1.5)):
        outer.inputs["Melanin"].default_value = melanin
        outer.inputs["Melanin"].keyframe_insert("default_value", frame=frame)
    bpy.context.view_layer.update()
    assert live_edits.animated_line(inner, scene) == (1.5, 1.0, 0.0)
    assert live_edits.line_status(inner, scene) == "Animation render: from the mask cache"
    mat.node_tree.animation_data_clear()
    outer.inputs["Melanin"].default_value = 1.5
    other = grouped_material(image, group)
    second = next(n for n in other.node_tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree == group)
    second.inputs["Melanin"].default_value = 1.5  # the same value: still one
    assert live_edits.input_value(inner, "Melanin") == 1.5
    second.inputs["Melanin"].default_value = 2.0
    assert live_edits.input_value(inner, "Melanin") is None and live_edits.cache_edit(inner) == 0
    assert live_edits.linked_flags(inner) == 1
    assert live_edits.cache_status(inner) == \
        "Read from the edit table: the node group's users give a control different values"


def test_a_mask_fed_through_the_artists_node_group_is_baked(tmp_path, scene):
    """Blood exposed as an input of the artist's node group and painted in the material by a mask image (its green,
    into a Math Multiply Add, into the group node): the edit reads the table, the panel says a node feeds it, and a
    bake from the live group reads the mask from its image, rows top down (edit_masks.live_bake_edit through
    wiring.source_socket)."""
    image = _skin_image(tmp_path)
    group, _ = skin_group()
    mat = grouped_material(image, group)
    _invert(mat)
    inner = wiring.wired_group_node(mat)
    group.interface.new_socket("Blush", in_out="INPUT", socket_type="NodeSocketFloat")
    group.links.new(next(n for n in group.nodes if n.bl_idname == "NodeGroupInput").outputs["Blush"],
                    inner.inputs["Blood"])
    tree = mat.node_tree
    tex = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage" and n.image == image)
    grey = (np.arange(SIZE * SIZE).reshape(SIZE, SIZE) % 251).astype(np.uint8)  # every row its own: orientation
    mask = tree.nodes.new("ShaderNodeTexImage")
    mask.image = bpy.data.images.load(str(write_image(tmp_path / "mask.png", np.repeat(grey[..., None], 3, -1),
                                                      "uint8")))
    mask.image.colorspace_settings.name = "Non-Color"
    tree.links.new(tex.inputs["Vector"].links[0].from_socket, mask.inputs["Vector"])
    split, blush = tree.nodes.new("ShaderNodeSeparateColor"), tree.nodes.new("ShaderNodeMath")
    blush.operation = "MULTIPLY_ADD"
    blush.inputs[1].default_value, blush.inputs[2].default_value = 1.5, 1.0
    tree.links.new(mask.outputs["Color"], split.inputs[0])
    tree.links.new(split.outputs["Green"], blush.inputs[0])
    outer = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree == group)
    tree.links.new(blush.outputs[0], outer.inputs["Blush"])
    bpy.context.view_layer.update()
    assert live_edits.input_value(inner, "Blood") is None
    assert live_edits.cache_status(inner) == "Read from the edit table: a control is fed by a node"
    edit, masks = edit_masks.live_bake_edit(mat, tex, (SIZE, SIZE))
    assert edit == (1.0, 2.5, 0.0) and list(masks) == ["blood"]
    np.testing.assert_allclose(masks["blood"], grey / 255.0, rtol=1e-6, atol=1e-7)
