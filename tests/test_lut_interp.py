"""Tests of the differentiable LUT interpolation (training/sim/lut_interp.py).

References are independent of the code under test: tables built from closed forms whose exact
interpolant is known (trilinear functions reproduce exactly), and the diffusion dipole (a test table
only; see training/sim/dipole.py) for physically shaped checks.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from exporters.constants import radial_edges
from training.sim.dipole import dipole_lut
from training.sim.lut_interp import LookupTables, bin_centres

EDGES = radial_edges()
CENTRES = bin_centres(EDGES)
# Non-uniform axes on purpose (albedo denser near 1).
ALB = np.array([0.0, 0.3, 0.6, 0.8, 0.9, 0.95, 0.99, 0.999, 1.0])
GG = np.array([-0.9, -0.2, 0.3, 0.6, 0.8, 0.95])


def _trilinear_coeffs() -> np.ndarray:
    return np.array([3.0, 1.5, -0.7, 0.25, 0.4, -0.3, 0.05, 0.02])


def _trilinear(a, g, x, c=None):
    """An exactly trilinear function of (albedo, g, x = log r) (incl. all cross terms)."""
    c = _trilinear_coeffs() if c is None else c
    lin = c[0] + c[1] * a + c[2] * g + c[3] * x
    return lin + c[4] * a * g + c[5] * a * x + c[6] * g * x + c[7] * a * g * x


@pytest.fixture(scope="module")
def linear_lut() -> LookupTables:
    a, g, x = np.meshgrid(ALB, GG, np.log(CENTRES), indexing="ij")
    P = _trilinear(a, g, x) + 20.0  # keep positive (not required by the interpolator)
    R = 0.2 + 0.5 * ALB[:, None] - 0.1 * GG[None, :] + 0.3 * ALB[:, None] * GG[None, :]
    return LookupTables.from_arrays(ALB, GG, EDGES, R, P)


@pytest.fixture(scope="module")
def dip() -> LookupTables:
    return LookupTables.from_arrays(**dipole_lut())


def test_bilinear_reflectance_exact(linear_lut):
    rng = np.random.default_rng(0)
    a, g = rng.uniform(0, 1, 200), rng.uniform(-0.9, 0.95, 200)
    want = 0.2 + 0.5 * a - 0.1 * g + 0.3 * a * g
    got = linear_lut.reflectance(torch.tensor(a), torch.tensor(g)).numpy()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)


@pytest.mark.parametrize("sigma_t", [1.0, 0.37, 25.0])
def test_trilinear_profile_exact(linear_lut, sigma_t):
    rng = np.random.default_rng(1)
    n = 64
    a, g = rng.uniform(0, 1, n), rng.uniform(-0.9, 0.95, n)
    # radii (cm) such that sigma_t * r lies strictly between the first and last bin centres
    x = rng.uniform(np.log(CENTRES[0]), np.log(CENTRES[-1]), (n, 30))
    r_cm = np.exp(x) / sigma_t
    st = np.full(n, sigma_t)
    got = linear_lut.profile(torch.tensor(r_cm), torch.tensor(a), torch.tensor(g), torch.tensor(st)).numpy()
    want = sigma_t**2 * (_trilinear(a[:, None], g[:, None], x) + 20.0)
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_edges_hold_and_zero_beyond(linear_lut):
    a, g = torch.tensor([0.5]), torch.tensor([0.1])
    r = torch.tensor([[0.0, 1e-7, CENTRES[0] * 0.999, 5.0 * 0.9999, 5.0 * 1.0001, 50.0]])
    got = linear_lut.profile(r, a, g, torch.tensor([1.0]))[0].numpy()
    rows = linear_lut.profile_rows(a, g)[0].numpy()
    np.testing.assert_allclose(got[:3], rows[0], rtol=1e-13)
    np.testing.assert_allclose(got[3], rows[-1], rtol=1e-13)
    assert got[4] == 0.0 and got[5] == 0.0
    # albedo / g outside the grid hold the edge values
    f64 = torch.float64
    out = linear_lut.reflectance(
        torch.tensor([-0.5, 1.5, 0.5, 0.5], dtype=f64), torch.tensor([0.0, 0.0, -0.99, 0.99], dtype=f64)
    )
    inside = linear_lut.reflectance(
        torch.tensor([0.0, 1.0, 0.5, 0.5], dtype=f64), torch.tensor([0.0, 0.0, -0.9, 0.95], dtype=f64)
    )
    np.testing.assert_allclose(out.numpy(), inside.numpy(), rtol=1e-14)


def test_table_reproduced_on_its_own_bins(dip):
    """At sigma_t = 1 the binned form on the table's own bins returns the table (centre convention)."""
    ia, ig = 17, 5
    got = dip.profile_binned(torch.tensor(EDGES), dip.albedo[ia], dip.g[ig], torch.tensor(1.0)).numpy()
    np.testing.assert_allclose(got, dip.P[ia, ig].numpy(), rtol=1e-12)


def test_gradcheck_float64(dip):
    rng = np.random.default_rng(2)
    # interior points, away from knots
    alpha = torch.tensor(rng.uniform(0.31, 0.98, 4), requires_grad=True)
    g = torch.tensor(rng.uniform(-0.5, 0.9, 4), requires_grad=True)
    sig = torch.tensor(rng.uniform(0.5, 200.0, 4), requires_grad=True)
    r = torch.tensor(np.geomspace(3e-4, 2.0, 23))
    assert torch.autograd.gradcheck(lambda a, gg, s: dip.profile(r, a, gg, s), (alpha, g, sig))
    assert torch.autograd.gradcheck(lambda a, gg: dip.reflectance(a, gg), (alpha, g))


@pytest.mark.parametrize("sigma_t", [0.3, 1.0, 7.0, 120.0])
def test_scaling_identity_area_integral(dip, sigma_t):
    """Integral over area of sigma_t^2 P(sigma_t r) is 1 when the scaled support fits inside 5 cm."""
    # a fine cm grid from 0 to 5/sigma_t (the scaled support), integrated by the area midpoint rule
    edges = np.concatenate([[0.0], np.geomspace(1e-6 / sigma_t, 5.0 / sigma_t, 4000)])
    area = np.pi * np.diff(edges**2)
    alpha = torch.tensor([0.2, 0.9, 0.995, 0.9999])
    g = torch.tensor([0.0, 0.5, 0.8, 0.9])
    p = dip.profile_binned(torch.tensor(edges), alpha, g, torch.full((4,), sigma_t), n_sub=4).numpy()
    total = (p * area).sum(-1)
    np.testing.assert_allclose(total, 1.0, atol=2e-3)


def test_centre_vs_integrated_binning_error(dip):
    """The documented error of evaluating at bin centres instead of integrating (module docstring)."""
    alpha, g = torch.tensor([0.5, 0.99, 0.9995]), torch.tensor([0.0, 0.8, 0.9])
    sig = torch.tensor([3.3, 40.0, 700.0])
    e = torch.tensor(EDGES)
    c = dip.profile_binned(e, alpha, g, sig).numpy()
    q = dip.profile_binned(e, alpha, g, sig, n_sub=32).numpy()
    # bins well inside the support on both sides: first bin excluded (it spans [0, r1]) and the bins
    # whose scaled radius approaches the end of the table
    keep = (CENTRES[None, :] * sig.numpy()[:, None] < 4.5) & (np.arange(512) > 0)
    rel = np.abs(c - q)[keep] / q[keep]
    assert np.median(rel) < 1e-5
    assert rel.max() < 1e-3


def test_extreme_inputs_finite(dip):
    sig = torch.tensor(np.geomspace(1e-2, 1e5, 9))
    alpha = torch.linspace(0.0, 1.0, 9)
    g = torch.linspace(-0.99, 0.99, 9)
    for a in (alpha, torch.zeros(9), torch.ones(9)):
        sig_g = sig.clone().requires_grad_(True)
        a_g = a.clone().requires_grad_(True)
        p = dip.profile_binned(torch.tensor(EDGES), a_g, g, sig_g)
        R = dip.reflectance(a_g, g)
        assert torch.isfinite(p).all() and torch.isfinite(R).all()
        (torch.log(p + 1e-30).sum() + R.sum()).backward()
        assert torch.isfinite(sig_g.grad).all() and torch.isfinite(a_g.grad).all()


def test_batched_leading_dims_and_dtype(dip):
    lut32 = dip.to("cpu", torch.float32)
    alpha = torch.full((2, 3, 4), 0.9)
    g = torch.full((1, 4), 0.5)
    sig = torch.full((3, 1), 10.0)
    out = lut32.profile_binned(torch.tensor(EDGES), alpha, g, sig)
    assert out.shape == (2, 3, 4, 512) and out.dtype == torch.float32
    ref = dip.profile_binned(torch.tensor(EDGES), torch.tensor(0.9), torch.tensor(0.5), torch.tensor(10.0))
    np.testing.assert_allclose(out[1, 2, 3].numpy(), ref.numpy(), rtol=1e-5, atol=1e-30)


def test_load_roundtrip_and_bad_input(tmp_path, dip):
    d = dipole_lut()
    f = tmp_path / "lut.npz"
    np.savez(f, **d)
    lut = LookupTables.load(f)
    np.testing.assert_array_equal(lut.P.numpy(), d["P"])
    bad = tmp_path / "bad.npz"
    np.savez(bad, albedo=d["albedo"], g=d["g"])
    with pytest.raises(ValueError, match="missing keys"):
        LookupTables.load(bad)
    with pytest.raises(ValueError, match="NaN"):
        lut.reflectance(torch.tensor([float("nan")]), torch.tensor([0.0]))
    with pytest.raises(ValueError, match="increasing"):
        LookupTables.from_arrays(d["albedo"][::-1], d["g"], d["r_edges_mfp"], d["R"], d["P"])


def test_explicit_derivatives_match_autograd(dip):
    """profile_grad / reflectance_grad (used by the Gauss-Newton fitter) against torch autograd."""
    rng = np.random.default_rng(3)
    n = 6
    alpha = torch.tensor(rng.uniform(0.31, 0.9995, n), requires_grad=True)
    g = torch.tensor(rng.uniform(-0.5, 0.9, n), requires_grad=True)
    log_s = torch.tensor(np.log(rng.uniform(0.5, 300.0, n)), requires_grad=True)
    r = torch.tensor(np.geomspace(1e-4, 4.0, 40))
    val, d_a, d_g, d_s = dip.profile_grad(r, alpha.detach(), g.detach(), log_s.detach().exp())
    prof = dip.profile(r, alpha, g, log_s.exp())
    np.testing.assert_allclose(val.numpy(), prof.detach().numpy(), rtol=1e-12)
    for j in range(0, 40, 7):  # rows of the Jacobian by reverse mode, one radius at a time
        ga, gg, gs = torch.autograd.grad(prof[:, j].sum(), (alpha, g, log_s), retain_graph=True)
        np.testing.assert_allclose(d_a[:, j].numpy(), ga.numpy(), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(d_g[:, j].numpy(), gg.numpy(), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(d_s[:, j].numpy(), gs.numpy(), rtol=1e-10, atol=1e-12)
    R, r_a, r_g = dip.reflectance_grad(alpha.detach(), g.detach())
    ga, gg = torch.autograd.grad(dip.reflectance(alpha, g).sum(), (alpha, g))
    np.testing.assert_allclose(r_a.numpy(), ga.numpy(), rtol=1e-10)
    np.testing.assert_allclose(r_g.numpy(), gg.numpy(), rtol=1e-10)


@pytest.mark.parametrize("table", ["linear_lut", "dip"])
def test_compiled_lookups_equal_the_torch_lookups(table, request):
    """Without a gradient to carry, profile and profile_grad run the compiled kernels (training.sim.lut_kernel);
    with one, torch's operations: both give the same numbers, in and beyond the table (albedo and g off the grid,
    sigma_t from 1e-3 to 1e6 cm^-1, r = 0 and beyond the last bin), on a non-uniform and a log-uniform radial axis."""
    lut = request.getfixturevalue(table)
    rng = np.random.default_rng(11)
    shape = (5, 3)
    alpha = torch.tensor(rng.uniform(-0.1, 1.1, shape))
    g = torch.tensor(rng.uniform(-1.0, 1.0, shape))
    sigma_t = torch.tensor(10.0 ** rng.uniform(-3, 6, shape))
    r = torch.tensor(np.r_[0.0, np.geomspace(1e-6, 50.0, 60)])
    fast = (lut.profile(r, alpha, g, sigma_t), *lut.profile_grad(r, alpha, g, sigma_t))
    alpha_g = alpha.clone().requires_grad_()
    slow = (lut.profile(r, alpha_g, g, sigma_t), *lut.profile_grad(r, alpha_g, g, sigma_t))
    for name, f, s in zip(("profile", "value", "d_alpha", "d_g", "d_log_sigma"), fast, slow, strict=True):
        assert f.shape == s.shape == (*shape, r.numel()), name
        assert torch.isfinite(f).all(), name
        np.testing.assert_allclose(f.numpy(), s.detach().numpy(), rtol=1e-13, atol=1e-300, err_msg=name)
    assert fast[0].abs().sum() > 0 and fast[2].abs().sum() > 0
