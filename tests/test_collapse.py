"""exporters.reflectance_tables and exporters.collapse against independent references.

References: van de Hulst's spherical albedo of the isotropic index-matched half-space (H-function values of
docs/research/monte_carlo.md §1b), iadpython adding-doubling evaluated here at points that are not table nodes
(for Cycles' refracting entry: iadpython's directional reflectance at its own 16 cosines, a cubic spline and
scipy's adaptive quadrature), and exporters.colorimetry for the target colour.  The render check of the
collapse (Cycles reproduces the target) is tests/test_bake_fidelity.py.
"""

from __future__ import annotations

import iadpython
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from exporters import collapse, cycles
from exporters import reflectance_tables as rt
from exporters.colorimetry import spectrum_to_linear_srgb

L = 376


def iad_uru(alpha: float, g: float, n: float) -> float:
    """Diffuse-incidence reflectance of the half-space, specular part removed (adding-doubling)."""
    value = float(iadpython.Sample(a=alpha, b=np.inf, g=g, n=n, quad_pts=16).rt()[2])
    if n != 1.0:
        value -= float(iadpython.Sample(a=0.0, b=np.inf, g=g, n=n, quad_pts=16).rt()[2])
    return value


def cycles_hemispherical(alpha: float, g: float, eta: float) -> float:
    """eta^2 int_{mu0}^1 2 mu R1(mu) dmu with R1 from iadpython (16 cosines), a cubic spline and quad."""
    s = iadpython.Sample(a=alpha, b=np.inf, g=g, n=1.0, quad_pts=16)
    s.update_quadrature()
    r1 = (s.rt_matrices()[0] * s.twonuw[None, :]).sum(axis=1)
    spline = CubicSpline(s.nu, r1)
    mu0 = np.sqrt(1.0 - 1.0 / eta**2)
    return eta**2 * quad(lambda m: 2.0 * m * spline(m), mu0, 1.0, epsabs=1e-10)[0]


def test_cycles_table_matches_van_de_hulst_isotropic():
    alpha = np.array([0.5, 0.9, 0.99, 0.999])
    spherical = np.array([0.14654, 0.47802, 0.79456, 0.92971])  # 1 - H-function moment sqrt(1 - a)
    np.testing.assert_allclose(rt.reflectance("cycles", alpha, 0.0, ior=1.0), spherical, atol=4e-4)
    # Refraction into the medium (ior > 1) never adds light: the grazing entries are lost, eta^2 < 1/(1-mu0^2)
    assert np.all(rt.reflectance("cycles", alpha, 0.0, ior=1.4) < spherical)


@pytest.mark.parametrize("boundary, n", [("cycles", 1.0), ("model", 1.4)])
def test_tables_between_nodes_match_adding_doubling(boundary, n):
    rng = np.random.default_rng(7)
    u = rng.uniform(0.002, 0.95, 6)  # sqrt(1 - alpha), off the 129 nodes
    g = np.array([0.12, 0.33, 0.47, 0.68, 0.72, 0.87])  # off the 0.05 grid
    alpha = 1.0 - u**2
    ours = rt.reflectance(boundary, alpha, g, ior=1.0) if boundary == "cycles" else rt.reflectance(boundary, alpha, g)
    ref = np.array([iad_uru(a, gi, n) for a, gi in zip(alpha, g, strict=True)])
    np.testing.assert_allclose(ours, ref, atol=1.5e-3, rtol=5e-3)


@pytest.mark.parametrize("eta", [1.01, 1.4, 2.0])
def test_cycles_refracting_entry_matches_spline_quadrature(eta):
    alpha = np.array([0.3, 0.8, 0.97, 0.999])
    g = np.array([0.0, 0.35, 0.7, 0.55])
    ours = rt.reflectance("cycles", alpha, g, ior=eta)
    ref = np.array([cycles_hemispherical(a, gi, eta) for a, gi in zip(alpha, g, strict=True)])
    np.testing.assert_allclose(ours, ref, rtol=4e-3, atol=3e-4)
    with pytest.raises(ValueError, match="IOR"):
        rt.reflectance("cycles", 0.5, 0.0, ior=4.0)


def test_table_inverse_round_trip_and_monotone():
    g = np.linspace(0.0, 0.9, 7)[:, None]
    alpha = np.linspace(0.0, 0.9999, 300)[None, :]
    r = rt.reflectance("cycles", alpha, g)
    assert np.all(np.diff(r, axis=1) > 0)
    back = rt.albedo_for_reflectance("cycles", r, g)
    np.testing.assert_allclose(rt.reflectance("cycles", back, g), r, atol=1e-12)
    with pytest.raises(ValueError, match="boundary"):
        rt.reflectance("mitsuba", 0.5, 0.0)
    with pytest.raises(ValueError, match="finite"):
        rt.reflectance("cycles", np.nan, 0.0)


def flat(n: int, k: int, alpha, sigma_t, g, weight):
    """Spectrally flat components: arrays (n, k, 376) from per-component values (k,)."""
    def rep(v):
        return np.broadcast_to(np.asarray(v, float)[None, :, None], (n, k, L)).copy()
    return rep(alpha), rep(sigma_t), rep(g), rep(weight)


def test_single_flat_component_reference():
    # One medium at the model boundary (n = 1.4): its reflectance R_F; Cycles (entry IOR 1.4, the isotropic
    # medium of collapse.G_MAX = 0) needs the albedo alpha' with H(alpha', 0; 1.4) = R_F (a flat spectrum).
    a, st, g = 0.995, 120.0, 0.8
    r_f = iad_uru(a, g, 1.4)
    al, s, gg, w = flat(1, 1, [a], [st], [g], [1.0])
    refl = np.full((1, L), r_f)
    media = collapse.collapse(refl, al, s, gg, w)
    t = spectrum_to_linear_srgb(refl)[0]
    np.testing.assert_allclose(media.target[0], t, rtol=1e-12)
    np.testing.assert_allclose(t, r_f, rtol=2e-3)  # D65 white is (1, 1, 1) in linear sRGB
    assert media.g[0, 0] == 0.0
    for c in range(3):
        alpha_ref = brentq(lambda x, c=c: cycles_hemispherical(x, 0.0, 1.4) - t[c], 0.5, 0.999999, xtol=1e-10)
        assert media.alpha[0, 0, c] == pytest.approx(alpha_ref, abs=2e-4)
    np.testing.assert_allclose(media.weight[0, 0], 1.0, rtol=1e-6)  # float32 spectral sums
    # diffusion length kept: 1 / (sigma_t sqrt(3 (1 - a)(1 - a g)))
    d_in = 1.0 / (st * np.sqrt(3 * (1 - a) * (1 - a * g)))
    ae, ge = media.alpha[0, 0], media.g[0, 0]
    d_out = 1.0 / (media.sigma_t_cm[0, 0] * np.sqrt(3 * (1 - ae) * (1 - ae * ge)))
    np.testing.assert_allclose(d_out, d_in, rtol=3e-6)  # float32 spectral work


def test_mixture_reaches_target_per_adding_doubling_and_keeps_shares():
    # Two flat components with different albedo: each keeps its share w_k R_F,k of the light.
    al, s, gg, w = flat(1, 2, [0.999, 0.9], [300.0, 40.0], [0.85, 0.6], [0.4, 0.6])
    r_k = np.array([iad_uru(0.999, 0.85, 1.4), iad_uru(0.9, 0.6, 1.4)])
    refl = np.full((1, L), 0.9 * (0.4 * r_k[0] + 0.6 * r_k[1]))  # the model's R need not equal sum w R_F
    # anisotropic components (capped where Cycles walks them accurately), not the isotropic default
    media = collapse.collapse(refl, al, s, gg, w, g_max=cycles.RECOMMENDED_G_MAX)
    reached = np.array([[sum(media.weight[0, k, c] * cycles_hemispherical(media.alpha[0, k, c], media.g[0, k], 1.4)
                             for k in range(2)) for c in range(3)]])
    np.testing.assert_allclose(reached, media.target, rtol=3e-3)
    contrib = media.weight[0] * rt.reflectance("cycles", media.alpha[0], media.g[0][:, None])
    share_ref = 0.4 * r_k[0] / (0.4 * r_k[0] + 0.6 * r_k[1])
    np.testing.assert_allclose(contrib[0] / contrib.sum(axis=0), share_ref, rtol=5e-3)
    np.testing.assert_allclose(media.g[0], [0.7, 0.6], atol=1e-12)


def test_dark_and_bright_shares_move_into_the_weights():
    al, s, gg, w = flat(2, 3, [0.3, 0.99, 0.999], [50.0, 100.0, 1000.0], [0.7, 0.8, 0.9], [0.5, 0.3, 0.2])
    refl = np.stack([np.full(L, 0.004), np.full(L, 0.3)])
    dark = collapse.collapse(refl[:1], al[:1], s[:1], gg[:1], w[:1])
    assert np.all(dark.alpha >= collapse.ALPHA_MIN) and dark.low.any()
    assert np.all(dark.weight.sum(axis=1) < 1.0)  # the rest is absorbed
    np.testing.assert_allclose(dark.cycles_reflectance(), dark.target, rtol=1e-6)
    bright = collapse.collapse(refl[1:], al[1:], s[1:], gg[1:], w[1:], painted_rgb=np.full((1, 3), 0.9))
    np.testing.assert_allclose(bright.target, 0.9, rtol=1e-12)
    assert np.all(bright.weight <= 1.0) and not bright.unreachable.any()
    np.testing.assert_allclose(bright.cycles_reflectance(), bright.target, rtol=1e-6)
    one = [x[1:, :1] for x in (al, s, gg)]  # a single component cannot show white: R_cycles(1 - 1e-6) < 1
    white = collapse.collapse(refl[1:], *one, np.ones_like(one[0]), painted_rgb=np.ones((1, 3)))
    assert white.unreachable.all() and np.all(white.weight <= 1.0)
    for m in (dark, bright, white):
        assert np.all(np.isfinite(m.sigma_t_cm)) and np.all(m.sigma_t_cm > 0)
        assert np.all(m.alpha <= collapse.ALPHA_HARD_MAX)


def test_bad_input_raises():
    al, s, gg, w = flat(1, 1, [0.9], [10.0], [0.8], [1.0])
    refl = np.full((1, L), 0.3)
    with pytest.raises(ValueError, match="finite"):
        collapse.collapse(np.full((1, L), np.nan), al, s, gg, w)
    with pytest.raises(ValueError, match="sigma_t > 0"):
        collapse.collapse(refl, al, -s, gg, w)
    with pytest.raises(ValueError, match="reflectance"):
        collapse.collapse(refl[:, :10], al, s, gg, w)


def test_to_cycles_inputs():
    al, s, gg, w = flat(1, 2, [0.95, 0.6], [80.0, 400.0], [0.5, 0.8], [0.5, 0.5])
    media = collapse.collapse(np.full((1, L), 0.2), al, s, gg, w)
    maps = collapse.to_cycles(media, unit_scale_m=0.1)
    g3 = media.g[..., None]
    np.testing.assert_allclose(maps.radius, 4 * np.pi / (media.sigma_t_cm * 100 * 0.1 * (1 - g3)), rtol=1e-12)
    np.testing.assert_allclose(cycles.rw_albedo_forward(maps.color, np.broadcast_to(g3, maps.color.shape)),
                               media.alpha, atol=1e-9)
    assert maps.anisotropy.shape == (1, 2) and maps.weight is media.weight


def test_stored_channel_matrix_is_the_colorimetry_one():
    stored = np.load(collapse.CHANNEL_MATRIX_PATH)
    np.testing.assert_allclose(stored, collapse.compute_channel_matrix(), rtol=0, atol=1e-15)
    refl = np.random.default_rng(2).uniform(0, 1, (4, L))
    np.testing.assert_allclose(refl @ collapse.channel_matrix().T, spectrum_to_linear_srgb(refl), atol=1e-14)
