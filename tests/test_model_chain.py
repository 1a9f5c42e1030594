"""The chained model in torch: colour head vs the project's colour pipeline, output ranges, input domain,
exposure identity, and the stage-3 loss terms against hand computations."""

import math

import numpy as np
import pytest
import torch

from exporters.colorimetry import SRGB_LUMINANCE, spectrum_to_linear_srgb
from exporters.constants import PARAM_NAMES, PARAM_RANGES, WAVELENGTHS_NM
from training.model import ModelConfig, SkinChain
from training.model.config import FALLBACK_ALBEDO_RGB, SIZES, SLAB_C
from training.model.networks import ReflectanceDecoder
from training.sim.dipole import dipole_lut
from training.sim.lut_interp import LookupTables
from training.train import losses as train_losses

TINY = {"enc_hidden": 16, "decr_hidden": 32, "dect_hidden": 32, "dect_layers": 3}


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return SkinChain(ModelConfig(k=3, g_range=(-0.9, 0.95), **TINY)).eval()


def rgb_cube(n: int = 33) -> torch.Tensor:
    v = torch.linspace(0.0, 1.0, n)
    return torch.cartesian_prod(v, v, v)


def test_colour_head_matches_the_colour_pipeline(model):
    rng = np.random.default_rng(1)
    spectra = rng.random((16, WAVELENGTHS_NM.size))
    ref = spectrum_to_linear_srgb(spectra, "D65")  # float64, colour-science CMFs and matrices
    got = model.colour.rgb(torch.tensor(spectra, dtype=torch.float32)).double().numpy()
    np.testing.assert_allclose(got, ref, rtol=2e-5, atol=2e-6)
    # a perfect white reflector is sRGB white (1, 1, 1) and has Y = 1
    white = model.colour.rgb(torch.ones(1, WAVELENGTHS_NM.size))
    np.testing.assert_allclose(white.numpy(), [[1.0, 1.0, 1.0]], atol=2e-3)


@torch.no_grad()
def test_outputs_on_the_rgb_cube_are_finite_and_in_range(model):
    cube = rgb_cube(17)  # incl. black, white and non-skin colours (the ONNX tests use 33^3)
    for chunk in torch.split(cube, 4096):
        out = model.invert(chunk)
        for name, t in out.items():
            assert torch.isfinite(t).all(), name
        assert ((out["alpha"] >= 0) & (out["alpha"] <= 1)).all()
        assert (out["sigma_t"] > 0).all()
        assert ((out["g"] >= -0.9 - 1e-6) & (out["g"] <= 0.95 + 1e-6)).all()
        assert (out["weight"] >= 0).all()
        torch.testing.assert_close(out["weight"].sum(1), torch.ones_like(out["weight"][:, 0]), atol=1e-5, rtol=0)
        for i, (lo, hi) in enumerate(PARAM_RANGES.values()):
            assert (out["biophysical"][:, i] >= lo - 1e-6).all() and (out["biophysical"][:, i] <= hi + 1e-6).all()
        assert (out["exposure"] >= 0).all()
        assert out["alpha"].shape == (len(chunk), 3, WAVELENGTHS_NM.size)


@torch.no_grad()
def test_exposure_identity(model):
    a = rgb_cube(9)[1:]  # black has Y = 0 and exposure 0; the identity is trivially 0 = 0 there
    out = model.invert(a)
    rgb_hat = spectrum_to_linear_srgb(out["reflectance"].double().numpy(), "D65")  # independent float64 path
    y_in = a.double().numpy() @ SRGB_LUMINANCE
    y_out = (out["exposure"].double().numpy() * rgb_hat) @ SRGB_LUMINANCE
    np.testing.assert_allclose(y_out, y_in, rtol=2e-5, atol=1e-7)


@torch.no_grad()
def test_non_finite_rows_take_the_fallback_colour_and_leave_other_rows_alone(model):
    good = torch.tensor([[0.5, 0.3, 0.2], [0.1, 0.05, 0.03]])
    bad = torch.tensor([[math.nan, 0.3, 0.2], [0.2, math.inf, 0.1], [-math.inf, -math.inf, -math.inf]])
    out = model.invert(torch.cat([good, bad]))
    ref_good = model.invert(good)
    ref_fb = model.invert(torch.tensor([FALLBACK_ALBEDO_RGB]))
    for name, t in out.items():
        assert torch.isfinite(t).all(), name
        torch.testing.assert_close(t[:2], ref_good[name], rtol=1e-5, atol=1e-6)
        for i in range(2, 5):
            torch.testing.assert_close(t[i : i + 1], ref_fb[name], rtol=1e-5, atol=1e-6)
    # clamping: out-of-gamut inputs behave as their clamped colour
    clamp = model.invert(torch.tensor([[1.7, -0.2, 0.4]]))
    ref = model.invert(torch.tensor([[1.0, 0.0, 0.4]]))
    torch.testing.assert_close(clamp["biophysical"], ref["biophysical"])
    # decoder input: NaN row -> centre of the ranges, out-of-range -> clamped
    p_mid = torch.tensor([[(lo + hi) / 2 for lo, hi in PARAM_RANGES.values()]])
    d_nan = model.decode(torch.tensor([[math.nan, 0.1, 0.01, 0.7, 0.5]]))
    d_mid = model.decode(p_mid)
    torch.testing.assert_close(d_nan["reflectance"], d_mid["reflectance"])


def test_translucency_unit_map_inverts_the_output_map(model):
    torch.manual_seed(3)
    p = model.enc.from_unit(torch.rand(4, 5))
    out = model.dec_t(p, model.dec_r(p))
    u = model.dec_t.to_unit(out["alpha"], out["g"], out["sigma_t"], out["weight"])
    torch.testing.assert_close(u, out["u"], rtol=1e-4, atol=1e-5)
    lo, hi = model.cfg.sigma_t_range_cm
    assert (out["sigma_t"] >= lo * (1 - 1e-5)).all() and (out["sigma_t"] <= hi * (1 + 1e-5)).all()


def test_lut_reflectance_with_slab_factor_matches_a_hand_computation(model):
    tab = dipole_lut()
    lut = LookupTables.from_arrays(**tab, dtype=torch.float32)
    ia, ig = np.array([[5, 30, 40]]), np.array([[2, 7, 11]])  # grid nodes: bilinear = table value
    alpha = torch.tensor(tab["albedo"][ia], dtype=torch.float32)[..., None].expand(1, 3, 376)
    g = torch.tensor(tab["g"][ig], dtype=torch.float32)[..., None].expand(1, 3, 376)
    sigma = torch.tensor([[0.5, 2.0, 300.0]])[..., None].expand(1, 3, 376)
    w = torch.tensor([[0.2, 0.3, 0.5]])[..., None].expand(1, 3, 376)
    got = train_losses.lut_reflectance(model, lut, {"alpha": alpha, "g": g, "sigma_t": sigma, "weight": w})
    c = 0.30  # the initial slab depth
    expect = sum(wk * tab["R"][a, b] * (1 - np.exp(-SLAB_C * s * c))
                 for wk, a, b, s in zip([0.2, 0.3, 0.5], ia[0], ig[0], [0.5, 2.0, 300.0], strict=True))
    np.testing.assert_allclose(got.detach().numpy(), np.full((1, 376), expect), rtol=1e-5)


def test_param_loss_weights_alpha_twice_and_is_huber():
    u = torch.zeros(2, 4, 3, 5)
    t = torch.zeros_like(u)
    t[:, 0] = 1.0  # alpha off by 1: Huber = delta * (1 - delta / 2)
    d = train_losses.HUBER_DELTA
    np.testing.assert_allclose(float(train_losses.param_loss(u, t)), 2.0 * d * (1 - d / 2) / 4, rtol=1e-6)
    t = torch.zeros_like(u)
    t[:, 2] = 0.01  # sigma_t off by 0.01 < delta: quadratic 0.5 * 0.01^2
    np.testing.assert_allclose(float(train_losses.param_loss(u, t)), 0.5 * 1e-4 / 4, rtol=1e-5)
    lam = torch.arange(5.0).expand(2, 4, 3, 5)
    np.testing.assert_allclose(float(train_losses.smooth_loss(lam)), 1.0, rtol=1e-6)


def test_log_scaled_parameters_and_legacy_configs():
    """f_mel and f_blood are seen on a log scale over their range (the dataset draws them log-uniformly);
    a config written before the option (no ``log_params``) keeps the linear scale, and the state of either
    loads into the other (the scale is derived from the config, not stored)."""
    cfg = ModelConfig(**SIZES["tiny"])
    assert cfg.log_params == ("f_mel", "f_blood")
    legacy = cfg.to_dict()
    del legacy["log_params"]
    old = ModelConfig.from_dict(legacy)
    assert old.log_params == () and ModelConfig.from_dict(cfg.to_dict()).log_params == cfg.log_params
    new_net, old_net = ReflectanceDecoder(cfg), ReflectanceDecoder(old)
    half = torch.full((1, 5), 0.5)
    lo = torch.tensor([[PARAM_RANGES[n][0] for n in PARAM_NAMES]])
    hi = torch.tensor([[PARAM_RANGES[n][1] for n in PARAM_NAMES]])
    i_mel, i_t = PARAM_NAMES.index("f_mel"), PARAM_NAMES.index("t_epi")
    assert float(new_net.from_unit(half)[0, i_mel]) == pytest.approx((0.001 * 0.65) ** 0.5, rel=1e-5)
    assert float(old_net.from_unit(half)[0, i_mel]) == pytest.approx(0.5 * (0.001 + 0.65), rel=1e-5)
    assert float(new_net.from_unit(half)[0, i_t]) == pytest.approx(float(old_net.from_unit(half)[0, i_t]))
    torch.testing.assert_close(new_net.normalise(lo), -torch.ones(1, 5))
    torch.testing.assert_close(new_net.normalise(hi), torch.ones(1, 5))
    u = torch.rand(64, 5)
    torch.testing.assert_close(new_net.normalise(new_net.from_unit(u)), 2 * u - 1, atol=1e-5, rtol=0)
    edge = torch.tensor([[0.001, 0.25, 0.02, 0.5, 0.0]], requires_grad=True)  # b_mel (linear) at 0, f_mel at lo
    new_net(edge).sum().backward()
    assert torch.isfinite(edge.grad).all(), edge.grad  # the log of a linear parameter must not leak NaN
    old_net.load_state_dict(new_net.state_dict())  # same stored keys
    p = new_net.from_unit(u)
    assert not torch.allclose(new_net(p), old_net(p))  # same weights, another input scale


def test_smoothed_weights_cannot_jump_whatever_the_network_learns():
    """Dec_T's weights pass through a normalised Gaussian along wavelength (6 nm): however hard the raw logits
    switch between neighbouring wavelengths, the weights stay a valid mixture and no weight changes by more
    than the kernel's peak (0.133 < the coherence measure's jump of 0.2) per 2 nm step.  Without the low-pass
    the same logits jump by ~1.  A config written before the option has none, and the state of either loads
    into the other (the kernel is derived from the config, not stored)."""
    from training.model.networks import TranslucencyDecoder, gaussian_taps
    from training.validate.coherence import JUMP_DW

    cfg = ModelConfig(k=3, **TINY)
    legacy = cfg.to_dict()
    del legacy["weight_smoothing_nm"]
    assert cfg.weight_smoothing_nm == 6.0 and ModelConfig.from_dict(legacy).weight_smoothing_nm == 0.0
    smooth, raw = TranslucencyDecoder(cfg), TranslucencyDecoder(ModelConfig.from_dict(legacy))
    raw.load_state_dict(smooth.state_dict())
    # Adversarial last layer: weight logits +-30 that swap the dominant component every few wavelengths,
    # with period and phase varying across the three components.
    last = smooth.net[-1]
    w = torch.arange(cfg.n_wavelengths)
    with torch.no_grad():
        last.weight.zero_()
        bias = last.bias.view(4, 3, -1)
        for k, period in enumerate((3, 7, 1)):
            bias[3, k] = torch.where((w // period + k) % 3 == 0, 30.0, -30.0)
        raw.load_state_dict(smooth.state_dict())
        p, refl = torch.full((4, 5), 0.5), torch.rand(4, cfg.n_wavelengths)
        w_smooth, w_raw = smooth(p, refl)["weight"], raw(p, refl)["weight"]
    assert torch.isfinite(w_smooth).all() and (w_smooth >= 0).all()
    torch.testing.assert_close(w_smooth.sum(1), torch.ones(4, cfg.n_wavelengths))
    peak = float(gaussian_taps(3.0).max())
    assert peak == pytest.approx(1 / math.sqrt(2 * math.pi * 9), rel=1e-3)
    assert float(w_smooth.diff(dim=2).abs().max()) <= peak + 1e-6 < JUMP_DW
    assert float(w_raw.diff(dim=2).abs().max()) > 0.99
