"""Make docs/figures/non_skin_colours.png: a face-like texture with lipstick, eyeshadow, eyebrows and a tattoo,
rendered in Cycles through the live group at Invert Skin Albedo's defaults; and docs/figures/non_skin_gradient.png:
a gradient from medium skin to a blue eyeshadow that leaves the table's skin colours half-way.

Face panels, left to right: the painted texture; the render (the probe box of blender_addon/probe.py: camera
straight above, white world, 1 Blender unit = 10 cm, so the face is 10 cm wide); the group's ``Outside`` output
(white where a colour is not a skin colour of the table).  Gradient: the painted gradient above, its render below
the white line, the coat's reflection (0.026) subtracted, a tick under the column where it leaves the skin
colours.  Run from the repository root (about two minutes on two cores; ``face`` or ``gradient`` makes one)::

    .venv/bin/python docs/figures/non_skin_colours.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
from PIL import Image  # noqa: E402

import blender_addon  # noqa: E402
from blender_addon import panels, probe  # noqa: E402
from exporters.colorimetry import srgb_decode, srgb_encode  # noqa: E402
from tests.addon_scene import run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402

SIZE, SAMPLES = 128, 128
OUT = ROOT / "docs" / "figures" / "non_skin_colours.png"
GRADIENT_OUT = ROOT / "docs" / "figures" / "non_skin_gradient.png"
GRADIENT_WIDTH, GRADIENT_HEIGHT, GRADIENT_SAMPLES = 64, 16, 512
COAT = 0.026  # the coat's reflection of the white world straight above (tests/test_live_colours.py measures it)


def face() -> np.ndarray:
    """8-bit sRGB codes (SIZE, SIZE, 3), row 0 at the top: skin with lips, eyeshadow, eyebrows, a tattoo."""
    y, x = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    rng = np.random.default_rng(4)
    codes = np.empty((SIZE, SIZE, 3))
    codes[:] = (198, 140, 112)  # medium skin
    codes += rng.normal(0.0, 3.0, (SIZE, SIZE, 1))  # a little mottling
    codes[:, :, 0] += 18 * np.exp(-((x - 0.25) ** 2 + (y - 0.58) ** 2) / 0.01)  # blush on the cheeks
    codes[:, :, 0] += 18 * np.exp(-((x - 0.75) ** 2 + (y - 0.58) ** 2) / 0.01)

    def ellipse(cx, cy, rx, ry):
        return ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0

    for cx, shadow in ((0.3, (70, 110, 190)), (0.7, (120, 60, 150))):  # blue and purple eyeshadow
        codes[ellipse(cx, 0.36, 0.13, 0.07)] = shadow
        codes[ellipse(cx, 0.38, 0.07, 0.03)] = (235, 232, 228)  # the eye: near-white
        codes[ellipse(cx, 0.38, 0.025, 0.025)] = (25, 20, 18)  # the pupil: near-black
        codes[ellipse(cx, 0.25, 0.12, 0.018)] = (70, 45, 30)  # eyebrow
    codes[ellipse(0.5, 0.8, 0.16, 0.045)] = (185, 25, 45)  # lipstick
    codes[ellipse(0.5, 0.8, 0.12, 0.008)] = (120, 15, 30)
    star = (np.abs(x - 0.83) + np.abs(y - 0.72) < 0.07) & ~(np.abs(x - 0.83) + np.abs(y - 0.72) < 0.045)
    codes[star] = (30, 45, 70)  # a blue-black tattoo on the cheek
    codes[(np.abs(x - 0.14) < 0.05) & (np.abs(y - 0.78) < 0.005)] = (20, 110, 70)  # a green ink line
    return np.clip(np.round(codes), 0, 255).astype(np.uint8)


def render(scene: bpy.types.Scene, path: Path) -> np.ndarray:
    """Render; linear RGB (height, width, 3), row 0 at the top."""
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)


def save(rgb: np.ndarray, path: Path, zoom: int) -> None:
    image = Image.fromarray(np.round(255 * srgb_encode(np.clip(rgb, 0.0, 1.0))).astype(np.uint8))
    image.resize((image.width * zoom, image.height * zoom), Image.NEAREST).save(path, optimize=True)
    print(f"wrote {path}")


def gradient_figure() -> None:
    from blender_addon import live, preferences

    t = np.linspace(0.0, 1.0, GRADIENT_WIDTH)[:, None]
    painted = (1.0 - t) * np.array([0.40, 0.20, 0.12]) + t * np.array([0.02, 0.15, 0.6])
    edge = int(np.argmax(~live.table_for_model(preferences.DEFAULT_MODEL).locate(painted)[0]))
    scene = probe.new_scene(samples=GRADIENT_SAMPLES, resolution=GRADIENT_WIDTH, seed=2)
    scene.render.resolution_y = GRADIENT_HEIGHT
    blender_addon.register()
    with tempfile.TemporaryDirectory() as tmp:
        exr = write_image(Path(tmp) / "gradient.exr", np.repeat(painted[None], GRADIENT_HEIGHT, axis=0).astype(
            np.float32), "float")
        image = bpy.data.images.load(str(exr))
        image.colorspace_settings.name = "Linear Rec.709"
        box_material(image, "principled")
        assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
        rendered = render(scene, Path(tmp) / "gradient_render.exr") - COAT
    blender_addon.unregister()
    top = np.repeat(painted[None], GRADIENT_HEIGHT, axis=0)
    line = np.ones((1, GRADIENT_WIDTH, 3))
    tick = np.ones((3, GRADIENT_WIDTH, 3))
    tick[:, edge] = 0.0
    save(np.concatenate([top, line, rendered, tick]), GRADIENT_OUT, 8)


def face_figure() -> None:
    codes = face()
    scene = probe.new_scene(samples=SAMPLES, resolution=SIZE, seed=2)
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.1
    blender_addon.register()
    with tempfile.TemporaryDirectory() as tmp:
        png = write_image(Path(tmp) / "face.png", codes, "uint8")  # row 0 at the top of the file
        material = box_material(bpy.data.images.load(str(png)), "principled")
        assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
        rendered = render(scene, Path(tmp) / "render.exr")
        node = panels.live_node(material)
        emission = material.node_tree.nodes.new("ShaderNodeEmission")
        material.node_tree.links.new(node.outputs["Outside"], emission.inputs["Strength"])
        material.node_tree.links.new(emission.outputs[0], probe.material_output(material).inputs["Surface"])
        scene.cycles.samples = 1
        outside = render(scene, Path(tmp) / "outside.exr")
    blender_addon.unregister()
    painted = srgb_decode(codes / 255.0)
    panels_rgb = [painted, rendered, np.where(outside > 0.0, 1.0, 0.08)]
    gap = np.ones((SIZE, 4, 3))
    save(np.concatenate([panels_rgb[0], gap, panels_rgb[1], gap, panels_rgb[2]], axis=1), OUT, 2)


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "all"
    if which in ("face", "all"):
        face_figure()
    if which in ("gradient", "all"):
        gradient_figure()
