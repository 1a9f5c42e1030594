"""Property-based stability tests (hypothesis) of the simulator's sampling routines (training/sim/physics.py) and
the lookup-table interpolation (training/sim/lut_interp.py), with extreme and degenerate inputs.

Documented behaviour: the sampling kernels are elementwise torch code inside the walk's hot loop and do not
validate (a NaN in gives NaN out, never a finite value); the media they run on are validated when built
(``LayeredMedium`` refuses NaN/Inf).  The LUT lookups refuse NaN/Inf input, hold the grid's edge values
outside it, and return finite, non-negative profiles.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from exporters.constants import R_EDGES_MFP
from training.sim import physics
from training.sim.lut_interp import LookupTables
from training.sim.medium import LayeredMedium

pytestmark = pytest.mark.stability
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
TINY = 5e-324


def t64(values) -> torch.Tensor:
    return torch.as_tensor(np.asarray(values, dtype=np.float64))


unit = st.one_of(st.sampled_from([0.0, TINY, 1e-300, 0.5, 1.0 - 1e-16, 1.0]), st.floats(0.0, 1.0))
g_values = st.one_of(st.sampled_from([0.0, TINY, -TINY, 1e-7, -1e-7, 0.99, -0.99, 0.5]), st.floats(-0.99, 0.99))
indices = st.sampled_from([1.0, 1.33, 1.4, 1.55, 2.5])


@SETTINGS
@given(g_values, st.lists(unit, min_size=1, max_size=32))
def test_hg_cosine_in_range_and_monotone(g, xi):
    xs = np.sort(np.clip(xi, 0.0, 1.0 - 2**-53))
    c = physics.hg_cos(t64(np.full(len(xs), g)), t64(xs)).numpy()
    assert np.all(np.isfinite(c)) and np.all((c >= -1) & (c <= 1))
    assert np.all(np.diff(c) >= -1e-12)  # inversion sampling: increasing in xi


@SETTINGS
@given(g_values)
def test_hg_cosine_mean_is_g(g):
    xi = (np.arange(20000) + 0.5) / 20000  # stratified: the mean of HG's cosine is g
    c = physics.hg_cos(t64(np.full(xi.size, g)), t64(xi)).numpy()
    assert abs(c.mean() - g) < 2e-3


@SETTINGS
@given(unit, indices, indices)
def test_fresnel_in_range_and_reciprocal(cos_i, n1, n2):
    r = float(physics.fresnel_unpolarised(t64([cos_i]), n1, n2)[0])
    assert 0.0 <= r <= 1.0
    if cos_i == 1.0:
        assert r == pytest.approx(((n1 - n2) / (n1 + n2)) ** 2, abs=1e-12)
    sin_t2 = (n1 / n2) ** 2 * (1 - cos_i**2)
    if sin_t2 < 1.0 and cos_i > 1e-6:  # Stokes: the same interface seen from the other side
        cos_t = float(physics.refract_cos(t64([cos_i]), n1, n2)[0])
        sin_i, sin_t = math.sqrt(max(1 - cos_i**2, 0)), math.sqrt(max(1 - cos_t**2, 0))  # ~1e-8 from cosines near 1
        assert math.isclose(n1 * sin_i, n2 * sin_t, abs_tol=5e-8)
        back = float(physics.fresnel_unpolarised(t64([cos_t]), n2, n1)[0])
        assert back == pytest.approx(r, abs=1e-9)
    elif sin_t2 >= 1.0:
        assert r == 1.0  # total internal reflection


@SETTINGS
@given(st.floats(-1.0, 1.0), st.floats(0.0, 2 * math.pi), st.floats(-1.0, 1.0), unit)
def test_rotation_keeps_unit_length_and_the_angle(uz, azimuth, cos_t, phi_xi):
    s = math.sqrt(max(1.0 - uz * uz, 0.0))
    ux, uy = s * math.cos(azimuth), s * math.sin(azimuth)
    nx, ny, nz = (v.numpy()[0] for v in physics.rotate(t64([ux]), t64([uy]), t64([uz]), t64([cos_t]), t64([phi_xi])))
    assert math.isclose(nx * nx + ny * ny + nz * nz, 1.0, abs_tol=1e-12)
    assert math.isclose(nx * ux + ny * uy + nz * uz, cos_t, abs_tol=1e-12)


def test_kernels_propagate_nan_and_media_refuse_it():
    nan = t64([math.nan])
    assert torch.isnan(physics.hg_cos(nan, t64([0.5]))).all()  # NaN in, NaN out: never a finite value
    assert torch.isnan(physics.fresnel_unpolarised(nan, 1.0, 1.4)).all()
    with pytest.raises(ValueError, match="NaN or Inf"):
        LayeredMedium(mua=[[math.nan]], mus=[[10.0]], g=[[0.8]], thickness=[math.inf])
    with pytest.raises(ValueError, match="NaN or Inf"):
        LayeredMedium(mua=[[1.0]], mus=[[math.inf]], g=[[0.8]], thickness=[math.inf])


# -- lookup-table interpolation -----------------------------------------------------------------------------------


def small_lut(seed: int) -> LookupTables:
    rng = np.random.default_rng(seed)
    albedo, g = np.sort(rng.choice(np.linspace(0.0, 0.999, 40), 5, replace=False)), np.linspace(0.0, 0.95, 4)
    p = rng.random((5, 4, 512)) + 1e-12
    p /= (p * np.pi * np.diff(R_EDGES_MFP**2)).sum(axis=-1, keepdims=True)
    return LookupTables.from_arrays(albedo, g, R_EDGES_MFP, rng.random((5, 4)), p)


wide = st.one_of(st.sampled_from([0.0, TINY, 1.0, -1.0, 1e300, -1e300]), st.floats(-2.0, 2.0))


@SETTINGS
@given(st.integers(0, 1000), st.lists(wide, min_size=0, max_size=8), wide)
def test_lut_reflectance_is_bounded_and_holds_edges(seed, alpha, g):
    lut = small_lut(seed)
    r = lut.reflectance(t64(alpha), t64(g)).numpy() if alpha else lut.reflectance(t64(np.zeros(0)), t64(g)).numpy()
    assert r.shape == (len(alpha),) and np.all(np.isfinite(r))
    assert np.all(r >= lut.R.min().item() - 1e-12) and np.all(r <= lut.R.max().item() + 1e-12)
    clamped = lut.reflectance(t64(np.clip(alpha, lut.albedo[0].item(), lut.albedo[-1].item())),
                              t64(np.clip(g, lut.g[0].item(), lut.g[-1].item()))).numpy()
    np.testing.assert_allclose(r, clamped, atol=1e-12)  # outside the grid: the edge value


@SETTINGS
@given(st.integers(0, 1000), st.lists(st.one_of(st.sampled_from([0.0, TINY, 1e-6, 5.0, 1e300]),
                                                st.floats(0.0, 10.0)), min_size=1, max_size=6),
       st.floats(0.0, 1.0), st.floats(0.0, 0.95), st.one_of(st.sampled_from([TINY, 1e-3, 1.0, 1e4]),
                                                           st.floats(1e-3, 1e4)))
def test_lut_profile_finite_and_non_negative(seed, r_cm, alpha, g, sigma_t):
    p = small_lut(seed).profile(t64([r_cm]), t64([alpha]), t64([g]), t64([sigma_t])).numpy()
    assert p.shape == (1, len(r_cm)) and np.all(np.isfinite(p)) and np.all(p >= 0)


@SETTINGS
@given(st.sampled_from([math.nan, math.inf, -math.inf]), st.integers(0, 3))
def test_lut_lookups_refuse_nan_and_inf(bad, which):
    args = [t64([0.1]), t64([0.5]), t64([0.5]), t64([10.0])]
    args[which] = t64([bad])
    with pytest.raises(ValueError, match="NaN or Inf"):
        small_lut(0).profile(*args)
    if which in (1, 2):
        with pytest.raises(ValueError, match="NaN or Inf"):
            small_lut(0).reflectance(args[1], args[2])


def test_lut_profile_with_huge_extinction():
    """sigma_t beyond float64's square (1e300) is clamped to 1e100: a profile of 0 at 1 mm, not NaN."""
    lut = small_lut(0)
    p = lut.profile(t64([0.1]), t64([0.5]), t64([0.5]), t64([1e300])).numpy()
    assert np.all(np.isfinite(p)) and np.all(p == 0)
    grads = lut.profile_grad(t64([0.1]), t64([0.5]), t64([0.5]), t64([1e300]))
    assert all(np.all(np.isfinite(g.numpy())) for g in grads)
