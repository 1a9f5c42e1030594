"""The live group's Melanin, Blood and Oxygenation inputs (blender_addon.live_edits) in real Cycles: the K media the
group looks up under an edit equal the numpy reference (exporters.edit_table: shift, edited colour, texel table at
the edited colour, radius factor) and the maps a fast bake writes with the same edit; at neutral inputs they equal
those of a group built without the edit nodes bit for bit, and keyframes on the node's inputs animate them.  Each
check renders one socket of the group as emission, one pixel per colour (tests/test_live_group.py's probe strip).
Invert Skin Albedo wires a group with the inputs and the panel's presets set them."""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import edit_masks, live, live_edits, preferences, probe  # noqa: E402
from exporters import bake, edit_table, live_table, maps, skin_edits  # noqa: E402
from tests.addon_scene import (  # noqa: E402
    cycles_memory_mb,
    image_pixels,
    run_invert,
    skin_codes,
    skin_object,
    write_image,
)
from tests.test_live_group import _probe_strip, _render_row  # noqa: E402

#: Skin colours light to dark, a saturated red, a colour outside the box (blue) and one above 1.
COLOURS = np.array([[0.62, 0.42, 0.33], [0.45, 0.28, 0.20], [0.40, 0.20, 0.12], [0.25, 0.14, 0.09],
                    [0.10, 0.055, 0.035], [0.9, 0.02, 0.01], [0.05, 0.1, 0.8], [1.2, 0.9, 0.8]])
EDIT = {"Melanin": 2.0, "Blood": 0.5, "Oxygenation": -0.2}


@pytest.fixture
def addon():
    blender_addon.register()
    yield
    blender_addon.unregister()


def _tables():
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    edits = live_edits.table_for_model(preferences.DEFAULT_MODEL, table.sha256)
    assert edits is not None, "the shipped edit table must belong to the shipped model and texel table"
    return table, edits


def _with_checks(group: bpy.types.NodeTree, k: int) -> list[str]:
    """Outputs 'Check k{i} {kind}' exposing the media the group hands its mixture."""
    mixture = next(n for n in group.nodes if n.bl_idname == "ShaderNodeGroup" and "k1 Color" in n.inputs)
    gout = next(n for n in group.nodes if n.bl_idname == "NodeGroupOutput")
    names = []
    for i in range(1, k + 1):
        for kind in ("Color", "Radius", "Weight"):
            name = f"Check k{i} {kind}"
            group.interface.new_socket(name, in_out="OUTPUT", socket_type="NodeSocketColor")
            group.links.new(mixture.inputs[f"k{i} {kind}"].links[0].from_socket, gout.inputs[name])
            names.append(name)
    return names


def _strip(tmp_path: Path):
    """The probe strip (a new scene: make groups after it) with a group node fed by the colours."""
    scene, mat, _ = _probe_strip(COLOURS, tmp_path)
    tree = mat.node_tree
    tex = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage")
    gnode = tree.nodes.new("ShaderNodeGroup")
    gnode["colour_source"] = tex.name
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(emission.outputs[0], probe.material_output(mat).inputs["Surface"])
    return scene, tree, gnode, emission


def _use(tree, gnode, group: bpy.types.NodeTree) -> None:
    """Give the strip's group node ``group``, fed by the colours."""
    gnode.node_tree = group
    tree.links.new(tree.nodes[gnode["colour_source"]].outputs["Color"], gnode.inputs["Color"])


def _edit_strip(tmp_path: Path):
    """The strip (:func:`_strip`) with the group node using a live group with the edit nodes and its media exposed
    (:func:`_with_checks`): (scene, tree, gnode, emission, table, edit table, layout, images, group, check names)."""
    scene, tree, gnode, emission = _strip(tmp_path)
    table, edits = _tables()
    layout, images = live.ensure_images(table)
    group = live.build_live_group(table, layout, images, (edits, live_edits.ensure_images(edits)))
    names = _with_checks(group, table.k)
    _use(tree, gnode, group)
    return scene, tree, gnode, emission, table, edits, layout, images, group, names


def _render(scene, tree, gnode, emission, name: str) -> np.ndarray:
    tree.links.new(gnode.outputs[name], emission.inputs["Color"])
    return _render_row(scene)


#: Samples of a probe render of the table's drawn texels: its average's spread is the draws' over 128.
DRAWN_SAMPLES = 16384


def _edited_media(table, d: np.ndarray, grids) -> dict[str, np.ndarray]:
    """Reference of the probe's media (:func:`_with_checks`' names) at :data:`COLOURS` under the shift ``d`` (N, 6):
    the unedited group's media at the edited colour, each radius times the radius correction exp(d_radius) per
    channel."""
    media = live_table.group_media(table, edit_table.edited_colour(COLOURS, d), grids)
    return {f"Check {name}": value * (np.exp(d[:, 3:6]) if name.endswith("Radius") else 1.0)
            for name, value in media.items() if name.split()[1] in ("Color", "Radius", "Weight")}


def _drawn_media(table, edits, rows, grids) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The media the table's path gives at :data:`COLOURS` under edit rows (N, 3) (or one row) per probe name, their
    mean and standard deviation over the draws (blender_addon.live_edits, "Drawn texels"), reckoned from the table's
    values: each control's level drawn with its hat weight (neutral, below the first level or above the last, a
    shift of 0), the colour grid's slice s + 1 with the slice fraction (one draw for every control), the two other
    grid axes bilinear within the slice; the media at the colour edited by the drawn shift."""
    layout = edits.layout()
    n = np.array(layout.shape)
    x = live_table.grid_coords(COLOURS, layout)
    s = np.floor(x[:, 0]).astype(np.int64)  # up to n0 - 1: the image's copy of the last slice follows
    corner = np.minimum(np.floor(x[:, 1:]).astype(np.int64), n[1:] - 2)
    inside = x[:, 1:] - corner
    weights = edit_table.level_weights(edit_table.control_coords(np.broadcast_to(rows, COLOURS.shape)))
    weights = np.concatenate([weights, 1.0 - weights.sum(axis=2, keepdims=True)], axis=2)  # then neutral's
    values = np.concatenate([edits.values, np.zeros_like(edits.values[:, :, :, :, :1])], axis=4)
    drawn = np.argsort(-weights, axis=2)[:, :, :2]  # each control's two levels with weight (or one, and another)
    chance = np.take_along_axis(weights, drawn, axis=2)
    outcomes = []
    for t in (0, 1):
        p_slice = x[:, 0] - s if t else 1.0 - (x[:, 0] - s)
        k = np.minimum(s + t, n[0] - 1)
        for levels in np.ndindex(2, 2, 2):
            p = p_slice * np.prod([chance[:, j, levels[j]] for j in range(3)], axis=0)
            d = np.zeros((len(COLOURS), edit_table.CHANNELS))
            for j in range(3):
                level = drawn[:, j, levels[j]]
                for b1, b2 in np.ndindex(2, 2):
                    w = (inside[:, 0] if b1 else 1.0 - inside[:, 0]) * (inside[:, 1] if b2 else 1.0 - inside[:, 1])
                    d += w[:, None] * values[k, corner[:, 0] + b1, corner[:, 1] + b2, j, level]
            outcomes.append((p, _edited_media(table, d, grids)))
    mean = {name: sum(p[:, None] * media[name] for p, media in outcomes) for name in outcomes[0][1]}
    sd = {name: np.sqrt(sum(p[:, None] * (media[name] - mean[name]) ** 2 for p, media in outcomes)) for name in mean}
    return mean, sd


def _assert_drawn(rendered: np.ndarray, mean: np.ndarray, sd: np.ndarray, label: str) -> None:
    """A probe render of :data:`DRAWN_SAMPLES` samples averages the draws (:func:`_drawn_media`): within 5 standard
    errors, plus the float rounding the cached path is held to (5e-4; 2e-3 for the colour above 1)."""
    rtol = np.where(np.arange(len(COLOURS))[:, None] == len(COLOURS) - 1, 2e-3, 5e-4)
    bound = 5.0 * sd / np.sqrt(DRAWN_SAMPLES) + rtol * np.abs(mean) + 1e-7
    assert np.all(np.abs(rendered - mean) <= bound), (label, rendered, mean, bound)


def test_edited_media_equal_the_reference_and_the_fast_bake(tmp_path, addon):
    scene, tree, gnode, emission = _strip(tmp_path)
    table, edits = _tables()
    group = live.ensure_live_group(table, edits)
    assert all(name in group.interface.items_tree for name in EDIT)
    names = _with_checks(group, table.k)
    _use(tree, gnode, group)
    for name, value in EDIT.items():
        gnode.inputs[name].default_value = value
    row = np.array([[EDIT["Melanin"], EDIT["Blood"], EDIT["Oxygenation"]]])
    d = edit_table.shift(edits, COLOURS, row)
    assert np.abs(d).max() > 0.05  # the edit does something
    albedo = write_image(tmp_path / "edited.exr", COLOURS[None].astype(np.float32), "float")
    (tmp_path / "bake").mkdir()
    bake.bake(albedo, tmp_path / "bake", preferences.DEFAULT_MODEL,
              bake.BakeOptions(threads=1, prune_share=0.0, half_maps=False, mantissa_bits=23,
                               edit=skin_edits.SkinEdit(*row[0])), colorspace="linear")
    reference = _edited_media(table, d, live_table.grid_values(table))
    for name in names:
        k, kind = name.split()[1], name.split()[2]
        rendered = _render(scene, tree, gnode, emission, name)
        np.testing.assert_allclose(rendered, reference[name], rtol=5e-4, atol=1e-7, err_msg=name)
        baked = maps.read_exr(tmp_path / "bake" / f"edited_{k}_{kind.lower()}.exr")[0][0].astype(np.float64)
        np.testing.assert_allclose(baked, rendered, rtol=5e-4, atol=1e-7, err_msg=f"bake {name}")  # bake = live


def test_neutral_inputs_render_the_unedited_group_bit_for_bit_and_keyframes_animate(tmp_path, addon):
    scene, tree, gnode, emission = _strip(tmp_path)
    table, edits = _tables()
    layout, images = live.ensure_images(table)
    plain = live.build_live_group(table, layout, images)
    edited = live.build_live_group(table, layout, images, (edits, live_edits.ensure_images(edits)))
    names = _with_checks(plain, table.k)
    _with_checks(edited, table.k)
    _use(tree, gnode, plain)
    before = {name: _render(scene, tree, gnode, emission, name) for name in names}
    _use(tree, gnode, edited)
    for name in names:
        np.testing.assert_array_equal(_render(scene, tree, gnode, emission, name), before[name], err_msg=name)
    # keyframes on the node's input: frame 1 as painted, frame 11 twice the blood
    blood = gnode.inputs["Blood"]
    scene.frame_set(1)
    blood.default_value = 1.0
    blood.keyframe_insert("default_value", frame=1)
    blood.default_value = 2.0
    blood.keyframe_insert("default_value", frame=11)
    name = names[1]  # k1 Radius
    scene.frame_set(1)
    np.testing.assert_array_equal(_render(scene, tree, gnode, emission, name), before[name])
    scene.frame_set(11)
    animated = _render(scene, tree, gnode, emission, name)
    tree.animation_data_clear()
    blood.default_value = 2.0  # a constant edit renders from its cache: the table's answer to float rounding
    np.testing.assert_allclose(animated, _render(scene, tree, gnode, emission, name), rtol=1e-5, atol=1e-9)
    assert not np.array_equal(animated, before[name])


def _cycles_memory_mb(scene, tree, gnode) -> float:
    """Render the group's Cycles output; the memory Cycles reports when done (MB: its images, BVH and buffers)."""
    output = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output)
    tree.links.new(gnode.outputs["Cycles"], output.inputs["Surface"])
    return cycles_memory_mb(lambda: _render_row(scene))


def test_neutral_controls_read_no_edit_image(tmp_path, addon):
    """A control at its neutral value adds exactly 0 in nodes Cycles can fold: with the inputs unlinked at neutral the
    compiled shader holds none of the six edit images (Cycles' memory is the group's without edit nodes), and an
    edit of one control holds only that control's two.  (With the add-on's handler off: a constant edit would
    otherwise render from its cache, test_a_constant_edit_renders_from_its_cache_as_from_the_table; the table's path
    is what a node renders when its cache is not current: the add-on not running, more edits than caches.)"""
    live_edits.unregister_handlers()
    scene, tree, gnode, _ = _strip(tmp_path)
    table, edits = _tables()
    layout, images = live.ensure_images(table)
    edit_images = live_edits.ensure_images(edits)
    mb_each = next(iter(edit_images.values())).size[0] * next(iter(edit_images.values())).size[1] * 16 / 2**20
    assert 2 * mb_each > 1.0  # a control's two images are visible at Cycles' 1 MB resolution of its memory statistic
    _use(tree, gnode, live.build_live_group(table, layout, images))
    plain = _cycles_memory_mb(scene, tree, gnode)
    _use(tree, gnode, live.build_live_group(table, layout, images, (edits, edit_images)))
    assert _cycles_memory_mb(scene, tree, gnode) == plain
    gnode.inputs["Melanin"].default_value = 1.5
    one = _cycles_memory_mb(scene, tree, gnode)
    assert 2 * mb_each - 1.0 <= one - plain <= 2 * mb_each + 1.0
    for name, value in EDIT.items():
        gnode.inputs[name].default_value = value
    assert _cycles_memory_mb(scene, tree, gnode) - plain >= 6 * mb_each - 1.0


def test_operator_wires_the_edit_inputs_and_presets_set_them(tmp_path, addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    png = write_image(tmp_path / "skin.png", skin_codes(), "uint8")
    obj, mat, _ = skin_object(png)
    assert run_invert(obj, mode="LIVE") == {"FINISHED"}
    node = live_edits.live_node(mat)
    assert node is not None and [node.inputs[n].default_value for n in EDIT] == [1.0, 1.0, 0.0]
    images = [i for i in bpy.data.images if i.name.startswith(live_edits.IMAGE_PREFIX)]
    assert len(images) == 6 + 2 * (live_edits.CACHE_SLOTS + 1) and all(i.packed_file is not None for i in images)
    table_bytes = sum(i.size[0] * i.size[1] * 16 for i in images if " Cache " not in i.name)
    mask = mat.node_tree.nodes.new("ShaderNodeAttribute")  # an input fed by a node is left as it is
    mat.node_tree.links.new(mask.outputs["Fac"], node.inputs["Oxygenation"])
    with bpy.context.temp_override(material=mat, object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.skin_edit_preset(preset="FLUSH") == {"FINISHED"}
    flush = skin_edits.PRESETS["flush"]
    assert node.inputs["Melanin"].default_value == pytest.approx(flush.melanin)
    assert node.inputs["Blood"].default_value == pytest.approx(flush.blood)
    assert node.inputs["Oxygenation"].default_value == 0.0
    assert node.inputs[live_edits.CACHE_INPUT].default_value == -4  # not cached; Oxygenation (2^2) flagged as fed
    assert live_edits.cache_status(node) == "Read from the edit table: a control is fed by a node"
    assert live_edits.edit_mask_hint(node) == live_edits.EDIT_MASK_HINT
    mat.node_tree.links.new(mask.outputs["Fac"], node.inputs[live_edits.MASK_INPUT])
    assert live_edits.edit_mask_hint(node) is None  # the Edit Mask is fed already
    mat.node_tree.nodes.remove(mask)
    with bpy.context.temp_override(material=mat, object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.skin_edit_preset(preset="FLUSH") == {"FINISHED"}
    assert node.inputs[live_edits.CACHE_INPUT].default_value == 1
    assert live_edits.cache_status(node) == "Rendered from edit cache 1"
    assert live_edits.edit_mask_hint(node) is None
    cache = bpy.data.images[f"{live_edits.IMAGE_PREFIX} {live_edits.cache_image_name(1, 'colour')}"]
    assert cache.size[1] * edit_table.STACKED == next(i for i in images if " Cache " not in i.name).size[1]
    atlases = live_edits.CACHE_SLOTS + live_edits.MASK_POINTS  # every cache filled: one atlas each, the mask's three
    cache_bytes = 2 * atlases * cache.size[0] * cache.size[1] * 16
    assert table_bytes + cache_bytes <= 8e6  # the images the edits add: at most 8 MB
    with bpy.context.temp_override(material=mat, object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.skin_edit_preset(preset="NEUTRAL") == {"FINISHED"}
    assert [node.inputs[n].default_value for n in ("Melanin", "Blood")] == [1.0, 1.0]
    assert node.inputs[live_edits.CACHE_INPUT].default_value == 0 and live_edits.cache_status(node) is None


def test_the_operator_takes_an_edit_into_the_live_group_and_into_baked_maps(tmp_path, addon):
    """Invert Skin Albedo's Melanin, Blood and Oxygenation: the live mode sets them on the group node (run again
    with the neutral defaults it leaves an edit made there as it is); the bake mode's maps carry the edit, equal to
    exporters.bake's with the same edit and unlike the unedited maps."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    png = write_image(tmp_path / "skin.png", skin_codes(), "uint8")
    obj, mat, _ = skin_object(png)
    assert run_invert(obj, mode="LIVE", melanin=1.5, blood=2.5) == {"FINISHED"}
    node = live_edits.live_node(mat)
    assert [node.inputs[n].default_value for n in EDIT] == pytest.approx([1.5, 2.5, 0.0])
    assert run_invert(obj, mode="LIVE") == {"FINISHED"}
    assert [node.inputs[n].default_value for n in EDIT] == pytest.approx([1.5, 2.5, 0.0])
    baked_obj, baked_mat, _ = skin_object(png, name="Baked")
    assert run_invert(baked_obj, mode="BAKE", melanin=1.5, blood=2.5) == {"FINISHED"}
    edited, plain = tmp_path / "edited", tmp_path / "plain"
    edited.mkdir()
    plain.mkdir()
    bake.bake(png, edited, preferences.DEFAULT_MODEL, bake.BakeOptions(threads=1, edit=skin_edits.SkinEdit(1.5, 2.5)))
    bake.bake(png, plain, preferences.DEFAULT_MODEL, bake.BakeOptions(threads=1))
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    change = {}
    for k in range(1, table.k + 1):
        for kind in ("color", "radius", "weight"):
            name = f"skin_k{k}_{kind}.exr"
            ref = maps.read_exr(edited / name)[0]
            got = image_pixels(bpy.data.images[f"skin.png_k{k}_{kind}.exr"])[..., : ref.shape[2]]  # the image's name
            np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7, err_msg=name)
            unedited = maps.read_exr(plain / name)[0]
            change[kind] = max(change.get(kind, 0.0), float(np.abs(ref - unedited).max() / np.abs(unedited).max()))
    assert change["radius"] > 0.01 and change["weight"] > 0.01, change  # the edit changes the translucency


def test_bake_mode_carries_the_live_groups_edit_and_its_masks(tmp_path, addon):
    """Invert Skin Albedo in Bake mode bakes the skin edit the live group renders (blender_addon.edit_masks): Melanin
    set on the node and Blood painted by a mask image (the green of a Separate Color, into a Math Multiply Add) give
    the maps exporters.bake writes with that edit and the mask read from its file (rows top down); an sRGB mask is
    decoded as Cycles reads it; a control fed by another node is a one-line error that changes nothing."""
    import colour

    bpy.ops.wm.read_factory_settings(use_empty=True)
    png = write_image(tmp_path / "skin.png", skin_codes(), "uint8")
    grey = (np.arange(12).reshape(3, 4) * 21).astype(np.uint8)  # every texel its own value: orientation shows
    mask_png = write_image(tmp_path / "mask.png", np.repeat(grey[..., None], 3, axis=-1), "uint8")
    obj, mat, tex = skin_object(png)
    assert run_invert(obj, mode="LIVE", melanin=1.5) == {"FINISHED"}
    node, tree = live_edits.live_node(mat), mat.node_tree
    mask = tree.nodes.new("ShaderNodeTexImage")
    mask.image = bpy.data.images.load(str(mask_png))
    tree.links.new(tex.inputs["Vector"].links[0].from_socket, mask.inputs["Vector"])  # the albedo's UV Map node
    split = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(mask.outputs["Color"], split.inputs[0])
    blood = tree.nodes.new("ShaderNodeMath")
    blood.operation = "MULTIPLY_ADD"
    tree.links.new(split.outputs["Green"], blood.inputs[0])
    blood.inputs[1].default_value, blood.inputs[2].default_value = 1.5, 1.0
    tree.links.new(blood.outputs[0], node.inputs["Blood"])
    mask.image.colorspace_settings.name = "sRGB"
    edit, masks = edit_masks.live_bake_edit(mat, tex, (3, 4))
    assert edit == (1.5, 2.5, 0.0) and list(masks) == ["blood"]
    np.testing.assert_allclose(masks["blood"], colour.models.eotf_sRGB(grey / 255.0), rtol=1e-5, atol=1e-7)
    mask.image.colorspace_settings.name = "Non-Color"
    attribute = tree.nodes.new("ShaderNodeAttribute")
    tree.links.new(attribute.outputs["Fac"], node.inputs["Oxygenation"])
    with pytest.raises(RuntimeError, match="Oxygenation .* cannot read per texel"):
        run_invert(obj, mode="BAKE")
    assert live_edits.live_node(mat) == node  # nothing changed
    tree.links.remove(node.inputs["Oxygenation"].links[0])
    assert run_invert(obj, mode="BAKE") == {"FINISHED"}
    assert live_edits.live_node(mat) is None  # the baked maps replace the live group
    reference = tmp_path / "reference"
    reference.mkdir()
    bake.bake(png, reference, preferences.DEFAULT_MODEL,
              bake.BakeOptions(threads=1, edit=skin_edits.SkinEdit(1.5, 2.5), edit_masks={"blood": grey / 255.0}))
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    for k in range(1, table.k + 1):
        for kind in ("color", "radius", "weight"):
            name = f"skin_k{k}_{kind}.exr"
            ref = maps.read_exr(reference / name)[0]
            got = image_pixels(bpy.data.images[name])[..., : ref.shape[2]]
            np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7, err_msg=name)


def test_a_constant_edit_renders_from_its_cache_as_from_the_table(tmp_path, addon):
    """set_edit holds a constant edit precombined in a cache of the edit group (live_edits.cache_edit): the media
    rendered from the cache equal the table's answer (exporters.edit_table.shift), the compiled shader reads only the
    cache's two small images instead of the table's six (Cycles' memory), values changed on the node without the
    add-on render through the table again, the caches hold several edits, the oldest given up for a new one, and the
    add-on's handlers cache an edit set on the node and each frame's keyframed values."""
    live_edits.unregister_handlers()  # values set on the node below stay uncached, as without the add-on running
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    grids = live_table.grid_values(table)
    row = (1.5, 2.5, -0.2)  # every control between two levels
    live_edits.set_edit(gnode, row)
    assert gnode.inputs[live_edits.CACHE_INPUT].default_value == 1
    d = edit_table.shift(edits, COLOURS, np.array(row))
    reference = _edited_media(table, d, grids)
    for name in names:
        np.testing.assert_allclose(_render(scene, tree, gnode, emission, name), reference[name], rtol=5e-4, atol=1e-7,
                                   err_msg=f"cached {name}")
    gnode.inputs["Melanin"].default_value = 1.25  # changed on the node: not the cache's values, the table's draws
    mean, sd = _drawn_media(table, edits, np.array([1.25, 2.5, -0.2]), grids)
    scene.cycles.samples = DRAWN_SAMPLES
    for name in names:
        _assert_drawn(_render(scene, tree, gnode, emission, name), mean[name], sd[name], f"table {name}")
    scene.cycles.samples = 1
    # memory: the cache's images only (each under Cycles' 1 MB resolution), not the table's six (4.7 MB)
    _use(tree, gnode, live.build_live_group(table, layout, images))
    plain = _cycles_memory_mb(scene, tree, gnode)
    _use(tree, gnode, group)  # the node's inputs are new: set the edit again (its cache is found, not refilled)
    live_edits.set_edit(gnode, row)
    assert gnode.inputs[live_edits.CACHE_INPUT].default_value == 1
    cached = _cycles_memory_mb(scene, tree, gnode)
    gnode.inputs["Melanin"].default_value = 1.25
    full = _cycles_memory_mb(scene, tree, gnode)
    assert cached - plain <= 1.0 and full - plain >= 4.0, (plain, cached, full)
    # more materials with edits than caches: each new edit fills a free cache (the twelve, then the spare ones in the
    # mask cache's images), then the one filled longest ago
    live_edits.set_edit(gnode, row)
    edit_group = live_edits._edit_group(group)
    others = [(1.0 + 0.1 * i, 1.0 + 0.05 * i, 0.0) for i in range(1, 15)] + [(1.0, 0.4, 0.0)]
    slots = [_slot(_edited_node(group, f"other {i}", other)) for i, other in enumerate(others)]
    assert slots == [*live_edits.CONSTANT_SLOTS[1:], *live_edits.SPARE_SLOTS, 1]
    assert len(set(slots)) == 15 and live_edits.CONSTANT_SLOTS == (1, 2, 3, *range(8, 17))
    assert gnode.inputs[live_edits.CACHE_INPUT].default_value == 0  # its cache was given up: it reads the table
    assert live_edits._cached_values(edit_group, 1) == tuple(float(np.float32(v)) for v in (1.0, 0.4, 0.0, 1.0))
    # a cache image gone from the group (an artist's edit of it): the edit is not cached, and nothing fails
    readers = [n for n in edit_group.nodes if n.bl_idname == "ShaderNodeTexImage" and n.image is not None
               and n.image.get(live_edits.IMAGE_KEY_PROP) == live_edits.cache_image_name(2, "radius")]
    image = readers[0].image
    for tex in readers:
        tex.image = None
    live_edits.set_edit(gnode, (3.0, 1.0, 0.0))
    assert gnode.inputs[live_edits.CACHE_INPUT].default_value == 0
    for tex in readers:
        tex.image = image
    # the handler: an edit set on the node (the panel's sliders, the node editor) is cached at the next update
    live_edits.register_handlers()
    gnode.inputs["Blood"].default_value = 0.7
    assert not live_edits.cache_is_current(gnode)
    assert live_edits.cache_status(gnode) == "Read from the edit table (not cached)"
    bpy.context.view_layer.update()
    assert live_edits.cache_is_current(gnode) and gnode.inputs[live_edits.CACHE_INPUT].default_value > 0
    # keyframes: a frame's values are cached when the frame changes, and its render reads the cache
    blood = gnode.inputs["Blood"]
    blood.keyframe_insert("default_value", frame=1)
    blood.default_value = 2.2
    blood.keyframe_insert("default_value", frame=11)
    scene.frame_set(6)
    assert 0.7 < blood.default_value < 2.2 and live_edits.cache_is_current(gnode)
    assert _cycles_memory_mb(scene, tree, gnode) - plain <= 1.0
    live_edits.set_edit(gnode, skin_edits.NEUTRAL)
    assert gnode.inputs[live_edits.CACHE_INPUT].default_value == 0


def test_controls_fed_by_value_nodes_render_from_a_cache(tmp_path, addon):
    """A control or the Edit Mask fed by a Value node (through a Reroute) is a value: Cycles folds the Value node into
    the shader as it does an unlinked input, so cache_edit caches the edit (live_edits.input_value) and the compiled
    shader reads the cache's images, not the table's (Cycles' memory), its media the table's answer and bit for bit
    those of the same values set on the node; the handler caches the Value node's new value; a muted link gives the
    input its own value, as the renderers read it."""
    live_edits.unregister_handlers()
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    row = (1.5, 2.5, -0.2)
    live_edits.set_edit(gnode, row)
    on_node = _render(scene, tree, gnode, emission, names[1])
    values = {}
    for name, value in (("Melanin", row[0]), ("Blood", row[1]), (live_edits.MASK_INPUT, 1.0)):
        values[name] = tree.nodes.new("ShaderNodeValue")
        values[name].outputs[0].default_value = value
        reroute = tree.nodes.new("NodeReroute")
        tree.links.new(values[name].outputs[0], reroute.inputs[0])
        tree.links.new(reroute.outputs[0], gnode.inputs[name])
    gnode.inputs["Oxygenation"].default_value = row[2]
    assert live_edits.constant_edit(gnode) == tuple(float(np.float32(v)) for v in row)
    assert live_edits.cache_edit(gnode) == 1 and live_edits.linked_flags(gnode) == 0
    assert live_edits.cache_status(gnode) == "Rendered from edit cache 1"
    d = edit_table.shift(edits, COLOURS, np.array(row))
    reference = _edited_media(table, d, live_table.grid_values(table))
    for name in names[:2]:  # k1 Color, k1 Radius
        np.testing.assert_allclose(_render(scene, tree, gnode, emission, name), reference[name], rtol=5e-4, atol=1e-7,
                                   err_msg=name)
    np.testing.assert_array_equal(_render(scene, tree, gnode, emission, names[1]), on_node)
    cached = _cycles_memory_mb(scene, tree, gnode)
    gnode.inputs[live_edits.CACHE_INPUT].default_value = 0  # the table's path
    assert _cycles_memory_mb(scene, tree, gnode) - cached >= 4.0
    live_edits.register_handlers()
    values["Blood"].outputs[0].default_value = 2.0
    bpy.context.view_layer.update()
    slot = int(gnode.inputs[live_edits.CACHE_INPUT].default_value)
    assert slot > 0 and live_edits.cache_is_current(gnode)
    assert live_edits._cached_values(live_edits._edit_group(group), slot)[:2] == (1.5, 2.0)
    assert _cycles_memory_mb(scene, tree, gnode) - cached <= 0.5
    link = next(lk for lk in tree.links if lk.to_node == gnode and lk.to_socket.name == "Melanin")
    link.is_muted = True
    gnode.inputs["Melanin"].default_value = 1.25  # the input's own value, not the Value node's 1.5
    assert live_edits.constant_edit(gnode)[0] == 1.25 and live_edits.cache_edit(gnode) > 0
    assert _cycles_memory_mb(scene, tree, gnode) - cached <= 0.5


def _edited_node(group: bpy.types.NodeTree, name: str, edit) -> bpy.types.Node:
    """A new material's group node using ``group``, its edit set (live_edits.set_edit: cached)."""
    mat = bpy.data.materials.new(name)  # with a node tree: Blender 5
    node = mat.node_tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    live_edits.set_edit(node, edit)
    return node


def _slot(node: bpy.types.Node) -> int:
    return int(node.inputs[live_edits.CACHE_INPUT].default_value)


def test_spare_caches_hold_more_constant_edits_while_the_mask_cache_holds_no_line(tmp_path, addon):
    """Past the twelve caches, constant edits take the spare caches: the mask cache's three atlases while it holds no
    line in use.  Rendered from a spare (its images' top and bottom atlas) the media equal the table's answer, and the
    shader loads the mask cache's small images, not the table's.  An edit painted by the Edit Mask takes the mask
    cache back (the spares' nodes read the table, constant edits then take the twelve caches only); once no node
    renders from its line, a constant edit takes a spare again, its atlas written among the line's."""
    live_edits.unregister_handlers()
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    edit_group = live_edits._edit_group(group)
    grids = live_table.grid_values(table)
    fill = [(1.0 + 0.05 * i, 0.9, 0.0) for i in range(1, live_edits.CACHE_SLOTS + 1)]
    others = [_edited_node(group, f"other {i}", edit) for i, edit in
              enumerate((*fill, (1.3, 1.0, 0.0), (1.0, 1.8, -0.1)))]
    assert [_slot(n) for n in others] == [*live_edits.CONSTANT_SLOTS, *live_edits.SPARE_SLOTS[:2]]
    spared = others[live_edits.CACHE_SLOTS:]

    def check(edit, label: str, which=None) -> None:
        reference = _edited_media(table, edit_table.shift(edits, COLOURS, np.array(edit)), grids)
        for name in which or names:
            np.testing.assert_allclose(_render(scene, tree, gnode, emission, name), reference[name], rtol=5e-4,
                                       atol=1e-7, err_msg=f"{label} {name}")

    row = (1.5, 2.5, -0.2)
    live_edits.set_edit(gnode, row)
    assert _slot(gnode) == live_edits.SPARE_SLOTS[-1]  # the images' top atlas
    assert live_edits.cache_status(gnode) == f"Rendered from edit cache {live_edits.SPARE_SLOTS[-1]}"
    check(row, "top atlas")
    live_edits.set_edit(gnode, (1.3, 1.0, 0.0))  # the bottom atlas's edit: found, not filled again
    assert _slot(gnode) == live_edits.SPARE_SLOTS[0]
    check((1.3, 1.0, 0.0), "bottom atlas", names[1:2])
    live_edits.set_edit(gnode, row)
    cached = _cycles_memory_mb(scene, tree, gnode)
    _use(tree, gnode, live.build_live_group(table, layout, images))
    plain = _cycles_memory_mb(scene, tree, gnode)
    _use(tree, gnode, group)
    live_edits.set_edit(gnode, row)
    gnode.inputs["Melanin"].default_value = 1.25  # not cached: the table
    full = _cycles_memory_mb(scene, tree, gnode)
    assert cached - plain <= 1.0 and full - plain >= 4.0, (plain, cached, full)
    output = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output)
    tree.links.new(emission.outputs[0], output.inputs["Surface"])  # the probe's emission again
    # an edit painted by the Edit Mask takes the mask cache: the spares are given up, read from the table
    live_edits.set_edit(gnode, row)
    masked = _edited_node(group, "masked", tuple(skin_edits.PRESETS["flush"].row()))
    painted = masked.id_data.nodes.new("ShaderNodeAttribute")  # a mask (a Value node would be a constant weight)
    masked.id_data.links.new(painted.outputs["Fac"], masked.inputs[live_edits.MASK_INPUT])
    assert live_edits.cache_edit(masked) == live_edits.MASK_SLOT
    assert [_slot(n) for n in (*spared, gnode)] == [0, 0, 0]
    assert all(np.isnan(live_edits._cached_values(edit_group, k)).all() for k in live_edits.SPARE_SLOTS)
    assert live_edits.cache_status(gnode) == "Read from the edit table (not cached)"
    mean, sd = _drawn_media(table, edits, np.array(row), grids)
    scene.cycles.samples = DRAWN_SAMPLES
    _assert_drawn(_render(scene, tree, gnode, emission, names[1]), mean[names[1]], sd[names[1]], "table")
    scene.cycles.samples = 1
    assert live_edits.cache_edit(spared[0]) == 1  # the twelve caches only: the one filled longest ago
    # the mask unlinked: the flush, now constant, lies on the line (its end), and still renders from the mask cache
    masked.id_data.links.remove(masked.inputs[live_edits.MASK_INPUT].links[0])
    assert live_edits.cache_is_current(masked) and live_edits.cache_status(masked) == "Rendered from the mask cache"
    assert live_edits.cache_edit(gnode) == 2  # the line in use: the twelve caches only
    # that node back at neutral: no node renders from the line, so a constant edit takes a spare and the line is emptied
    live_edits.set_edit(masked, skin_edits.NEUTRAL)
    assert _slot(_edited_node(group, "another", (1.2, 2.0, -0.1))) == live_edits.SPARE_SLOTS[0]  # the twelve in use
    assert live_edits._cached_values(edit_group, live_edits.MASK_SLOT) == skin_edits.NEUTRAL
    live_edits.set_edit(gnode, (1.2, 2.0, -0.1))  # the spare's edit: found there
    assert _slot(gnode) == live_edits.SPARE_SLOTS[0]
    check((1.2, 2.0, -0.1), "spare among the line's points", names[1:2])


def test_an_edit_painted_by_the_edit_mask_renders_from_the_mask_cache(tmp_path, addon):
    """An edit weighed by a linked Edit Mask (control = neutral + mask x (value - neutral), bake masks' convention):
    through the table the media average the table's texels drawn at each texel's weighed edit, and the fast bake's
    maps with that mask equal the table's answer there; cached (live_edits.cache_edit: the mask cache) they equal the
    cache's reference (edit_table.masked_shift), which stays within a few thousandths of the table's, and the
    compiled shader reads the cache's small images instead of the table's.  An edit spanning more levels than the
    cache holds reads the table."""
    live_edits.unregister_handlers()
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    red = tree.nodes.new("ShaderNodeSeparateColor")  # the mask: the colours' red, 1.2 clamped to 1
    tree.links.new(tree.nodes[gnode["colour_source"]].outputs["Color"], red.inputs[0])
    tree.links.new(red.outputs[0], gnode.inputs[live_edits.MASK_INPUT])
    masks = np.clip(COLOURS[:, 0], 0.0, 1.0)
    flush = skin_edits.PRESETS["flush"]
    live_edits.set_edit(gnode, tuple(flush.row()), cache=False)
    grids = live_table.grid_values(table)
    rtol = np.where(np.arange(len(COLOURS))[:, None] == len(COLOURS) - 1, 2e-3, 5e-4)  # above 1: as without a mask

    def check(d: np.ndarray, label: str) -> None:
        references = _edited_media(table, d, grids)
        for name in names:
            ref = references[name]
            rendered = _render(scene, tree, gnode, emission, name)
            assert np.all(np.abs(rendered - ref) <= rtol * np.abs(ref) + 1e-7), f"{label} {name}"

    rows = edit_table.masked_edits(flush.row(), masks)
    table_d = edit_table.shift(edits, COLOURS, rows)
    assert np.abs(table_d).max() > 0.05
    mean, sd = _drawn_media(table, edits, rows, grids)  # through the table: its texels drawn
    scene.cycles.samples = DRAWN_SAMPLES
    for name in names:
        _assert_drawn(_render(scene, tree, gnode, emission, name), mean[name], sd[name], f"table {name}")
    scene.cycles.samples = 1
    albedo = write_image(tmp_path / "masked.exr", COLOURS[None].astype(np.float32), "float")
    (tmp_path / "bake").mkdir()
    bake.bake(albedo, tmp_path / "bake", preferences.DEFAULT_MODEL,
              bake.BakeOptions(threads=1, prune_share=0.0, half_maps=False, mantissa_bits=23, edit=flush,
                               edit_masks={"blood": masks[None], "oxygenation": masks[None]}), colorspace="linear")
    references = _edited_media(table, table_d, grids)
    for name in names:  # the bake: the table's answer at each texel's weighed edit
        ref, (k, kind) = references[name], name.split()[1:]
        baked = maps.read_exr(tmp_path / "bake" / f"masked_{k}_{kind.lower()}.exr")[0][0].astype(np.float64)
        assert np.all(np.abs(baked - ref) <= rtol * np.abs(ref) + 1e-7), f"bake {name}"
    assert live_edits.cache_edit(gnode) == live_edits.MASK_SLOT
    assert live_edits.cache_status(gnode) == "Rendered from the mask cache"
    line = edit_table.mask_line(flush.row())
    cached_d = edit_table.masked_shift(edits, COLOURS, line, masks)
    assert np.abs(cached_d - table_d).max() < 5e-3  # the cache's points lie on blood's levels
    check(cached_d, "cached")
    # memory (renders the group's Cycles output): the cache's images only, not the two controls' four
    cached = _cycles_memory_mb(scene, tree, gnode)
    gnode.inputs[live_edits.CACHE_INPUT].default_value = 0  # another cache named: the line still matches
    assert _cycles_memory_mb(scene, tree, gnode) == cached
    _assert_reads_the_mask_cache(scene, tree, gnode, group, table, layout, images)
    tree.links.new(red.outputs[0], gnode.inputs[live_edits.MASK_INPUT])
    live_edits.set_edit(gnode, (4.0, 1.0, 0.0))  # melanin x4 spans four levels: more than the cache's points
    assert gnode.inputs[live_edits.CACHE_INPUT].default_value == 0
    assert live_edits.cache_status(gnode).startswith("Read from the edit table: the mask cache holds")


def _key_flush(scene, gnode) -> tuple[float, float, float]:
    """Keyframe the node's controls from as painted (frame 1) to the Flush preset (frame 21), the scene's frames 1-24,
    and let the handlers see the keys; returns the preset's values."""
    flush = skin_edits.PRESETS["flush"].row()
    scene.frame_start, scene.frame_end = 1, 24
    for frame, row in ((1, skin_edits.NEUTRAL), (21, flush)):
        for name, value in zip(live_edits.CONTROL_NAMES, row, strict=True):
            gnode.inputs[name].default_value = value
            gnode.inputs[name].keyframe_insert("default_value", frame=frame)
    bpy.context.view_layer.update()
    return flush


def test_a_keyframed_edit_renders_from_the_mask_cache_where_no_frame_is_cached(tmp_path, addon):
    """A flush keyframed on the node (as painted at frame 1, the Flush preset at frame 21, the same keys on every
    control): the handlers hold its line in the mask cache (live_edits.hold_line), so a frame whose edit no cache holds
    (as Blender's interface renders an animation: outside the main thread, where no frame's edit is cached) renders
    the mask cache's answer at its place on the line (edit_table.masked_shift, within a few thousandths of the
    table's), reading the cache's small images, not the table's.  Keys that leave the line read the table."""
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    flush = _key_flush(scene, gnode)
    line = tuple(float(np.float32(v)) for v in flush)
    assert live_edits.animated_line(gnode, scene) == line
    assert live_edits._cached_values(live_edits._edit_group(group), live_edits.MASK_SLOT) == line
    assert live_edits.line_status(gnode, scene) == "Animation render: from the mask cache"
    live_edits.unregister_handlers()  # as the interface's render thread: no frame's edit cached
    scene.frame_set(11)
    gnode.inputs[live_edits.CACHE_INPUT].default_value = 0
    blood = gnode.inputs["Blood"].default_value
    t = (blood - 1.0) / (flush[1] - 1.0)
    assert 0.2 < t < 0.8 and not live_edits.cache_is_current(gnode)
    d = edit_table.masked_shift(edits, COLOURS, edit_table.mask_line(line), np.full(len(COLOURS), t))
    table_d = edit_table.shift(edits, COLOURS, np.array([[1.0, blood, gnode.inputs["Oxygenation"].default_value]]))
    assert np.abs(d - table_d).max() < 5e-3 and np.abs(table_d).max() > 0.02
    reference = _edited_media(table, d, live_table.grid_values(table))
    rtol = np.where(np.arange(len(COLOURS))[:, None] == len(COLOURS) - 1, 2e-3, 5e-4)  # above 1: as for constants
    for name in names:
        ref = reference[name]
        rendered = _render(scene, tree, gnode, emission, name)
        assert np.all(np.abs(rendered - ref) <= rtol * np.abs(ref) + 1e-7), name
    _assert_reads_the_mask_cache(scene, tree, gnode, group, table, layout, images)
    oxygenation = live_edits.wiring.animation(gnode.inputs["Oxygenation"])[0]
    oxygenation.keyframe_points[-1].co.x = 15.0  # the flush's oxygenation ends earlier: off the line
    oxygenation.update()
    assert live_edits.animated_line(gnode, scene) is None
    assert live_edits.line_status(gnode, scene).startswith("Animation render: read from the edit table (the keyframes")


def test_keys_on_a_value_node_feeding_a_control_hold_their_line(tmp_path, addon):
    """The flush keyframed on Value nodes feeding Blood and Oxygenation (as painted at frame 1, the preset at frame
    21): the keys reach the controls as the node's own do (live_edits.value_sockets), so the handlers hold their line
    in the mask cache and a frame no cache holds (as Blender's interface renders it) reads the mask cache's images,
    not the table's."""
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    flush = skin_edits.PRESETS["flush"]
    scene.frame_start, scene.frame_end = 1, 24
    for name, end in (("Blood", flush.blood), ("Oxygenation", flush.oxygenation)):
        value = tree.nodes.new("ShaderNodeValue")
        tree.links.new(value.outputs[0], gnode.inputs[name])
        for frame, v in ((1, dict(zip(live_edits.CONTROL_NAMES, skin_edits.NEUTRAL, strict=True))[name]), (21, end)):
            value.outputs[0].default_value = v
            value.outputs[0].keyframe_insert("default_value", frame=frame)
    bpy.context.view_layer.update()
    assert live_edits.animated_line(gnode, scene) == tuple(float(np.float32(v)) for v in flush.row())
    assert live_edits.line_status(gnode, scene) == "Animation render: from the mask cache"
    live_edits.unregister_handlers()  # as the interface's render thread: no frame's edit cached
    scene.frame_set(11)
    gnode.inputs[live_edits.CACHE_INPUT].default_value = 0
    assert 1.2 < live_edits.input_value(gnode, "Blood") < 2.3
    _assert_reads_the_mask_cache(scene, tree, gnode, group, table, layout, images)


def test_frames_on_the_held_line_give_up_no_other_materials_cache(tmp_path, addon):
    """Twelve other materials' constant edits fill the twelve caches, and a flush keyframed on the node holds its line
    in the mask cache (the spares are not free then): each frame's edit, cached as the frame changes (viewport
    playback, command-line renders), lies on that line, so it renders from the mask cache instead of giving up
    another material's cache, and reads the mask cache's images, not the table's."""
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    others = [_edited_node(group, f"other {i}", (1.0 + 0.05 * i, 0.9, 0.0))
              for i in range(1, live_edits.CACHE_SLOTS + 1)]
    _key_flush(scene, gnode)
    assert live_edits.line_status(gnode, scene) == "Animation render: from the mask cache"
    for frame in (6, 11, 21):
        scene.frame_set(frame)
        assert [_slot(n) for n in others] == list(live_edits.CONSTANT_SLOTS), frame
        assert all(map(live_edits.cache_is_current, others)), frame
        assert _slot(gnode) == live_edits.MASK_SLOT and live_edits.cache_is_current(gnode), frame
        assert live_edits.cache_status(gnode) == "Rendered from the mask cache"
    scene.frame_set(11)
    live_edits.unregister_handlers()  # the checks below change the group: no handler caches the frame again
    _assert_reads_the_mask_cache(scene, tree, gnode, group, table, layout, images)


def test_a_presets_keyframed_edit_mask_renders_from_the_mask_cache(tmp_path, addon):
    """The Flush preset set on the node and its Edit Mask keyframed from 0 (frame 1) to 1 (frame 21), a blush's
    amount animated: the handlers hold the preset's line, and a frame no cache holds reads the mask cache's images,
    not the table's."""
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    live_edits.set_edit(gnode, tuple(skin_edits.PRESETS["flush"].row()))
    mask = gnode.inputs[live_edits.MASK_INPUT]
    for frame, value in ((1, 0.0), (21, 1.0)):
        mask.default_value = value
        mask.keyframe_insert("default_value", frame=frame)
    bpy.context.view_layer.update()
    assert live_edits.line_status(gnode, scene) == "Animation render: from the mask cache"
    live_edits.unregister_handlers()
    scene.frame_set(11)
    gnode.inputs[live_edits.CACHE_INPUT].default_value = 0
    assert 0.2 < mask.default_value < 0.8 and not live_edits.cache_is_current(gnode)
    _assert_reads_the_mask_cache(scene, tree, gnode, group, table, layout, images)


def _assert_reads_the_mask_cache(scene, tree, gnode, group, table, layout, images) -> None:
    """The node's render (its group's Cycles output) loads the mask cache's small images, not the table's: Cycles'
    memory within 1 MB of the group without edit nodes, and at least 3 MB over it once the mask cache holds no edit
    (which it is left holding)."""
    cached = _cycles_memory_mb(scene, tree, gnode)
    live_edits.empty_mask_cache(group)
    full = _cycles_memory_mb(scene, tree, gnode)
    _use(tree, gnode, live.build_live_group(table, layout, images))
    plain = _cycles_memory_mb(scene, tree, gnode)
    assert cached - plain <= 1.0 and full - plain >= 3.0, (plain, cached, full)
    _use(tree, gnode, group)


def test_one_mask_fed_to_each_control_becomes_the_edit_mask(tmp_path, addon):
    """The flush painted by one mask fed to Blood and Oxygenation through Math nodes of the material (neutral + mask x
    (value - neutral), as the edit-cost bench's fed row): live_edits.mask_feeding finds the mask and the edit, and Use
    Edit Mask links the mask to Edit Mask instead (the Math nodes kept, unlinked) and caches the edit in the mask
    cache.  Before, the media average the table's texels drawn at each texel's edit; after, they equal the table's
    answer to within the mask cache's accuracy, where the mask lies in [0, 1].  Map Range and Mix nodes of that form
    are found too; a second mask, an unlinked control away from neutral or a clamped Math node are not."""
    live_edits.unregister_handlers()
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    material = next(m for m in bpy.data.materials if m.node_tree == tree)
    colour = tree.nodes[gnode["colour_source"]].outputs["Color"]
    split = tree.nodes.new("ShaderNodeSeparateColor")  # the masks: the colours' red (and green)
    tree.links.new(colour, split.inputs[0])
    flush = tuple(float(np.float32(v)) for v in skin_edits.PRESETS["flush"].row())
    fed = {}
    for name, value, neutral in zip(live_edits.CONTROL_NAMES, flush, skin_edits.NEUTRAL, strict=True):
        if value != neutral:
            fed[name] = tree.nodes.new("ShaderNodeMath")
            fed[name].operation = "MULTIPLY_ADD"
            tree.links.new(split.outputs[0], fed[name].inputs[0])
            fed[name].inputs[1].default_value, fed[name].inputs[2].default_value = value - neutral, neutral
            tree.links.new(fed[name].outputs[0], gnode.inputs[name])
    mask, edit = live_edits.mask_feeding(gnode)
    assert mask == split.outputs[0] and edit == pytest.approx(flush, abs=1e-6)
    rows = np.array(skin_edits.NEUTRAL) + COLOURS[:, :1] * (np.array(flush) - np.array(skin_edits.NEUTRAL))
    grids = live_table.grid_values(table)
    mean, sd = _drawn_media(table, edits, rows, grids)
    scene.cycles.samples = DRAWN_SAMPLES
    for name in names:  # before: the table's texels drawn at each texel's edit
        _assert_drawn(_render(scene, tree, gnode, emission, name), mean[name], sd[name], f"table {name}")
    scene.cycles.samples = 1
    with bpy.context.temp_override(material=material):
        assert bpy.ops.spectral_skin.use_edit_mask() == {"FINISHED"}
        assert not bpy.ops.spectral_skin.use_edit_mask.poll()  # done: nothing left to convert
    assert gnode.inputs[live_edits.MASK_INPUT].links[0].from_socket == split.outputs[0]
    assert not any(gnode.inputs[name].is_linked for name in live_edits.CONTROL_NAMES)
    assert all(node.name in tree.nodes for node in fed.values())  # the artist's nodes kept
    assert _slot(gnode) == live_edits.MASK_SLOT and live_edits.cache_status(gnode) == "Rendered from the mask cache"
    d = edit_table.shift(edits, COLOURS, rows)
    reference = _edited_media(table, d, grids)
    for name in names:  # the table's answer, but at the colour above 1, whose red (1.2) Edit Mask clamps to 1
        np.testing.assert_allclose(_render(scene, tree, gnode, emission, name)[:-1], reference[name][:-1], rtol=5e-3,
                                   atol=1e-6, err_msg=name)
    # Map Range and Mix of the same form; then forms that are not one mask painting the edit
    tree.links.remove(gnode.inputs[live_edits.MASK_INPUT].links[0])
    ranged = tree.nodes.new("ShaderNodeMapRange")
    tree.links.new(split.outputs[0], ranged.inputs["Value"])
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 1.0, flush[1]
    tree.links.new(ranged.outputs[0], gnode.inputs["Blood"])
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "FLOAT"
    tree.links.new(split.outputs[0], mix.inputs["Factor"])
    mix.inputs[2].default_value, mix.inputs[3].default_value = 0.0, flush[2]  # A, B of the float mix
    tree.links.new(mix.outputs[0], gnode.inputs["Oxygenation"])
    assert live_edits.mask_feeding(gnode) == (split.outputs[0], pytest.approx(flush, abs=1e-6))
    gnode.inputs["Melanin"].default_value = 1.2  # a constant the mask does not weigh
    assert live_edits.mask_feeding(gnode) is None
    gnode.inputs["Melanin"].default_value = 1.0
    tree.links.new(split.outputs[1], mix.inputs["Factor"])  # a second mask
    assert live_edits.mask_feeding(gnode) is None
    tree.links.new(fed["Oxygenation"].outputs[0], gnode.inputs["Oxygenation"])
    assert live_edits.mask_feeding(gnode) is not None
    fed["Oxygenation"].use_clamp = True
    assert live_edits.mask_feeding(gnode) is None


def test_controls_fed_by_nodes_render_the_tables_answer_flagged_or_not(tmp_path, addon):
    """Controls fed by nodes of their own (Blood = 1 + 1.5 x the colours' red; Oxygenation from a Value node, a value
    Cycles folds) read the table, its texels drawn per sample (live_edits._chances), flagged or not: the samples
    average the draws at each texel's edit (within 5 standard errors at 16384 samples), the table's interpolated
    answer over the strip within 0.3 % (the draws' spread through the media's curvature), and differ from that answer
    by more than 2 % at one sample.  cache_edit flags the fed one on the cache input (minus 2^j per fed control j),
    which folds its neutral test away: unflagged (cache input 0, as a node the add-on never saw) the draws are the
    same.  A neutral unlinked control wrongly flagged as fed reads 0 at every draw.  A neutral group flagged so (a
    stale flag) renders its unedited colours to the exp curve's accuracy at 0 (1e-4 in the colour, 2e-4 in the media
    it gives), not bit for bit."""
    live_edits.unregister_handlers()
    scene, tree, gnode, emission, table, edits, layout, images, group, names = _edit_strip(tmp_path)
    red = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(tree.nodes[gnode["colour_source"]].outputs["Color"], red.inputs[0])
    blood = tree.nodes.new("ShaderNodeMath")
    blood.operation = "MULTIPLY_ADD"
    tree.links.new(red.outputs[0], blood.inputs[0])
    blood.inputs[1].default_value, blood.inputs[2].default_value = 1.5, 1.0
    oxygen = tree.nodes.new("ShaderNodeValue")
    oxygen.outputs[0].default_value = -0.1
    tree.links.new(blood.outputs[0], gnode.inputs["Blood"])
    tree.links.new(oxygen.outputs[0], gnode.inputs["Oxygenation"])
    assert live_edits.cache_edit(gnode) == 0 and gnode.inputs[live_edits.CACHE_INPUT].default_value == -2
    assert live_edits.cache_is_current(gnode)
    rows = np.column_stack([np.ones(len(COLOURS)), 1.0 + 1.5 * COLOURS[:, 0], np.full(len(COLOURS), -0.1)])
    d = edit_table.shift(edits, COLOURS, rows)
    grids = live_table.grid_values(table)
    reference = _edited_media(table, d, grids)
    mean, sd = _drawn_media(table, edits, rows, grids)
    name = "Check k1 Radius"
    one = _render(scene, tree, gnode, emission, name)
    assert np.abs(one / reference[name] - 1.0).max() > 0.02  # one sample: one texel drawn
    scene.cycles.samples = DRAWN_SAMPLES
    for value in (0.0, -2.0, -3.0):  # unflagged; Blood flagged; Melanin (unlinked, neutral) flagged too: it reads 0
        gnode.inputs[live_edits.CACHE_INPUT].default_value = value
        for name in names:
            drawn = _render(scene, tree, gnode, emission, name)
            _assert_drawn(drawn, mean[name], sd[name], f"{value} {name}")
            assert np.abs(drawn.mean(axis=0) / reference[name].mean(axis=0) - 1.0).max() < 3e-3, (value, name)
    scene.cycles.samples = 1
    for link in [lk for lk in tree.links if lk.to_node == gnode and lk.to_socket.name in ("Blood", "Oxygenation")]:
        tree.links.remove(link)
    gnode.inputs["Blood"].default_value, gnode.inputs["Oxygenation"].default_value = 1.0, 0.0
    gnode.inputs[live_edits.CACHE_INPUT].default_value = 0.0
    plain = {name: _render(scene, tree, gnode, emission, name) for name in names}
    gnode.inputs[live_edits.CACHE_INPUT].default_value = -7.0
    assert not live_edits.cache_is_current(gnode)
    for name in names:
        np.testing.assert_allclose(_render(scene, tree, gnode, emission, name), plain[name], rtol=5e-4, atol=1e-9,
                                   err_msg=name)


def test_edit_images_of_another_layout_are_made_again(addon):
    """The control images stack their levels in exporters.edit_table.BLOCK_LEVELS' order (above neutral, then below)
    and say so: an image of the same table without that tag (an earlier add-on's layout) is made again, not read in
    the wrong order."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _, edits = _tables()
    name = edit_table.image_name(1, "colour")
    image = live_edits.ensure_images(edits)[name]
    blocks = live_edits._pixels(image).reshape(edit_table.STACKED, -1, image.size[0], 4)
    layout = edits.layout()
    for block, level in enumerate((0.5, 1.0, 1.5, 2.0, -2.0, -1.5, -1.0, -0.5)):  # Blood's log2 levels
        i = edit_table.LEVELS["blood"].index(level)
        np.testing.assert_allclose(blocks[block, ..., :3], live_table.atlas_of(edits.values[:, :, :, 1, i, :3], layout),
                                   rtol=0, atol=1e-6, err_msg=f"block {block}")
    image["marker"] = 1
    assert live_edits.has_images(edits) and live_edits.ensure_images(edits)[name].get("marker") == 1  # reused
    del image[live_edits.IMAGE_LAYOUT_PROP]  # as an earlier add-on made it
    assert not live_edits.has_images(edits)
    again = live_edits.ensure_images(edits)[name]
    assert again.get("marker") is None and again[live_edits.IMAGE_LAYOUT_PROP] == edit_table.IMAGE_LAYOUT
    np.testing.assert_array_equal(live_edits._pixels(again), blocks.reshape(live_edits._pixels(again).shape))
