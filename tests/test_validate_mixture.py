"""Our mixture renderer (training.validate.mixture) against adding-doubling, and the validate command."""

from __future__ import annotations

import iadpython as iad
import numpy as np
import pytest

from training.commands import validate as validate_cli
from training.validate.mixture import (
    check_mixture,
    mixture_reflectance,
    neyman_allocation,
    photons_for_precision,
    reflectance_srgb,
)

SPECULAR_NORMAL = ((1.4 - 1.0) / (1.4 + 1.0)) ** 2  # Fresnel at normal incidence, n = 1.4


def _iad(alpha: float, g: float) -> tuple[float, float]:
    """(R_d normal incidence, R_d diffuse incidence) of a thick slab, n = 1.4, specular removed."""
    s = lambda a: iad.Sample(a=a, b=1000, g=g, n=1.4, n_above=1.0, n_below=1.0, quad_pts=32).rt()  # noqa: E731
    ur1, _, uru, _ = s(alpha)
    return ur1 - SPECULAR_NORMAL, uru - s(0.0)[2]


def test_two_component_mixture_matches_adding_doubling():
    # K = 2 at two wavelengths: (alpha, g) per component and wavelength, weights per wavelength
    alpha = np.array([[0.95, 0.7], [0.6, 0.9]])
    g = np.array([[0.8, 0.5], [0.0, 0.7]])
    weight = np.array([[0.3, 0.6], [0.7, 0.4]])
    sigma_t = np.array([[100.0, 20.0], [1000.0, 50.0]])
    ref_normal = np.zeros(2)
    ref_diffuse = np.zeros(2)
    for k in range(2):
        for j in range(2):
            rn, rd = _iad(alpha[k, j], g[k, j])
            ref_normal[j] += weight[k, j] * rn
            ref_diffuse[j] += weight[k, j] * rd
    for illumination, ref in (("diffuse", ref_diffuse), ("normal", ref_normal)):
        res = mixture_reflectance(alpha, sigma_t, g, weight, photons=40000, seed=2, illumination=illumination)
        assert res.R_k.shape == (2, 2)
        np.testing.assert_allclose(res.R_d, np.sum(weight * res.R_k, axis=0))
        assert np.all(np.abs(res.R_d - ref) < 4 * res.R_d_stderr + 5e-4), (illumination, res.R_d, ref)


def test_neyman_allocation_by_hand():
    # w = (0.5, 0.5), per-sample spreads (1, 3), target 0.1: n_k = w_k s_k (0.5 + 1.5) / 0.01 = (100, 300), whose
    # variance 0.25 / 100 + 0.25 * 9 / 300 = 0.01 is the target's square; a zero weight gets no samples
    weight = np.array([[0.5, 0.2], [0.5, 0.8], [0.0, 0.0]])
    n = neyman_allocation(weight, np.array([[1.0, 2.0], [3.0, 0.5], [9.0, 9.0]]), np.array([0.1, 0.1]))
    np.testing.assert_array_equal(n[:, 0], [100, 300, 0])
    # (0.4 + 0.4) * 0.4 / 0.01 = 32 for both; rounded up to a multiple of 16, at least 40
    np.testing.assert_array_equal(neyman_allocation(np.array([[0.2], [0.8]]), np.array([[2.0], [0.5]]),
                                                    np.array([0.1]), multiple=16, floor=40), [[48], [48]])
    with pytest.raises(ValueError, match="positive target"):
        neyman_allocation(np.ones((2, 3)) / 2, np.ones((2, 3)), np.zeros(3))


def test_photons_per_component_reach_the_asked_precision():
    # a bright and a dark component at two wavelengths; the dark one hardly matters where its weight is small
    alpha = np.array([[0.99, 0.9], [0.3, 0.3]])
    weight = np.array([[0.9, 0.5], [0.1, 0.5]])
    sigma_t, g = np.full((2, 2), 50.0), np.full((2, 2), 0.7)
    photons = photons_for_precision(alpha, sigma_t, g, weight, 0.01, pilot_photons=4000, seed=3)
    assert photons.shape == (2, 2) and photons[1, 0] < photons[0, 0]
    res = mixture_reflectance(alpha, sigma_t, g, weight, photons=photons, seed=4)
    np.testing.assert_array_equal(res.photons, photons)
    np.testing.assert_allclose(res.R_d_stderr / res.R_d, 0.01, rtol=0.15)
    # one count for all components is the one batched walk of a single number
    same = mixture_reflectance(alpha, sigma_t, g, weight, photons=np.full((2, 2), 3000), seed=4)
    np.testing.assert_array_equal(same.R_k, mixture_reflectance(alpha, sigma_t, g, weight, photons=3000,
                                                                seed=4).R_k)
    with pytest.raises(ValueError, match="photons must be > 0"):
        mixture_reflectance(alpha, sigma_t, g, weight, photons=np.array([[100, 100], [0, 100]]))


def test_bad_mixtures_are_refused():
    a = np.full((2, 3), 0.5)
    with pytest.raises(ValueError, match="sum to 1"):
        check_mixture(a, a * 10, a * 0, np.full((2, 3), 0.4))
    with pytest.raises(ValueError, match="shape"):
        check_mixture(a, np.ones((3, 3)), a * 0, a)
    with pytest.raises(ValueError, match="g must"):
        check_mixture(a, a * 10, a * 0 + 0.995, a)
    with pytest.raises(ValueError, match="NaN"):
        check_mixture(a * np.nan, a, a, a)


def test_srgb_of_a_flat_spectrum():
    # a flat 50 % reflector is neutral grey: linear 0.5 in every channel -> sRGB 0.7354 (IEC 61966-2-1)
    rgb = reflectance_srgb(np.full(376, 0.5))
    np.testing.assert_allclose(rgb, 1.055 * 0.5 ** (1 / 2.4) - 0.055, atol=2e-3)
    with pytest.raises(ValueError, match="376"):
        reflectance_srgb(np.full(10, 0.5))


def test_validate_needs_an_output_folder(capsys):
    assert validate_cli.main([]) == 2
    assert "--out" in capsys.readouterr().err
    assert validate_cli.main(["--mitsuba"]) == 2
    assert "--out" in capsys.readouterr().err
