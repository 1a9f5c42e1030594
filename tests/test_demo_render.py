"""make demo's artist path (training/demo_render.py) at a tiny size: texture, bake, render, contact sheet."""

from __future__ import annotations

import json

import numpy as np
import OpenImageIO as oiio

from exporters.colorimetry import srgb_decode
from training import demo_render


def test_procedural_texture_has_gradient_freckles_and_redness():
    codes = demo_render.skin_albedo_texture(128, seed=0)
    assert codes.shape == (128, 128, 3) and codes.dtype == np.uint8
    lin = srgb_decode(codes / 255.0)
    lum = lin @ np.array([0.2126, 0.7152, 0.0722])
    assert lum[:16].mean() > 1.8 * lum[-16:].mean()  # light at the top, dark at the bottom
    # freckles: small spots clearly darker than their surroundings (3 x 3 vs 15 x 15 neighbourhood)
    pad = np.pad(lum, 7, mode="edge")
    local = np.mean([pad[dy:dy + 128, dx:dx + 128] for dy in range(15) for dx in range(15)], axis=0)
    assert np.count_nonzero(lum < 0.8 * local) > 20
    redness = lin[..., 0] / lin[..., 1]
    assert np.percentile(redness, 95) > 1.15 * np.percentile(redness, 5)  # red patches
    np.testing.assert_array_equal(codes, demo_render.skin_albedo_texture(128, seed=0))  # seeded


def test_tiny_demo_run(tmp_path):
    info = demo_render.run(tmp_path, texture_size=16, render_size=24, samples=2)
    for name in ("skin_albedo.png", "preview.png", "preview_albedo_only.png", "preview_compare.png",
                 "maps_contact_sheet.png"):
        assert (tmp_path / name).is_file(), name
    record = json.loads((tmp_path / "maps" / "skin_albedo_maps.json").read_text())
    assert record["image_size"] == [16, 16] and record["collapse"]["colour"] == "painted"
    preview = oiio.ImageBuf(str(tmp_path / "preview.png")).get_pixels(oiio.FLOAT)
    assert preview.shape[:2] == (24, 24) and np.all(np.isfinite(preview))
    assert info["timings_s"]["bake"] > 0
