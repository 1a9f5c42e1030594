"""Invert Skin Albedo with the real pip bpy, the real shipped model and real files: register, bake from the
active Image Texture node, check the images and the node group, render 32 x 32 in Cycles (SVM and OSL), step
and cancel like the modal operator, unregister cleanly."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import baker, nodes, oblique, preferences, wiring  # noqa: E402
from exporters import bake, image_input, inference, maps  # noqa: E402
from tests.addon_scene import (  # noqa: E402
    image_pixels,
    render_small,
    run_invert,
    skin_codes,
    skin_object,
    snapshot,
    write_image,
)

addon_utils = importlib.import_module("addon_utils")
ADDON = "blender_addon"
K = inference.load_model(preferences.DEFAULT_MODEL, threads=1).k


@pytest.fixture(scope="module")
def albedo_png(tmp_path_factory) -> Path:
    return write_image(tmp_path_factory.mktemp("alb") / "albedo.png", skin_codes(), "uint8")


@pytest.fixture(scope="module")
def reference_maps(albedo_png, tmp_path_factory) -> Path:
    """The same PNG baked by exporters.bake (no Blender involved): what the images must hold."""
    out = tmp_path_factory.mktemp("ref")
    bake.bake(albedo_png, out, preferences.DEFAULT_MODEL, bake.BakeOptions(threads=1))
    return out


def group_node(mat):
    """The mixture group node (the grazing-light correction's group node beside it is not counted)."""
    found = [n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup" and not n.node_tree.get(
        oblique.CORRECTION_PROP)]
    assert len(found) == 1
    return found[0]


def test_bake_svm_packed_wired_and_renders(addon, albedo_png, reference_maps):
    obj, mat, tex = skin_object(albedo_png)
    user_nodes = {n.name for n in mat.node_tree.nodes}
    assert run_invert(obj, backend="SVM") == {"FINISHED"}
    tree = mat.node_tree
    assert user_nodes < {n.name for n in tree.nodes}  # the user's nodes are all kept
    assert tree.nodes["Principled BSDF"].inputs["Base Color"].links[0].from_node == tex
    gnode = group_node(mat)
    assert gnode.node_tree.name.startswith(nodes.GROUP_NAME) and gnode.node_tree["spectral_skin_sss_k"] == K
    assert gnode.node_tree["spectral_skin_sss_backend"] == "SVM"
    out = tree.nodes["Material Output"]  # still the Principled BSDF (Blender's exporters read it); Cycles the group
    assert out.is_active_output and out.inputs["Surface"].links[0].from_node == tree.nodes["Principled BSDF"]
    assert wiring.wired_group_node(mat) == gnode
    assert mat[nodes.PREVIOUS_SURFACE_PROP] == "Principled BSDF"
    assert gnode.inputs["IOR"].default_value == pytest.approx(1.4)
    principled = tree.nodes["Principled BSDF"]  # the coat takes the user's roughness (0.5, Blender's default)
    assert gnode.inputs["Roughness"].default_value == pytest.approx(principled.inputs["Roughness"].default_value)
    grazing = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree.get(
        oblique.CORRECTION_PROP))  # the grazing-light correction reads the albedo, as the live group its colour
    assert grazing.inputs["Color"].links[0].from_node == tex and wiring.is_added(grazing)
    assert gnode.inputs["Weight Scale"].links[0].from_node == grazing  # the weight factors, once for every k
    uv = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeUVMap")
    for k in range(1, K + 1):
        for kind in nodes.KINDS:
            sock = gnode.inputs[nodes.socket_name(k, kind)]
            src = oblique.map_node(sock)
            assert (sock.links[0].from_node != src) == (kind == "Radius")  # through the correction
            assert src.bl_idname == "ShaderNodeTexImage" and src.interpolation == "Closest"
            assert src.inputs["Vector"].links[0].from_node == uv  # same UVs as the albedo
            image = src.image
            name = f"albedo_k{k}_{kind.lower()}.exr"
            assert image.name == name and image.packed_file is not None and image.is_float
            assert image.colorspace_settings.name == "Non-Color"
            assert tuple(image.size) == (4, 3)
            ref, _, _ = maps.read_exr(reference_maps / name)
            got = image_pixels(image)[..., : ref.shape[2]]
            np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7)
    assert not any(p.name.startswith("spectral_skin_sss_") for p in Path(baker.tempfile.gettempdir()).iterdir())
    px = render_small()
    assert np.all(np.isfinite(px)) and px[16, 16, :3].max() > 0.0


def test_without_an_active_image_the_base_colours_image_is_baked(addon, albedo_png, tmp_path):
    """The active node is whatever the artist clicked last: where it is no Image Texture, the bake inverts the
    image feeding the Principled BSDF's Base Color (here through a Reroute), as the live group reads it; an active
    Image Texture stays the artist's choice."""
    obj, mat, tex = skin_object(albedo_png)
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    reroute = tree.nodes.new("NodeReroute")
    tree.links.new(tex.outputs["Color"], reroute.inputs[0])
    tree.links.new(reroute.outputs[0], principled.inputs["Base Color"])
    other = tree.nodes.new("ShaderNodeTexImage")
    other.image = bpy.data.images.load(str(write_image(tmp_path / "other.png", skin_codes()[::-1].copy(), "uint8")))
    tree.nodes.active = principled
    assert baker.albedo_image_node(mat) == tex
    assert run_invert(obj) == {"FINISHED"}
    assert oblique.map_node(group_node(mat).inputs[nodes.socket_name(1, "Color")]).image.name == "albedo_k1_color.exr"
    tree.nodes.active = other
    assert run_invert(obj) == {"FINISHED"}
    assert oblique.map_node(group_node(mat).inputs[nodes.socket_name(1, "Color")]).image.name == "other_k1_color.exr"


def test_bake_osl_and_files_beside_blend(addon, albedo_png, tmp_path):
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    obj, mat, _ = skin_object(albedo_png)
    assert run_invert(obj, backend="OSL", storage="FILES") == {"FINISHED"}
    folder = tmp_path / "albedo_skin_maps"
    expected = {f"albedo_k{k}_{kind}.exr" for k in range(1, K + 1) for kind in ("color", "radius", "weight",
                                                                                 "anisotropy")}
    assert {p.name for p in folder.iterdir()} == expected | {"albedo_maps.json"}
    gnode = group_node(mat)
    assert gnode.node_tree["spectral_skin_sss_backend"] == "OSL"
    assert not bpy.context.scene.cycles.shading_system  # the scene's shading system is the user's to change
    bpy.context.scene.cycles.shading_system = True
    image = oblique.map_node(gnode.inputs["k1 Radius"]).image
    assert image.packed_file is None and Path(bpy.path.abspath(image.filepath)) == folder / "albedo_k1_radius.exr"
    px = render_small()
    assert np.all(np.isfinite(px)) and px[16, 16, :3].max() > 0.0


def test_svm_is_the_default_and_osl_only_on_request(addon, albedo_png):
    assert bpy.ops.spectral_skin.invert_albedo.get_rna_type().properties["backend"].default == "SVM"
    assert baker.BakeSettings(model_path="m.onnx").backend == "SVM"
    scene = bpy.context.scene
    scene.cycles.device = "CPU"
    assert baker.pick_backend(scene, "SVM") == "SVM" and baker.pick_backend(scene, "OSL") == "OSL"
    assert "Open Shading Language" in baker.osl_warning(scene, "OSL") and baker.osl_warning(scene, "SVM") == ""
    scene.cycles.shading_system = True
    assert baker.osl_warning(scene, "OSL") == ""
    scene.cycles.device = "GPU"  # no OptiX on this machine: compute device type NONE
    with pytest.raises(baker.BakeInputError, match="OSL does not run"):
        baker.pick_backend(scene, "OSL")
    assert baker.pick_backend(scene, "SVM") == "SVM"
    with pytest.raises(baker.BakeInputError, match="unknown shading path"):
        baker.pick_backend(scene, "AUTO")


def test_a_scene_saved_with_the_former_auto_shading_asks_for_svm(addon):
    from blender_addon import panels

    settings = bpy.context.scene.spectral_skin
    settings.backend = "OSL"
    assert settings["backend"] == 2 and panels.shading_of(settings) == "OSL"  # the numbers "Auto" = 0 left
    settings.backend = "SVM"
    assert settings["backend"] == 1 and panels.shading_of(settings) == "SVM"
    settings["backend"] = 0  # what a scene saved with "Auto" holds
    assert settings.backend == "" and panels.shading_of(settings) == "SVM"


def test_osl_on_request_leaves_the_scene_shading_system_and_says_so(addon):
    mesh = bpy.data.meshes.new("m")
    obj = bpy.data.objects.new("o", mesh)
    bpy.context.scene.collection.objects.link(obj)
    mesh.materials.append(bpy.data.materials.new("Skin"))
    bpy.context.scene.cycles.shading_system = False
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.add_mixture(components=1, backend="OSL") == {"FINISHED"}
    assert not bpy.context.scene.cycles.shading_system


def test_generated_image_and_shared_group(addon, tmp_path):
    # An image with no file (painted in Blender): float pixels, non-square 3 x 2, linear.
    lin = np.array([[0.55, 0.32, 0.25], [0.30, 0.17, 0.12], [0.62, 0.40, 0.33]])
    img = bpy.data.images.new("painted", 3, 2, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    rows = np.stack([lin, lin[::-1]])  # top row, bottom row
    img.pixels.foreach_set(np.concatenate([rows[::-1], np.ones((2, 3, 1))], axis=2).astype(np.float32).ravel())
    obj1, mat1, _ = skin_object(None, name="A")
    obj2, mat2, _ = skin_object(None, name="B")
    assert run_invert(obj1, image_name="painted", backend="SVM") == {"FINISHED"}
    assert run_invert(obj2, image_name="painted", backend="SVM") == {"FINISHED"}
    g1, g2 = group_node(mat1), group_node(mat2)
    assert g1.node_tree == g2.node_tree  # one shared group, the first material still has it
    model = inference.load_model(preferences.DEFAULT_MODEL, threads=1)
    albedo = image_input.AlbedoImage(rgb=rows, alpha=None, colorspace="linear", source_format="float", n_clamped=0)
    job = bake.BakeJob(albedo, tmp_path, "ref", model, bake.BakeOptions(threads=1))
    for _ in job.steps():
        pass
    job.finish()
    ref = maps.read_exr(tmp_path / f"ref_k{K}_color.exr")[0]
    got = image_pixels(g2.inputs[f"k{K} Color"].links[0].from_node.image)[..., :3]
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7)


def test_stepping_then_cancel_changes_nothing(addon, tmp_path):
    codes = np.random.default_rng(3).integers(60, 230, (6, 5, 3)).astype(np.uint8)  # 30 distinct texels
    png = write_image(tmp_path / "many.png", codes, "uint8")
    obj, mat, _ = skin_object(png)
    out = tmp_path / "maps_out"
    before = snapshot(out)
    for storage in ("FILES", "PACK"):
        settings = baker.BakeSettings(model_path=preferences.DEFAULT_MODEL, storage=storage, output_dir=str(out),
                                      threads=1, chunk=7)
        with bpy.context.temp_override(object=obj, active_object=obj):
            run = baker.AddonBake(bpy.context, settings)
        assert run.step() and 0.0 < run.fraction < 1.0  # one chunk of 7 of the 30 colours
        run.cancel()
        assert snapshot(out) == before
    with bpy.context.temp_override(object=obj, active_object=obj):
        run = baker.AddonBake(bpy.context, baker.BakeSettings(model_path=preferences.DEFAULT_MODEL, threads=1,
                                                              chunk=7, backend="SVM", exact=True))
    fractions = []
    while run.step():
        fractions.append(run.fraction)
    # exact: 5 chunks of at most 7 of the 30 colours, then one band of rows written
    assert fractions == sorted(fractions) and len(fractions) == 6 and fractions[-1] == pytest.approx(1.0)
    assert "baked" in run.apply(bpy.context)


def test_unregister_cleanly():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert addon_utils.enable(ADDON, default_set=True, handle_error=None) is not None
    assert hasattr(bpy.types.Scene, "spectral_skin") and hasattr(bpy.types.WindowManager, "spectral_skin_running")
    assert bpy.types.SPECTRAL_SKIN_OT_invert_albedo.bl_options == {"REGISTER", "UNDO"}  # one undo step
    addon_utils.disable(ADDON, default_set=True)
    assert not hasattr(bpy.types.Scene, "spectral_skin")
    assert not hasattr(bpy.types.WindowManager, "spectral_skin_progress")
    assert not hasattr(bpy.types, "SPECTRAL_SKIN_OT_invert_albedo")


def test_invoke_in_background_runs_synchronously(addon, albedo_png):
    # From the UI the operator is modal (timer steps, Esc); without a window (background, scripts) invoke
    # falls back to the synchronous execute.
    obj, mat, _ = skin_object(albedo_png)
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.invert_albedo("INVOKE_DEFAULT", backend="SVM") == {"FINISHED"}
    assert group_node(mat).node_tree["spectral_skin_sss_k"] == K
    assert not bpy.context.window_manager.spectral_skin_running


def test_udim_albedo_bakes_every_tile_into_udim_maps(addon, tmp_path):
    # The case: a tiled image whose Blender file path is skin.<UDIM>.png, both tiles on disk.
    write_image(tmp_path / "skin.1001.png", skin_codes(), "uint8")
    dark = np.full((3, 4, 3), (120, 80, 60), np.uint8)
    write_image(tmp_path / "skin.1002.png", dark, "uint8")
    obj, mat, tex = skin_object(tmp_path / "skin.1001.png")
    tex.image.source = "TILED"
    assert tex.image.filepath.endswith("skin.<UDIM>.png") and [t.number for t in tex.image.tiles] == [1001, 1002]
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    assert run_invert(obj, backend="SVM", storage="FILES") == {"FINISHED"}
    folder = tmp_path / "skin_skin_maps"
    per_tile = {f"skin.{tile}_k{k}_{kind}.exr" for tile in (1001, 1002) for k in range(1, K + 1)
                for kind in ("color", "radius", "weight", "anisotropy")}
    assert {p.name for p in folder.iterdir()} == per_tile | {"skin.1001_maps.json", "skin.1002_maps.json"}
    gnode = group_node(mat)
    image = gnode.inputs["k1 Color"].links[0].from_node.image
    assert image.source == "TILED" and [t.number for t in image.tiles] == [1001, 1002]
    assert Path(bpy.path.abspath(image.filepath)) == folder / "skin.<UDIM>_k1_color.exr"
    first = maps.read_exr(folder / "skin.1001_k1_weight.exr")[0]
    second = maps.read_exr(folder / "skin.1002_k1_weight.exr")[0]
    assert not np.allclose(first[1, 1], second[1, 1])  # each tile from its own colours
    px = render_small()
    assert np.all(np.isfinite(px)) and px[16, 16, :3].max() > 0.0


def test_udim_albedo_packed_maps_and_a_missing_tile(addon, tmp_path):
    write_image(tmp_path / "skin.1001.png", skin_codes(), "uint8")
    write_image(tmp_path / "skin.1002.png", skin_codes(), "uint8")
    obj, mat, tex = skin_object(tmp_path / "skin.1001.png")
    tex.image.source = "TILED"
    assert run_invert(obj, backend="SVM") == {"FINISHED"}
    image = oblique.map_node(group_node(mat).inputs["k2 Radius"]).image
    assert image.source == "TILED" and len(image.packed_files) == 2 and image.name == "skin.<UDIM>_k2_radius.exr"
    px = render_small()
    assert np.all(np.isfinite(px)) and px[16, 16, :3].max() > 0.0
    obj2, mat2, tex2 = skin_object(tmp_path / "skin.1001.png", name="Other")
    tex2.image.source = "TILED"
    (tmp_path / "skin.1002.png").unlink()
    before = snapshot()
    with pytest.raises(RuntimeError, match=r"tile 1002 of UDIM image '.*' is missing: .*skin\.1002\.png"):
        run_invert(obj2, backend="SVM")
    assert snapshot() == before


def test_without_openimageio_the_file_is_read_by_blender_and_the_maps_are_the_same(addon, albedo_png,
                                                                                    reference_maps, tmp_path):
    # Blender 4.2's Python has no OpenImageIO module: the albedo file is read through Blender and the maps are
    # written uncompressed (exporters.exr).  Same texels, same maps as with OpenImageIO (reference_maps; for the
    # UDIM tiles, exporters.bake of each tile file).
    out, tiled_out = tmp_path / "maps", tmp_path / "tiled"
    write_image(tmp_path / "skin.1001.png", skin_codes(), "uint8")
    write_image(tmp_path / "skin.1002.png", np.full((2, 3, 3), (120, 80, 60), np.uint8), "uint8")
    script = (
        "import sys\n"
        "sys.modules['OpenImageIO'] = None  # any import of it now fails\n"
        f"sys.path.insert(0, {str(Path(__file__).resolve().parents[1])!r})\n"
        "import bpy\nimport addon_utils\n"
        "addon_utils.enable('blender_addon', default_set=True, handle_error=None)\n"
        "bpy.context.preferences.addons['blender_addon'].preferences.threads = 1\n"
        f"print(bpy.ops.spectral_skin.invert_albedo(filepath={str(albedo_png)!r}, storage='FILES', "
        f"output_dir={str(out)!r}, backend='SVM', uv_coverage=False))\n"
        f"image = bpy.data.images.load({str(tmp_path / 'skin.1001.png')!r})\n"
        "image.source = 'TILED'\n"
        f"print(bpy.ops.spectral_skin.invert_albedo(image_name=image.name, storage='FILES', "
        f"output_dir={str(tiled_out)!r}, backend='SVM'))\n"
        "print('OpenImageIO' in sys.modules and sys.modules['OpenImageIO'] is not None)\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "{'FINISHED'}" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert proc.stdout.strip().splitlines()[-1] == "False"
    names = sorted(p.name for p in reference_maps.iterdir() if p.suffix == ".exr")
    assert names and sorted(p.name for p in out.iterdir() if p.suffix == ".exr") == names
    for name in names:
        got, channels, attrs = maps.read_exr(out / name)
        ref, ref_channels, _ = maps.read_exr(reference_maps / name)
        assert channels == ref_channels and attrs["compression"] == "none", name
        np.testing.assert_array_equal(got, ref, err_msg=name)
    assert proc.stdout.count("{'FINISHED'}") == 2
    for tile in (1001, 1002):
        ref_dir = tmp_path / f"ref{tile}"
        ref_dir.mkdir()
        bake.bake(tmp_path / f"skin.{tile}.png", ref_dir, preferences.DEFAULT_MODEL,
                  bake.BakeOptions(threads=1, prune_share=0.0))
        for ref_path in ref_dir.glob("*.exr"):
            np.testing.assert_array_equal(maps.read_exr(tiled_out / ref_path.name)[0], maps.read_exr(ref_path)[0],
                                          err_msg=ref_path.name)
