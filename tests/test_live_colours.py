"""Every colour renders as painted through the live group, in real Cycles (the add-on's convention: the painted
colour plus the coat).

Sixteen non-skin colours of a face texture (lipstick reds, tattoo inks, eyeshadows, bruises, paint, greys,
near-white, near-black: tests/test_painted_gain.NON_SKIN) as stripes of an 8-bit sRGB texture, and float colours
(negative, above 1, saturated) as stripes of a float EXR, on the probe box (blender_addon.probe: camera straight
above, white world); Invert Skin Albedo at its defaults (the live group).  The reference is the painted colour
(clamped to [0, 1]: what a Diffuse BSDF of that texture renders here, tests/test_bake_painted_colour.py) plus what
Blender's Principled BSDF with a black base reflects at the material's roughness and the group's IOR.  Stripes are
6 cm wide (1 Blender unit = 1 m), far wider than any colour's diffusion length; their inner pixels are averaged.

A gradient from medium skin to a blue eyeshadow, crossing the edge of the table's box of skin colours, renders
along its whole length within ΔE76 2 of the painted gradient and without a step where it leaves the box.
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import live, preferences, probe  # noqa: E402
from exporters import live_table  # noqa: E402
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode  # noqa: E402
from tests.addon_scene import principled_coat_reflectance, render_linear, run_invert, write_image  # noqa: E402
from tests.test_bake_painted_colour import box_material  # noqa: E402
from tests.test_painted_gain import NON_SKIN  # noqa: E402

STRIPE = 8  # texels and pixels per stripe
EDGE = 2  # pixels left out at each stripe edge
SAMPLES = 512
#: Float colours: negative, above 1, a saturated blue, a deep red ink, pure green, linear.
FLOATS = np.array([[-0.3, 0.25, 0.1], [1.6, 0.7, 0.2], [0.02, 0.04, 0.7], [0.3, 0.01, 0.02], [0.0, 0.6, 0.0]])
ROUGHNESS = 0.5  # the Principled BSDF's default, which the group takes


@pytest.fixture
def addon():
    blender_addon.register()
    yield
    blender_addon.unregister()


def _render(scene: bpy.types.Scene, tmp: Path, name: str) -> np.ndarray:
    """Render; linear RGB (H, W, 3)."""
    return render_linear(scene, tmp / f"{name}.exr")


def _stripes(rgb: np.ndarray, n: int) -> np.ndarray:
    return np.array([rgb[:, i * STRIPE + EDGE:(i + 1) * STRIPE - EDGE].reshape(-1, 3).mean(axis=0) for i in range(n)])


def _probe(width: int, samples: int = SAMPLES) -> bpy.types.Scene:
    scene = probe.new_scene(samples=samples, resolution=width, seed=5)
    scene.render.resolution_y = STRIPE
    return scene


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["8-bit", "float"])
def test_non_skin_colours_render_as_painted(tmp_path, addon, kind):
    if kind == "8-bit":
        painted, pixels = srgb_decode(NON_SKIN / 255.0), NON_SKIN
    else:
        painted, pixels = np.clip(FLOATS, 0.0, 1.0), FLOATS.astype(np.float32)
    n = len(pixels)
    scene = _probe(n * STRIPE)
    texture = np.repeat(np.repeat(pixels[None], STRIPE, axis=0), STRIPE, axis=1)
    path = write_image(tmp_path / ("paint.png" if kind == "8-bit" else "paint.exr"), texture,
                       "uint8" if kind == "8-bit" else "float")
    image = bpy.data.images.load(str(path))
    if kind == "float":
        image.colorspace_settings.name = "Linear Rec.709"  # the values as written
    box_material(image, "principled")
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    assert live_table.outside_fraction(table, painted) > 0.5  # most of them are not skin colours
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    body = _stripes(_render(scene, tmp_path, kind), n)
    coat = principled_coat_reflectance(scene, [1.0], ROUGHNESS, live.nodes.DEFAULT_IOR)[0]
    de = delta_e76(linear_srgb_to_lab(body - coat), linear_srgb_to_lab(painted))
    print(f"\n{kind}: ΔE76 {np.round(de, 2).tolist()} mean {de.mean():.2f} max {de.max():.2f}")
    assert de.mean() <= 1.0 and de.max() <= 2.0, de


@pytest.mark.slow
def test_a_gradient_leaving_the_skin_colours_renders_without_a_seam(tmp_path, addon):
    width = 32
    t = np.linspace(0.0, 1.0, width)[:, None]
    painted = (1.0 - t) * np.array([0.40, 0.20, 0.12]) + t * np.array([0.02, 0.15, 0.6])
    table = live.table_for_model(preferences.DEFAULT_MODEL)
    inside = table.locate(painted)[0]
    edge = int(np.argmax(~inside))
    assert 4 <= edge <= width - 4 and not inside[edge:].any()  # the gradient crosses the box's edge once
    scene = _probe(width)
    image = bpy.data.images.load(str(write_image(tmp_path / "gradient.exr", np.repeat(
        painted[None].astype(np.float32), STRIPE, axis=0), "float")))
    image.colorspace_settings.name = "Linear Rec.709"
    box_material(image, "principled")
    assert run_invert(bpy.data.objects["ProbeSlab"], mode="LIVE") == {"FINISHED"}
    row = _render(scene, tmp_path, "gradient").mean(axis=0).reshape(-1, 2, 3).mean(axis=1)  # pairs of columns
    coat = principled_coat_reflectance(scene, [1.0], ROUGHNESS, live.nodes.DEFAULT_IOR)[0]
    de = delta_e76(linear_srgb_to_lab(row - coat), linear_srgb_to_lab(painted.reshape(-1, 2, 3).mean(axis=1)))
    print(f"\ngradient ΔE76 {np.round(de, 2).tolist()} (leaves the box at column {edge})")
    assert de.mean() <= 1.0 and de.max() <= 2.0, de
    assert de[edge // 2 - 2:edge // 2 + 2].mean() <= 1.0, de  # no seam: the render follows it across the edge
