"""The oblique-light measurement (training.validate.oblique): its median of a histogram, its colour, and a tiny
resumable run of one tone through the real decoder and the real walk."""

from __future__ import annotations

import numpy as np
import pytest

from exporters.colorimetry import spectrum_to_lab
from exporters.constants import WAVELENGTHS_NM
from training.paths import SHIPPED_MODEL_DIR
from training.skin.tones import load_tones
from training.validate import oblique


def test_median_of_a_histogram_is_the_samples_median():
    rng = np.random.default_rng(0)
    x = rng.exponential(0.1, 200_000) - 0.05
    edges = np.linspace(-0.1, 2.0, 2001)
    hist = np.histogram(x, bins=edges)[0].astype(float)
    assert oblique.median_of_hist(hist[None], edges)[0] == pytest.approx(np.median(x), abs=2e-3)
    assert np.isnan(oblique.median_of_hist(np.zeros((1, 4)), np.arange(5.0)))[0]


def test_colour_of_samples_is_the_colour_of_the_full_spectrum_when_it_is_linear():
    nm = np.asarray(oblique.SAMPLE_NM)
    full = 0.2 + 0.4 * (WAVELENGTHS_NM - 250) / 750
    sampled = 0.2 + 0.4 * (nm - 250) / 750
    assert oblique.lab(sampled)[0] == pytest.approx(spectrum_to_lab(full), abs=1e-9)


def test_a_tiny_run_resumes_from_its_cache(tmp_path):
    tones = load_tones().select("representative")
    one = type(tones)(tones.names[4:5], tones.kinds[4:5], tones.values[4:5], tones.descriptions[4:5])
    decoder = SHIPPED_MODEL_DIR / "skin_decoder.onnx"
    walked: list[str] = []
    runs = oblique.run(one, decoder, 300, tmp_path, thetas=(0.0, 70.0), log=walked.append)
    assert len(walked) == 2 and len(list(tmp_path.glob("*.npz"))) == 2
    again: list[str] = []
    assert oblique.run(one, decoder, 300, tmp_path, thetas=(0.0, 70.0), log=again.append).keys() == runs.keys()
    assert again == []
    for r in runs.values():
        for side in ("truth", "mix"):
            assert np.all((r[f"{side}_R"] > 0) & (r[f"{side}_R"] < 1))
            assert np.all(r[f"{side}_hist_x"].sum(axis=1) <= r[f"{side}_R"] * (1 + 1e-5))
    rows = {r["theta_deg"]: r for r in oblique.summarise(runs)}
    assert rows[0.0]["dE76_angle"] == 0.0 and rows[70.0]["dE76_angle"] > 0.0
    assert rows[70.0]["NIR_xmean_truth_mm"] > 0.05 and rows[70.0]["NIR_xmean_mix_mm"] > 0.05


def test_reweighted_weights_match_the_truth_where_the_components_allow():
    r_k = np.array([[0.2, 0.2, 0.5], [0.4, 0.3, 0.6], [0.6, 0.35, 0.7]])
    w = np.full((3, 3), 1 / 3)
    run = {"weight": w, "mix_R_k": r_k, "truth_R": np.array([0.45, 0.1, 0.6])}
    w2 = oblique.reweighted(run)
    assert np.all(w2 >= 0) and w2.sum(axis=0) == pytest.approx(np.ones(3))
    mix = np.sum(w2 * r_k, axis=0)
    assert mix[0] == pytest.approx(0.45) and mix[2] == pytest.approx(0.6)  # reachable: matched
    assert 0.2 <= mix[1] < np.sum(w * r_k, axis=0)[1]  # below every component: moved towards the truth


def test_the_correction_fit_recovers_a_known_angular_darkening():
    """Walks made up so that the truth is the mixture darkened by 10 % x smoothstep(0.2, 0.8, 1 - mu) in every
    wavelength for a dark tone, and equal to it for a light tone (the same profiles): the fit finds that ramp, those
    slopes and no radius change, and the corrected colour matches the truth."""
    from exporters import oblique_correction as oc
    from training.validate import oblique_fit

    n_w, n_b = len(oblique.SAMPLE_NM), len(oblique.R_EDGES_CM) - 1
    hist = np.exp(-np.arange(n_b) / 40.0)[None].repeat(n_w, 0).astype(np.float32)
    mix = np.linspace(0.05, 0.4, n_w)
    runs = {}
    for name, depth in (("dark", 0.1), ("light", 0.0)):
        for theta in (0.0, 45.0, 60.0, 70.0, 85.0):
            h = oc.angle_shape(np.cos(np.radians(theta)), (0.2, 0.8))
            runs[(name, theta)] = {"truth_R": mix * (1 - depth * h), "mix_R": mix, "truth_hist_r": hist,
                                   "mix_hist_r": hist}
    colours = np.array([[0.08, 0.04, 0.03], [0.5, 0.35, 0.28]])
    corr = oblique_fit.fit(runs, ["dark", "light"], colours)
    assert corr.weight_ramp == pytest.approx((0.2, 0.8))
    assert corr.weight_slope[0] == pytest.approx([-0.1] * 3, abs=1e-9)  # the darker colour is the first knot
    assert corr.weight_slope[1] == pytest.approx([0.0] * 3, abs=1e-9)
    assert np.all(corr.radius_slope == 0.0)
    rows = oblique_fit.evaluate(runs, ["dark", "light"], colours, corr)
    assert max(r["dE76_corrected"] for r in rows) < 1e-6
    assert max(r["dE76_shipped"] for r in rows) > 1.0
