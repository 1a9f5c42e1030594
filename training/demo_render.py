"""The Blender half of ``make demo``: what the method changes, shown on a life-sized head.

Three procedural skin albedo textures (light, medium, dark: mottling, redness, freckles, pores) on a
procedural head with ears (training/demo_subject.py, metres, Unit Scale 1), each rendered three ways with
Cycles under the same lights:

(a) **albedo only**: the texture through a Diffuse BSDF (no light travels under the surface);
(b) **Principled BSDF, Random Walk (Skin)**: Subsurface Weight 1, the texture as Base Color and Blender's
    default Subsurface Radius and Scale (what an artist gets today by turning subsurface on);
(c) **Spectral Skin SSS**: the add-on's Invert Skin Albedo at its default settings: the live node group
    (blender_addon.live) fed by the texture that fed the Principled BSDF's Base Color, at the scene's Unit
    Scale; nothing is baked.

The lights are set for translucency: a back light behind the head that reaches only the back of the ear
(the ear's visible side has no direct light: whatever it shows came through it), and a key light from the
front-right whose terminator crosses the cheek (subsurface light softens and reddens it).  A grid of the
nine renders (demo/out/translucency.png; the README opens with it), the single renders, the ear's pixel
mask and a contact sheet of the medium tone's maps (what the live group computes per texel, baked here with
the operator's Bake mode on a copy of the material, which is not rendered) are written.

Nothing is downloaded.  Run as ``python -m training.demo_render --out demo/out`` (``python -m training demo``
calls it).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from training.demo_subject import TONES, skin_albedo_texture

#: The three ways the textures are rendered: key, label of the figure's column.
METHODS: tuple[tuple[str, str], ...] = (
    ("albedo", "(a) albedo only\nDiffuse BSDF"),
    ("principled", "(b) Principled BSDF, Random Walk (Skin)\nBlender's default radius"),
    ("spectral", "(c) Spectral Skin SSS\nInvert Skin Albedo, defaults (live group)"),
)
#: Camera (metres, looking at TARGET) and point lights: (location, power W, radius m).  The back light stands
#: behind the head, which hides it from the camera: it lights the back of the ears and a rim of the head only.
CAMERA_M, TARGET_M, LENS_MM = (-0.56, -0.50, 0.05), (-0.035, -0.02, -0.01), 100.0
BACK_LIGHT = ((0.02, 0.50, 0.05), 40.0, 0.015)
KEY_LIGHT = ((0.28, -0.62, 0.12), 20.0, 0.03)
WORLD_GREY = 0.04
#: Default size of each render (pixels, square) and Cycles samples per pixel (then OpenImageDenoise): the
#: whole ``make demo`` stays within 3 minutes on 2 cores (docs/user/demo.md).
RENDER_SIZE, SAMPLES = 256, 16
#: Frames per row of the flush strip.
STRIP_ROW = 8


def write_image(path: Path, codes: np.ndarray) -> Path:
    """Write (H, W, C) uint8 ``codes``; the format follows the extension (.png, or .jpg at quality 90)."""
    import OpenImageIO as oiio

    h, w, c = codes.shape
    spec = oiio.ImageSpec(w, h, c, "uint8")
    if Path(path).suffix.lower() in (".jpg", ".jpeg"):
        spec.attribute("Compression", "jpeg:90")
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise OSError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(np.ascontiguousarray(codes))
    out.close()
    return path


def read_image(path: Path) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1] of an 8-bit image, top row first."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise OSError(f"cannot read {path}: {buf.geterror()}")
    return buf.get_pixels(oiio.FLOAT)[..., :3]


# ------------------------------------------------------------------------------------------------ scene
def _look_at(obj, location, target) -> None:
    from mathutils import Vector

    obj.location = location
    obj.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()


def _point_light(scene, name: str, spec) -> None:
    import bpy

    location, power, radius = spec
    light = bpy.data.lights.new(name, "POINT")
    light.energy, light.shadow_soft_size = power, radius
    obj = bpy.data.objects.new(name, light)
    obj.location = location
    scene.collection.objects.link(obj)


def _scene(size: int, samples: int):
    """Empty factory scene at Unit Scale 1 (metres): the head, camera, back and key lights, a near-black world;
    Cycles on the CPU with OpenImageDenoise.  Returns (scene, [head, left ear, right ear])."""
    import bpy

    from training import demo_subject

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True  # OpenImageDenoise: clean panels at few samples
    scene.cycles.denoiser = "OPENIMAGEDENOISE"
    scene.cycles.seed = 1
    scene.cycles.max_bounces = 6  # Blender: 12; a near-black world and two lights need fewer
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 1.0  # the head is modelled in metres: the bake's radii are in metres
    parts = demo_subject.build_head(scene.collection)
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (WORLD_GREY,) * 3 + (1.0,)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = LENS_MM
    _look_at(cam, CAMERA_M, TARGET_M)
    scene.collection.objects.link(cam)
    scene.camera = cam
    _point_light(scene, "Back light", BACK_LIGHT)
    _point_light(scene, "Key light", KEY_LIGHT)
    return scene, parts


def _material(name: str, image, shader: str):
    """A material reading ``image`` (sRGB) into ``shader``: "diffuse" (Diffuse BSDF), "principled_skin"
    (Principled BSDF, Subsurface Weight 1, Random Walk (Skin), default radius and scale) or "principled"
    (the Principled BSDF as it comes, before Invert Skin Albedo).  The image node is the active node."""
    import bpy

    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.location = (-500.0, 200.0)
    if shader == "diffuse":
        diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
        tree.nodes.remove(principled)
        tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
        tree.links.new(diffuse.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    else:
        tree.links.new(tex.outputs["Color"], principled.inputs["Base Color"])
        if shader == "principled_skin":
            principled.inputs["Subsurface Weight"].default_value = 1.0
            principled.subsurface_method = "RANDOM_WALK_SKIN"
    tree.nodes.active = tex
    return mat


def _assign(parts, material) -> None:
    for obj in parts:
        obj.data.materials.clear()
        obj.data.materials.append(material)


def _render(scene, path: Path) -> np.ndarray:
    import bpy

    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_depth = "8"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return read_image(path)


def _ear_mask(scene, parts, path: Path) -> np.ndarray:
    """(H, W) bool: pixels where the camera sees the left ear (an emission-only render: ear white, head black,
    no lights, no denoising)."""
    import bpy

    def emission(name: str, strength: float):
        mat = bpy.data.materials.new(name)
        tree = mat.node_tree
        tree.nodes.remove(tree.nodes["Principled BSDF"])
        node = tree.nodes.new("ShaderNodeEmission")
        node.inputs["Strength"].default_value = strength
        tree.links.new(node.outputs["Emission"], tree.nodes["Material Output"].inputs["Surface"])
        return mat

    head, left, right = parts
    _assign([head, right], emission("Mask black", 0.0))
    _assign([left], emission("Mask white", 1.0))
    saved = (scene.cycles.samples, scene.cycles.use_denoising, scene.world)
    scene.cycles.samples, scene.cycles.use_denoising, scene.world = 16, False, None
    try:
        mask = _render(scene, path)[..., 0] > 0.5
    finally:
        scene.cycles.samples, scene.cycles.use_denoising, scene.world = saved
    return mask


# ------------------------------------------------------------------------------------------------ figures
def contact_sheet(maps_dir: Path, stem: str, k_count: int, albedo: np.ndarray, path: Path) -> Path:
    """Grid figure: the albedo, and per component the colour, radius (log10, channel mean), weight and
    anisotropy maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from exporters import maps

    fig, axes = plt.subplots(k_count, 5, figsize=(13, 2.8 * k_count), squeeze=False)
    for k in range(1, k_count + 1):
        color = maps.read_exr(maps_dir / f"{stem}_k{k}_color.exr")[0]
        radius = maps.read_exr(maps_dir / f"{stem}_k{k}_radius.exr")[0].mean(axis=2)
        weight = maps.read_exr(maps_dir / f"{stem}_k{k}_weight.exr")[0]
        aniso = maps.read_exr(maps_dir / f"{stem}_k{k}_anisotropy.exr")[0][..., 0]
        row = axes[k - 1]
        if k == 1:
            row[0].imshow(albedo)
            row[0].set_title("albedo (input, sRGB)")
        else:
            row[0].axis("off")
        row[1].imshow(np.clip(color / max(float(color.max()), 1e-6), 0, 1))
        row[1].set_title(f"k{k} Subsurface Color (/ {color.max():.3f})")
        im = row[2].imshow(np.log10(radius), cmap="magma")
        fig.colorbar(im, ax=row[2], fraction=0.046)
        row[2].set_title(f"k{k} log10 radius [BU]")
        row[3].imshow(np.clip(weight, 0, 1))
        row[3].set_title(f"k{k} weight (RGB)")
        im = row[4].imshow(aniso, cmap="viridis", vmin=0.0, vmax=0.7)
        fig.colorbar(im, ax=row[4], fraction=0.046)
        row[4].set_title(f"k{k} anisotropy g")
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def comparison_figure(panels: dict[tuple[str, str], np.ndarray], tones: list[str], paths: list[Path],
                      footer: str = "", columns: tuple[tuple[str, str], ...] = METHODS) -> list[Path]:
    """One row per tone, one column per (key, label) of ``columns`` (default METHODS), panels (H, W, 3) in [0, 1]
    shown pixel for pixel under a header; ``footer``: a line of small print below.  Written to each of ``paths``
    (.png or .jpg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h, w = next(iter(panels.values())).shape[:2]
    gap, left, top, bottom = 4, 70, 44, 22 if footer else 4
    grid = np.ones((len(tones) * (h + gap) - gap, len(columns) * (w + gap) - gap, 3), np.float32)
    for i, tone in enumerate(tones):
        for j, (method, _) in enumerate(columns):
            grid[i * (h + gap):i * (h + gap) + h, j * (w + gap):j * (w + gap) + w] = panels[tone, method]
    width, height = grid.shape[1] + left, grid.shape[0] + top + bottom
    dpi = 100
    fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    ax = fig.add_axes((left / width, bottom / height, grid.shape[1] / width, grid.shape[0] / height))
    ax.imshow(np.clip(grid, 0.0, 1.0), interpolation="nearest")
    ax.axis("off")
    for j, (_, label) in enumerate(columns):
        fig.text((left + j * (w + gap) + w / 2) / width, 1 - 4 / height, label, ha="center", va="top", fontsize=8.5)
    for i, tone in enumerate(tones):
        fig.text(6 / width, 1 - (top + i * (h + gap) + h / 2) / height, f"{tone}\nskin", ha="left", va="center",
                 fontsize=9)
    if footer:
        fig.text(6 / width, 4 / height, footer, ha="left", va="bottom", fontsize=7, color="0.3")
    fig.set_facecolor("white")
    fig.canvas.draw()
    codes = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return [write_image(path, codes) for path in paths]


# ------------------------------------------------------------------------------------------------ run
def _fresh_dir(path: Path) -> Path:
    """The demo's own output folder, emptied (it is replaced on every run)."""
    if path.exists():
        for f in path.iterdir():
            f.unlink()
    else:
        path.mkdir(parents=True)
    return path


def _invert(obj, material) -> None:
    """Invert Skin Albedo on ``material`` at the operator's default settings: the live group."""
    import bpy

    obj.active_material = material
    with bpy.context.temp_override(object=obj, active_object=obj):
        result = bpy.ops.spectral_skin.invert_albedo()
    if result != {"FINISHED"}:
        raise RuntimeError(f"Invert Skin Albedo returned {result}")


def _bake(obj, material, maps_dir: Path) -> dict:
    """Invert Skin Albedo's Bake mode on ``material``'s image (maps saved as files in ``maps_dir``); returns the
    bake's record (S_maps.json)."""
    import bpy

    obj.active_material = material
    with bpy.context.temp_override(object=obj, active_object=obj):
        result = bpy.ops.spectral_skin.invert_albedo(mode="BAKE", storage="FILES", output_dir=str(maps_dir))
    if result != {"FINISHED"}:
        raise RuntimeError(f"Invert Skin Albedo returned {result}")
    return json.loads(next(maps_dir.glob("*_maps.json")).read_text())


def run(out: Path, texture_size: int = 512, render_size: int = RENDER_SIZE, samples: int = SAMPLES,
        tones: tuple[str, ...] = tuple(TONES), figure: Path | None = None) -> dict:
    """Generate the textures, build the scene, invert (the add-on's operator: the live group) and render every
    tone with every method; write the figure (``out``/translucency.png, and ``figure`` when given) and bake the
    contact sheet's tone.  Returns what was written, the timings (s), the bake record of the sheet's tone and, per
    tone and method, the mean of the render (display sRGB in [0, 1]) over the left ear's pixels."""
    import bpy

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import blender_addon

    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    scene, parts = _scene(render_size, samples)
    timings["scene"] = time.perf_counter() - t0
    ear = _ear_mask(scene, parts, out / "ear_mask.png")
    materials, records, textures = {}, {}, {}
    sheet_tone = "medium" if "medium" in tones else tones[0]
    blender_addon.register()
    try:
        for tone in tones:
            t0 = time.perf_counter()
            textures[tone] = skin_albedo_texture(texture_size, seed=0, base=TONES[tone])
            image = bpy.data.images.load(str(write_image(out / f"skin_{tone}.png", textures[tone])))
            for method, shader in zip((m for m, _ in METHODS), ("diffuse", "principled_skin", "principled"),
                                      strict=True):
                materials[tone, method] = _material(f"{tone} {method}", image, shader)
            timings[f"texture_{tone}"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            _invert(parts[0], materials[tone, "spectral"])
            timings[f"invert_{tone}"] = time.perf_counter() - t0
            if tone == sheet_tone:
                t0 = time.perf_counter()
                baked = _material(f"{tone} baked", image, "principled")
                records[tone] = _bake(parts[0], baked, _fresh_dir(out / "maps" / tone))
                timings[f"bake_{tone}"] = time.perf_counter() - t0
    finally:
        blender_addon.unregister()
    panels, ear_means = {}, {}
    for tone in tones:
        for method, _ in METHODS:
            _assign(parts, materials[tone, method])
            t0 = time.perf_counter()
            panels[tone, method] = _render(scene, out / f"render_{tone}_{method}.png")
            timings[f"render_{tone}_{method}"] = time.perf_counter() - t0
            ear_means[f"{tone}/{method}"] = panels[tone, method][ear].mean(axis=0).tolist()
    footer = (f"Cycles {bpy.app.version_string}, {render_size} px, {samples} spp + OpenImageDenoise; head modelled "
              f"in metres (Unit Scale 1), back light behind the ear, key light from the front right.")
    comparison_figure(panels, list(tones), [out / "translucency.png", *([figure] if figure else [])], footer)
    rec = records[sheet_tone]
    contact_sheet(out / "maps" / sheet_tone, f"skin_{sheet_tone}", rec["K"], textures[sheet_tone],
                  out / "maps_contact_sheet.png")
    return {"files": ["translucency.png", "render_*.png", "skin_*.png", "ear_mask.png", "maps/",
                      "maps_contact_sheet.png"],
            "timings_s": timings, "records": records, "ear_mean_srgb": ear_means,
            "ear_pixels": int(ear.sum())}


#: The skin edits of the demo's row (exporters.skin_edits.PRESETS): key, label.
EDIT_ROW: tuple[tuple[str, str], ...] = (("as painted", "as painted"), ("tan", "tan\nmelanin x2"),
                                         ("flush", "flush\nblood x2.5"), ("pallor", "pallor\nblood x0.4"))


def _live_head(out: Path, texture_size: int, render_size: int, samples: int, tone: str, label: str,
               mask_name: str):
    """The demo's head scene with the ``tone`` skin texture through Invert Skin Albedo (the live group) on every
    part; returns (scene, the left ear's pixel mask, the material)."""
    import bpy

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import blender_addon

    out.mkdir(parents=True, exist_ok=True)
    scene, parts = _scene(render_size, samples)
    ear = _ear_mask(scene, parts, out / mask_name)
    texture = skin_albedo_texture(texture_size, seed=0, base=TONES[tone])
    image = bpy.data.images.load(str(write_image(out / f"skin_{tone}.png", texture)))
    material = _material(f"{tone} {label}", image, "principled")
    blender_addon.register()
    try:
        _invert(parts[0], material)
    finally:
        blender_addon.unregister()
    _assign(parts, material)
    return scene, ear, material


def edits_row(out: Path, texture_size: int = 512, render_size: int = RENDER_SIZE, samples: int = SAMPLES,
              tone: str = "medium", figure: Path | None = None) -> dict:
    """The ``tone`` head through the live group as painted and under the tan, flush and pallor presets (the group
    node's Melanin, Blood and Oxygenation inputs), under the demo's lights (back light behind the ear); writes the
    row (``out``/skin_edits_row.png, and ``figure`` when given) and returns the left ear's mean colour per edit."""
    import bpy

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from blender_addon import live_edits
    from exporters import skin_edits

    scene, ear, material = _live_head(out, texture_size, render_size, samples, tone, "edited", "ear_mask.png")
    node = live_edits.live_node(material)
    panels, ear_means = {}, {}
    for key, _ in EDIT_ROW:
        edit = skin_edits.PRESETS.get(key, skin_edits.SkinEdit())
        for (name, *_), value in zip(live_edits.INPUTS, edit.row(), strict=True):
            node.inputs[name].default_value = float(value)
        panels[tone, key] = _render(scene, out / f"render_{tone}_{key.replace(' ', '_')}.png")
        ear_means[key] = panels[tone, key][ear].mean(axis=0).tolist()
    footer = (f"Cycles {bpy.app.version_string}, {render_size} px, {samples} spp + OpenImageDenoise; live group, "
              "Melanin / Blood / Oxygenation inputs; back light behind the ear.")
    comparison_figure(panels, [tone], [out / "skin_edits_row.png", *([figure] if figure else [])], footer, EDIT_ROW)
    return {"ear_mean_srgb": ear_means, "ear_pixels": int(ear.sum())}


def flush_strip(out: Path, texture_size: int = 256, render_size: int = 80, samples: int = 8, tone: str = "medium",
                frames: int = 24, peak: float = 2.5, figure: Path | None = None) -> dict:
    """A flush as an animation: the live group's Blood input keyframed 1 -> ``peak`` -> 1 over ``frames`` frames
    (Bezier keys at the first, middle and last frame), every frame rendered, side by side in a strip of rows of
    STRIP_ROW frames, left to right, top to bottom (``out``/flush_strip.png, and ``figure`` when given).  Returns
    the Blood value and the left ear's mean colour per frame."""

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from blender_addon import live_edits

    scene, ear, material = _live_head(out, texture_size, render_size, samples, tone, "flush", "ear_mask_strip.png")
    blood = live_edits.live_node(material).inputs["Blood"]
    for frame, value in ((1, 1.0), ((frames + 1) // 2, peak), (frames, 1.0)):
        blood.default_value = value
        blood.keyframe_insert("default_value", frame=frame)
    tiles, values, ear_means = [], [], []
    for frame in range(1, frames + 1):
        scene.frame_set(frame)
        values.append(float(blood.default_value))
        tile = _render(scene, out / f"flush_{frame:02d}.png")
        ear_means.append(tile[ear].mean(axis=0).tolist())
        tiles.append(tile)
    rows = [np.concatenate(tiles[i:i + STRIP_ROW], axis=1) for i in range(0, len(tiles), STRIP_ROW)]
    rows[-1] = np.pad(rows[-1], ((0, 0), (0, rows[0].shape[1] - rows[-1].shape[1]), (0, 0)))
    strip = np.concatenate(rows, axis=0)
    codes = np.clip(np.rint(strip * 255.0), 0, 255).astype(np.uint8)
    for path in (out / "flush_strip.png", *([figure] if figure else [])):
        write_image(path, codes)
    return {"blood": values, "ear_mean_srgb": ear_means}


#: The mask row's panels: (key, header).
MASK_ROW: tuple[tuple[str, str], ...] = (("as painted", "as painted"),
                                         ("cheek", "flush painted by\na mask (Edit Mask)"),
                                         ("flush", "flush everywhere\n(no mask)"))
#: A pixel's change (sum over its display RGB, 0-3) that the mask row counts as changed by an edit.
CHANGED = 0.03
#: The mask row's cheek patch, in the head's object space (metres): a spherical gradient's centre and radius.
CHEEK_M: tuple[tuple[float, float, float], float] = ((-0.056, -0.064, -0.028), 0.045)


def mask_row(out: Path, texture_size: int = 256, render_size: int = 160, samples: int = 16, tone: str = "light",
             figure: Path | None = None) -> dict:
    """The ``tone`` head as painted, with the flush preset painted by a soft patch on the cheek through the live
    group's Edit Mask (the patch a spherical gradient in object space, :data:`CHEEK_M`), and with the flush
    everywhere; writes the row (``out``/skin_edits_mask_row.png, and ``figure`` when given) and returns the cache
    each edit rendered from and the share of the image's pixels each edit changes (more than :data:`CHANGED`)."""
    import bpy

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from blender_addon import live_edits
    from exporters import skin_edits

    scene, _, material = _live_head(out, texture_size, render_size, samples, tone, "masked", "ear_mask_row.png")
    node = live_edits.live_node(material)
    tree = material.node_tree
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")  # the patch's centre to the origin, its radius to 1
    centre, radius = CHEEK_M
    mapping.inputs["Location"].default_value = tuple(-c / radius for c in centre)
    mapping.inputs["Scale"].default_value = (1.0 / radius,) * 3
    patch = tree.nodes.new("ShaderNodeTexGradient")
    patch.gradient_type = "SPHERICAL"
    tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], patch.inputs["Vector"])
    flush = tuple(skin_edits.PRESETS["flush"].row())
    panels, caches = {}, {}
    panels[tone, "as painted"] = _render(scene, out / f"render_{tone}_painted.png")
    tree.links.new(patch.outputs["Fac"], node.inputs[live_edits.MASK_INPUT])
    live_edits.set_edit(node, flush)
    caches["cheek"] = live_edits.cache_status(node)
    panels[tone, "cheek"] = _render(scene, out / f"render_{tone}_cheek.png")
    tree.links.remove(node.inputs[live_edits.MASK_INPUT].links[0])
    live_edits.set_edit(node, flush)
    caches["flush"] = live_edits.cache_status(node)
    panels[tone, "flush"] = _render(scene, out / f"render_{tone}_flush.png")
    footer = (f"Cycles {bpy.app.version_string}, {render_size} px, {samples} spp + OpenImageDenoise; live group, flush "
              "preset (blood x2.5, oxygenation +0.05).")
    comparison_figure(panels, [tone], [out / "skin_edits_mask_row.png", *([figure] if figure else [])], footer,
                      MASK_ROW)
    painted = panels[tone, "as painted"]
    changed = {key: float(np.mean(np.abs(panels[tone, key] - painted).sum(axis=-1) > CHANGED)) for key in caches}
    return {"caches": caches, "changed_share": changed}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m training.demo_render", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("demo/out"))
    parser.add_argument("--texture-size", type=int, default=512)
    parser.add_argument("--render-size", type=int, default=RENDER_SIZE)
    parser.add_argument("--samples", type=int, default=SAMPLES)
    parser.add_argument("--figure", type=Path, default=None, help="also write the figure here (.png or .jpg)")
    parser.add_argument("--edits-row", action="store_true",
                        help="only the skin-edits row: the medium head as painted, tanned, flushed and pale")
    parser.add_argument("--flush-strip", action="store_true",
                        help="only the animated flush: Blood keyframed 1 -> 2.5 -> 1 over 24 frames, as a strip")
    parser.add_argument("--mask-row", action="store_true",
                        help="only the masked edit: the flush painted on the cheek through the Edit Mask")
    args = parser.parse_args(argv)
    if args.mask_row:
        info = mask_row(args.out, figure=args.figure)
        print(json.dumps(info))
        return 0
    if args.flush_strip:
        info = flush_strip(args.out, figure=args.figure)
        print(json.dumps(info))
        return 0
    if args.edits_row:
        info = edits_row(args.out, args.texture_size, args.render_size, args.samples, figure=args.figure)
        print(json.dumps(info, indent=1))
        return 0
    info = run(args.out, args.texture_size, args.render_size, args.samples, figure=args.figure)
    print(json.dumps({k: v for k, v in info.items() if k != "records"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
