"""Radial profile estimators (training/sim/resample.py) and the `resampling` comparison command.

The reference for the estimators' accuracy is analytic: exit radii drawn from an exponential law
r ~ Exp(L) have the per-area profile exp(-r / L) / (2 pi L r), whose bin averages are
(exp(-a / L) - exp(-b / L)) / (pi (b^2 - a^2)) exactly.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from exporters.constants import R_EDGES_CM
from training.sim.medium import LayeredMedium
from training.sim.resample import cdf_resample, cdf_resample_profile, histogram_profile
from training.sim.resample_compare import main as resampling_main
from training.sim.transport import simulate

AREA = math.pi * np.diff(R_EDGES_CM**2)


def _exponential_tallies(n: int, length_cm: float, seed: int):
    r = np.random.default_rng(seed).exponential(length_cm, n)
    e = np.histogram(r, bins=R_EDGES_CM)[0] / n  # unit weights: energy_sq = energy
    exact = (np.exp(-R_EDGES_CM[:-1] / length_cm) - np.exp(-R_EDGES_CM[1:] / length_cm)) / AREA
    return e, exact


def test_cdf_resampling_is_conservative_and_beats_the_histogram_against_the_exact_profile() -> None:
    n = 20_000
    e, exact = _exponential_tallies(n, 0.1, seed=3)
    p_cdf = cdf_resample(e, e, R_EDGES_CM, n)
    p_hist = histogram_profile(e, R_EDGES_CM)
    assert np.all(np.isfinite(p_cdf)) and np.all(p_cdf >= 0)
    assert (p_cdf * AREA).sum() == pytest.approx(e.sum(), rel=1e-12)  # the energy inside is kept
    sel = exact * AREA * n >= 10  # bins expecting >= 10 photons
    rmsr = lambda p: math.sqrt(np.mean(((p[sel] - exact[sel]) / exact[sel]) ** 2))  # noqa: E731
    assert rmsr(p_cdf) < 0.5 * rmsr(p_hist), (rmsr(p_cdf), rmsr(p_hist))
    # nothing spread beyond the outermost photon
    assert np.all(p_cdf[np.flatnonzero(e)[-1] + 1:] == 0)


def test_cdf_resampling_keeps_well_sampled_bins_and_batches() -> None:
    """Where every bin holds >= min_count effective photons the result is the histogram itself."""
    n = 10**9
    e, _ = _exponential_tallies(2_000_000, 0.1, seed=4)
    e = np.where(e > 0, e, 0.0)
    dense = np.clip(e, 1e-6, None)  # every bin >= 1e-6 x 1e9 = 1000 photons
    stack = np.stack([dense, e])
    out = cdf_resample(stack, stack, R_EDGES_CM, n, min_count=400)  # unit weights: energy_sq = energy
    np.testing.assert_allclose(out[0], histogram_profile(dense, R_EDGES_CM), rtol=1e-9)
    assert out.shape == (2, 512) and (out[1] * AREA).sum() == pytest.approx(e.sum(), rel=1e-12)
    with pytest.raises(ValueError, match="min_count"):
        cdf_resample(e, e, R_EDGES_CM, n, min_count=0)


def test_simulate_cdf_profile_has_the_histograms_shape_and_energy() -> None:
    torch.set_num_threads(1)
    m = LayeredMedium.homogeneous([5.0, 1.0], [95.0, 99.0], 0.8, n_medium=1.4)
    hist = simulate(m, 3000, seed=2, compile=False)
    cdf = simulate(m, 3000, seed=2, compile=False, profile_estimator="cdf")
    assert cdf.profile.shape == hist.profile.shape == (2, 512)
    np.testing.assert_array_equal(cdf.R_d, hist.R_d)
    np.testing.assert_allclose((cdf.profile * AREA).sum(-1), (hist.profile * AREA).sum(-1), rtol=1e-12)
    # the post-hoc form (from profile and its standard error, as the tone files hold them) gives the same
    again = cdf_resample_profile(hist.profile, hist.profile_stderr, R_EDGES_CM, 3000)
    np.testing.assert_allclose(again, cdf.profile, rtol=1e-6, atol=1e-12)
    with pytest.raises(ValueError, match="profile_estimator"):
        simulate(m, 10, profile_estimator="kde")


def test_resampling_command_quick(tmp_path) -> None:
    assert resampling_main(["--out", str(tmp_path), "--quick"]) == 0
    s = json.loads((tmp_path / "resampling.json").read_text())
    assert (tmp_path / "fig_resampling.png").stat().st_size > 10_000
    assert (tmp_path / "resampling.md").read_text().startswith("# Profile estimators")
    assert {c["kind"] for c in s["cases"]} == {"homogeneous", "skin"}
    for case in s["cases"]:
        assert set(case["rmsr"]) >= {"histogram", "uniform", "kde", "cdf"}
        assert all(math.isfinite(v) for v in case["rmsr"].values())
    assert s["ratio_histogram_over_cdf"] > 1.0  # CDF resampling beats the plain histogram
    assert resampling_main(["--out", str(tmp_path), "--photons", "5"]) == 2
