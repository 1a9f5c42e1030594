"""Helpers for the add-on tests: a material with an albedo Image Texture, images on disk, a small render,
and a snapshot of everything the operator may touch (to check that a failed run changed nothing)."""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Callable
from pathlib import Path

import bpy
import numpy as np
import OpenImageIO as oiio


def write_image(path: Path, pixels: np.ndarray, fmt: str, channel_names=None, **attrs) -> Path:
    """Write ``pixels`` (H, W[, C]) with OpenImageIO in ``fmt`` ("uint8", "uint16", "float")."""
    pixels = pixels if pixels.ndim == 3 else pixels[..., None]
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    if channel_names:
        spec.channelnames = tuple(channel_names)
    if c in (2, 4):
        spec.alpha_channel = c - 1
        spec.attribute("oiio:UnassociatedAlpha", 1)
    for key, value in attrs.items():
        spec.attribute(key.replace("__", ":"), value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(np.ascontiguousarray(pixels))
    out.close()
    return path


def skin_codes(h: int = 3, w: int = 4) -> np.ndarray:
    """8-bit sRGB skin-like texture (H, W, 3) with a few distinct colours (rows differ: orientation)."""
    codes = np.empty((h, w, 3), np.uint8)
    codes[...] = (224, 172, 150)
    codes[0, :] = (150, 100, 80)
    codes[-1, -1] = (90, 60, 45)
    return codes


def skin_object(albedo: Path | None = None, name: str = "Skin", with_uv_node: bool = True):
    """A UV sphere with a material: Image Texture (albedo) -> Principled Base Color, the texture node active.
    Returns (object, material, texture node or None)."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.0)
    obj = bpy.context.active_object
    mat = bpy.data.materials.new(name)
    obj.data.materials.append(mat)
    tree = mat.node_tree
    tex = None
    if albedo is not None:
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(str(albedo), check_existing=False)
        tex.location = (-500.0, 200.0)
        tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
        if with_uv_node:
            uv = tree.nodes.new("ShaderNodeUVMap")
            uv.location = (-800.0, 200.0)
            tree.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        tree.nodes.active = tex
    return obj, mat, tex


def run_invert(obj, **kwargs) -> set[str]:
    """bpy.ops.spectral_skin.invert_albedo with ``obj`` active (raises RuntimeError on a reported error); mode
    BAKE unless ``mode`` is given (the bake tests' helper: the operator's own default is the live group)."""
    kwargs.setdefault("mode", "BAKE")
    with bpy.context.temp_override(object=obj, active_object=obj):
        return bpy.ops.spectral_skin.invert_albedo(**kwargs)


def render_linear(scene: bpy.types.Scene, path: Path) -> np.ndarray:
    """Render ``scene`` to ``path`` (its file format) and read it back: linear RGB (H, W, 3) float64, row 0 at the
    bottom (Blender's order); fails on a non-finite pixel."""
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    bpy.data.images.remove(image)
    rgb = px.reshape(h, w, 4)[..., :3].astype(np.float64)
    assert np.all(np.isfinite(rgb)), f"non-finite pixels in {path}"
    return rgb


def cycles_memory_mb(render: Callable[[], object]) -> float:
    """Run ``render`` (a Cycles render) and return the memory Cycles reports when done (MB: its images, BVH and
    buffers), read from the render's statistics."""
    stats: list[str] = []

    def keep(text: str) -> None:
        stats.append(text)

    bpy.app.handlers.render_stats.append(keep)
    try:
        render()
    finally:
        bpy.app.handlers.render_stats.remove(keep)
    found = [re.findall(r"Mem: *([0-9.]+)M", text) for text in stats]
    return float([f for f in found if f][-1][0])


def render_small(size: int = 32, samples: int = 8) -> np.ndarray:
    """Render the current scene with Cycles (CPU) from a camera in front of the origin, lit by a sun and a
    grey world; returns the (size, size, 4) float pixels."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.5
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.rotation_euler = (0.8, 0.2, 0.3)
    scene.collection.objects.link(sun)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "r.exr")
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.filepath = path
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(path)
        px = np.empty(size * size * 4, np.float32)
        img.pixels.foreach_get(px)
        bpy.data.images.remove(img)
    return px.reshape(size, size, 4)


def image_pixels(image) -> np.ndarray:
    """(H, W, C) float pixels of a Blender image, rows top to bottom (as the files store them)."""
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, image.channels)[::-1]


def snapshot(folder: Path | None = None) -> dict:
    """What a failed Invert Skin Albedo must leave untouched."""
    state = {
        "images": sorted((i.name, i.filepath, i.packed_file is not None) for i in bpy.data.images),
        "groups": sorted(bpy.data.node_groups.keys()),
        "materials": {m.name: (sorted(n.name for n in m.node_tree.nodes),
                               sorted((ln.from_node.name, ln.from_socket.identifier, ln.to_node.name,
                                       ln.to_socket.identifier) for ln in m.node_tree.links),
                               sorted(m.keys()), m.use_thickness_from_shadow)
                      for m in bpy.data.materials if m.node_tree is not None},
        "osl": bpy.context.scene.cycles.shading_system,
        "texts": sorted(bpy.data.texts.keys()),
    }
    if folder is not None:
        state["files"] = sorted(p.name for p in folder.iterdir()) if folder.exists() else None
    state["tmp"] = sorted(p for p in os.listdir(tempfile.gettempdir()) if p.startswith("spectral_skin_sss_"))
    return state


def principled_coat_reflectance(scene, mus, roughness: float, ior: float) -> np.ndarray:
    """(len(mus), 3) mean render of the probe slab (blender_addon.probe) under its white world, seen at each
    view cosine of ``mus``, with a plain Principled BSDF of black base colour, ``roughness`` and ``ior``: what
    Blender's own Principled specular layer reflects, the reference for the skin group's coat.  The slab's
    material is restored afterwards."""
    from blender_addon import probe

    slab = bpy.data.objects["ProbeSlab"]
    kept = list(slab.data.materials)
    mat = probe.slab_material("PrincipledCoatReference")
    spec = mat.node_tree.nodes.new("ShaderNodeBsdfPrincipled")
    spec.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    spec.inputs["Roughness"].default_value = roughness
    spec.inputs["IOR"].default_value = ior
    mat.node_tree.links.new(spec.outputs["BSDF"], probe.material_output(mat).inputs["Surface"])
    out = []
    for mu in mus:
        probe.view_from(scene, float(mu))
        out.append(probe.render_mean(scene)[0])
    slab.data.materials.clear()
    for m in kept:
        slab.data.materials.append(m)
    bpy.data.materials.remove(mat)
    return np.array(out)
