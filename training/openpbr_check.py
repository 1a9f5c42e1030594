"""The OpenPBR maps (``--target openpbr``) checked in a renderer: Blender's Principled BSDF, which follows OpenPBR
Surface, reads them in Cycles and is compared with the live group (the K-media mixture) on the same scenes.

* :func:`principled_material` — the OpenPBR maps through a Principled BSDF: Base Color = subsurface_color,
  Subsurface Weight, Radius = subsurface_radius_scale, Scale = subsurface_radius x 4 pi (Cycles walks
  sigma_t = 4 pi / (Radius x Scale); OpenPBR's radius is the mean free path 1 / sigma_t: exporters.openpbr),
  Subsurface Anisotropy, Random Walk, Coat Tint = coat_color under Coat Weight 1 with the written material's IOR and
  roughness as Coat IOR and Coat Roughness (its clear coat); Roughness and IOR of the written material.
* :func:`shadow_edge` — a flat skin box (1 unit = 1 cm) lit straight from above by a sun whose light a hidden
  plate stops over half of it: the light that bleeds under the plate, integrated across the shadow and divided by
  the lit level, is the *bleed width* (mm, per channel).
* :func:`ear` — the demo head (training.demo_subject, metres) with the demo's back light behind the ear: the mean
  linear colour over the ear's pixels.

``python -m training.openpbr_check --out DIR`` measures both for the live group and the Principled BSDF and writes
the figure of docs/user/other_renderers.md and the numbers as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "blender_addon" / "models" / "skin_inversion.onnx"
#: The box of :func:`shadow_edge`: unit scale (m per unit: 1 unit = 1 cm), view width (units), height of the hidden
#: plate above the box (units), the lit side's texels averaged for the lit level (from this far from the edge, units).
BOX_UNIT_M, BOX_VIEW, PLATE_HEIGHT, LIT_FROM = 0.01, 1.0, 0.01, 0.3
#: Render size of the box (pixels across the edge x along it) and of the head (square).
BOX_PIXELS, HEAD_PIXELS = (128, 32), 96
#: The skin colours checked (sRGB codes of the demo's light, medium and dark textures: training.demo_subject.TONES).
SHADOW_TONES = ("light", "medium", "dark")


def _bpy():
    import bpy

    return bpy


def image_node(tree, path: Path, coords=None):
    """An Image Texture node reading ``path`` (Non-Color, closest texel), fed by ``coords`` when given."""
    bpy = _bpy()
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = bpy.data.images.load(str(path), check_existing=True)
    node.image.colorspace_settings.name = "Non-Color"
    node.interpolation, node.extension = "Closest", "EXTEND"
    if coords is not None:
        tree.links.new(coords, node.inputs["Vector"])
    return node


def principled_material(name: str, maps_dir: Path, stem: str, roughness: float, ior: float, coords=None):
    """A material whose Principled BSDF reads the OpenPBR maps ``<stem>_openpbr_*.exr`` of ``maps_dir`` (module
    docstring); ``coords``: a function (tree) -> the texture coordinate socket (None: the UV map)."""
    from blender_addon.nodes import random_walk_method
    from exporters import openpbr

    bpy = _bpy()
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    vec = coords(tree) if coords is not None else None

    def read(kind: str):
        return image_node(tree, maps_dir / f"{stem}_openpbr_{kind}.exr", vec).outputs["Color"]

    bsdf.subsurface_method = random_walk_method()  # the radius divided by 4 pi: CYCLES_RADIUS_SCALE's convention
    tree.links.new(read("subsurface_color"), bsdf.inputs["Base Color"])
    tree.links.new(read("subsurface_weight"), bsdf.inputs["Subsurface Weight"])
    tree.links.new(read("subsurface_radius_scale"), bsdf.inputs["Subsurface Radius"])
    scale = tree.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = openpbr.CYCLES_RADIUS_SCALE
    tree.links.new(read("subsurface_radius"), scale.inputs[0])
    tree.links.new(scale.outputs[0], bsdf.inputs["Subsurface Scale"])
    tree.links.new(read("subsurface_anisotropy"), bsdf.inputs["Subsurface Anisotropy"])
    tree.links.new(read("coat_color"), bsdf.inputs["Coat Tint"])
    bsdf.inputs["Coat Weight"].default_value = 1.0
    bsdf.inputs["Coat IOR"].default_value = ior
    bsdf.inputs["Coat Roughness"].default_value = roughness
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["IOR"].default_value = ior
    return mat


def live_material(name: str, albedo_png: Path, roughness: float, ior: float, coords=None):
    """The artist's material (Image Texture -> Principled BSDF at ``roughness`` and ``ior``) before Invert Skin
    Albedo; the image node is active."""
    bpy = _bpy()
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(albedo_png), check_existing=True)
    tex.interpolation, tex.extension = "Closest", "EXTEND"
    if coords is not None:
        tree.links.new(coords(tree), tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["IOR"].default_value = ior
    tree.nodes.active = tex
    return mat


def invert_live(obj, material) -> None:
    """Invert Skin Albedo (the live group, the operator's defaults) on ``material`` of ``obj``."""
    bpy = _bpy()
    obj.active_material = material
    with bpy.context.temp_override(object=obj, active_object=obj):
        result = bpy.ops.spectral_skin.invert_albedo()
    if result != {"FINISHED"}:
        raise RuntimeError(f"Invert Skin Albedo returned {result}")


def bake_openpbr(albedo_png: Path, out: Path, unit_scale_m: float) -> Path:
    """``--target openpbr`` maps of ``albedo_png`` in ``out`` (created); returns ``out``."""
    from exporters import bake

    out.mkdir(parents=True, exist_ok=True)
    bake.bake(albedo_png, out, MODEL, bake.BakeOptions(targets=("openpbr",), unit_scale_m=unit_scale_m, force=True,
                                                          overwrite=True))
    return out


def _render_linear(scene, path: Path) -> np.ndarray:
    """Render to a float EXR; (H, W, 3) linear RGB, top row first."""
    bpy = _bpy()
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    try:
        w, h = image.size
        px = np.empty(w * h * 4, np.float32)
        image.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(image)
    rgb = px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    if not np.all(np.isfinite(rgb)):
        raise RuntimeError("Cycles produced non-finite pixels")
    return rgb


def _box_coords(tree):
    """Object coordinates of the box's top face, the view's [-BOX_VIEW/2, BOX_VIEW/2] mapped onto [0, 1]."""
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Location"].default_value = (0.5, 0.5, 0.0)
    mapping.inputs["Scale"].default_value = (1.0 / BOX_VIEW, 1.0 / BOX_VIEW, 1.0)
    tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    return mapping.outputs["Vector"]


def shadow_scene(samples: int, seed: int = 3):
    """The probe box (blender_addon.probe, 1 unit = 1 cm) in a black world, a sun straight above (angle 0) and a
    plate PLATE_HEIGHT above the box over x < 0 that the camera does not see: a sharp shadow edge along y."""
    from blender_addon import probe

    bpy = _bpy()
    scene = probe.new_scene(samples=samples, resolution=BOX_PIXELS[0], seed=seed)
    scene.render.resolution_y = BOX_PIXELS[1]
    scene.camera.data.ortho_scale = BOX_VIEW
    scene.cycles.filter_width = 0.01  # no pixel filter: it would spread the lit side over the edge by ~1 px
    scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", BOX_UNIT_M
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.0
    sun_obj = bpy.data.objects.new("Sun", sun)
    scene.collection.objects.link(sun_obj)
    plate = bpy.data.objects.new("Plate", probe.cube_mesh("Plate", 1.0))
    plate.scale = (20.0, 20.0, 0.001)
    plate.location = (-20.0, 0.0, PLATE_HEIGHT)
    plate.visible_camera = plate.visible_glossy = plate.visible_diffuse = plate.visible_transmission = False
    scene.collection.objects.link(plate)
    return scene


def bleed_width_mm(row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(bleed width per channel in mm, lit level per channel) of a render's mean row (W, 3) across the edge at the
    image's centre: the light on the shadowed half (x < 0) integrated over x, divided by the lit level (the mean
    from LIT_FROM units on the lit side)."""
    w = len(row)
    dx_mm = BOX_VIEW / w * BOX_UNIT_M * 1000.0
    x = (np.arange(w) + 0.5 - w / 2) * BOX_VIEW / w
    lit = row[x >= LIT_FROM].mean(axis=0)
    return row[x < 0].sum(axis=0) * dx_mm / lit, lit


def uniform_png(path: Path, codes) -> Path:
    """A 4 x 4 8-bit sRGB image of one colour."""
    from training.demo_render import write_image

    return write_image(path, np.broadcast_to(np.asarray(codes, np.uint8), (4, 4, 3)).copy())


def shadow_edge(tmp: Path, tone: str, samples: int = 64) -> dict:
    """Bleed width (mm) and lit level per channel of the live group and of the Principled BSDF with the OpenPBR maps,
    for the demo's ``tone`` painted uniformly on the box; the two renders' rows (W, 3)."""
    import blender_addon
    from exporters.bake import material_files
    from training.demo_subject import TONES

    png = uniform_png(tmp / f"{tone}.png", TONES[tone])
    maps_dir = bake_openpbr(png, tmp / f"maps_{tone}", BOX_UNIT_M)
    roughness, ior = material_files.SPECULAR_ROUGHNESS, 1.4
    out: dict = {}
    for method in ("live", "openpbr"):
        scene = shadow_scene(samples)
        slab = _bpy().data.objects["ProbeSlab"]
        slab.data.materials.clear()
        if method == "live":
            mat = live_material("Live", png, roughness, ior, _box_coords)
            slab.data.materials.append(mat)
            blender_addon.register()
            try:
                invert_live(slab, mat)
            finally:
                blender_addon.unregister()
        else:
            slab.data.materials.append(principled_material("OpenPBR", maps_dir, tone, roughness, ior, _box_coords))
        rgb = _render_linear(scene, tmp / f"edge_{tone}_{method}.exr")
        row = rgb.mean(axis=0)
        width, lit = bleed_width_mm(row)
        out[method] = {"bleed_width_mm": width.tolist(), "lit": lit.tolist(), "row": row}
    return out


def ear(tmp: Path, tone: str, samples: int = 32, texture_size: int = 64) -> dict:
    """Mean linear colour over the left ear's pixels on the demo head (the demo's back light behind it), for the live
    group and for the Principled BSDF with the OpenPBR maps of the demo's ``tone`` texture; and the renders."""
    import blender_addon
    from exporters.bake import material_files
    from training import demo_render
    from training.demo_subject import TONES, skin_albedo_texture

    png = demo_render.write_image(tmp / f"head_{tone}.png", skin_albedo_texture(texture_size, 0, TONES[tone]))
    maps_dir = bake_openpbr(png, tmp / f"head_maps_{tone}", 1.0)
    roughness, ior = material_files.SPECULAR_ROUGHNESS, 1.4
    scene, parts = demo_render._scene(HEAD_PIXELS, samples)
    scene.cycles.use_denoising = False
    mask = demo_render._ear_mask(scene, parts, tmp / "ear_mask.png")
    live = live_material("Live head", png, roughness, ior)
    blender_addon.register()
    try:
        invert_live(parts[0], live)
    finally:
        blender_addon.unregister()
    pbr = principled_material("OpenPBR head", maps_dir, f"head_{tone}", roughness, ior)
    out: dict = {"ear_pixels": int(mask.sum())}
    for method, mat in (("live", live), ("openpbr", pbr)):
        demo_render._assign(parts, mat)
        rgb = _render_linear(scene, tmp / f"head_{tone}_{method}.exr")
        out[method] = {"ear_mean": rgb[mask].mean(axis=0).tolist(), "render": rgb}
    return out


def _display(rgb: np.ndarray) -> np.ndarray:
    from exporters.colorimetry import srgb_encode

    return np.clip(srgb_encode(np.clip(rgb, 0.0, 1.0)), 0.0, 1.0)


def figure(head: dict, edges: dict[str, dict], path: Path) -> Path:
    """The picture of docs/user/other_renderers.md: the head (live group | Principled with the OpenPBR maps) and the
    shadow-edge profiles per tone."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2 + len(edges), figsize=(3.2 * (2 + len(edges)), 3.4))
    for ax, method, title in ((axes[0], "live", "live group (K media)"),
                              (axes[1], "openpbr", "Principled BSDF, OpenPBR maps")):
        ax.imshow(_display(head[method]["render"]), interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    for ax, (tone, edge) in zip(axes[2:], edges.items(), strict=True):
        w = len(edge["live"]["row"])
        x_mm = (np.arange(w) + 0.5 - w / 2) * BOX_VIEW / w * BOX_UNIT_M * 1000.0
        for method, style in (("live", "-"), ("openpbr", "--")):
            row = np.asarray(edge[method]["row"]) / np.asarray(edge[method]["lit"])
            for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
                ax.plot(x_mm, row[:, c], style, color=colour, lw=1.2,
                        label=("live group" if method == "live" else "OpenPBR") if c == 0 else None)
        ax.set_xlim(-3.0, 1.5)
        ax.set_ylim(0.0, 1.1)
        ax.set_title(f"shadow edge, {tone} skin", fontsize=9)
        ax.set_xlabel("mm from the edge (shadow < 0)", fontsize=8)
        ax.legend(fontsize=7, loc="upper left")
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def run(out: Path, figure_path: Path | None = None, tones: tuple[str, ...] = SHADOW_TONES) -> dict:
    """Measure every check (the ear for the medium tone, the shadow edge for ``tones``), write ``out``/checks.json and
    the figure; returns the numbers (relative differences: OpenPBR over live, minus 1)."""
    sys.path.insert(0, str(ROOT))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    head = ear(out, "medium")
    edges = {tone: shadow_edge(out, tone) for tone in tones}
    numbers = {"ear": {"live": head["live"]["ear_mean"], "openpbr": head["openpbr"]["ear_mean"],
                       "relative": (np.array(head["openpbr"]["ear_mean"]) / np.array(head["live"]["ear_mean"])
                                    - 1.0).tolist(), "pixels": head["ear_pixels"]},
               "shadow_edge": {tone: _edge_numbers(e) for tone, e in edges.items()},
               "seconds": time.perf_counter() - t0}
    (out / "checks.json").write_text(json.dumps(numbers, indent=2) + "\n")
    figure(head, edges, figure_path or out / "other_renderers.png")
    return numbers


def _edge_numbers(edge: dict) -> dict:
    live, pbr = (np.array(edge[m]["bleed_width_mm"]) for m in ("live", "openpbr"))
    return {"live_mm": live.tolist(), "openpbr_mm": pbr.tolist(), "relative": (pbr / live - 1.0).tolist()}


def representative_fidelity() -> tuple[list[str], np.ndarray, object]:
    """The single medium against the mixture (exporters.openpbr.fidelity) for the colours of the 10 representative
    tones (training/skin/tones.csv: their reflectance by skin_decoder.onnx, in linear sRGB under D65), evaluated
    exactly (the network and the collapse, the painted colour): (names, colours (10, 3), Fidelity)."""
    from exporters import collapse, inference, openpbr, texel_records
    from exporters.texel_records import CollapseOptions
    from training.skin.tones import load_tones

    tones = load_tones().select("representative")
    refl = inference.run_decoder(tones.values, MODEL.with_name("skin_decoder.onnx"), ["reflectance"])["reflectance"]
    rgb = np.clip(refl @ collapse.channel_matrix().T, 0.0, 1.0)
    rec = texel_records.exact_records(inference.load_model(MODEL), rgb.astype(np.float32), ("physical",),
                                      CollapseOptions())
    return list(tones.names), rgb, openpbr.fidelity(rec["weight"], rec["alpha"], rec["sigma_t_cm"],
                                                    rec["anisotropy"])


def fidelity_markdown() -> str:
    """The table of docs/user/other_renderers.md: per representative tone, per channel (R / G / B)."""
    names, rgb, f = representative_fidelity()

    def cell(values, fmt: str) -> str:
        return " / ".join(format(float(v), fmt) for v in values)

    head = ("| tone | colour (linear) | D mixture, mean (mm) | D components (mm) | D single (mm) | bleed | "
            "half-light radius | " + " | ".join(f"through {t:g} mm" for t in f.thin_mm) + " |")
    rows = [head, "|" + "---|" * (7 + len(f.thin_mm))]
    for i, name in enumerate(names):
        comp = " / ".join(f"{lo:.2f}-{hi:.2f}" for lo, hi in zip(f.d_lo_mm[i], f.d_hi_mm[i], strict=True))
        rows.append(f"| {name} | {cell(rgb[i], '.3f')} | {cell(f.d_mean_mm[i], '.3f')} | {comp} | "
                    f"{cell(f.d_single_mm[i], '.3f')} | {cell(f.bleed[i], '.2f')} | {cell(f.half_light[i], '.2f')} | "
                    + " | ".join(cell(f.thin[i, :, j], '.2f') for j in range(len(f.thin_mm))) + " |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.openpbr_check", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, help="folder for the renders, checks.json and the figure")
    p.add_argument("--figure", type=Path, default=None, help="also write the figure here (.png or .jpg)")
    p.add_argument("--table", action="store_true",
                   help="print the single medium against the mixture on the representative tones (Markdown; no "
                        "rendering)")
    args = p.parse_args(argv)
    if args.table:
        print(fidelity_markdown(), end="")
    if args.out is not None:
        print(json.dumps(run(args.out, args.figure), indent=2))
    elif not args.table:
        p.error("give --out (the renders) and/or --table")
    return 0


if __name__ == "__main__":
    sys.exit(main())
