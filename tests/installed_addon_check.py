"""Run by tests/test_addon_versions.py with the Python of another Blender (bpy 4.2 ... 5.3): the extension zip is
installed through Blender's own extension system, enabled, used, and left enabled at exit.

    python tests/installed_addon_check.py ZIP WORKDIR [register-only]

``register-only``: install without enabling, import the extension's package and call its ``register()`` as a
script would, then exit without unregistering (Blender then has nothing of its own to disable).

BLENDER_USER_RESOURCES must point into WORKDIR (nothing is written to the user's Blender configuration).  Prints
one line ``RESULT{json}``; the caller checks it and that the process exits by itself with status 0 (the add-on
is still registered then: 4.2 crashed and 4.5 hung there).  Imports only the standard library, bpy and numpy
(what Blender's own Python has), so it runs unchanged on Python 3.11 and 3.13.
"""

from __future__ import annotations

import importlib
import json
import os
import runpy
import sys
import time

import bpy
import numpy as np

EXTENSION = "bl_ext.user_default.spectral_skin_sss"
#: A light skin colour (linear Rec.709) for the tiny bake.
SKIN_LINEAR = (0.55, 0.32, 0.25)


#: Samples of the renders comparing an edit from its cache with the same edit from the table, whose texels are drawn
#: per sample: the two renders' difference is their noise.
DRAWN_SAMPLES = 256


def render_centre(scene, samples: int = 8, folder: str | None = None) -> list[float]:
    """Render the scene (Cycles CPU, 16 x 16, ``samples`` samples) and return the mean linear RGB of its centre 6 x 6
    pixels (all on the sphere); the render is written in ``folder`` (default: the script's work folder)."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.render.resolution_percentage = 100
    return render_pixels(scene, folder)[5:11, 5:11].mean(axis=(0, 1)).astype(float).tolist()


def render_pixels(scene, folder: str | None = None) -> np.ndarray:
    """Render the scene as it is set up; its linear RGB (height, width, 3), bottom row first, read back from an EXR
    written in ``folder`` (default: the script's work folder)."""
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = os.path.join(folder or sys.argv[2], f"render_{time.monotonic_ns()}.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath)
    width, height = image.size
    px = np.empty(width * height * image.channels, np.float32)
    image.pixels.foreach_get(px)
    bpy.data.images.remove(image)
    return px.reshape(height, width, -1)[..., :3]


def set_component(gnode) -> None:
    """Give component 1 of a mixture group node a skin colour and radius (constant inputs, no maps)."""
    for socket, rgb in (("k1 Color", SKIN_LINEAR), ("k1 Radius", (0.3, 0.1, 0.05))):
        value = gnode.inputs[socket].default_value
        gnode.inputs[socket].default_value = (*rgb, 1.0)[: len(value)]


def skin_scene():
    """The scene emptied (factory settings would also disable the extension), with a UV sphere in front of a
    camera, lit by a white world; returns the sphere."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0):  # node trees are always there from 5.0 on (use_nodes is deprecated)
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    scene.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0)
    obj = bpy.context.active_object
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location = (0.0, -4.0, 0.0)
    camera.rotation_euler = (1.5708, 0.0, 0.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    return obj


#: Samples of the thin-disk probe: its centre's mean then moves by about 1 % (blue; red 0.3 %) from seed to seed.
THIN_SAMPLES = 1024


def thin_disk_centre(backend: str, wire, folder: str | None = None) -> list[float]:
    """The mixture group of ``backend`` ("SVM" or "OSL"; one component, :func:`set_component`'s medium) on the
    sphere flattened to a disk 0.06 thick facing the camera, the white world behind it: how much light its
    translucency lets through, which the closures' radius sets (on the round sphere the colour hardly depends on
    it).  ``wire(material, backend)`` puts the group into the material and returns its node; ``folder``: as
    :func:`render_centre`'s."""
    obj = skin_scene()
    obj.scale = (1.0, 0.03, 1.0)
    material = bpy.data.materials.new(f"Thin{backend}")
    if bpy.app.version < (5, 0):
        material.use_nodes = True
    obj.data.materials.append(material)
    set_component(wire(material, backend))
    bpy.context.scene.cycles.shading_system = backend == "OSL"
    try:
        return render_centre(bpy.context.scene, THIN_SAMPLES, folder)
    finally:
        bpy.context.scene.cycles.shading_system = False


#: Colours (linear) whose live-group media the check reads back: skin, pure blue, white, a deep red, negative and
#: above 1 (outside the table's box: projected and brought to the painted colour).
PROBE_COLOURS = ((0.45, 0.28, 0.20), (0.0, 0.0, 1.0), (1.0, 1.0, 1.0), (0.9, 0.02, 0.01), (-0.5, 0.2, 0.1),
                 (5.0, 3.0, 2.0))


def media_probe(material, colour, group, probe) -> tuple:
    """A node of the live ``group`` in ``material``, fed ``colour`` (a socket), and an Emission node feeding the
    material's output, through which a value inside the group is read back (``probe``: the add-on's probe module).
    Returns (the group node, the group's mixture node, its Group Output, the Emission node)."""
    tree = material.node_tree
    mixture = next(n for n in group.nodes if n.bl_idname == "ShaderNodeGroup" and "k1 Color" in n.inputs)
    gout = next(n for n in group.nodes if n.bl_idname == "NodeGroupOutput")
    gnode = tree.nodes.new("ShaderNodeGroup")
    gnode.node_tree = group
    tree.links.new(colour, gnode.inputs["Color"])
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(emission.outputs[0], probe.material_output(material).inputs["Surface"])
    return gnode, mixture, gout, emission


def live_media(addon: str, folder: str | None = None) -> dict[str, list]:
    """The live group's media for :data:`PROBE_COLOURS` as this Blender's nodes compute them: each mixture input
    (``k{k} Color|Radius|Weight``) read back as emission, one column per colour, face-on (no grazing factor).
    ``addon``: the add-on's package ("blender_addon", or the installed extension's); ``folder``: as
    :func:`render_centre`'s."""
    live = importlib.import_module(f"{addon}.live")
    preferences = importlib.import_module(f"{addon}.preferences")
    probe = importlib.import_module(f"{addon}.probe")
    scene = probe.new_scene(samples=1, resolution=len(PROBE_COLOURS), seed=3)
    scene.render.resolution_y = 2
    scene.cycles.filter_width = 0.01  # one column per colour, nothing blended
    image = bpy.data.images.new("probe colours", len(PROBE_COLOURS), 1, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(np.array([(*c, 1.0) for c in PROBE_COLOURS], np.float32).ravel())
    material = probe.slab_material("LiveMedia")
    tree = material.node_tree
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Location"].default_value = (0.5, 0.5, 0.0)  # the view's x, y in [-0.5, 0.5] onto [0, 1]
    tree.links.new(tree.nodes.new("ShaderNodeTexCoord").outputs["Object"], mapping.inputs["Vector"])
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image, texture.interpolation, texture.extension = image, "Closest", "EXTEND"
    tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    group = live.ensure_live_group(live.table_for_model(preferences.DEFAULT_MODEL))
    gnode, mixture, gout, emission = media_probe(material, texture.outputs["Color"], group, probe)
    out = {}
    for k in range(1, group["spectral_skin_sss_k"] + 1):
        for kind in ("Color", "Radius", "Weight"):
            name = f"k{k} {kind}"
            group.interface.new_socket(f"Check {name}", in_out="OUTPUT", socket_type="NodeSocketColor")
            group.links.new(mixture.inputs[name].links[0].from_socket, gout.inputs[f"Check {name}"])
            tree.links.new(gnode.outputs[f"Check {name}"], emission.inputs["Color"])
            out[name] = render_pixels(scene, folder)[0].astype(float).tolist()
    return out


def _wire_by_operator(material, backend: str):
    """The installed add-on's Add Mixture operator on the active object: its group node."""
    obj = bpy.context.active_object
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.spectral_skin.add_mixture(components=1, backend=backend)
    return next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup")


def textured_material(obj, name: str, image):
    """A new material on ``obj``: ``image`` in an Image Texture node (active) feeding its Principled BSDF's Base
    Color."""
    material = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0):
        material.use_nodes = True
    obj.data.materials.append(material)
    tex = material.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    material.node_tree.links.new(tex.outputs["Color"], material.node_tree.nodes["Principled BSDF"].inputs[0])
    material.node_tree.nodes.active = tex
    return material


def main() -> dict:
    zip_path = sys.argv[1]
    out: dict = {"blender": bpy.app.version_string, "python": "{}.{}".format(*sys.version_info[:2])}
    t0 = time.perf_counter()
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    out["install_s"] = round(time.perf_counter() - t0, 2)
    out["enabled"] = EXTENSION in bpy.context.preferences.addons
    package = sys.modules[EXTENSION]
    folder = os.path.dirname(os.path.abspath(package.__file__))
    out["top_level_modules"] = sorted(m for m in ("exporters", "blender_addon") if m in sys.modules)
    out["extension_on_sys_path"] = any(os.path.abspath(p or ".") == folder for p in sys.path)
    out["openimageio_imported_by_enabling"] = "OpenImageIO" in sys.modules
    out["core"] = sys.modules[f"{EXTENSION}.blender_addon.core"].EXPORTERS

    # The network, through the extension's own exporters and the onnxruntime wheel the zip carries for this Python.
    inference = importlib.import_module(f"{EXTENSION}.exporters.inference")
    models = importlib.import_module(f"{EXTENSION}.blender_addon.models")
    rows = inference.load_model(models.INVERSION_MODEL, threads=1).run(np.array([SKIN_LINEAR]))
    out["inference_finite"] = all(bool(np.all(np.isfinite(v))) for v in rows.values())
    out["onnxruntime"] = getattr(sys.modules.get("onnxruntime"), "__file__", None)

    # The baked path: Invert Skin Albedo on an image painted in Blender (no file), every colour through the model,
    # SVM, maps packed (on 4.2, which has no OpenImageIO module, written by exporters.exr).
    obj = skin_scene()
    bpy.context.preferences.addons[EXTENSION].preferences.threads = 1
    image = bpy.data.images.new("painted", 4, 4, float_buffer=True)
    image.colorspace_settings.name = "Linear Rec.709"
    image.pixels.foreach_set([*SKIN_LINEAR, 1.0] * 16)
    material = textured_material(obj, "Skin", image)
    t0 = time.perf_counter()
    try:
        with bpy.context.temp_override(object=obj, active_object=obj):
            out["invert"] = sorted(bpy.ops.spectral_skin.invert_albedo(mode="BAKE", exact=True))
    except RuntimeError as exc:
        out["invert"], out["invert_error"] = ["ERROR"], str(exc)
    out["invert_s"] = round(time.perf_counter() - t0, 2)
    out["openimageio"] = getattr(sys.modules.get("OpenImageIO"), "__file__", None)
    groups = [n.node_tree for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]
    out["nodes_after_invert"] = len(material.node_tree.nodes)
    if not groups:  # no baked maps (4.2): the SVM group with constant inputs
        with bpy.context.temp_override(object=obj, active_object=obj):
            bpy.ops.spectral_skin.add_mixture(components=1, backend="SVM")
        set_component(next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"))
        groups = [n.node_tree for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"]
    out["group_backend"] = groups[0].get("spectral_skin_sss_backend") if groups else None
    out["shading_system_after_invert"] = bool(bpy.context.scene.cycles.shading_system)
    t0 = time.perf_counter()
    out["svm_centre"] = render_centre(bpy.context.scene)
    out["svm_render_s"] = round(time.perf_counter() - t0, 2)

    # The headless script of the installed extension, run as Blender runs `--python <extension>/blender_addon/bake.py`
    # (it finds the extension's own exporters, never a top-level one).
    png = os.path.join(sys.argv[2], "albedo.png")
    image.filepath_raw, image.file_format = png, "PNG"
    image.save()
    argv, sys.argv = sys.argv, ["bake.py", "--", "--albedo", png, "--out", os.path.join(sys.argv[2], "maps"),
                                "--threads", "1", "--quiet"]
    try:
        runpy.run_path(os.path.join(folder, "blender_addon", "bake.py"), run_name="__main__")
        out["bake_script_exit"] = 0
    except SystemExit as exc:
        out["bake_script_exit"] = exc.code
    finally:
        sys.argv = argv
    maps_dir = os.path.join(sys.argv[2], "maps")
    out["bake_script_files"] = len(os.listdir(maps_dir)) if os.path.isdir(maps_dir) else 0
    out["top_level_modules_after_script"] = sorted(m for m in ("exporters", "blender_addon") if m in sys.modules)

    # The default of Invert Skin Albedo: the live group, fed by the Image Texture that feeds Base Color.
    obj = skin_scene()
    material = textured_material(obj, "SkinLive", image)
    t0 = time.perf_counter()
    try:
        with bpy.context.temp_override(object=obj, active_object=obj):
            out["live_invert"] = sorted(bpy.ops.spectral_skin.invert_albedo())
    except RuntimeError as exc:
        out["live_invert"], out["live_invert_error"] = ["ERROR"], str(exc)
    out["live_invert_s"] = round(time.perf_counter() - t0, 2)
    out["live_group"] = sorted(n.node_tree.name for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup")
    out["live_centre"] = render_centre(bpy.context.scene)
    # A skin edit from a preset renders from its cache, as from the table (the cache input set back to 0 with the
    # add-on's handlers off, which would cache it again).
    live_edits = importlib.import_module(f"{EXTENSION}.blender_addon.live_edits")
    with bpy.context.temp_override(object=obj, active_object=obj, material=material):
        out["edit_preset"] = sorted(bpy.ops.spectral_skin.skin_edit_preset(preset="FLUSH"))
    node = live_edits.live_node(material)

    def cached_and_table(prefix: str) -> None:
        """The node's cache status and render, then its render with the cache input set back to 0 and the mask cache
        holding no edit (its line's end at neutral), which draws the table's texels per sample: both at
        :data:`DRAWN_SAMPLES`."""
        out[f"{prefix}_cache"] = live_edits.cache_status(node)
        out[f"{prefix}_centre_cached"] = render_centre(bpy.context.scene, DRAWN_SAMPLES)
        live_edits.unregister_handlers()
        live_edits.set_edit(node, tuple(node.inputs[name].default_value for name in ("Melanin", "Blood",
                                                                                       "Oxygenation")), cache=False)
        live_edits.empty_mask_cache(node.node_tree)
        out[f"{prefix}_centre_table"] = render_centre(bpy.context.scene, DRAWN_SAMPLES)
        live_edits.register_handlers()

    cached_and_table("edit")
    # The same edit painted by a mask (the albedo's red into Edit Mask): the add-on's handler caches it in the mask
    # cache, which renders the table's answer to within the cache's own difference.
    tree = material.node_tree
    tex = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage" and n.image == image)
    red = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(tex.outputs["Color"], red.inputs[0])
    tree.links.new(red.outputs[0], node.inputs["Edit Mask"])
    bpy.context.view_layer.update()
    cached_and_table("edit_mask")
    # A blush keyframed on Blood (as painted at frame 1, 2.5 at frame 21; the mask unlinked): the add-on holds its
    # line in the mask cache, which the frames an animation render from the interface evaluates read.
    tree.links.remove(node.inputs["Edit Mask"].links[0])
    node.inputs["Oxygenation"].default_value = 0.0
    for frame, value in ((1, 1.0), (21, 2.5)):
        node.inputs["Blood"].default_value = value
        node.inputs["Blood"].keyframe_insert("default_value", frame=frame)
    bpy.context.view_layer.update()
    out["keyed_line"] = live_edits.animated_line(node, bpy.context.scene)
    out["keyed_status"] = live_edits.line_status(node, bpy.context.scene)
    tree.animation_data_clear()
    # Twelve constant edits in the file (eleven materials not rendered, then this one): the twelfth renders from the
    # last cache of images of its own; the fifteenth from the last spare cache (an atlas of the mask cache's images,
    # which holds no line in use now); each as from the table.
    live_edits.set_edit(node, (1.0, 1.0, 0.0))  # as painted: no cache of the file in use

    def edit_others(first: int, last: int) -> None:
        for i in range(first, last):
            other = bpy.data.materials.new(f"Edited {i}")
            if bpy.app.version < (5, 0):
                other.use_nodes = True
            other_node = other.node_tree.nodes.new("ShaderNodeGroup")
            other_node.node_tree = node.node_tree
            live_edits.set_edit(other_node, (1.0 + 0.05 * i, 0.9, 0.0))

    edit_others(1, 12)
    live_edits.set_edit(node, (1.5, 2.5, -0.2))
    cached_and_table("edit_twelfth")
    live_edits.set_edit(node, (1.0, 1.0, 0.0))
    edit_others(12, 15)
    live_edits.set_edit(node, (1.5, 2.5, -0.2))
    cached_and_table("edit_spare")
    # The flush painted by the albedo's red fed to Blood and Oxygenation through Math nodes: Use Edit Mask links that
    # mask to Edit Mask instead, and the edit renders from the mask cache.
    live_edits.set_edit(node, (1.0, 1.0, 0.0))
    for name, slope, neutral in (("Blood", 1.5, 1.0), ("Oxygenation", 0.05, 0.0)):
        math = tree.nodes.new("ShaderNodeMath")
        math.operation = "MULTIPLY_ADD"
        tree.links.new(red.outputs[0], math.inputs[0])
        math.inputs[1].default_value, math.inputs[2].default_value = slope, neutral
        tree.links.new(math.outputs[0], node.inputs[name])
    with bpy.context.temp_override(object=obj, active_object=obj, material=material):
        out["use_edit_mask"] = sorted(bpy.ops.spectral_skin.use_edit_mask())
    out["use_edit_mask_cache"] = live_edits.cache_status(node)
    tree.links.remove(node.inputs["Edit Mask"].links[0])
    # The skin material appended from another file holding the same groups: it renders through this file's, and the
    # copies it brought are left unused (a timer of the main loop, which a script has not, removes them).
    first, second = (os.path.join(sys.argv[2], name) for name in ("first.blend", "second.blend"))
    bpy.ops.wm.save_as_mainfile(filepath=first)
    bpy.ops.wm.save_as_mainfile(filepath=second)
    with bpy.data.libraries.load(first, link=False) as (_, target):
        target.materials = [material.name]
    obj.data.materials.append(target.materials[0])
    bpy.context.view_layer.update()
    out["appended_group"] = live_edits.live_node(target.materials[0]).node_tree.name
    out["appended_copies_used"] = sorted(g.name for g in bpy.data.node_groups
                                         if g.name.startswith("Spectral Skin SSS") and g.name[-4:-3] == "." and g.users)

    # The live material on a sphere of its own, Melanin fed by a Value node (a constant edit: from a cache) and Blood
    # painted by the albedo's red through a Math node: a bake takes that edit (blender_addon.edit_masks), as the same
    # values set on the operator bake it for another material.
    obj = skin_scene()
    obj.data.materials.append(material)
    value = tree.nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 1.5
    tree.links.new(value.outputs[0], node.inputs["Melanin"])
    node.inputs["Oxygenation"].default_value = 0.0
    bpy.context.view_layer.update()
    out["value_fed_cache"] = live_edits.cache_status(node)
    math = tree.nodes.new("ShaderNodeMath")
    math.operation = "MULTIPLY_ADD"
    tree.links.new(red.outputs[0], math.inputs[0])
    math.inputs[1].default_value, math.inputs[2].default_value = 1.5, 1.0
    tree.links.new(math.outputs[0], node.inputs["Blood"])
    with bpy.context.temp_override(object=obj, active_object=obj):
        out["live_edit_bake"] = sorted(bpy.ops.spectral_skin.invert_albedo(mode="BAKE", exact=True))
    out["live_edit_bake_centre"] = render_centre(bpy.context.scene)
    obj = skin_scene()
    textured_material(obj, "SkinValuesBake", image)
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.spectral_skin.invert_albedo(mode="BAKE", exact=True, edit_from_live=False, melanin=1.5,
                                            blood=1.0 + 1.5 * image.pixels[0])
    out["values_bake_centre"] = render_centre(bpy.context.scene)

    # OSL on request: the Script node compiles (Cycles 4.2 has no oslquery) and renders once OSL is turned on.
    obj = skin_scene()
    material = bpy.data.materials.new("SkinOSL")
    if bpy.app.version < (5, 0):
        material.use_nodes = True
    obj.data.materials.append(material)
    with bpy.context.temp_override(object=obj, active_object=obj):
        out["add_osl"] = sorted(bpy.ops.spectral_skin.add_mixture(components=1, backend="OSL"))
    out["shading_system_after_add_osl"] = bool(bpy.context.scene.cycles.shading_system)
    gnode = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup")
    set_component(gnode)
    script = next(n for n in gnode.node_tree.nodes if n.bl_idname == "ShaderNodeScript")
    out["osl_compiled"] = bool(script.bytecode) and "BSSRDF" in script.outputs
    bpy.context.scene.cycles.shading_system = True
    t0 = time.perf_counter()
    out["osl_centre"] = render_centre(bpy.context.scene)
    out["osl_render_s"] = round(time.perf_counter() - t0, 2)

    # Translucency: a thin disk lit from behind, whose brightness the closures' radius sets (the caller compares it
    # with Blender 5.0's; Blender 5.3's "Random Walk" takes radii 4 pi times longer than earlier ones').
    for backend in ("SVM", "OSL"):
        out[f"thin_{backend.lower()}"] = thin_disk_centre(backend, _wire_by_operator)

    # The live material again, its Principled BSDF inside a node group: the live group goes in there and renders the
    # sphere as it rendered the flat material; Remove Skin SSS gives back the node group as it was.
    obj = skin_scene()
    bpy.context.scene.cycles.shading_system = False  # SVM, as the flat renders it is compared with (OSL is on above)
    material = textured_material(obj, "SkinGrouped", image)
    group = group_the_principled(material)
    before = sorted(n.name for n in group.nodes), len(group.interface.items_tree)
    with bpy.context.temp_override(object=obj, active_object=obj):
        out["grouped_invert"] = sorted(bpy.ops.spectral_skin.invert_albedo())
        out["grouped_outputs"] = sorted(i.name for i in group.interface.items_tree if i.in_out == "OUTPUT")
        out["grouped_centre"] = render_centre(bpy.context.scene)
        # Melanin exposed as the node group's input, set on the material's group node: a constant edit, cached.
        inner = live_edits.live_node(material)
        exposed = group.interface.new_socket("Melanin", in_out="INPUT", socket_type="NodeSocketFloat")
        group.links.new(next(n for n in group.nodes if n.bl_idname == "NodeGroupInput").outputs["Melanin"],
                        inner.inputs["Melanin"])
        next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"
             and n.node_tree == group).inputs["Melanin"].default_value = 1.5
        bpy.context.view_layer.update()
        out["grouped_exposed"] = (live_edits.input_value(inner, "Melanin"), live_edits.cache_status(inner))
        group.interface.remove(exposed)
        bpy.ops.spectral_skin.remove()
    out["grouped_restored"] = (sorted(n.name for n in group.nodes), len(group.interface.items_tree)) == before
    # Baked maps go into the same node group (the material's alone, the albedo on the default UVs) and render the
    # sphere as the flat material's baked maps do (rendered here, in the same scene state).
    flat_obj = skin_scene()
    textured_material(flat_obj, "SkinFlatBake", image)
    with bpy.context.temp_override(object=flat_obj, active_object=flat_obj):
        bpy.ops.spectral_skin.invert_albedo(mode="BAKE", exact=True)
    out["flat_bake_centre"] = render_centre(bpy.context.scene)
    obj = skin_scene()
    obj.data.materials.append(material)
    with bpy.context.temp_override(object=obj, active_object=obj):
        out["grouped_bake"] = sorted(bpy.ops.spectral_skin.invert_albedo(mode="BAKE", exact=True))
        out["grouped_bake_inside"] = sum(n.bl_idname == "ShaderNodeTexImage" for n in group.nodes)
        out["grouped_bake_centre"] = render_centre(bpy.context.scene)
        bpy.ops.spectral_skin.remove()
    out["grouped_bake_restored"] = (sorted(n.name for n in group.nodes), len(group.interface.items_tree)) == before

    # The live group's node math: its media for colours in and out of the skin box (the caller compares with 5.0's).
    out["live_media"] = live_media(f"{EXTENSION}.blender_addon")
    return out


def group_the_principled(material):
    """Put ``material``'s Principled BSDF into a node group (a new one inside, fed through a Base Color input of the
    group node by what fed it), as an asset's skin shader has it; returns the node group."""
    tree = material.node_tree
    principled = tree.nodes["Principled BSDF"]
    group = bpy.data.node_groups.new("Skin Shader", "ShaderNodeTree")
    group.interface.new_socket("Base Color", in_out="INPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")
    inner = group.nodes.new("ShaderNodeBsdfPrincipled")
    group.links.new(group.nodes.new("NodeGroupInput").outputs[0], inner.inputs["Base Color"])
    group.links.new(inner.outputs[0], group.nodes.new("NodeGroupOutput").inputs[0])
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    tree.links.new(principled.inputs["Base Color"].links[0].from_socket, node.inputs[0])
    tree.links.new(node.outputs[0], principled.outputs[0].links[0].to_socket)
    tree.nodes.remove(principled)
    return group


def register_only() -> dict:
    bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=False)
    package = importlib.import_module(EXTENSION)
    package.register()
    return {"blender": bpy.app.version_string, "registered": hasattr(bpy.types, "SPECTRAL_SKIN_OT_invert_albedo"),
            "enabled": EXTENSION in bpy.context.preferences.addons}


if __name__ == "__main__":
    print("RESULT" + json.dumps(register_only() if sys.argv[3:] == ["register-only"] else main()), flush=True)
