"""exporters.cycles: Subsurface Color <-> single-scattering albedo, radius <-> extinction (numpy only)."""

from __future__ import annotations

import iadpython
import numpy as np
import pytest

from exporters import cycles


def test_forward_matches_kernel_reference_points():
    # Preimages quoted in docs/research/blender_cycles.md §2d, computed there independently of this module.
    for alpha, g, color in [(0.99, 0.0, 0.784), (0.999, 0.0, 0.895), (0.99, 0.5, 0.706), (0.99, 0.9, 0.488),
                            (0.999, 0.9, 0.671), (0.2, 0.0, 0.046), (0.2, 0.9, 0.0045)]:
        inv = cycles.rw_albedo_inverse(alpha, g)
        assert inv.color == pytest.approx(color, abs=6e-4)


def test_forward_is_increasing_then_saturated():
    colors = np.linspace(0.0, 1.0, 20001)
    for g in np.linspace(0.0, 0.9, 19):
        alpha = cycles.rw_albedo_forward(colors, g)
        sat = cycles.saturation_color(g)
        assert np.all(np.diff(alpha[colors <= sat]) > 0.0)
        assert np.all(alpha[colors > sat] == cycles.ALPHA_MAX)
    assert cycles.saturation_color([0.0, 0.5, 0.9]) == pytest.approx([0.918, 0.857, 0.702], abs=1e-3)


def test_inverse_round_trip_any_shape():
    rng = np.random.default_rng(7)
    alpha = rng.uniform(0.0, cycles.ALPHA_MAX, size=(40, 30, 3))
    g = rng.uniform(0.0, 0.9, size=(40, 30, 1))
    inv = cycles.rw_albedo_inverse(alpha, g)
    assert inv.color.shape == (40, 30, 3) and inv.color.dtype == np.float64
    assert not inv.saturated.any()
    np.testing.assert_allclose(cycles.rw_albedo_forward(inv.color, g), alpha, rtol=0, atol=2e-15)
    assert np.array_equal(inv.approximate, alpha < 0.2)


def test_inverse_ends_of_range_are_flagged_not_nan():
    inv = cycles.rw_albedo_inverse([0.0, 0.9999995, 1.0, 0.1], 0.5)
    sat = cycles.saturation_color(0.5)
    assert inv.color[0] == 0.0
    assert inv.color[1] == pytest.approx(sat) and inv.color[2] == pytest.approx(sat)
    assert inv.saturated.tolist() == [False, True, True, False]
    assert inv.approximate.tolist() == [True, False, False, True]
    assert np.all(np.isfinite(inv.color))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_inputs_raise(bad):
    with pytest.raises(ValueError, match="NaN or infinite"):
        cycles.rw_albedo_inverse([0.5, bad], 0.3)
    with pytest.raises(ValueError, match="NaN or infinite"):
        cycles.rw_albedo_forward(0.5, bad)
    with pytest.raises(ValueError, match="NaN or infinite"):
        cycles.rw_radius_from_sigma_t([10.0, bad], 0.5)
    with pytest.raises(ValueError, match="NaN or infinite"):
        cycles.medium_to_cycles(0.9, 10.0, bad)


def test_out_of_range_inputs_raise():
    with pytest.raises(ValueError, match="anisotropy"):
        cycles.rw_albedo_inverse(0.5, 0.95)
    with pytest.raises(ValueError, match="anisotropy"):
        cycles.rw_albedo_forward(0.5, -0.1)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        cycles.rw_albedo_inverse(1.2, 0.5)
    with pytest.raises(ValueError, match="> 0"):
        cycles.rw_radius_from_sigma_t(0.0, 0.5)
    with pytest.raises(ValueError, match="unit_scale_m"):
        cycles.rw_radius_from_sigma_t(1.0, 0.5, unit_scale_m=0.0)
    with pytest.raises(ValueError, match="minimum"):
        cycles.rw_radius_from_sigma_t(1e12, 0.0)


def test_radius_units_and_round_trip():
    # sigma_t = 1 cm^-1 = 100 m^-1; with 1 BU = 1 m and g = 0: r = 4 pi / 100 BU.
    assert cycles.rw_radius_from_sigma_t(1.0, 0.0) == pytest.approx(4 * np.pi / 100)
    # 1 BU = 1 cm: sigma_t = 1 BU^-1, g = 0.5 halves the reduced extinction -> r = 8 pi.
    assert cycles.rw_radius_from_sigma_t(1.0, 0.5, unit_scale_m=0.01) == pytest.approx(8 * np.pi)
    rng = np.random.default_rng(3)
    st = 10 ** rng.uniform(-1, 4, size=(5, 7))
    g = rng.uniform(0, 0.9, size=(5, 7))
    r = cycles.rw_radius_from_sigma_t(st, g, unit_scale_m=0.001)
    np.testing.assert_allclose(cycles.rw_sigma_t_from_radius(r, g, unit_scale_m=0.001), st, rtol=1e-14)


def test_similarity_keeps_absorption_and_reduced_scattering():
    alpha = np.array([0.9, 0.99, 0.999, 0.5])
    st = np.array([100.0, 250.0, 30.0, 10.0])
    g = np.array([0.95, 0.92, -0.2, 0.5])
    sim = cycles.similar_medium(alpha, st, g)
    assert sim.g.tolist() == [0.9, 0.9, 0.0, 0.5]
    assert sim.changed.tolist() == [True, True, True, False]
    np.testing.assert_allclose((1 - sim.alpha) * sim.sigma_t_cm, (1 - alpha) * st, rtol=1e-12)
    np.testing.assert_allclose(sim.alpha * sim.sigma_t_cm * (1 - sim.g), alpha * st * (1 - g), rtol=1e-12)


def test_similarity_preserves_diffuse_reflectance_independent_reference():
    # iadpython adding-doubling: the similarity move changes URU (diffuse illumination) by < 0.5%
    # for skin-like albedos; this is why g > g_max is moved rather than clamped.
    for alpha, g in [(0.99, 0.92), (0.995, 0.8), (0.999, 0.95)]:
        sim = cycles.similar_medium(alpha, 1.0, g, g_max=cycles.RECOMMENDED_G_MAX)
        exact = iadpython.Sample(a=alpha, b=np.inf, g=g, n=1.0, quad_pts=16).rt()[2]
        moved = iadpython.Sample(a=float(sim.alpha), b=np.inf, g=float(sim.g), n=1.0, quad_pts=16).rt()[2]
        clamped = iadpython.Sample(a=alpha, b=np.inf, g=float(sim.g), n=1.0, quad_pts=16).rt()[2]
        assert abs(moved / exact - 1) < 5e-3
        assert abs(clamped / exact - 1) > 3 * abs(moved / exact - 1)


def test_medium_to_cycles_flags_and_shapes():
    out = cycles.medium_to_cycles(np.array([[0.1, 0.99, 0.9999999]]), np.array([[5.0, 50.0, 500.0]]),
                                  np.array([[0.8, 0.5, 0.95]]), unit_scale_m=0.01)
    assert out.color.shape == out.radius.shape == out.g.shape == (1, 3)
    assert out.approximate.tolist() == [[True, False, False]]
    assert out.saturated.tolist() == [[False, False, True]]
    assert out.g_moved.tolist() == [[True, False, True]]
    assert np.all(out.g <= cycles.RECOMMENDED_G_MAX)
    common = cycles.medium_to_cycles([0.9, 0.95, 0.99], [10.0, 20.0, 40.0], [0.75, 0.78, 0.8], g_common=0.7)
    assert np.all(common.g == 0.7)
