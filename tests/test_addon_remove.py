"""The artist's material around Invert Skin Albedo: what renders, what Remove Skin SSS gives back, linked data.

(a) the per-target outputs (blender_addon.wiring) render in Cycles exactly what the group rendered when it fed the
    active Material Output (one seed: bit for bit), and each renderer's output is the group's; EEVEE (opt-in:
    software OpenGL takes minutes) renders the group's EEVEE output bit for bit as when it fed the active output;
(b) Remove Skin SSS returns the material to exactly what the artist had — every node, every property and socket
    value, every link, the material's custom properties — for the live group and for baked maps, also when the file
    was saved and reopened between wiring and removing and after saving and reopening the removed state; the shared
    group and its table images go once no material uses them; Ctrl+Z (an undo step) brings the wiring back;
    an output of the artist's of target EEVEE is fed instead of adding one, and its link comes back on removal;
(c) a material wired in the add-on's earlier layout (the group fed the active output) is restored the same way;
(d) a material linked from another .blend (a real library file written here), or the material of a linked object,
    is refused in one line that says to make it local, with nothing changed; made local, the operator works and the
    wiring survives save and reopen.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from blender_addon import live, wiring  # noqa: E402
from tests.addon_scene import render_small, skin_codes, skin_object, write_image  # noqa: E402

#: Node properties that are Blender's drawing state, recomputed when a file is drawn (not the artist's data).
_DRAWN = {"dimensions", "is_active_output"}
#: A material's properties that are Blender's bookkeeping of the data-block (not the artist's settings), and
#: use_nodes (deprecated: always on from Blender 5.0).
_BOOKKEEPING = {"session_uid", "is_evaluated", "original", "users", "tag", "is_runtime_data", "preview", "use_nodes"}


def _value(value):
    if isinstance(value, bpy.types.ID):
        return ("ID", value.name)
    if isinstance(value, bpy.types.bpy_struct):
        return _rna(value)
    if hasattr(value, "__len__") and not isinstance(value, str):
        return tuple(round(float(v), 6) if isinstance(v, float) else v for v in value)
    return round(value, 6) if isinstance(value, float) else value


def _rna(struct, skip=frozenset()) -> dict:
    """Every readable RNA property of ``struct`` (nested structs dumped, IDs by name, collections skipped)."""
    out = {}
    for prop in struct.bl_rna.properties:
        key = prop.identifier
        if key == "rna_type" or key in skip or prop.type == "COLLECTION":
            continue
        out[key] = _value(getattr(struct, key))
    return out


def dump(material: bpy.types.Material) -> dict:
    """The material's whole node tree: each node's properties, custom properties and socket values, every link,
    and the material's own settings (EEVEE's Thickness From Shadow among them) and custom properties."""
    tree = material.node_tree
    nodes = {}
    for node in tree.nodes:
        sockets = {f"{side}:{s.identifier}": _rna(s, skip={"link_limit"})
                   for side, group in (("in", node.inputs), ("out", node.outputs)) for s in group}
        nodes[node.name] = {"props": _rna(node, skip=_DRAWN), "custom": dict(node.items()), "sockets": sockets}
    links = sorted((ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier,
                    ln.is_muted) for ln in tree.links)
    active = next((n.name for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output),
                  None)
    return {"nodes": nodes, "links": links, "active_output": active, "custom": dict(material.items()),
            "settings": _rna(material, skip=_BOOKKEEPING)}


def artist_material(tmp_path: Path, name: str = "Skin"):
    """A sphere whose material an artist built: albedo texture, a bump chain into Normal, Roughness 0.37, Specular
    IOR Level 0.42, a muted link and a custom property; returns (object, material)."""
    png = tmp_path / f"{name}.png"
    if not png.exists():
        write_image(png, skin_codes(), "uint8")
    obj, mat, tex = skin_object(png, name=name)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    bump = tree.nodes.new("ShaderNodeBump")
    bump.inputs["Strength"].default_value = 0.3
    tree.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    noise = tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(noise.outputs["Fac"], bump.inputs["Height"])
    tree.links.new(noise.outputs["Fac"], bsdf.inputs["Alpha"]).is_muted = True
    bsdf.inputs["Roughness"].default_value = 0.37
    bsdf.inputs["Specular IOR Level"].default_value = 0.42
    mat["artist_note"] = "keep me"
    return obj, mat


def invert(obj, **kwargs) -> set[str]:
    with bpy.context.temp_override(object=obj, active_object=obj):
        return bpy.ops.spectral_skin.invert_albedo(**kwargs)


def remove(obj) -> set[str]:
    with bpy.context.temp_override(object=obj, active_object=obj):
        return bpy.ops.spectral_skin.remove()


def reopen(path: Path) -> None:
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))


def addon_data() -> tuple[list[str], list[str]]:
    """The add-on's node groups and images in the file."""
    groups = sorted(g.name for g in bpy.data.node_groups if wiring.is_addon_group(g))
    images = sorted(i.name for i in bpy.data.images if i.name.startswith(live.IMAGE_PREFIX)
                    or "spectral_skin_sss_bake_key" in i)
    return groups, images


# -- (a) what renders ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["LIVE", "BAKE"])
def test_each_renderer_renders_the_group_and_cycles_renders_as_before(tmp_path, registered, mode):
    obj, mat = artist_material(tmp_path)
    assert invert(obj, mode=mode, exact=True) == {"FINISHED"}
    tree = mat.node_tree
    gnode = wiring.wired_group_node(mat)
    cycles, eevee = ("Cycles", "EEVEE") if mode == "LIVE" else ("BSSRDF", "BSSRDF")
    bsdf = tree.nodes["Principled BSDF"]
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    active = next(n for n in outputs if n.is_active_output)
    assert active.target == "ALL" and active.inputs["Surface"].links[0].from_node == bsdf  # what exporters read
    by_target = {n.target: n for n in outputs if n is not active}
    assert by_target["CYCLES"].inputs["Surface"].links[0].from_socket == gnode.outputs[cycles]
    assert by_target["EEVEE"].inputs["Surface"].links[0].from_socket == gnode.outputs[eevee]
    # ... and they are the outputs Blender picks for each renderer (EEVEE asks for the same as this function).
    assert tree.get_output_node("CYCLES") == by_target["CYCLES"] and tree.get_output_node("EEVEE") == by_target["EEVEE"]
    assert tree.get_output_node("ALL") == active
    bpy.context.scene.cycles.seed = 3
    now = render_small(size=16, samples=4)
    # The layout before: the group's output into the active output, no Cycles-target output.
    tree.nodes.remove(by_target["CYCLES"])
    tree.links.new(gnode.outputs[cycles], active.inputs["Surface"])
    for helper in [o for o in bpy.data.objects if o.type in ("CAMERA", "LIGHT")]:
        bpy.data.objects.remove(helper)
    earlier = render_small(size=16, samples=4)
    assert now[..., :3].std() > 0.01  # something rendered
    np.testing.assert_array_equal(now, earlier)


EEVEE_SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
from pathlib import Path
import bpy, numpy as np
import blender_addon
from blender_addon import wiring
from tests.addon_scene import skin_codes, skin_object, write_image
bpy.ops.wm.read_homefile(use_empty=True)
blender_addon.register()
obj, mat, _ = skin_object(write_image(Path({tmp!r}) / "albedo.png", skin_codes(), "uint8"))
scene = bpy.context.scene
scene.render.engine = "BLENDER_EEVEE"
scene.eevee.taa_render_samples = 4
scene.render.resolution_x = scene.render.resolution_y = 16
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location, cam.rotation_euler = (0.0, -4.0, 0.0), (np.pi / 2, 0.0, 0.0)
scene.collection.objects.link(cam)
scene.camera, scene.world = cam, bpy.data.worlds.new("World")
scene.collection.objects.link(bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN")))
def render(tag):
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(Path({tmp!r}) / f"{{tag}}.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath)
    px = np.empty(16 * 16 * 4, np.float32)
    image.pixels.foreach_get(px)
    return px
principled = render("principled")
with bpy.context.temp_override(object=obj, active_object=obj):
    assert bpy.ops.spectral_skin.invert_albedo() == {{"FINISHED"}}
wired = render("wired")
tree = mat.node_tree
gnode = wiring.wired_group_node(mat)
for node in [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target != "ALL"]:
    tree.nodes.remove(node)
tree.links.new(gnode.outputs["EEVEE"], tree.nodes["Material Output"].inputs["Surface"])
alone = render("alone")
print("RESULT" + json.dumps({{"wired_vs_alone": float(np.abs(wired - alone).max()),
                              "wired_vs_principled": float(np.abs(wired - principled).max())}}))
"""


@pytest.mark.slow
def test_eevee_renders_the_groups_eevee_output(tmp_path):
    """EEVEE renders the wired material bit for bit as the group's EEVEE output alone in the active output (the
    earlier layout), and not as the artist's Principled BSDF (which the exporters read)."""
    script = EEVEE_SCRIPT.format(root=str(ROOT), tmp=str(tmp_path))
    env = dict(os.environ, EGL_PLATFORM=os.environ.get("EGL_PLATFORM", "surfaceless"))
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=1200)
    line = next((ln for ln in done.stdout.splitlines() if ln.startswith("RESULT")), None)
    assert line is not None, done.stdout[-2000:] + done.stderr[-2000:]
    diff = json.loads(line[len("RESULT"):])
    assert diff["wired_vs_alone"] == 0.0 and diff["wired_vs_principled"] > 0.01, diff


# -- (b) remove ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["LIVE", "BAKE"])
def test_remove_returns_exactly_the_artists_material(tmp_path, registered, mode):
    obj, mat = artist_material(tmp_path)
    obj2, mat2 = artist_material(tmp_path, name="Skin 2")
    mat2.use_thickness_from_shadow = True  # EEVEE's setting, which wiring turns on: this artist had it on already
    original, original2 = dump(mat), dump(mat2)
    kwargs = {"mode": mode, "exact": True} if mode == "BAKE" else {}
    assert invert(obj, **kwargs) == {"FINISHED"}
    assert invert(obj2, **kwargs) == {"FINISHED"}
    assert mat.use_thickness_from_shadow and mat2.use_thickness_from_shadow  # back-lit thin parts glow in EEVEE
    wired = dump(bpy.data.materials["Skin"])
    assert wired != original and addon_data() != ([], [])
    name, name2 = obj.name, obj2.name
    reopen(tmp_path / "wired.blend")  # the wiring saved, and removed in the reopened file
    obj, mat = bpy.data.objects[name], bpy.data.materials["Skin"]
    assert dump(mat) == wired
    kept = addon_data()
    bpy.ops.ed.undo_push(message="wired")
    assert remove(obj) == {"FINISHED"}
    assert dump(mat) == original
    # "Skin 2" still uses the group and the table images (live) or its own maps (bake); the maps of "Skin" went.
    assert addon_data() == (kept[0], [im for im in kept[1] if not im.startswith("Skin_")])
    assert mode == "LIVE" or len(kept[1]) == 2 * len(addon_data()[1])
    # Ctrl+Z: the window manager stores an undo step after each operator whose bl_options hold UNDO (pushed by hand
    # here: a background Blender has no window manager to push it), and undoing it brings the wiring back.
    assert bpy.types.SPECTRAL_SKIN_OT_remove.bl_options == {"REGISTER", "UNDO"}
    bpy.ops.ed.undo_push(message="Remove Skin SSS")
    bpy.ops.ed.undo()
    assert dump(bpy.data.materials["Skin"]) == wired
    assert remove(bpy.data.objects[name]) == {"FINISHED"}
    assert remove(bpy.data.objects[name2]) == {"FINISHED"}
    assert addon_data() == ([], [])  # no material uses them any more
    assert dump(bpy.data.materials["Skin 2"]) == original2
    reopen(tmp_path / "removed.blend")
    assert dump(bpy.data.materials["Skin"]) == original
    assert remove(bpy.data.objects[name]) == {"CANCELLED"}  # nothing left to remove


def test_rewiring_keeps_one_set_of_nodes_and_remove_still_restores(tmp_path, registered):
    obj, mat = artist_material(tmp_path)
    original = dump(mat)
    assert invert(obj) == {"FINISHED"}
    count = len(mat.node_tree.nodes)
    assert invert(obj, mode="BAKE", exact=True) == {"FINISHED"}  # baked maps replace the live group
    groups = sorted(n.node_tree.get("spectral_skin_sss_backend") for n in mat.node_tree.nodes
                    if n.bl_idname == "ShaderNodeGroup")
    assert groups == ["GRAZING", "SVM"]  # the mixture and the grazing-light correction of its maps
    assert wiring.wired_group_node(mat).node_tree.get("spectral_skin_sss_backend") == "SVM"
    assert invert(obj) == {"FINISHED"}  # and the live group the maps
    assert len(mat.node_tree.nodes) == count
    assert remove(obj) == {"FINISHED"}
    assert dump(mat) == original


def test_an_artists_eevee_output_is_fed_and_given_back(tmp_path, registered):
    obj, mat = artist_material(tmp_path)
    tree = mat.node_tree
    viewport = tree.nodes.new("ShaderNodeEmission")  # the artist's own look for EEVEE
    eevee = tree.nodes.new("ShaderNodeOutputMaterial")
    eevee.target = "EEVEE"
    tree.links.new(viewport.outputs[0], eevee.inputs["Surface"])
    tree.nodes["Material Output"].is_active_output = True
    original = dump(mat)
    assert invert(obj) == {"FINISHED"}
    gnode = wiring.wired_group_node(mat)
    assert tree.get_output_node("EEVEE") == eevee  # still the output EEVEE takes, now fed by the group
    assert eevee.inputs["Surface"].links[0].from_socket == gnode.outputs["EEVEE"]
    assert len([n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target == "EEVEE"]) == 1
    name = obj.name
    reopen(tmp_path / "eevee.blend")
    assert remove(bpy.data.objects[name]) == {"FINISHED"}
    assert dump(bpy.data.materials["Skin"]) == original


# -- (c) the earlier layout ------------------------------------------------------------------------------------
def test_remove_restores_a_material_wired_in_the_earlier_layout(tmp_path, registered):
    obj, mat = artist_material(tmp_path)
    original = dump(mat)
    tree = mat.node_tree
    assert invert(obj) == {"FINISHED"}
    gnode = wiring.wired_group_node(mat)
    # What the add-on left before the per-target outputs: no tags, the group into the active output, an EEVEE
    # output labelled for the live group, the replaced surface named in a custom property.
    for node in tree.nodes:
        node.pop(wiring.ADDED_PROP, None)
    cycles_out = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target == "CYCLES")
    tree.nodes.remove(cycles_out)
    next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target == "EEVEE").label = \
        "EEVEE (Spectral Skin SSS Live)"
    tree.links.new(gnode.outputs["Cycles"], tree.nodes["Material Output"].inputs["Surface"])
    name = obj.name
    reopen(tmp_path / "earlier.blend")
    assert remove(bpy.data.objects[name]) == {"FINISHED"}
    assert dump(bpy.data.materials["Skin"]) == original


# -- (d) linked data -------------------------------------------------------------------------------------------
def _library(tmp_path: Path) -> Path:
    """A .blend holding the object "SkinObj" with the artist's material "SkinLib"."""
    obj, mat = artist_material(tmp_path, name="SkinLib")
    obj.name = "SkinObj"
    path = tmp_path / "characters.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    return path


@pytest.mark.parametrize("what", ["material", "object"])
def test_a_linked_material_is_refused_in_one_line_and_works_once_made_local(tmp_path, registered, what):
    library = _library(tmp_path)
    with bpy.data.libraries.load(str(library), link=True) as (src, dst):
        setattr(dst, f"{what}s", ["SkinLib" if what == "material" else "SkinObj"])
    if what == "material":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6)
        obj = bpy.context.active_object
        obj.data.materials.append(bpy.data.materials["SkinLib"])
    else:
        obj = bpy.data.objects["SkinObj"]
        bpy.context.scene.collection.objects.link(obj)
    mat = bpy.data.materials["SkinLib"]
    assert mat.library is not None
    before = dump(mat)
    for mode in ("LIVE", "BAKE"):
        with pytest.raises(RuntimeError, match=r"linked from characters\.blend .*make it local") as err:
            invert(obj, mode=mode, exact=True)
        assert "\n" not in str(err.value).strip()
    with bpy.context.temp_override(object=obj, active_object=obj):
        for operator in (bpy.ops.spectral_skin.remove, bpy.ops.spectral_skin.add_mixture):
            with pytest.raises(RuntimeError, match="make it local"):
                operator()
    assert dump(mat) == before and addon_data() == ([], [])
    # Made local as the message says, the operator's work lasts.
    if what == "object":
        bpy.ops.object.select_all(action="DESELECT")
        with bpy.context.temp_override(selected_objects=[obj], selected_editable_objects=[obj], active_object=obj,
                                       object=obj):
            bpy.ops.object.make_local(type="SELECT_OBDATA_MATERIAL")
        obj = bpy.data.objects["SkinObj"]
    else:
        mat.make_local()
    mat = obj.active_material
    assert mat.library is None
    assert invert(obj) == {"FINISHED"}
    name = obj.name
    reopen(tmp_path / "shot.blend")
    mat = bpy.data.objects[name].active_material
    assert mat.library is None and wiring.wired_group_node(mat) is not None
