"""make demo's artist path (training/demo_render.py, training/demo_subject.py) at a tiny size, in real Blender:
the procedural textures and head, the bakes, the nine renders and what translucency predicts of them."""

from __future__ import annotations

import json
from pathlib import Path

import bpy
import numpy as np
import pytest

from exporters.colorimetry import srgb_decode
from training import demo_render, demo_subject
from training.export.card import summary

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB -> Y (IEC 61966-2-1)
CARD = Path(__file__).resolve().parents[1] / "blender_addon" / "models" / "skin_inversion.json"


@pytest.mark.parametrize("tone", list(demo_render.TONES))
def test_procedural_texture_is_the_tone_with_freckles_and_redness(tone):
    n = 256
    codes = demo_render.skin_albedo_texture(n, seed=0, base=demo_render.TONES[tone])
    assert codes.shape == (n, n, 3) and codes.dtype == np.uint8
    lin = srgb_decode(codes / 255.0)
    lum = lin @ LUMINANCE
    base = srgb_decode(np.array(demo_render.TONES[tone]) / 255.0) @ LUMINANCE
    assert 0.7 * base < np.median(lum) < 1.1 * base  # around the tone (freckles and redness only darken)
    # freckles: small spots clearly darker than their surroundings (3 x 3 vs 15 x 15 neighbourhood)
    pad = np.pad(lum, 7, mode="edge")
    local = np.mean([pad[dy:dy + n, dx:dx + n] for dy in range(15) for dx in range(15)], axis=0)
    assert np.count_nonzero(lum < 0.8 * local) > 20
    redness = lin[..., 0] / lin[..., 1]
    assert np.percentile(redness, 95) > 1.15 * np.percentile(redness, 5)  # red patches
    np.testing.assert_array_equal(codes, demo_render.skin_albedo_texture(n, seed=0, base=demo_render.TONES[tone]))


def test_tones_go_from_light_to_dark():
    lum = [np.mean(srgb_decode(demo_render.skin_albedo_texture(64, base=demo_render.TONES[t]) / 255.0) @ LUMINANCE)
           for t in ("light", "medium", "dark")]
    assert lum[0] > 1.5 * lum[1] > 1.5 * 1.5 * lum[2]


def _extent(obj) -> np.ndarray:
    co = np.array([v.co[:] for v in obj.data.vertices])
    return np.stack([co.min(axis=0), co.max(axis=0)])


def test_head_is_life_sized_with_ears_standing_out():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    head, left, right = demo_subject.build_head()
    lo, hi = _extent(head)
    width, depth, height = hi - lo
    # an adult head (anthropometric surveys such as ANSUR II: breadth about 15 cm, length 19-20 cm, chin to
    # crown about 23 cm; the depth here includes the nose, the height the neck)
    assert 0.12 < width < 0.17 and 0.18 < depth < 0.26 and 0.25 < height < 0.36
    for ear, side in ((left, -1), (right, 1)):
        elo, ehi = _extent(ear)
        assert 0.055 < ehi[2] - elo[2] < 0.08  # ~6-7 cm tall
        outer = -elo[0] if side < 0 else ehi[0]
        assert outer > hi[0] + 0.01  # its back edge stands off the head
    for obj in (head, left, right):
        uv = np.empty(2 * len(obj.data.loops))
        obj.data.uv_layers[0].data.foreach_get("uv", uv)
        assert np.all((uv >= 0.0) & (uv <= 1.0)), obj.name
        assert all(p.use_smooth for p in obj.data.polygons)


def test_tiny_demo_shows_translucency(tmp_path):
    # 24 samples: at fewer the dark ear's red lies within the noise of the 1.5x bound below
    info = demo_render.run(tmp_path, texture_size=32, render_size=64, samples=24)
    figure = demo_render.read_image(tmp_path / "translucency.png")
    assert figure.shape[0] > 3 * 64 and figure.shape[1] > 3 * 64
    assert (tmp_path / "maps_contact_sheet.png").is_file()
    panels = {}
    rec = json.loads(next((tmp_path / "maps" / "medium").glob("*_maps.json")).read_text())
    assert rec["unit_scale_m_per_blender_unit"] == 1.0  # the head is modelled in metres
    assert rec["image_size"] == [32, 32] and rec["collapse"]["colour"] == "painted"  # the contact sheet's bake
    assert sorted(p.name for p in (tmp_path / "maps").iterdir()) == ["medium"]  # the renders bake nothing
    for tone in demo_render.TONES:
        spectral = bpy.data.materials[f"{tone} spectral"]
        assert any(n.bl_idname == "ShaderNodeGroup" and n.node_tree.get("spectral_skin_sss_backend") == "LIVE"
                   for n in spectral.node_tree.nodes), tone  # the live group, the operator's default
        for method, _ in demo_render.METHODS:
            panels[method] = demo_render.read_image(tmp_path / f"render_{tone}_{method}.png")
            assert panels[method].shape == (64, 64, 3) and np.all(np.isfinite(panels[method]))
        ear = {m: np.array(info["ear_mean_srgb"][f"{tone}/{m}"]) for m, _ in demo_render.METHODS}
        # the visible side of the ear gets no direct light: a Diffuse ear is dark, a subsurface ear shows the
        # back light coming through, reddened (red travels furthest in skin); relative, since the dark tone's
        # ear is dim in every column (seen at 256 px: albedo 0.04, spectral 0.08)
        assert ear["spectral"][0] > 1.5 * ear["albedo"][0], (tone, ear)
        assert ear["spectral"][0] > 1.5 * ear["spectral"][2], (tone, ear)
        assert ear["principled"].mean() > 1.5 * ear["albedo"].mean() + 0.03, (tone, ear)
        # and the three columns are three different pictures
        for a, b in (("albedo", "principled"), ("albedo", "spectral"), ("principled", "spectral")):
            assert np.abs(panels[a] - panels[b]).mean() > 0.01, (tone, a, b)
    assert info["ear_pixels"] > 10


def test_model_summary_comes_from_the_card():
    card = json.loads(CARD.read_text())
    text = summary(card)
    assert text.startswith(card["name"]) and f"K = {card['K']}" in text
    assert f"{card['dataset']['n_train']:,} training" in text
    assert f"{card['metrics']['validation']['enc_delta_e76']['mean']:.2f}" in text
    assert "integration model" not in text and "16 training tones" not in text
    assert summary({}) == "unnamed model"
    assert summary({"name": "m", "K": 2}) == "m, K = 2"


def test_edits_row_shows_the_ear_glow_follow_melanin_and_blood(tmp_path):
    """The skin-edits row at a tiny size: under the back light the ear's glow darkens with a tan (melanin x2 absorbs
    more of the light crossing the ear), brightens with pallor (less blood absorbs less) and loses green with a flush
    (haemoglobin's bands absorb green); the row figure is written."""
    info = demo_render.edits_row(tmp_path, texture_size=64, render_size=64, samples=8)
    ear = {key: np.array(v) for key, v in info["ear_mean_srgb"].items()}
    assert info["ear_pixels"] > 20
    assert ear["tan"] @ LUMINANCE < ear["as painted"] @ LUMINANCE < ear["pallor"] @ LUMINANCE
    assert ear["flush"][1] < ear["as painted"][1]
    assert (tmp_path / "skin_edits_row.png").is_file()


def test_mask_row_paints_the_flush_on_the_cheek_only(tmp_path):
    """The masked-edit row at a tiny size: the flush painted through the Edit Mask renders from the mask cache and
    changes a patch of the image (the cheek), far fewer pixels than the flush everywhere, which renders from an edit
    cache; the row figure is written."""
    info = demo_render.mask_row(tmp_path, texture_size=64, render_size=64, samples=8)
    assert info["caches"] == {"cheek": "Rendered from the mask cache", "flush": "Rendered from edit cache 1"}
    share = info["changed_share"]
    assert 0.005 < share["cheek"] < share["flush"] / 3, share
    assert (tmp_path / "skin_edits_mask_row.png").is_file()
