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
#: Carlo ground truth (`validate`'s cache) give a far-side translucency at 898 nm of 0.081, 0.055, 0.040,
#: 0.070, 0.076 for R01, R03, R05, R08, R10 (2026-11-22): in the NIR melanin absorbs little and the dermis
#: sets the glow, so it does not fall from light to dark skin.  The visible glow does (melanin).
REGENERATE = "regenerate with `python -m training validate --mitsuba --out docs/figures --overwrite`"


def test_committed_strips_are_for_the_shipped_model():
    rec = json.loads((FIGURES / strips.FILES["metrics"]).read_text())
    assert rec["decoder_sha256"] == sha256_file(em.DEFAULT_DECODER), f"strips are for another model: {REGENERATE}"


def test_committed_strips_show_the_physics():
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
    # near-opaque in the UV, translucent in the NIR for every tone (the fits: 0.04-0.08, comment above);
    # in the visible, light skin glows and the darkest does not
    assert np.all(t["uv"] < 0.002)
    assert np.all(t["nir"] > 0.01) and np.all(t["nir"] > 5 * np.maximum(t["uv"], 1e-3))
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
