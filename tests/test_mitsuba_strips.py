"""The teaser-like Mitsuba strips: the committed ones for the shipped model, and the physics they show."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from exporters.maps import sha256_file
from training.skin.tones import load_tones
from training.validate import mitsuba_scene as em
from training.validate import strips

FIGURES = Path(__file__).resolve().parent.parent / "docs" / "figures"
#: What the NIR strip can be held to.  Rendered the same way (32 px, 48 spp), the K = 3 fits of the Monte
#: Carlo ground truth (`validate`'s cache) gave a far-side translucency at 898 nm of 0.081, 0.055, 0.040,
#: 0.070, 0.076 for R01, R03, R05, R08, R10 (the skin model without the real-skin calibration): in
#: the NIR melanin absorbs little and the dermis sets the glow, so it does not fall from light to dark skin.
#: The visible glow does (melanin): rendered as the strips are (64 px, 48 spp, the strips' seeds), the K = 3
#: fits of the 500,000-photon ground truth of the calibrated skin model (`runs/validation/cache`)
#: give vis_E 0.0029, 0.0017, 0.0010, 0.00064, 0.00011, 4e-7 for R01, R03, R05, R08, R09, R10 (vis_A within
#: 25 % of those).
#: The shipped model gives 0.0028, 0.0019, 0.0009, 0.0009, 0.0015, 0.0003: right for light
#: and medium skin, 14x too translucent at R09 (f_mel 0.2) and far too at R10 (f_mel 0.65).
REGENERATE = "regenerate with `python -m training validate --mitsuba --out docs/figures --overwrite`"


def test_committed_strips_are_for_the_shipped_model():
    rec = json.loads((FIGURES / strips.FILES["metrics"]).read_text())
    assert rec["decoder_sha256"] == sha256_file(em.DEFAULT_DECODER), f"strips are for another model: {REGENERATE}"


def test_committed_strips_show_the_physics():
    """The committed strips are the shipped decoder's, exposed, and show UV opaque and NIR translucent for
    every tone (the visible: next test)."""
    rec = json.loads((FIGURES / strips.FILES["metrics"]).read_text())
    assert rec["decoder_sha256"] == sha256_file(em.DEFAULT_DECODER), f"strips are for another model: {REGENERATE}"
    size = rec["config"]["size"]
    for band in strips.BANDS:
        img = mpimg.imread(FIGURES / strips.FILES[band])
        assert img.shape[:2] == (size, 10 * size), band
        assert img.max() > 0.5, band  # exposed, not black
    t = {band: np.asarray(v) for band, v in rec["translucency"].items()}
    names = rec["tones"]
    assert names[0] == "R01" and names[-1] == "R10"
    # near-opaque in the UV, translucent in the NIR for every tone (the fits: 0.04-0.08, comment above)
    assert np.all(t["uv"] < 0.002)
    assert np.all(t["nir"] > 0.01) and np.all(t["nir"] > 5 * np.maximum(t["uv"], 1e-3))


@pytest.mark.xfail(strict=True, reason="the shipped model lets the very dark tones glow in the "
                   "visible: R09 0.0015 and R10 0.0003 against the fits' 0.0001 and 4e-7 (comment above)")
def test_committed_strips_darkest_skin_does_not_glow_in_the_visible():
    """In the visible the glow falls with melanin: the lightest tone more than 10x the darkest, the three
    lightest more than 3x the three darkest (the fits of the ground truth: R01 ~8,000x R10; R01 and R03
    ~20x R08-R10)."""
    rec = json.loads((FIGURES / strips.FILES["metrics"]).read_text())
    t = {band: np.asarray(v) for band, v in rec["translucency"].items()}
    for band in ("vis_E", "vis_A"):
        assert t[band][0] > 10 * t[band][-1] and np.mean(t[band][:3]) > 3 * np.mean(t[band][-3:]), band


def test_live_render_uv_opaque_nir_translucent():
    """A small live render (scalar variant) of the lightest tone: the far side of the sphere glows in the
    NIR and stays black in the UV; the light side is on the left of the image (light towards -x)."""
    setup = em.ObjectSetup(width=24, height=24, **strips.SETUP)
    renderer = em.ObjectRenderer("scalar_rgb", setup)
    cos = strips.sphere_cosines(setup)
    tone = load_tones().select("representative").values[0]
    out = {}
    for band, lam in (("uv", 300.0), ("nir", 900.0)):
        img = renderer.render_mixture(em.decode(tone).at([lam]), 0, spp=64, seed=5)
        assert np.all(np.isfinite(img)) and img.min() >= 0
        out[band] = strips.translucency(img, cos, strips.far_cos(setup))
        lit = np.nan_to_num(cos) > strips.LIT_COS
        assert img[lit].mean() > 0 and lit[:, :12].sum() > lit[:, 12:].sum()
    assert out["uv"] < 1e-3 < out["nir"]


def test_render_strips_refuses_to_overwrite(tmp_path):
    existing = tmp_path / strips.FILES["uv"]
    existing.write_bytes(b"user file")
    with pytest.raises(FileExistsError, match="--overwrite"):
        strips.render_strips(tmp_path, strips.StripConfig(size=8, spp=1, variant="scalar_rgb"))
    assert existing.read_bytes() == b"user file"
