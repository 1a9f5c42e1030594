"""The render-cost benchmark's estimators: noise from two or more seeds, and the time-to-equal-noise fit."""

import numpy as np

from training.bench import render_cost


def test_two_seed_rmse_is_the_noise_of_one_render():
    rng = np.random.default_rng(3)
    truth = rng.uniform(0.0, 1.0, (64, 64, 3))
    sigma = 0.05
    a = truth + rng.normal(0.0, sigma, truth.shape)
    b = truth + rng.normal(0.0, sigma, truth.shape)
    assert abs(render_cost.noise_rmse(a, b) - sigma) < 0.02 * sigma


def test_fit_recovers_noise_constant_and_time_per_sample():
    samples = np.array([8, 16, 32, 64])
    fit = render_cost.fit_cost(samples, 0.2 / np.sqrt(samples), 0.5 + 0.03 * samples)
    assert np.isclose(fit["c"], 0.2) and np.isclose(fit["a"], 0.03) and np.isclose(fit["t0"], 0.5)
    # samples to reach RMSE e: (c / e)^2; CPU seconds: a (c / e)^2, so cost = a c^2 at e = 1
    assert np.isclose(fit["cost"], 0.03 * 0.04)


def test_ten_seed_rmse_is_the_noise_of_one_render():
    """Ten renders of one image with independent per-pixel noise of standard deviation s: RMSE s (within the sampling
    error of 10 renders of 64 x 64 x 3 values)."""
    rng = np.random.default_rng(3)
    truth = rng.random((64, 64, 3))
    s = 0.02
    images = [truth + s * rng.standard_normal(truth.shape) for _ in range(10)]
    assert abs(render_cost.noise_rmse(*images) / s - 1.0) < 0.01
