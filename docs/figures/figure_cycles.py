"""What the Cycles figure scripts of this folder share (metal_layer.py, displacement.py): an empty Cycles scene, its
camera and area lights, a render read back display-referred, and panels saved side by side.  Imported by those
scripts, which run from the repository root with the project's venv (``.venv/bin/python docs/figures/displacement.py``,
for one)."""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from pathlib import Path

import bpy
import numpy as np
from PIL import Image

import blender_addon
from exporters.colorimetry import srgb_encode


def cycles_scene(width: int, height: int, samples: int, seed: int, world_rgb: tuple[float, float, float]
                 ) -> bpy.types.Scene:
    """An empty factory scene set to render in Cycles at ``width`` x ``height`` px, ``samples`` without denoising,
    view transform Standard, into OpenEXR, under a uniform world of linear colour ``world_rgb``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples, scene.cycles.use_denoising, scene.cycles.seed = samples, False, seed
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*world_rgb, 1.0)
    scene.world = world
    return scene


def look_from(scene: bpy.types.Scene, location: tuple[float, float, float], tilt_deg: float) -> None:
    """The scene's camera: a 50 mm lens at ``location`` (m), tilted ``tilt_deg`` from looking straight down about x,
    clipping from 1 mm (the subjects are centimetres across)."""
    bpy.ops.object.camera_add(location=location, rotation=(math.radians(tilt_deg), 0.0, 0.0))
    scene.camera = bpy.context.object
    scene.camera.data.lens, scene.camera.data.clip_start = 50, 0.001


def area_light(location: tuple[float, float, float], energy: float, size: float,
               rotation_deg: tuple[float, float, float]) -> bpy.types.Object:
    """A square area light of ``energy`` (W) and side ``size`` (m) at ``location`` (m), turned by ``rotation_deg``
    (Euler XYZ, degrees); returns it."""
    bpy.ops.object.light_add(type="AREA", location=location)
    light = bpy.context.object
    light.data.energy, light.data.size = energy, size
    light.rotation_euler = tuple(math.radians(angle) for angle in rotation_deg)
    return light


def render(path: Path) -> np.ndarray:
    """Render the scene to ``path`` and read it back display-referred: (H, W, 3) sRGB in [0, 1], row 0 at the top."""
    scene = bpy.context.scene
    width, height = scene.render.resolution_x, scene.render.resolution_y
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    pixels = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(pixels)
    return srgb_encode(np.clip(pixels.reshape(height, width, 4)[::-1, :, :3], 0.0, 1.0))


def save_panels(panels: list[np.ndarray], out: Path) -> None:
    """``panels`` (each (H, W, 3) in [0, 1]) side by side, 4 white pixels apart, as an 8-bit PNG at ``out``."""
    gap = np.ones((panels[0].shape[0], 4, 3))
    row = np.concatenate([part for panel in panels for part in (gap, panel)][1:], axis=1)
    Image.fromarray(np.round(255 * row).astype(np.uint8)).save(out, optimize=True)
    print(f"wrote {out}")


def skin_material(obj: bpy.types.Object, name: str) -> bpy.types.Material:
    """A new material ``name`` on ``obj`` with nodes: Blender's default Principled BSDF at Subsurface Weight 1."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    obj.data.materials.append(mat)
    mat.node_tree.nodes["Principled BSDF"].inputs["Subsurface Weight"].default_value = 1.0
    return mat


def before_after_without(obj: bpy.types.Object, out: Path, check: Callable[[bpy.types.Material], None],
                         take_out: Callable[[bpy.types.Material], None]) -> None:
    """Render ``obj`` with its material as the artist made it (their Principled BSDF), after Invert Skin Albedo (the
    live group; ``check`` asserts what the add-on made), and after ``take_out`` removed a part of what it made (the
    add-on unregistered first, so that no handler puts it back); save the three panels at ``out``."""
    mat = obj.active_material
    blender_addon.register()
    with tempfile.TemporaryDirectory() as tmp:
        principled = render(Path(tmp) / "principled.exr")
        with bpy.context.temp_override(object=obj, active_object=obj):
            assert bpy.ops.spectral_skin.invert_albedo(mode="LIVE") == {"FINISHED"}
        check(mat)
        live = render(Path(tmp) / "live.exr")
        blender_addon.unregister()
        take_out(mat)
        without = render(Path(tmp) / "without.exr")
    save_panels([principled, live, without], out)
