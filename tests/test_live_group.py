"""The live node group (blender_addon.live) against the per-texel exact bake, in real Cycles.

(a) painted colours: the three skin colours of tests/test_bake_painted_colour.py as stripes of one 8-bit texture on
    the probe box; Invert Skin Albedo at its default (the live group) and with mode Bake, exact, SVM.  Both renders
    use one seed, so their Monte Carlo noise is largely shared: stripe means within ΔE76 0.1 mean / 0.3 max;
(b) a backlit edge: a 5 mm sphere of medium skin lit from behind by an area light, seen from the front; the rim
    (what light crossing thin skin looks like) within ΔE76 0.3 of the exact bake's;
(c) colours outside the table's domain (non-skin, negative, above 1, a path from skin to pure blue): the K media
    the group gives equal the reference exporters.live_table.group_media (a numpy evaluation of the same table and
    the painted gain, exporters.painted_gain) and change
    continuously along the path (500 steps, none more than twice its neighbours: no jump); the material renders
    finite, about the painted colour;
(d) a UDIM (two-tile) albedo feeding the Principled BSDF: each tile renders as the live group renders its colour;
(e) the operator: the live group is its default, fed by what fed Base Color, every artist node kept, Normal and
    Roughness taken, an EEVEE-target output added; it reports the share of the image outside the domain; a
    material without a Principled BSDF is refused with nothing changed;
(f) EEVEE (software OpenGL where there is no GPU, one subprocess): the live group's EEVEE output near the painted
    colour, skin or not (make-up, ink, paint), and PRINCIPLED_BASE_SHARE against a Principled BSDF rendered in EEVEE.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import follow, live, live_edits, preferences, probe, wiring  # noqa: E402
from exporters import live_table  # noqa: E402
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode, srgb_encode  # noqa: E402
from tests.addon_scene import run_invert, skin_codes, skin_object, snapshot, write_image  # noqa: E402
from tests.installed_addon_check import group_the_principled, media_probe  # noqa: E402
from tests.test_bake_painted_colour import _scene, box_material, painted_codes, render_stripes, stripes_texture  # noqa: E402,I001
from tests.test_painted_gain import NON_SKIN  # noqa: E402

PAINTED_SAMPLES = 256
#: Medium skin, linear sRGB (tests/test_bake_fidelity.py's medium tone).
MEDIUM = np.array([0.40, 0.20, 0.12])
EDGE_SIZE, EDGE_SAMPLES = 40, 96
#: Steps of the colour path from skin to pure blue.
PATH_STEPS = 500


@pytest.fixture
def addon():
    """The add-on registered in an empty factory scene (Unit Scale 1): no scene another test file left behind."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    blender_addon.register()
    yield
    blender_addon.unregister()


def _lab(rgb: np.ndarray) -> np.ndarray:
    return linear_srgb_to_lab(np.asarray(rgb, np.float64))


@pytest.mark.slow
def test_live_group_renders_the_painted_colours_as_the_exact_bake(tmp_path):
    codes = painted_codes()
    means = {}
    for name, options in (("live", {"mode": "AUTO"}), ("exact", {"mode": "BAKE", "exact": True, "backend": "SVM"})):
        scene = _scene()
        scene.cycles.samples = PAINTED_SAMPLES
        blender_addon.register()
        try:
            png = stripes_texture(tmp_path / "painted.png", codes)
            mat = box_material(bpy.data.images.load(str(png)), "principled")
            assert run_invert(bpy.data.objects["ProbeSlab"], **options) == {"FINISHED"}
            groups = {n.node_tree.get("spectral_skin_sss_backend") for n in mat.node_tree.nodes
                      if n.bl_idname == "ShaderNodeGroup"}
            assert groups == ({"LIVE"} if name == "live" else {"SVM", "GRAZING"})
            means[name], _ = render_stripes(scene, tmp_path, name)
        finally:
            blender_addon.unregister()
    de = delta_e76(_lab(means["live"]), _lab(means["exact"]))
    print(f"\nlive {np.round(means['live'], 4).tolist()}\nexact {np.round(means['exact'], 4).tolist()}\n"
          f"ΔE76 {np.round(de, 3).tolist()}")
    assert de.mean() <= 0.1 and de.max() <= 0.3, de


def _edge_scene(tmp_path: Path, options: dict) -> np.ndarray:
    """The backlit sphere rendered after Invert Skin Albedo with ``options``: mean linear RGB of its rim."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.seed = "CPU", EDGE_SAMPLES, 5
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    scene.render.resolution_x = scene.render.resolution_y = EDGE_SIZE
    scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
    scene.render.image_settings.file_format, scene.render.image_settings.color_depth = "OPEN_EXR", "32"
    scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", 0.002
    codes = np.round(255 * srgb_encode(MEDIUM)).astype(np.uint8)
    png = write_image(tmp_path / "medium.png", np.broadcast_to(codes, (2, 2, 3)).copy(), "uint8")
    obj, _, _ = skin_object(png)
    bpy.ops.object.shade_smooth()
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", 2.2
    cam.location, cam.rotation_euler = (0.0, -5.0, 0.0), (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    light = bpy.data.objects.new("Back", bpy.data.lights.new("Back", "AREA"))
    light.data.energy, light.data.size = 3000.0, 3.0
    light.location, light.rotation_euler = (0.0, 3.0, 0.0), (-np.pi / 2, 0.0, 0.0)  # behind, facing the camera
    scene.collection.objects.link(light)
    blender_addon.register()
    try:
        assert run_invert(obj, **options) == {"FINISHED"}
        mean, _ = _render_rim(scene, tmp_path)
    finally:
        blender_addon.unregister()
    return mean


def _render_rim(scene: bpy.types.Scene, tmp_path: Path) -> tuple[np.ndarray, int]:
    path = tmp_path / "edge.exr"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    px = np.empty(EDGE_SIZE * EDGE_SIZE * 4, np.float32)
    image.pixels.foreach_get(px)
    bpy.data.images.remove(image)
    px = px.reshape(EDGE_SIZE, EDGE_SIZE, 4)
    assert np.all(np.isfinite(px))
    centre = (EDGE_SIZE - 1) / 2.0
    y, x = np.mgrid[:EDGE_SIZE, :EDGE_SIZE]
    r = np.hypot(x - centre, y - centre) / (EDGE_SIZE / 2.2)  # in sphere radii (ortho scale 2.2)
    rim = (r > 0.8) & (r < 0.97)
    return px[rim, :3].astype(np.float64).mean(axis=0), int(rim.sum())


@pytest.mark.slow
def test_live_group_renders_a_backlit_edge_as_the_exact_bake(tmp_path):
    live_rim = _edge_scene(tmp_path, {"mode": "AUTO"})
    exact_rim = _edge_scene(tmp_path, {"mode": "BAKE", "exact": True, "backend": "SVM"})
    de = float(delta_e76(_lab(live_rim[None]), _lab(exact_rim[None]))[0])
    print(f"\nrim live {np.round(live_rim, 4).tolist()} exact {np.round(exact_rim, 4).tolist()} ΔE76 {de:.3f}")
    assert np.all(exact_rim > 0.02), "the rim must glow (light through thin skin) for the test to mean anything"
    assert de <= 0.3


# -- outside the domain ----------------------------------------------------------------------------------------
def _outside_colours() -> np.ndarray:
    """Test colours (N, 3) linear: skin, non-skin, negative, above 1, and a path from skin to pure blue."""
    fixed = np.array([MEDIUM, [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 1.0],
                      [-0.5, 0.2, 0.1], [5.0, 3.0, 2.0], [0.9, 0.02, 0.01], [0.02, 0.02, 0.2]])
    t = np.linspace(0.0, 1.0, PATH_STEPS + 1)[:, None]
    return np.concatenate([fixed, (1.0 - t) * MEDIUM + t * np.array([0.0, 0.0, 1.0])])


def _probe_strip(colours: np.ndarray, tmp_path: Path):
    """The probe box's top face showing ``colours`` as columns of a float texture (one pixel each), fed to a live
    group node; returns (scene, material, group node)."""
    scene = probe.new_scene(samples=1, resolution=len(colours), seed=3)
    scene.render.resolution_y = 2
    scene.cycles.filter_width = 0.01  # one texel per pixel, no blending between columns
    exr = write_image(tmp_path / "colours.exr", colours[None].astype(np.float32), "float")
    image = bpy.data.images.load(str(exr))
    image.colorspace_settings.name = "Non-Color"  # the values as written
    mat = box_material(image, "principled")
    return scene, mat, image


def _render_rows(scene: bpy.types.Scene) -> np.ndarray:
    """Render; linear RGB (W, 3) of each column's mean."""
    return _render_image(scene).mean(axis=0)


def _render_row(scene: bpy.types.Scene) -> np.ndarray:
    """Render; linear RGB (W, 3) of the bottom pixel row."""
    return _render_image(scene)[0]


def _render_image(scene: bpy.types.Scene) -> np.ndarray:
    """Render; linear RGB (H, W, 3)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "row.exr")
        scene.render.filepath = path
        bpy.ops.render.render(write_still=True)
        image = bpy.data.images.load(path)
        w, h = image.size
        px = np.empty(w * h * 4, np.float32)
        image.pixels.foreach_get(px)
        bpy.data.images.remove(image)
    return px.reshape(h, w, 4)[..., :3].astype(np.float64)


def test_outside_colours_get_the_reference_media_continuously(tmp_path, addon):
    colours = _outside_colours()
    scene, mat, _ = _probe_strip(colours, tmp_path)
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    group = live.ensure_live_group(table)
    tree = mat.node_tree
    tex = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage")
    gnode, mixture, gout, emission = media_probe(mat, tex.outputs["Color"], group, probe)
    reference = live_table.group_media(table, colours)
    path = slice(10, None)
    for k in range(1, table.k + 1):
        for kind in ("Color", "Radius", "Weight"):
            name = f"k{k} {kind}"
            group.interface.new_socket(f"Check {name}", in_out="OUTPUT", socket_type="NodeSocketColor")
            group.links.new(mixture.inputs[name].links[0].from_socket, gout.inputs[f"Check {name}"])
            tree.links.new(gnode.outputs[f"Check {name}"], emission.inputs["Color"])
            rendered = _render_row(scene)
            ref = reference[name]
            assert np.all(np.isfinite(rendered)) and np.all(rendered >= 0.0), name
            assert kind == "Weight" or np.all(rendered > 0.0), name  # a weight is 0 where the colour is
            np.testing.assert_allclose(rendered, ref, rtol=2e-4, atol=1e-6, err_msg=name)
            along = rendered[path] if kind == "Weight" else np.log(rendered[path])
            steps = np.abs(np.diff(along, axis=0)).max(axis=1)  # along the path to pure blue
            neighbours = np.maximum(steps[:-2], steps[2:])
            assert np.all(steps[1:-1] <= 2.0 * neighbours + 2e-4), name  # no step stands out: no jump
    tree.links.new(gnode.outputs["Outside"], emission.inputs["Color"])
    outside = _render_row(scene)[:, 0]
    assert outside[0] == 0.0 and np.all(outside[[1, 2, 3, 5]] > 0.0)  # skin in the box; blue, green, white, magenta out


def test_outside_colours_render_finite_and_as_painted(tmp_path, addon):
    colours = _outside_colours()[:10]
    scene, mat, _ = _probe_strip(colours, tmp_path)
    scene.cycles.samples = 128
    scene.render.resolution_y = 8
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    rendered = _render_rows(scene)
    assert np.all(np.isfinite(rendered))
    # the painted colour clamped to [0, 1] plus about the coat (0.026); 8 pixels each (tight: test_live_colours)
    np.testing.assert_allclose(rendered, np.clip(colours, 0.0, 1.0) + 0.026, atol=0.12)


# -- UDIM ------------------------------------------------------------------------------------------------------
def test_udim_albedo_feeds_the_live_group(tmp_path, addon):
    tiles = {1001: np.array([224, 172, 150], np.uint8), 1002: np.array([120, 70, 50], np.uint8)}
    for number, code in tiles.items():
        write_image(tmp_path / f"skin.{number}.png", np.broadcast_to(code, (4, 4, 3)).copy(), "uint8")
    scene = probe.new_scene(samples=64, resolution=16, seed=9)
    scene.render.resolution_x = 32
    scene.camera.data.ortho_scale = 2.0
    mat = probe.slab_material("UDIM skin")
    tree = mat.node_tree
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
    tree.links.new(bsdf.outputs[0], probe.material_output(mat).inputs["Surface"])
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")  # the view's x in [-1, 1] onto u in [0, 2]: tile 1001, then 1002
    mapping.inputs["Location"].default_value = (1.0, 0.5, 0.0)
    tex = tree.nodes.new("ShaderNodeTexImage")
    image = bpy.data.images.load(str(tmp_path / "skin.1001.png"))
    image.source = "TILED"
    image.filepath = str(tmp_path / "skin.<UDIM>.png")
    image.tiles.new(1002)
    image.reload()
    tex.image, tex.interpolation, tex.extension = image, "Closest", "EXTEND"
    tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    slab = bpy.data.objects["ProbeSlab"]
    with bpy.context.temp_override(object=slab, active_object=slab):
        assert bpy.ops.spectral_skin.invert_albedo() == {"FINISHED"}
    gnode = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup")
    read = live.image_colours(image, "srgb")  # what the operator's outside-domain report reads: every tile
    assert len(read) == 2 * 16
    np.testing.assert_allclose(np.unique(read, axis=0), [_decode(tiles[1002]), _decode(tiles[1001])],  # dark, light
                               atol=1e-6)
    tiled = _render_row(scene)
    tree.links.remove(gnode.inputs["Color"].links[0])
    for number, half in ((1001, slice(2, 14)), (1002, slice(18, 30))):
        gnode.inputs["Color"].default_value = (*_decode(tiles[number]), 1.0)
        constant = _render_row(scene)
        de = delta_e76(_lab(tiled[half].mean(axis=0)[None]), _lab(constant[half].mean(axis=0)[None]))[0]
        assert de < 0.5, (number, de)
    assert _lab(tiled[2:14].mean(axis=0)[None])[0, 0] > _lab(tiled[18:30].mean(axis=0)[None])[0, 0] + 20


def _decode(code: np.ndarray) -> np.ndarray:
    return srgb_decode(code / 255.0)


# -- the operator ----------------------------------------------------------------------------------------------
def test_operator_default_wires_the_live_group_and_keeps_the_artists_nodes(tmp_path, addon):
    codes = np.empty((4, 4, 3), np.uint8)
    codes[...] = (224, 172, 150)
    codes[0, :] = (20, 40, 230)  # a quarter of the texels: blue, no skin colour
    png = write_image(tmp_path / "albedo.png", codes, "uint8")
    obj, mat, tex = skin_object(png)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    bump = tree.nodes.new("ShaderNodeBump")
    tree.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    bsdf.inputs["Roughness"].default_value = 0.37
    before = {n.name for n in tree.nodes}
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.invert_albedo() == {"FINISHED"}
    gnode = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup")
    assert gnode.node_tree.get("spectral_skin_sss_backend") == "LIVE"
    assert before <= {n.name for n in tree.nodes}
    assert gnode.inputs["Color"].links[0].from_node == tex
    assert bsdf.inputs["Base Color"].links[0].from_node == tex  # the artist's link stays
    assert gnode.inputs["Normal"].links[0].from_node == bump
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.37)
    outputs = {n.target: n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"}
    assert outputs["EEVEE"].inputs["Surface"].links[0].from_socket == gnode.outputs["EEVEE"]
    assert outputs["CYCLES"].inputs["Surface"].links[0].from_socket == gnode.outputs["Cycles"]
    assert outputs["ALL"].inputs["Surface"].links[0].from_node == bsdf and outputs["ALL"].is_active_output
    assert gnode.inputs["Unit Scale"].default_value == pytest.approx(1.0)
    share = live_table.outside_fraction(live.table_for_model(preferences.DEFAULT_MODEL),
                                        _decode(codes.reshape(-1, 3)))
    assert share == pytest.approx(0.25)
    report = live.outside_report(live.table_for_model(preferences.DEFAULT_MODEL), tex.image, "FROM_IMAGE")
    assert "25.00 % of the texels of 'albedo.png' lie outside the table's skin colours" in report
    assert "render as painted" in report and "warning" not in report
    images = [i for i in bpy.data.images if i.name.startswith(live.IMAGE_PREFIX)]
    assert len(images) == 9 and all(i.packed_file is not None for i in images)
    assert sum(i.size[0] * i.size[1] * 16 for i in images) <= 16 * 2 ** 20
    count = len(tree.nodes)
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.invert_albedo() == {"FINISHED"}  # again: up to date, nothing added
    assert len(tree.nodes) == count
    obj2, mat2, _ = skin_object(png, name="Skin 2")  # a second material shares the group and its images
    with bpy.context.temp_override(object=obj2, active_object=obj2):
        assert bpy.ops.spectral_skin.invert_albedo() == {"FINISHED"}
    groups = {n.node_tree.name for m in (mat, mat2) for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"
              and n.node_tree.get("spectral_skin_sss_backend") == "LIVE"}
    assert len(groups) == 1
    assert len([i for i in bpy.data.images if i.name.startswith(live.IMAGE_PREFIX)]) == 9


def test_operator_reports_what_the_file_holds_now(tmp_path, addon):
    """The operator's report (its outside-colour share read beside the node building) is that of the file as it is
    when the operator runs: a file rewritten since an earlier report is read again."""
    codes = np.empty((4, 4, 3), np.uint8)
    codes[...] = (224, 172, 150)
    codes[:2, :] = (20, 40, 230)  # half of the texels: blue, no skin colour
    png = write_image(tmp_path / "albedo.png", codes, "uint8")
    for name in ("Skin A", "Skin B"):  # B: the same file through another image
        obj, _, tex = skin_object(png, name=name)
        with bpy.context.temp_override(object=obj, active_object=obj):
            report = live.apply(bpy.context, preferences.DEFAULT_MODEL, 1.0)
        assert f"50.00 % of the texels of '{tex.image.name}' lie outside" in report, report
    write_image(png, np.broadcast_to(np.array([224, 172, 150], np.uint8), (8, 8, 3)).copy(), "uint8")
    obj, _, tex = skin_object(png, name="Skin C")
    with bpy.context.temp_override(object=obj, active_object=obj):
        report = live.apply(bpy.context, preferences.DEFAULT_MODEL, 1.0)
    assert f"every texel of '{tex.image.name}' is a skin colour of the table" in report, report
    assert report.endswith(live.outside_report(live.table_for_model(preferences.DEFAULT_MODEL), tex.image,
                                               "FROM_IMAGE"))


def test_the_built_groups_lay_their_nodes_out_apart(addon):
    """The builder places the nodes it makes (all at once, after building): no two nodes of the live group, of the
    edit groups or of the caches group nested in Cycles' share a location, none is left where Blender puts a new
    node."""
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    edits = live_edits.table_for_model(preferences.DEFAULT_MODEL, table.sha256)
    group = live.ensure_live_group(table, edits)
    edit_groups = [n.node_tree for n in group.nodes if n.bl_idname == "ShaderNodeGroup"
                   and n.node_tree.name.startswith(live_edits.EDIT_GROUP_NAME)]
    assert len(edit_groups) == 2  # Cycles' and EEVEE's
    caches = [n.node_tree for tree in edit_groups for n in tree.nodes if n.bl_idname == "ShaderNodeGroup"]
    assert [tree.name for tree in caches] == [live_edits.CACHES_GROUP_NAME]  # Cycles' edit group only
    for tree in (group, *edit_groups, *caches):
        spots = [tuple(n.location) for n in tree.nodes]
        assert len(set(spots)) == len(spots) and (0.0, 0.0) not in spots, tree.name


def test_operator_refuses_a_material_without_principled_and_changes_nothing(addon):
    obj, mat, _ = skin_object(None)
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(emission.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    state = snapshot()
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="no Principled BSDF feeds its Material Output's Surface"):
            bpy.ops.spectral_skin.invert_albedo()
        with pytest.raises(RuntimeError, match="needs mode Bake"):
            bpy.ops.spectral_skin.invert_albedo(mode="LIVE", model_colour=True)
    assert snapshot() == state


def test_a_principled_bsdf_inside_a_node_group_is_named_and_nothing_changes(addon):
    """An asset's skin shader with its Principled BSDF two node groups deep (under a Mix Shader layer) reaching the
    inner group's output only through a Shader to RGB and an Emission (a toon set-up), which the live group cannot
    render through (it goes through node groups and layers: tests/test_live_grouped.py); the operator names the
    group and says how to ungroup it, and changes nothing."""
    obj, mat, _ = skin_object(None)
    tree = mat.node_tree
    inner = bpy.data.node_groups.new("Skin Core", "ShaderNodeTree")
    inner.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    bsdf = inner.nodes.new("ShaderNodeBsdfPrincipled")
    toon, emission = inner.nodes.new("ShaderNodeShaderToRGB"), inner.nodes.new("ShaderNodeEmission")
    inner.links.new(bsdf.outputs[0], toon.inputs[0])
    inner.links.new(toon.outputs["Color"], emission.inputs["Color"])
    inner.links.new(emission.outputs[0], inner.nodes.new("NodeGroupOutput").inputs[0])
    outer = bpy.data.node_groups.new("Skin Shader", "ShaderNodeTree")
    outer.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    core = outer.nodes.new("ShaderNodeGroup")
    core.node_tree = inner
    outer.links.new(core.outputs[0], outer.nodes.new("NodeGroupOutput").inputs[0])
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    shader = tree.nodes.new("ShaderNodeGroup")
    shader.node_tree = outer
    layer = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(shader.outputs[0], layer.inputs[1])
    tree.links.new(tree.nodes.new("ShaderNodeBsdfGlossy").outputs[0], layer.inputs[2])
    tree.links.new(layer.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    state = snapshot()
    with bpy.context.temp_override(object=obj, active_object=obj):
        with pytest.raises(RuntimeError, match="sits in the node group 'Skin Shader'.*Ctrl\\+Alt\\+G"):
            bpy.ops.spectral_skin.invert_albedo()
    assert snapshot() == state


def test_baked_maps_over_a_shared_grouped_principled_bsdf_warn(addon, tmp_path, capfd):
    """Bake maps goes into the node group holding the Principled BSDF (tests/test_live_grouped.py) only where that
    node group is this material's alone (the maps are one material's): where another material uses it too, the maps
    are wired over the group node and the report warns, naming the node group and the other material, that they
    render without the inputs the group holds."""
    obj, mat, tex = skin_object(write_image(tmp_path / "skin.png", skin_codes(), "uint8"))
    tree = mat.node_tree
    group = group_the_principled(mat)
    other = bpy.data.materials.new("Other")
    other.node_tree.nodes.new("ShaderNodeGroup").node_tree = group
    bsdf = next(n for n in group.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    tree.nodes.active = tex
    capfd.readouterr()
    assert run_invert(obj, mode="BAKE") == {"FINISHED"}
    gnode = wiring.wired_group_node(mat)
    assert gnode is not None and gnode.id_data == tree
    assert ("node group 'Skin Shader', which holds the Principled BSDF, is also used by 'Other', so the maps render "
            "over the group") in capfd.readouterr().out
    bsdf.inputs["Roughness"].default_value = 0.2
    assert follow.follow(mat) == []  # nothing of the node group is taken over baked maps (nor across node trees)
    bpy.data.materials.remove(other)
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.remove() == {"FINISHED"}
    assert run_invert(obj, mode="BAKE") == {"FINISHED"}  # the node group is the material's alone: inside, no warning
    assert wiring.wired_group_node(mat).id_data == group and "warning" not in capfd.readouterr().out.lower()


# -- EEVEE -----------------------------------------------------------------------------------------------------
EEVEE_SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
import bpy, numpy as np
import blender_addon
from blender_addon import probe, live
from tests.test_bake_painted_colour import STRIPE, box_material, stripes_texture
from pathlib import Path
codes = np.array({codes!r}, np.uint8)
n = len(codes)
scene = probe.new_scene(samples=1, resolution=n * STRIPE, seed=1)
scene.render.resolution_y = STRIPE
scene.render.engine = "BLENDER_EEVEE"
scene.eevee.taa_render_samples = {taa}
blender_addon.register()
mat = box_material(bpy.data.images.load(str(stripes_texture(Path({tmp!r}) / "painted.png", codes))), "principled")
mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value = live.nodes.DEFAULT_IOR
mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.5

def render(name):
    scene.render.filepath = str(Path({tmp!r}) / name)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath)
    px = np.empty(n * STRIPE * STRIPE * 4, np.float32)
    image.pixels.foreach_get(px)
    rgb = px.reshape(STRIPE, n * STRIPE, 4)[..., :3]
    return [rgb[:, i * STRIPE + 3:(i + 1) * STRIPE - 3].reshape(-1, 3).mean(axis=0).tolist() for i in range(n)]

principled_bsdf = mat.node_tree.nodes["Principled BSDF"]
principled_bsdf.inputs["Metallic"].default_value = 1.0
principled_metal = render("principled_metal.exr")
principled_bsdf.inputs["Metallic"].default_value = 0.0
principled = render("principled.exr")
slab = bpy.data.objects["ProbeSlab"]
with bpy.context.temp_override(object=slab, active_object=slab):
    assert bpy.ops.spectral_skin.invert_albedo() == {{"FINISHED"}}
live_rgb = render("live.exr")
principled_bsdf.inputs["Metallic"].default_value = 1.0  # the metal layer (blender_addon.wiring) comes in
bpy.context.view_layer.update()
live_metal = render("live_metal.exr")
principled_bsdf.inputs["Metallic"].default_value = 0.0
# a sun from the side and a height rising along x into the Material Output's Displacement (EEVEE bumps by it)
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy, sun.rotation_euler = 3.0, (0.0, 0.8727, 0.0)
scene.collection.objects.link(sun)
tree = mat.node_tree
coords, separate = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeSeparateXYZ")
height = tree.nodes.new("ShaderNodeDisplacement")
height.inputs["Scale"].default_value = 0.7
tree.links.new(coords.outputs["Object"], separate.inputs[0])
tree.links.new(separate.outputs["X"], height.inputs["Height"])
output = tree.get_output_node("ALL")
bpy.context.view_layer.update()
sun_flat = render("live_sun.exr")
tree.links.new(height.outputs[0], output.inputs["Displacement"])
bpy.context.view_layer.update()
sun_bumped = render("live_bumped.exr")
with bpy.context.temp_override(object=slab, active_object=slab):
    assert bpy.ops.spectral_skin.remove() == {{"FINISHED"}}
principled_bsdf.inputs["Subsurface Weight"].default_value = 1.0
principled_bumped = render("principled_bumped.exr")
tree.links.remove(output.inputs["Displacement"].links[0])
principled_sun = render("principled_sun.exr")
print("RESULT" + json.dumps({{"principled": principled, "live": live_rgb, "principled_metal": principled_metal,
                              "live_metal": live_metal, "bump": [sun_flat, sun_bumped, principled_sun,
                                                                 principled_bumped]}}))
"""
#: EEVEE's temporal anti-aliasing samples: the probe is flat and uniformly lit, so a few suffice.
EEVEE_TAA = 4


@pytest.fixture(scope="module")
def eevee_renders(tmp_path_factory):
    """One EEVEE process (software OpenGL where there is no GPU: Mesa, EGL surfaceless) rendering the painted
    skin stripes, a black one and the sixteen colours that are not skin (tests.test_painted_gain.NON_SKIN) on the
    probe box, straight above under the white world: first the artist's Principled BSDF (Roughness 0.5, skin's
    IOR), then the material after Invert Skin Albedo (the live group's EEVEE output).  Returns the painted linear
    colours of the skin stripes (3, 3) and of the others (16, 3), and the stripes' mean linear RGB of both renders
    (20, 3: skin, black, the others); then the same two at Metallic 1 (the Principled BSDF's metal, and the metal
    layer the add-on mixes over the live group); then, under a sun from the side, the live material and the artist's
    Principled BSDF at Subsurface Weight 1 without and with a height rising along x in the Material Output's
    Displacement (4, 20, 3: live flat, live bumped, Principled flat, Principled bumped)."""
    import json
    import subprocess

    tmp = tmp_path_factory.mktemp("eevee")
    codes = np.concatenate([painted_codes(), np.zeros((1, 3), np.uint8), np.asarray(NON_SKIN, np.uint8)])
    script = EEVEE_SCRIPT.format(root=str(ROOT), codes=codes.tolist(), tmp=str(tmp), taa=EEVEE_TAA)
    env = dict(os.environ, EGL_PLATFORM=os.environ.get("EGL_PLATFORM", "surfaceless"),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=1200)
    line = next((ln for ln in done.stdout.splitlines() if ln.startswith("RESULT")), None)
    assert line is not None, done.stdout[-2000:] + done.stderr[-2000:]
    result = json.loads(line[len("RESULT"):])
    return (_decode(codes[:3].astype(np.float64)), _decode(codes[4:].astype(np.float64)),
            np.array(result["principled"]), np.array(result["live"]),
            np.array(result["principled_metal"]), np.array(result["live_metal"]), np.array(result["bump"]))


@pytest.mark.slow
def test_eevee_renders_the_live_material_near_the_painted_colour(eevee_renders):
    """The live group's EEVEE output: each painted stripe within ΔE76 1 of the painted colour plus the coat's F0
    (EEVEE's subsurface is an approximation), never black."""
    painted, _, _, eevee, _, _, _ = eevee_renders
    eevee = eevee[:3]
    f0 = ((1.4 - 1.0) / (1.4 + 1.0)) ** 2
    de = delta_e76(_lab(eevee), _lab(painted + f0))
    print(f"\nEEVEE {np.round(eevee, 4).tolist()} painted + F0 {np.round(painted + f0, 4).tolist()} ΔE76 "
          f"{np.round(de, 2).tolist()}")
    assert np.all(eevee.sum(axis=1) > 0.1)
    assert np.all(de <= 1.0), de


@pytest.mark.slow
def test_eevee_renders_colours_that_are_not_skin_as_painted(eevee_renders):
    """Make-up, ink and paint through the live group's EEVEE output (Material Preview): the sixteen colours of
    tests.test_painted_gain.NON_SKIN within ΔE76 1.0 mean / 2.0 max of the painted colour plus the coat's F0, the
    bounds the Cycles output meets (tests/test_live_colours.py); the nearest skin colour would be up to ΔE76 22 off."""
    _, painted, _, live_rgb, _, _, _ = eevee_renders
    f0 = ((1.4 - 1.0) / (1.4 + 1.0)) ** 2
    de = delta_e76(_lab(live_rgb[4:]), _lab(painted + f0))
    print(f"\nEEVEE, not skin: ΔE76 {np.round(de, 2).tolist()} mean {de.mean():.2f} max {de.max():.2f}")
    assert de.mean() <= 1.0 and de.max() <= 2.0, de


@pytest.mark.slow
def test_principled_base_share_is_what_eevee_renders(eevee_renders):
    """blender_addon.live.PRINCIPLED_BASE_SHARE (the share of the light a Principled BSDF's specular layer leaves its
    base, by which the EEVEE output divides the colour) against a Principled BSDF rendered in EEVEE: (render of
    the painted base - render of a black base) / painted, weighted by luminance per stripe, within 0.015 of it
    (EEVEE's per-channel shares spread 0.93-0.97 on the dark stripe's blue, 0.96-0.97 elsewhere)."""
    painted, _, principled, _, _, _, _ = eevee_renders
    share = (principled[:3] - principled[3]) / painted
    luminance = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB -> Y (ITU-R BT.709)
    by_luminance = ((share * painted) @ luminance) / (painted @ luminance)
    print(f"\nEEVEE Principled base share {np.round(share, 4).tolist()}, by luminance "
          f"{np.round(by_luminance, 4).tolist()}; live.PRINCIPLED_BASE_SHARE {live.PRINCIPLED_BASE_SHARE}")
    assert np.all(np.abs(by_luminance - live.PRINCIPLED_BASE_SHARE) <= 0.015), by_luminance


@pytest.mark.slow
def test_eevee_renders_metal_over_the_skin_as_the_principled_bsdf(eevee_renders):
    """Metallic 1 on the artist's Principled BSDF after Invert Skin Albedo: EEVEE renders each stripe as it renders
    the Principled BSDF's metal (within 2 % per channel), not the skin group's colour."""
    _, _, _, live_rgb, principled_metal, live_metal, _ = eevee_renders
    print(f"\nEEVEE metal: live {np.round(live_metal[:3], 4).tolist()} Principled "
          f"{np.round(principled_metal[:3], 4).tolist()}")
    np.testing.assert_allclose(live_metal, principled_metal, rtol=0.02, atol=1e-4)
    assert np.max(np.abs(live_rgb[:3] - principled_metal[:3])) > 0.02


@pytest.mark.slow
def test_eevee_bumps_the_live_material_by_the_artists_displacement(eevee_renders):
    """The artist's Material Output's Displacement (a height rising along x, the surface tilted away from a side
    sun) reaches the output the add-on added for EEVEE: each skin stripe darkens by the factor the artist's
    Principled BSDF darkens by (within 6 % per channel; about 0.7 here)."""
    live_flat, live_bumped, principled_flat, principled_bumped = eevee_renders[-1][:, :3]
    live, principled = live_bumped / live_flat, principled_bumped / principled_flat
    print(f"\nEEVEE bumped / flat: live {np.round(live, 4).tolist()} Principled {np.round(principled, 4).tolist()}")
    assert np.all(principled < 0.8)
    np.testing.assert_allclose(live, principled, rtol=0.06)


def test_images_of_an_older_layout_still_in_use_are_kept_and_the_new_ones_reused(addon):
    """A file whose older live group still reads images of another layout under the images' names: the new images
    get Blender's suffixed names, the old ones stay for the group that uses them, and a second call finds the new
    ones instead of making more."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    old = bpy.data.images.new(live.image_name("k1 Color"), 8, 8, float_buffer=True)
    old[live.TABLE_PROP] = table.sha256
    older_group = bpy.data.node_groups.new("older live group", "ShaderNodeTree")
    older_group.nodes.new("ShaderNodeTexImage").image = old
    _, first = live.ensure_images(table)
    assert first["k1 Color"] != old and first["k1 Color"].name.startswith(live.image_name("k1 Color") + ".")
    assert tuple(old.size) == (8, 8) and old.users > 0
    count = len(bpy.data.images)
    _, again = live.ensure_images(table)
    assert again == first and len(bpy.data.images) == count


def test_non_finite_colours_read_from_an_image_render_finite(addon):
    """NaN, +Inf and -Inf texels (a float image, as an EXR can hold them) fed to the live group render finite: the
    group's clamp reads NaN as 0 and +Inf as 1 (exporters.live_table, step 3)."""
    scene = probe.new_scene(samples=8, resolution=4, seed=1)
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    for texel in ((np.nan, 0.3, 0.2), (np.inf, 0.3, 0.2), (-np.inf, np.nan, np.inf)):
        image = bpy.data.images.new("non-finite", 2, 2, float_buffer=True)
        image.colorspace_settings.name = "Non-Color"
        image.pixels.foreach_set(np.tile(np.array([*texel, 1.0], np.float32), 4))
        mat = probe.slab_material("non-finite colour")
        tree = mat.node_tree
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Closest"
        node = tree.nodes.new("ShaderNodeGroup")
        node.node_tree = live.ensure_live_group(table)
        node.inputs["Unit Scale"].default_value = 0.01
        tree.links.new(tex.outputs["Color"], node.inputs["Color"])
        tree.links.new(node.outputs["Cycles"], probe.material_output(mat).inputs["Surface"])
        mean = probe.render_mean(scene)[0]
        assert np.all(np.isfinite(mean)) and np.all(mean >= 0.0), (texel, mean)
