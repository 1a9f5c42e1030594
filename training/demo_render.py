"""The Blender half of ``make demo``: a procedural skin albedo texture, baked by the add-on's Invert Skin
Albedo, applied to Suzanne and rendered with Cycles; a contact sheet of the maps.

Nothing is downloaded: the texture is generated here (light-to-dark variation, freckles, redness, pores).
Run as ``python -m training.demo_render --out demo/out`` (``python -m training demo`` calls it).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from exporters.colorimetry import srgb_decode, srgb_encode

#: sRGB (0-255) anchors of the procedural texture.
LIGHT = (236, 196, 176)
DARK = (120, 80, 62)
RED = (214, 120, 112)
FRECKLE = (156, 98, 70)


def _value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Smooth noise in [0, 1], shape (size, size): a random (cells+1)^2 grid, bicubic-smoothstep interpolated."""
    grid = rng.uniform(0.0, 1.0, (cells + 1, cells + 1))
    t = np.linspace(0.0, cells, size, endpoint=False)
    i = t.astype(int)
    f = t - i
    f = f * f * (3.0 - 2.0 * f)
    rows = grid[i][:, None, :] * (1 - f)[:, None, None] + grid[i + 1][:, None, :] * f[:, None, None]  # (s, 1, c+1)
    rows = rows[:, 0, :]
    return rows[:, i] * (1 - f)[None, :] + rows[:, i + 1] * f[None, :]


def skin_albedo_texture(size: int = 512, seed: int = 0) -> np.ndarray:
    """(size, size, 3) uint8 sRGB skin albedo: a light-to-dark gradient from top to bottom (Suzanne's UV
    halves are mirrored side by side, so a vertical gradient looks the same on both) with mottling, red
    patches (cheek-like blotches), freckles (small dark spots, denser in the upper half) and pore noise."""
    rng = np.random.default_rng(seed)
    light, dark, red, freckle = (srgb_decode(np.array(c) / 255.0) for c in (LIGHT, DARK, RED, FRECKLE))
    y = np.linspace(0.0, 1.0, size)[:, None, None]
    mottle = (0.6 * _value_noise(rng, size, 5) + 0.4 * _value_noise(rng, size, 17) - 0.5)[..., None] * 0.3
    tone = np.clip(y + mottle, 0.0, 1.0)
    lin = light * (1.0 - tone) + dark * tone
    blotch = 0.7 * _value_noise(rng, size, 4) + 0.3 * _value_noise(rng, size, 13)
    redness = 0.45 * np.clip((blotch - 0.5) * 3.0, 0.0, 1.0)[..., None] ** 1.5
    lin = lin * (1.0 - redness) + red * (lin / light) * redness
    yy, xx = np.mgrid[0:size, 0:size]
    n_freckles = size * size // 900
    cy = rng.beta(1.6, 2.6, n_freckles) * size
    cx = rng.uniform(0, size, n_freckles)
    radius = rng.uniform(0.8, 2.6, n_freckles) * size / 512
    spots = np.zeros((size, size))
    for y0, x0, r in zip(cy, cx, radius, strict=True):
        y1, y2, x1, x2 = (int(max(0, y0 - 4 * r)), int(min(size, y0 + 4 * r + 1)), int(max(0, x0 - 4 * r)),
                          int(min(size, x0 + 4 * r + 1)))
        d2 = (yy[y1:y2, x1:x2] - y0) ** 2 + (xx[y1:y2, x1:x2] - x0) ** 2
        spots[y1:y2, x1:x2] = np.maximum(spots[y1:y2, x1:x2], np.exp(-d2 / (2 * r * r)))
    spots = (0.75 * spots)[..., None]
    lin = lin * (1.0 - spots) + freckle * (lin / light) * spots
    lin = lin * (1.0 + 0.03 * rng.standard_normal((size, size, 1)))
    return np.round(np.clip(srgb_encode(np.clip(lin, 0.0, 1.0)), 0.0, 1.0) * 255).astype(np.uint8)


def write_png(path: Path, codes: np.ndarray) -> Path:
    import OpenImageIO as oiio

    h, w, c = codes.shape
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), oiio.ImageSpec(w, h, c, "uint8")):
        raise OSError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(np.ascontiguousarray(codes))
    out.close()
    return path


def _scene(albedo: Path, size: int, samples: int):
    """Suzanne (subdivided, smooth) with a Principled material reading ``albedo``; camera, lights."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True  # OpenImageDenoise: a clean preview at few samples
    scene.cycles.seed = 1
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.1  # Suzanne is ~2.7 units wide: a 27 cm head
    bpy.ops.mesh.primitive_monkey_add(size=2.0, calc_uvs=True)
    obj = bpy.context.active_object
    mod = obj.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = mod.render_levels = 2
    for poly in obj.data.polygons:
        poly.use_smooth = True
    mat = bpy.data.materials.new("Skin")
    obj.data.materials.append(mat)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(albedo))
    tex.location = (-500.0, 200.0)
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    tree.nodes.active = tex
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.6, 0.65, 0.75, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.35
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -7.0, 0.3)
    cam.rotation_euler = (np.radians(88.0), 0.0, 0.0)
    cam.data.lens = 85.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    key = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "AREA"))
    key.data.energy, key.data.size = 600.0, 2.0
    key.location = (-4.0, -4.0, 3.0)
    key.rotation_euler = (np.radians(55.0), 0.0, np.radians(-45.0))
    scene.collection.objects.link(key)
    rim = bpy.data.objects.new("Rim", bpy.data.lights.new("Rim", "AREA"))
    rim.data.energy, rim.data.size = 500.0, 1.0
    rim.location = (3.5, 3.0, 1.5)
    rim.rotation_euler = (np.radians(-70.0), 0.0, np.radians(45.0))
    scene.collection.objects.link(rim)
    return scene, obj


def _render(scene, path: Path) -> np.ndarray:
    import bpy

    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(str(path))
    px = np.empty(img.size[0] * img.size[1] * img.channels, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(img.size[1], img.size[0], img.channels)[::-1, :, :3]
    bpy.data.images.remove(img)
    return px


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


def run(out: Path, texture_size: int = 512, render_size: int = 256, samples: int = 64) -> dict:
    """Generate, bake (through the add-on's operator), render; returns what was written and timings."""
    import bpy

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import blender_addon

    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    t0 = time.perf_counter()
    codes = skin_albedo_texture(texture_size)
    albedo = write_png(out / "skin_albedo.png", codes)
    timings["texture"] = time.perf_counter() - t0
    maps_dir = out / "maps"
    if maps_dir.exists():  # the demo's own output folder: replaced on every run
        for f in maps_dir.iterdir():
            f.unlink()
    else:
        maps_dir.mkdir()
    scene, obj = _scene(albedo, render_size, samples)
    blender_addon.register()
    try:
        t0 = time.perf_counter()
        _render(scene, out / "preview_albedo_only.png")
        timings["render_albedo_only"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        with bpy.context.temp_override(object=obj, active_object=obj):
            result = bpy.ops.spectral_skin.invert_albedo(storage="FILES", output_dir=str(maps_dir),
                                                         match_exposure=True, backend="AUTO")
        timings["bake"] = time.perf_counter() - t0
        if result != {"FINISHED"}:
            raise RuntimeError(f"Invert Skin Albedo returned {result}")
        t0 = time.perf_counter()
        sss = _render(scene, out / "preview.png")
        timings["render"] = time.perf_counter() - t0
    finally:
        blender_addon.unregister()
    flat = _render_compare(out)
    record = json.loads((maps_dir / "skin_albedo_maps.json").read_text())
    contact_sheet(maps_dir, "skin_albedo", record["K"], codes, out / "maps_contact_sheet.png")
    return {"files": ["skin_albedo.png", "maps/", "preview.png", "preview_albedo_only.png", "preview_compare.png",
                      "maps_contact_sheet.png"], "timings_s": timings, "record": record,
            "mean_rgb": {"albedo_only": flat, "spectral_sss": sss.reshape(-1, 3).mean(axis=0).tolist()}}


def _render_compare(out: Path) -> list[float]:
    """Side-by-side PNG: albedo-only render | spectral SSS render."""
    import OpenImageIO as oiio

    a = oiio.ImageBuf(str(out / "preview_albedo_only.png"))
    b = oiio.ImageBuf(str(out / "preview.png"))
    pa, pb = a.get_pixels(oiio.FLOAT), b.get_pixels(oiio.FLOAT)
    both = np.concatenate([pa, np.ones((pa.shape[0], 4, pa.shape[2]), np.float32), pb], axis=1)
    codes = np.round(np.clip(both, 0, 1) * 255).astype(np.uint8)
    write_png(out / "preview_compare.png", codes)
    return pa[..., :3].reshape(-1, 3).mean(axis=0).tolist()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m training.demo_render", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("demo/out"))
    parser.add_argument("--texture-size", type=int, default=512)
    parser.add_argument("--render-size", type=int, default=256)
    parser.add_argument("--samples", type=int, default=64)
    args = parser.parse_args(argv)
    info = run(args.out, args.texture_size, args.render_size, args.samples)
    print(json.dumps({k: v for k, v in info.items() if k != "record"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
