"""A skin material appended from another file (an asset library's character): the file keeps one copy of the add-on's
groups and tables, and the appended skin renders as it did in its own file, in real Cycles on the probe box.

File A holds a skin edited by Melanin 1.5, file B another skin edited by Blood 2, each wired live.  Appending A's
material into B brings A's copies of the live group, its inner groups and their images (Blender names them .001);
the add-on moves A's material onto B's groups and removes the copies (blender_addon.merge).  A timer removes them
in Blender's main loop, which the bpy module has not: the tests call it."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import live_edits, merge, probe, wiring  # noqa: E402
from tests.addon_scene import render_linear, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SIZE = 16
SUFFIXED = re.compile(r"\.\d{3}$")


def _skin_file(tmp_path: Path, name: str, rgb: tuple[int, int, int], edit: tuple[float, float, float],
               mode: str = "LIVE") -> np.ndarray:
    """A new file: the probe scene with a skin material ``name`` of colour ``rgb`` wired live with ``edit`` (or, mode
    BAKE, baked maps of that edit), saved to ``tmp_path / name.blend``; returns its render."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = probe.new_scene(samples=16, resolution=SIZE, seed=3)
    pixels = np.broadcast_to(np.array(rgb, np.uint8), (SIZE, SIZE, 3))
    image = bpy.data.images.load(str(write_image(tmp_path / f"{name}.png", pixels, "uint8")))
    material = box_material(image, "principled")
    material.name = name
    slab = bpy.data.objects["ProbeSlab"]
    slab.active_material = material
    options = {} if mode == "LIVE" else dict(zip(("melanin", "blood", "oxygenation"), edit, strict=True))
    with bpy.context.temp_override(object=slab, active_object=slab):
        assert bpy.ops.spectral_skin.invert_albedo(mode=mode, **options) == {"FINISHED"}
    if mode == "LIVE":
        live_edits.set_edit(wiring.wired_group_node(material), edit)
    bpy.context.view_layer.update()
    rgb_render = render_linear(scene, tmp_path / f"{name}.exr")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / f"{name}.blend"))
    return rgb_render


def _append(tmp_path: Path, name: str, link: bool = False) -> bpy.types.Material:
    """Append (or link) material ``name`` from its file and put it on the probe box."""
    with bpy.data.libraries.load(str(tmp_path / f"{name}.blend"), link=link) as (_, target):
        target.materials = [name]
    (material,) = target.materials
    bpy.data.objects["ProbeSlab"].active_material = material
    bpy.context.view_layer.update()
    return material


def _addon_data(used: bool = False) -> tuple[list[str], list[str]]:
    """Names of the file's add-on node groups and add-on images (``used``: the groups something uses, the images
    they read)."""
    groups = [g for g in bpy.data.node_groups if wiring.is_addon_group(g) and (g.users or not used)]
    read = {n.image.name for g in groups for n in g.nodes if getattr(n, "image", None) is not None}
    return (sorted(g.name for g in groups),
            sorted(i.name for i in bpy.data.images if any(tag in i for tag in wiring.IMAGE_TAGS)
                   and (i.name in read or not used)))


def test_an_appended_skin_shares_the_files_groups_and_renders_as_in_its_own(tmp_path, registered):
    expected = _skin_file(tmp_path, "SkinA", (180, 120, 95), (1.5, 1.0, 0.0))
    _skin_file(tmp_path, "SkinB", (120, 80, 60), (1.0, 2.0, 0.0))
    groups, images = _addon_data()
    assert len(groups) >= 5 and len(images) >= 20

    appended = _append(tmp_path, "SkinA")
    assert _addon_data(used=True) == (groups, images)  # the copies unused: one set of tables renders
    assert bpy.app.timers.is_registered(merge.remove_merged)  # the timer that removes them, run here by hand
    merge.remove_merged()
    assert _addon_data() == (groups, images)
    node = wiring.wired_group_node(appended)
    assert node.node_tree == wiring.wired_group_node(bpy.data.materials["SkinB"]).node_tree
    assert live_edits.cache_is_current(node) and node.inputs[live_edits.CACHE_INPUT].default_value > 0
    rgb = render_linear(bpy.context.scene, tmp_path / "appended.exr")
    assert rgb.mean() > 0.05
    np.testing.assert_array_equal(rgb, expected)

    other = bpy.data.materials["SkinB"]  # B's own skin still renders from its own cache
    assert live_edits.cache_is_current(wiring.wired_group_node(other))


def test_an_appended_baked_skin_shares_the_files_groups_and_renders_as_in_its_own(tmp_path, registered):
    """Baked maps: the appended material's mixture and grazing-light groups are the file's; its maps are its own."""
    expected = _skin_file(tmp_path, "SkinA", (180, 120, 95), (1.5, 1.0, 0.0), mode="BAKE")
    _skin_file(tmp_path, "SkinB", (120, 80, 60), (1.0, 2.0, 0.0), mode="BAKE")
    groups, images = _addon_data()
    appended = _append(tmp_path, "SkinA")
    merge.remove_merged()
    groups_now, images_now = _addon_data()
    assert groups_now == groups and not any(SUFFIXED.search(name) for name in groups_now)
    assert len(images_now) == len(images) + 12  # the appended material's twelve maps (K = 3), and no table twice
    assert wiring.wired_group_node(appended).node_tree == wiring.wired_group_node(bpy.data.materials["SkinB"]).node_tree
    np.testing.assert_array_equal(render_linear(bpy.context.scene, tmp_path / "appended.exr"), expected)


def test_copies_changed_by_hand_or_linked_are_kept(tmp_path, registered):
    """A live group the artist changed by hand in the other file (a node added) is not a copy: it stays, and so do
    groups linked from a library (read-only); what they render is theirs."""
    _skin_file(tmp_path, "SkinA", (180, 120, 95), (1.5, 1.0, 0.0))
    changed = wiring.wired_group_node(bpy.data.materials["SkinA"]).node_tree
    changed.nodes.new("ShaderNodeMath").name = "Artist's note"
    bpy.ops.wm.save_mainfile()
    _skin_file(tmp_path, "SkinC", (200, 150, 130), (1.0, 1.0, -0.2))
    _skin_file(tmp_path, "SkinB", (120, 80, 60), (1.0, 2.0, 0.0))

    appended = _append(tmp_path, "SkinA")
    kept = wiring.wired_group_node(appended).node_tree
    assert SUFFIXED.search(kept.name) and "Artist's note" in kept.nodes
    inner = {n.node_tree.name for n in kept.nodes if n.bl_idname == "ShaderNodeGroup"}
    assert inner and not any(SUFFIXED.search(name) for name in inner)  # its unchanged inner groups: the file's

    linked = _append(tmp_path, "SkinC", link=True)
    assert wiring.wired_group_node(linked).node_tree.library is not None


def test_a_copy_the_artist_makes_in_the_file_stays_theirs(tmp_path, registered):
    """A single-user copy of the live group made in the file (to change it for one material) is not an appended copy:
    it stays, and the material renders through it."""
    _skin_file(tmp_path, "SkinB", (120, 80, 60), (1.0, 2.0, 0.0))
    node = wiring.wired_group_node(bpy.data.materials["SkinB"])
    original = node.node_tree
    node.node_tree = original.copy()
    bpy.context.view_layer.update()
    assert node.node_tree != original and SUFFIXED.search(node.node_tree.name)
    assert merge.merge_copies() == []


def test_a_file_saved_with_copies_is_merged_when_opened(tmp_path, registered):
    """Appended while the add-on was off, the copies are saved with the file; opened with it on, they go."""
    _skin_file(tmp_path, "SkinA", (180, 120, 95), (1.5, 1.0, 0.0))
    _skin_file(tmp_path, "SkinB", (120, 80, 60), (1.0, 2.0, 0.0))
    groups, images = _addon_data()
    blender_addon.unregister()
    _append(tmp_path, "SkinA")
    assert any(SUFFIXED.search(name) for name in _addon_data()[0])
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "both.blend"))
    blender_addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "both.blend"))
    assert _addon_data() == (groups, images)
    assert live_edits.cache_is_current(wiring.wired_group_node(bpy.data.materials["SkinA"]))
