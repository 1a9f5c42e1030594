"""Property-based stability tests (hypothesis) of the exporters' public numeric functions: colour conversion,
the Cycles mappings and their inverses, the reflectance tables, the collapse.

Every function is driven with ordinary values and with the edges: 0, 1, denormals, huge values, NaN, Inf and
empty arrays.  Documented behaviour at every edge: finite input inside the domain gives finite output inside
the stated range; NaN/Inf input, or a result that would overflow float64, raises ValueError; empty arrays
give empty arrays of the right shape.  Nothing returns NaN/Inf silently.  Each test is derandomised and
bounded (``deadline=None``: the 2-core CI machine is shared), so the suite is reproducible and fast.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from exporters import collapse, colorimetry, cycles, reflectance_tables

pytestmark = pytest.mark.stability
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
TINY = 5e-324  # smallest denormal
HUGE = 1e300


def floats(lo: float, hi: float) -> st.SearchStrategy:
    """Finite floats in [lo, hi], with the edges (and denormals when lo <= 0) drawn often."""
    edges = [v for v in (lo, hi, 0.0, TINY, 1.0, 1e-308, 0.5) if lo <= v <= hi]
    return st.one_of(st.sampled_from(edges), st.floats(lo, hi, allow_nan=False, allow_infinity=False))


SHAPES = hnp.array_shapes(min_dims=1, max_dims=2, min_side=0, max_side=6)  # empty arrays included


def arrays(elements: st.SearchStrategy, shape=SHAPES):
    return hnp.arrays(np.float64, shape, elements=elements)


BAD = st.sampled_from([np.nan, np.inf, -np.inf])


def with_bad(arr: np.ndarray, bad: float, index: int) -> np.ndarray:
    out = np.array(arr, dtype=np.float64, copy=True)
    out.flat[index % out.size] = bad
    return out


# -- colour ------------------------------------------------------------------------------------------------------


@SETTINGS
@given(arrays(floats(-HUGE, HUGE)))
def test_srgb_curves_are_finite_or_refuse(x):
    enc = colorimetry.srgb_encode(x)
    assert enc.shape == x.shape and np.all(np.isfinite(enc))
    assert np.all(np.sign(enc) == np.sign(x))  # odd-ish: negatives stay on the linear segment
    try:
        dec = colorimetry.srgb_decode(x)
    except ValueError as exc:  # ((|v| + 0.055) / 1.055)^2.4 overflows above ~1e128
        assert "overflow" in str(exc) and np.max(np.abs(x)) > 1e100
    else:
        assert dec.shape == x.shape and np.all(np.isfinite(dec))


@SETTINGS
@given(arrays(floats(0.0, 1.0)))
def test_srgb_round_trip_and_monotone(x):
    np.testing.assert_allclose(colorimetry.srgb_decode(colorimetry.srgb_encode(x)), x, rtol=1e-12, atol=1e-15)
    s = np.sort(x.ravel())
    assert np.all(np.diff(colorimetry.srgb_encode(s)) >= 0)


@SETTINGS
@given(arrays(floats(-2.0, 2.0)), BAD, st.integers(0, 100))
def test_colour_functions_refuse_nan_and_inf(x, bad, i):
    if x.size == 0:
        return
    x = with_bad(x, bad, i)
    for fn in (colorimetry.srgb_encode, colorimetry.srgb_decode):
        with pytest.raises(ValueError, match="NaN or Inf"):
            fn(x)


spectra = hnp.arrays(np.float64, st.tuples(st.integers(0, 4), st.just(376)), elements=floats(0.0, 1.0))


@SETTINGS
@given(spectra, st.sampled_from(["D65", "A", "E"]))
def test_spectrum_to_colour(refl, illuminant):
    xyz = colorimetry.spectrum_to_xyz(refl, illuminant)
    lab = colorimetry.spectrum_to_lab(refl, illuminant)
    rgb = colorimetry.spectrum_to_linear_srgb(refl, illuminant)
    assert xyz.shape == lab.shape == rgb.shape == (len(refl), 3)
    assert np.all(np.isfinite(lab)) and np.all(np.isfinite(rgb))
    assert np.all(xyz[:, 1] >= 0) and np.all(xyz[:, 1] <= 1 + 1e-12)  # Y of a reflectance in [0, 1]
    assert np.all(lab[:, 0] >= -1e-9) and np.all(lab[:, 0] <= 100 + 1e-9)
    np.testing.assert_allclose(colorimetry.spectrum_to_xyz(np.ones(376), illuminant)[1], 1.0, rtol=1e-12)


@SETTINGS
@given(st.floats(1e300, 1.7e308))
def test_spectrum_overflow_is_refused(big):
    refl = np.full(376, big)
    try:
        xyz = colorimetry.spectrum_to_xyz(refl)
    except ValueError as exc:
        assert "overflow" in str(exc)
    else:
        assert np.all(np.isfinite(xyz))


@SETTINGS
@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 5), st.just(3)), elements=floats(-HUGE, HUGE)),
       hnp.arrays(np.float64, st.tuples(st.integers(0, 5), st.just(3)), elements=floats(-HUGE, HUGE)))
def test_delta_e_is_finite_or_refuses(a, b):
    n = min(len(a), len(b))
    a, b = a[:n], b[:n]
    try:
        de = colorimetry.delta_e76(a, b)
    except ValueError as exc:
        assert "overflow" in str(exc)
    else:
        assert de.shape == (n,) and np.all(np.isfinite(de)) and np.all(de >= 0)
        np.testing.assert_allclose(de, colorimetry.delta_e76(b, a))


@SETTINGS
@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 5), st.just(3)), elements=floats(0.0, 1.0)))
def test_linear_srgb_lab_round_trip(rgb):
    lab = colorimetry.linear_srgb_to_lab(rgb)
    assert lab.shape == rgb.shape and np.all(np.isfinite(lab))
    xyz = colorimetry.linear_srgb_to_xyz(rgb)
    np.testing.assert_allclose(colorimetry.xyz_to_linear_srgb(xyz), rgb, atol=1e-12)


# -- Cycles mappings ---------------------------------------------------------------------------------------------

g_values = floats(0.0, 0.9)


@SETTINGS
@given(arrays(floats(0.0, 1.0)), g_values)
def test_albedo_forward_in_range_and_monotone(color, g):
    alpha = cycles.rw_albedo_forward(color, g)
    assert alpha.shape == color.shape and np.all((alpha >= 0) & (alpha <= cycles.ALPHA_MAX))
    s = np.sort(color.ravel())
    assert np.all(np.diff(cycles.rw_albedo_forward(s, g)) >= -1e-15)


@SETTINGS
@given(arrays(floats(0.0, 1.0)), g_values)
def test_albedo_inverse_round_trip(alpha, g):
    inv = cycles.rw_albedo_inverse(alpha, g)
    assert inv.color.shape == alpha.shape and np.all(np.isfinite(inv.color))
    assert np.all((inv.color >= 0) & (inv.color <= cycles.saturation_color(g) + 1e-15))
    back = cycles.rw_albedo_forward(inv.color, g)
    np.testing.assert_allclose(back, np.minimum(alpha, cycles.ALPHA_MAX), atol=1e-9)
    np.testing.assert_array_equal(inv.saturated, alpha > cycles.ALPHA_MAX)
    np.testing.assert_array_equal(inv.approximate, alpha < cycles.ALPHA_EXACT_MIN)


@SETTINGS
@given(arrays(floats(-HUGE, HUGE)), floats(-HUGE, HUGE))
def test_albedo_maps_refuse_out_of_domain(x, g):
    inside = bool(np.all((x >= 0) & (x <= 1))) and 0 <= g <= 0.9  # an empty x still needs a valid g
    for fn in (cycles.rw_albedo_forward, lambda a, b: cycles.rw_albedo_inverse(a, b).color):
        if inside:
            assert np.all(np.isfinite(fn(x, g)))
        else:
            with pytest.raises(ValueError):
                fn(x, g)


@SETTINGS
@given(arrays(floats(0.0, 1.0)), BAD, st.integers(0, 50))
def test_cycles_maps_refuse_nan_and_inf(x, bad, i):
    if x.size == 0:
        return
    x = with_bad(x, bad, i)
    for fn in (lambda v: cycles.rw_albedo_forward(v, 0.5), lambda v: cycles.rw_albedo_inverse(v, 0.5),
               lambda v: cycles.rw_albedo_forward(0.5, v), lambda v: cycles.rw_radius_from_sigma_t(v, 0.5),
               lambda v: cycles.rw_sigma_t_from_radius(v, 0.5), lambda v: cycles.similar_medium(v, 10.0, 0.5),
               lambda v: cycles.medium_to_cycles(0.5, v, 0.5)):
        with pytest.raises(ValueError):
            fn(x)


@SETTINGS
@given(arrays(floats(TINY, HUGE)), g_values, floats(1e-6, 1e6))
def test_radius_and_extinction_invert_or_refuse(sigma_t, g, scale):
    try:
        r = cycles.rw_radius_from_sigma_t(sigma_t, g, scale)
    except ValueError as exc:  # below Cycles' minimum radius, or overflowing float64
        assert "minimum" in str(exc) or "overflow" in str(exc)
        return
    assert r.shape == sigma_t.shape and np.all(np.isfinite(r)) and np.all(r >= cycles.MIN_RADIUS)
    back = cycles.rw_sigma_t_from_radius(r, g, scale)
    np.testing.assert_allclose(back, sigma_t, rtol=1e-9)


@SETTINGS
@given(arrays(floats(0.0, 1.0)), floats(TINY, 1e6), floats(-0.99, 0.99), floats(0.0, 0.9))
def test_similarity_keeps_absorption_and_reduced_scattering(alpha, sigma_t, g, g_new):
    try:
        sim = cycles.similar_medium(alpha, sigma_t, g, g_new)
    except ValueError as exc:
        assert "overflows" in str(exc)
        return
    assert np.all(np.isfinite(sim.alpha)) and np.all(np.isfinite(sim.sigma_t_cm))
    assert np.all((sim.alpha >= 0) & (sim.alpha <= 1))
    np.testing.assert_allclose((1 - sim.alpha) * sim.sigma_t_cm, (1 - alpha) * sigma_t, rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(sim.alpha * sim.sigma_t_cm * (1 - g_new), alpha * sigma_t * (1 - g), rtol=1e-9,
                               atol=1e-300)


# -- reflectance tables ---------------------------------------------------------------------------------------------


@SETTINGS
@given(arrays(floats(-HUGE, HUGE)), floats(-HUGE, HUGE), st.sampled_from(["cycles", "model"]))
def test_reflectance_clips_to_the_table(alpha, g, boundary):
    r = reflectance_tables.reflectance(boundary, alpha, g)
    assert r.shape == alpha.shape and np.all(np.isfinite(r)) and np.all((r >= 0) & (r <= 1))


@SETTINGS
@given(arrays(floats(0.2, 0.999)), floats(0.0, 0.9))
def test_reflectance_inverse_round_trip(alpha, g):
    r = reflectance_tables.reflectance("cycles", alpha, g)
    back = reflectance_tables.albedo_for_reflectance("cycles", r, g)
    assert back.shape == alpha.shape
    np.testing.assert_allclose(reflectance_tables.reflectance("cycles", back, g), r, atol=1e-12)


@SETTINGS
@given(arrays(floats(-HUGE, HUGE)), floats(0.0, 0.95))
def test_reflectance_inverse_holds_the_ends(target, g):
    alpha = reflectance_tables.albedo_for_reflectance("cycles", target, g)
    assert alpha.shape == target.shape and np.all(np.isfinite(alpha))
    assert np.all((alpha >= 0) & (alpha <= reflectance_tables.ALPHA_TABLE_MAX + 1e-12))


# -- the collapse ---------------------------------------------------------------------------------------------------

K = 2


@st.composite
def mixtures(draw):
    n = draw(st.integers(0, 3))
    shape = (n, K, 376)
    base = draw(st.sampled_from(["random", "edges"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if base == "edges":
        alpha = rng.choice([0.0, TINY, 1e-6, 0.5, 1.0 - 1e-6, 1.0], shape)
        sigma = rng.choice([1e-30, 1e-3, 1.0, 1e4, 1e30], shape)
        g = rng.choice([-0.99, 0.0, 0.5, 0.95, 0.99], shape)
        w = rng.choice([0.0, TINY, 0.5, 1.0], shape)
        refl = rng.choice([0.0, TINY, 0.5, 1.0], (n, 376))
    else:
        alpha, sigma = rng.random(shape), np.exp(rng.uniform(-5, 10, shape))
        g, w, refl = rng.uniform(-0.9, 0.95, shape), rng.random(shape), rng.random((n, 376))
    return refl, alpha, sigma, g, w


@SETTINGS
@given(mixtures())
def test_collapse_is_finite_and_in_range(mix):
    media = collapse.collapse(*mix)
    n = len(mix[0])
    assert media.alpha.shape == media.weight.shape == media.sigma_t_cm.shape == (n, K, 3) and media.g.shape == (n, K)
    for name in ("alpha", "sigma_t_cm", "g", "weight", "target"):
        assert np.all(np.isfinite(getattr(media, name))), name
    assert np.all((media.alpha >= collapse.ALPHA_MIN) & (media.alpha <= collapse.ALPHA_HARD_MAX))
    assert np.all((media.g >= 0) & (media.g <= collapse.G_MAX)) and np.all(media.weight >= 0)
    assert np.all(media.sigma_t_cm > 0) and np.all(media.sigma_t_cm <= 1 / collapse.MIN_MFP_CM * (1 + 1e-12))
    reached = media.cycles_reflectance()
    ok = ~media.unreachable
    np.testing.assert_allclose(reached[ok], media.target[ok], rtol=2e-3, atol=1e-12)  # what Cycles shows
    cyc = collapse.to_cycles(media, 1.0)
    assert np.all(np.isfinite(cyc.color)) and np.all(np.isfinite(cyc.radius)) and np.all(cyc.radius > 0)


@SETTINGS
@given(mixtures(), BAD, st.integers(0, 4), st.integers(0, 10**6))
def test_collapse_refuses_nan_and_inf(mix, bad, which, i):
    if len(mix[0]) == 0:
        return
    mix = list(mix)
    mix[which] = with_bad(mix[which], bad, i)
    with pytest.raises(ValueError, match="NaN or infinite"):
        collapse.collapse(*mix)


@SETTINGS
@given(mixtures(), st.integers(0, 2**32 - 1))
def test_collapse_to_the_painted_colour_is_finite_and_reaches_it(mix, seed):
    n = len(mix[0])
    rgb = np.random.default_rng(seed).choice([0.0, TINY, 1e-4, 0.3, 1.0, 1.5, HUGE], (n, 3))
    media = collapse.collapse(*mix, painted_rgb=rgb)
    np.testing.assert_array_equal(media.target, np.clip(rgb, 0.0, 1.0))
    for name in ("alpha", "sigma_t_cm", "g", "weight"):
        assert np.all(np.isfinite(getattr(media, name))), name
    assert np.all((media.alpha >= collapse.ALPHA_MIN) & (media.alpha <= collapse.ALPHA_HARD_MAX))
    assert media.spectral_clamped.shape == (n,) and media.spectral_clamped.dtype == bool
    ok = ~media.unreachable
    np.testing.assert_allclose(media.cycles_reflectance()[ok], media.target[ok], rtol=2e-3, atol=1e-12)
    if n:
        with pytest.raises(ValueError, match="finite"):
            collapse.collapse(*mix, painted_rgb=with_bad(rgb, np.nan, seed))


@SETTINGS
@given(floats(0.0, 0.99), floats(1.0, 3.8))
def test_face_on_albedo_is_an_albedo(g, ior):
    value = collapse.face_on_albedo(g, ior)
    assert np.isfinite(value) and collapse.ALPHA_MIN <= value < 1.0


@SETTINGS
@given(floats(-HUGE, HUGE))
def test_alpha_soft_max(g):
    value = collapse.alpha_soft_max(np.clip(g, 0.0, 0.99))
    assert np.isfinite(value) and 0 < value <= 1
