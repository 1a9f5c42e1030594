"""Benchmark: the mixture group's nested closures against its single-channel closures, rendered to low noise.

The mixture group (blender_addon.nodes) renders each component either as three closures over nested channel sets
(the default, ``design="nested"``) or as three single-channel closures (``design="per_channel"``, the earlier
design).  Both have the same expectation (the weighted sum of the components per channel); this benchmark checks it
where subsurface light matters most, on the demo head (training.demo_render: back light behind the ear, key light
whose terminator crosses the cheek), Invert Skin Albedo's default on the medium tone, ``SAMPLES`` samples at
``RESOLUTION`` squared px, Cycles CPU, no denoiser, the same seed:

* **back-lit ear**: per-channel mean over the ears' pixels (a render where only the ears emit);
* **shadow-edge bleed**: per-channel mean over the head's pixels that a Diffuse BSDF render of the same texture
  under the key light alone shows in shadow (below :data:`SHADOW_LEVEL` of the head's median) within :data:`EDGE_PX`
  px of a lit pixel: the light that subsurface transport carries across the key light's shadow edge.

The ratio nested / per-channel per channel is the result (issue criterion: within 5 %); the statistical error of
each mean is estimated from the two halves of the pixels' noise (two seeds).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from training.bench.live import run_script

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION = 128
SAMPLES = 256
SEEDS = (1, 2)
TEXTURE = 256
SHADOW_LEVEL = 0.1
EDGE_PX = 3

_CHILD = """
import json, sys
sys.path.insert(0, {root!r})
import bpy
import blender_addon
from blender_addon import nodes
from training import demo_render
from training.demo_subject import TONES, skin_albedo_texture
scene, parts = demo_render._scene({resolution}, {samples})
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.render.threads_mode, scene.render.threads = "FIXED", 2
image = bpy.data.images.load(str(demo_render.write_image({texture_path!r},
                                  skin_albedo_texture({texture}, seed=0, base=TONES["medium"]))))
mode = {mode!r}
mat = demo_render._material("skin", image, "diffuse" if mode == "diffuse" else "principled")
if mode == "diffuse":  # the key light alone: its shadow
    bpy.data.objects["Back light"].data.energy = 0.0
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
demo_render._assign(parts, mat)
blender_addon.register()
if mode != "diffuse":
    demo_render._invert(parts[0], mat)
    live = next(n for n in mat.node_tree.nodes
                if n.type == "GROUP" and n.node_tree.name.startswith("Spectral Skin SSS Live"))
    mixture = next(n for n in live.node_tree.nodes if n.type == "GROUP" and "k1 Weight" in n.inputs)
    k_count = sum(1 for s in mixture.inputs if s.name.startswith("k") and s.name.endswith(" Weight"))
    mixture.node_tree = nodes.build_svm_group(k_count, "mixture " + mode, design=mode)
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.image_settings.color_depth = "32"
paths = []
for seed in {seeds!r}:
    scene.cycles.seed = seed
    scene.render.filepath = f"{out}/{{mode}}_{{seed}}.exr"
    bpy.ops.render.render(write_still=True)
    paths.append(scene.render.filepath)
if mode == "diffuse":  # the ears' mask: ears emit 1, the head 0 (it hides what it covers), one sample
    for obj, strength in zip(parts, (0.0, 1.0, 1.0)):
        mask = bpy.data.materials.new(f"mask {{strength}}")
        emission = mask.node_tree.nodes.new("ShaderNodeEmission")
        emission.inputs["Strength"].default_value = strength
        out = mask.node_tree.nodes["Material Output"]
        mask.node_tree.links.new(emission.outputs[0], out.inputs["Surface"])
        obj.data.materials.clear()
        obj.data.materials.append(mask)
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.cycles.samples, scene.cycles.seed = 1, 1
    scene.render.filepath = f"{out}/mask.exr"
    bpy.ops.render.render(write_still=True)
    paths.append(scene.render.filepath)
print("RESULT" + json.dumps(paths))
"""


def _read(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(linear RGB (H, W, 3), alpha (H, W)) of an EXR render."""
    import OpenImageIO as oiio

    pixels = np.asarray(oiio.ImageBuf(path).get_pixels(oiio.FLOAT), np.float64)
    return pixels[..., :3], pixels[..., 3]


def _dilate(mask: np.ndarray, px: int) -> np.ndarray:
    out = mask.copy()
    for dy in range(-px, px + 1):
        for dx in range(-px, px + 1):
            out |= np.roll(np.roll(mask, dy, 0), dx, 1)
    return out


def regions(diffuse: np.ndarray, alpha: np.ndarray, ears: np.ndarray) -> dict[str, np.ndarray]:
    """Pixel masks (H, W) of the ears and of the shadow-edge band (module docstring): ``diffuse`` the Diffuse BSDF
    render (H, W, 3), ``alpha`` its coverage, ``ears`` the ears' emission mask (H, W, 3)."""
    ear = ears.mean(axis=2) > 0.99
    head = (alpha > 0.99) & (ears.mean(axis=2) < 0.01)
    luminance = diffuse.mean(axis=2)
    lit = head & (luminance > SHADOW_LEVEL * np.median(luminance[head]))
    return {"back-lit ear": ear, "shadow-edge bleed": head & ~lit & _dilate(lit, EDGE_PX)}


def measure(samples: int = SAMPLES, resolution: int = RESOLUTION) -> dict[str, dict]:
    """Per region: per-channel means of the nested and the per-channel design, their ratio and its error."""
    with tempfile.TemporaryDirectory(prefix="bench_design_") as tmp:
        renders = {}
        for mode in ("diffuse", "nested", "per_channel"):
            script = _CHILD.format(root=str(ROOT), resolution=resolution, samples=samples if mode != "diffuse" else 16,
                                   texture=TEXTURE, texture_path=str(Path(tmp) / "skin.png"), mode=mode,
                                   seeds=SEEDS, out=tmp).replace("{mode}_", f"{mode}_")
            renders[mode] = [_read(p) for p in run_script(script)]
    diffuse, alpha = renders["diffuse"][0]
    out = {}
    for name, mask in regions(diffuse, alpha, renders["diffuse"][-1][0]).items():
        row = {"pixels": int(mask.sum())}
        for mode in ("nested", "per_channel"):
            a, b = (img[mask] for img, _ in renders[mode])
            row[mode] = ((a + b) / 2.0).mean(axis=0)
            row[mode + "_err"] = (a - b).std(axis=0) / 2.0 / np.sqrt(mask.sum())
        row["ratio"] = row["nested"] / row["per_channel"]
        row["ratio_err"] = row["ratio"] * np.hypot(row["nested_err"] / row["nested"],
                                                   row["per_channel_err"] / row["per_channel"])
        out[name] = row
    return out


def benchmarks(quick: bool) -> list[dict]:
    samples = SAMPLES // 4 if quick else SAMPLES
    res = measure(samples)
    rows = []
    for name, r in res.items():
        def rgb(v):
            return "(" + ", ".join(f"{x:.4f}" for x in v) + ")"

        rows.append({"workload": f"mixture design, demo head {RESOLUTION}² px, {samples} spp x {len(SEEDS)} seeds, "
                                 f"Cycles CPU, no denoiser, {name} ({r['pixels']} px): nested closures (default) vs "
                                 "single-channel closures",
                     "ours": f"mean RGB {rgb(r['nested'])} ± {rgb(r['nested_err'])}",
                     "anchor": f"mean RGB {rgb(r['per_channel'])} ± {rgb(r['per_channel_err'])}",
                     "ratio": f"per channel {rgb(r['ratio'])} ± {rgb(r['ratio_err'])}; largest deviation "
                              f"{np.max(np.abs(r['ratio'] - 1.0)) * 100:.1f} %",
                     "error": "-",
                     "notes": "same scene, texture, seeds; the two designs share the expectation (blender_addon.nodes "
                              "module docstring); ± from the difference of the two seeds' renders"})
    return rows
