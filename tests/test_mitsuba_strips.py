"""The teaser-like Mitsuba strips: the committed ones for the shipped model, and the physics they show."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from exporters import mitsuba as em
from exporters.maps import sha256_file
from training.skin.tones import load_tones
from training.validate import strips

FIGURES = Path(__file__).resolve().parent.parent / "docs" / "figures"
#: Known defect of the shipped laptop model (issue 6), measured 2026-11-22: for R01 (f_mel 0.001, lighter than
#: any fitted training tone) at 900 nm the decoder gives g ~ 0, sigma_t 216-242 cm^-1, alpha 0.96-0.98
#: (sigma_s' ~ 230, sigma_a ~ 5-10 cm^-1) where the fits of the nearest light tones say g 0.88, sigma_t 83-90,
#: alpha 0.995 (sigma_s' ~ 11, sigma_a ~ 0.45): 20x too dense, so the sphere stays dark in the NIR.  The UV
#: half is right now (sigma_t 227-2568 cm^-1: opaque).  L_param averages the fits' degenerate (alpha, g,
#: sigma_t) choices; weighting it by the target weights is the next thing to try.
NIR_DEFECT = ("known defect of the shipped laptop model (issue 6): R01's NIR media are ~20x too dense, so the "
              "sphere does not glow at 900 nm (see NIR_DEFECT's comment)")
REGENERATE = "regenerate with `python -m training validate --mitsuba --out docs/figures --overwrite`"


def test_committed_strips_are_for_the_shipped_model():
    rec = json.loads((FIGURES / strips.FILES["metrics"]).read_text())
    assert rec["decoder_sha256"] == sha256_file(em.DEFAULT_DECODER), f"strips are for another model: {REGENERATE}"


@pytest.mark.xfail(strict=True, reason=NIR_DEFECT)
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
    # near-opaque in the UV, translucent in the NIR, less so for darker tones
    assert np.all(t["uv"] < 0.002)
    assert np.all(t["nir"][:7] > 5 * np.maximum(t["uv"][:7], 1e-3))
    assert t["nir"][0] > 3 * t["nir"][-1]
    assert np.mean(t["nir"][:3]) > np.mean(t["nir"][-3:])


@pytest.mark.xfail(strict=True, reason=NIR_DEFECT)
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
