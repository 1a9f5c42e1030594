"""Spectral coherence: components matched along wavelength, targets interpolated to every
wavelength, the coherence metric on constructed decoders, and on the shipped decoder.

The constructed mixtures are smooth made-up functions of wavelength (not physics); the LUT is the
closed-form diffusion dipole (training/sim/dipole.py), a stand-in table through which both sides of
the metric's "explained" comparison go.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from exporters.constants import WAVELENGTHS_NM
from training.fit.matching import apply_order, match_along_wavelength, matched
from training.fit.problems import DIPOLE_ALBEDO, DIPOLE_EDGES_MFP
from training.paths import SHIPPED_DECODER
from training.sim.dipole import dipole_lut
from training.sim.lut_interp import LookupTables
from training.train.spectral import interpolate, interpolation_matrix
from training.validate import coherence as C

FITTED = np.arange(0, 376, 4)


@pytest.fixture(scope="module")
def lut():
    return LookupTables.from_arrays(**dipole_lut(albedo=DIPOLE_ALBEDO, r_edges_mfp=DIPOLE_EDGES_MFP))


def crossing_media(n: int, wl: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    """Smooth (N, 3, W) mixtures: media 0 and 1 cross in sigma_t near 625 nm (a per-wavelength sort by sigma_t
    swaps them there), medium 2 carries weight 1e-4 and random alpha, g, sigma_t at every wavelength."""
    rng = np.random.default_rng(seed)
    x = (wl[None, :] - 250.0) / 750.0  # (1, W)
    off = rng.uniform(-0.2, 0.2, (n, 1))
    ln_s = np.stack([5.0 - 3.0 * x + off, 3.0 + 1.0 * x + off, rng.uniform(0, 8, (n, wl.size))], 1)
    alpha = np.stack([0.6 + 0.3 * x + 0 * off, 0.95 - 0.1 * x + 0 * off, rng.uniform(0.01, 0.99, (n, wl.size))], 1)
    g = np.stack([0.8 + 0 * x + 0 * off, 0.5 + 0.2 * x + 0 * off, rng.uniform(0, 0.9, (n, wl.size))], 1)
    w0 = 0.55 + 0.1 * np.sin(6 * x) + 0 * off
    weight = np.stack([w0, 1 - w0 - 1e-4, np.full((n, wl.size), 1e-4)], 1)
    return {"alpha": alpha, "g": g, "sigma_t": np.exp(ln_s), "weight": weight}


def test_matching_recovers_shuffled_components():
    wl = WAVELENGTHS_NM[FITTED]
    truth = crossing_media(12, wl)
    ref = int(np.abs(wl - 600.0).argmin())
    # the identities the matching promises: sorted by sigma_t at 600 nm, then followed along wavelength
    expected = apply_order(truth, np.repeat(np.argsort(truth["sigma_t"][..., ref : ref + 1], axis=1), wl.size, 2))
    rng = np.random.default_rng(1)
    shuffled = apply_order(truth, np.argsort(rng.random(truth["alpha"].shape), axis=1))
    got = matched(shuffled, wl)
    for name in truth:
        np.testing.assert_array_equal(got[name], expected[name], err_msg=name)
    # idempotent; and a per-wavelength sort by sigma_t would have swapped media 0 and 1 (the comb's cause)
    np.testing.assert_array_equal(match_along_wavelength(got, wl), np.broadcast_to(np.arange(3)[None, :, None],
                                                                                   got["alpha"].shape))
    slower = truth["sigma_t"][:, 0] < truth["sigma_t"][:, 1]  # (N, W)
    assert slower.any(1).all() and (~slower).any(1).all()
    with pytest.raises(ValueError, match="NaN"):
        matched({**truth, "g": np.full_like(truth["g"], np.nan)}, wl)


def test_interpolation_matrix_is_linear_interpolation_with_constant_ends():
    m = interpolation_matrix(FITTED, 376)
    assert m.shape == (94, 376)
    torch.testing.assert_close(m.sum(0), torch.ones(376))  # weights of each wavelength sum to 1
    rng = np.random.default_rng(0)
    y = rng.random((2, 3, 94))
    got = interpolate(torch.tensor(y, dtype=torch.float32), m).numpy()
    ref = np.stack([[np.interp(np.arange(376), FITTED, row) for row in tone] for tone in y])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got[..., FITTED], y, rtol=0, atol=1e-6)  # exact at the fitted wavelengths
    np.testing.assert_allclose(got[..., 373:], np.repeat(y[..., -1:], 3, -1), atol=1e-6)  # beyond the last
    line = interpolate(torch.tensor(2.0 * FITTED + 1.0)[None], m.double())[0]  # a linear function: exact
    torch.testing.assert_close(line[:373], 2.0 * torch.arange(373.0, dtype=torch.float64) + 1.0)
    with pytest.raises(ValueError, match="increasing"):
        interpolation_matrix(np.array([4, 0]), 376)


def smooth_decoder(n: int = 16, seed: int = 0) -> dict[str, np.ndarray]:
    """(N, 3, 376) mixtures varying slowly with wavelength: distinct media, weights 0.6 / 0.25 / 0.15."""
    rng = np.random.default_rng(seed)
    x = (WAVELENGTHS_NM[None, None, :] - 250.0) / 750.0
    k = np.arange(3)[None, :, None]
    off = rng.uniform(-0.3, 0.3, (n, 1, 1))
    ones = np.ones((n, 3, 376))
    ln_s = (np.log(1000.0) - 2.5 * x + 1.2 * k + off) * ones
    alpha = (0.55 + 0.4 * x - 0.1 * k) * ones
    g = (0.55 + 0.1 * k) * ones
    logits = np.log(np.array([0.6, 0.25, 0.15]))[None, :, None] + 0.2 * np.sin(4 * x + off) * (k == 1)
    weight = np.exp(logits) / np.exp(logits).sum(1, keepdims=True) * ones
    return {"alpha": alpha, "g": g, "sigma_t": np.exp(ln_s), "weight": weight}


def test_metric_passes_a_smooth_decoder_and_catches_a_comb(lut):
    smooth = smooth_decoder()
    res = C.coherence(smooth, FITTED, lut)
    assert res["fitted"]["steps"] == 187 and res["other"]["steps"] == 188
    assert res["fitted"]["switch_rate"] == res["other"]["switch_rate"] == 0.0
    assert res["fitted"]["median_dlog_sigma_t"] == pytest.approx(2.5 / 375, rel=1e-6)
    assert res["other"]["median_dlog_sigma_t"] == pytest.approx(2.5 / 375, rel=1e-6)
    assert res["fitted"]["weight_jumps"] == res["other"]["weight_jumps"] == res["window"]["weight_jumps"] == 0
    assert res["acceptance"]["all"]
    # the comb: at the fitted wavelengths media 0 and 1 trade labels (the mixture is the same)
    comb = {name: v.copy() for name, v in smooth.items()}
    for v in comb.values():
        v[:, :2, FITTED] = v[:, 1::-1, FITTED]
    res = C.coherence(comb, FITTED, lut)
    assert res["fitted"]["switch_rate"] == pytest.approx(1.0, abs=0.01)  # every step at a fitted wavelength
    assert res["other"]["switch_rate"] == 0.0
    assert res["fitted"]["median_dlog_sigma_t"] == pytest.approx(1.2, abs=0.01)
    assert res["fitted"]["unexplained_jumps"] == res["fitted"]["weight_jumps"] > 0
    acc = res["acceptance"]
    assert not acc["switch_rate"] and not acc["dlog_sigma_t"] and not acc["no_unexplained_jumps"]


def test_a_real_change_of_weight_is_an_explained_jump(lut):
    """Light moving from medium 0 to medium 1 at one wavelength, the media unchanged: the rendered exitance
    changes as much as the weights alone make it change, so the jump is explained."""
    dec = smooth_decoder(n=5)
    dec["weight"][:, :, 201:] = np.array([0.25, 0.6, 0.15])[None, :, None]
    jumps = C.weight_jumps(dec, lut)
    assert jumps["step"].tolist() == [200] * 5 and jumps["explained"].all()
    assert (jumps["dw"] > 0.3).all()
    assert (jumps["actual"] > 0.9 * jumps["weight_only"]).all() and (jumps["weight_only"] > 0.05).all()
    assert C.coherence(dec, FITTED, lut)["window"] == {"span_nm": 8, "weight_jumps": 5 * 4, "unexplained_jumps": 0}


def test_a_slow_relabelling_is_no_step_jump_but_an_unexplained_window_jump(lut):
    """Media 0 and 1 trade places, parameters and weights alike, over 6 nm (0.117 of weight per step): no step
    passes the 0.2 of a jump, so the acceptance (per step) holds; the 8 nm windows across the whole trade do,
    and since the mixture at their two ends is the same, they are unexplained."""
    dec = smooth_decoder(n=3)
    ramp = np.clip((np.arange(376) - 200) / 3, 0, 1)  # 0 up to 200, 1 from 203
    for f in ("alpha", "g", "sigma_t", "weight"):
        a, b = dec[f][:, 0].copy(), dec[f][:, 1].copy()
        dec[f][:, 0], dec[f][:, 1] = a + ramp * (b - a), b + ramp * (a - b)
    res = C.coherence(dec, FITTED, lut)
    assert res["fitted"]["weight_jumps"] == res["other"]["weight_jumps"] == 0 and res["acceptance"]["all"]
    assert res["window"]["unexplained_jumps"] >= 2 * 3  # windows 199 -> 203 and 200 -> 204, each tone


def shipped_coherence(lut) -> dict:
    fn = C.decoder(SHIPPED_DECODER)
    return C.coherence(C.decode(fn, C.random_tones(300, seed=0)), np.arange(0, 376, C.SHIPPED_FITTED_STRIDE), lut)


def test_shipped_decoder_is_spectrally_coherent(lut):
    """The coherence acceptance on the shipped decoder (300 random tones in the box of docs/contracts.md §1;
    tolerance ``coherence.SWITCH_TOL``, ``DSIGMA_RATIO_TOL`` and no unexplained weight jump).  The earlier
    decoder recorded in docs/validation/coherence/shipped_before_rebuild.json fails it: its dominant component
    switched on ~25 % of the steps at a fitted wavelength against ~1 % elsewhere."""
    res = shipped_coherence(lut)
    assert res["acceptance"]["all"], res


def test_sweep_fits_stay_in_one_basin_and_fit_as_well(lut):
    """``fit --continuity sweep`` against the nearest-anchor warm starts on the same problems (closed-form
    dipole mixtures of two media varying smoothly with wavelength, 1 % standard errors): the sweep's fits
    are matched along wavelength, their dominant medium switches less often between neighbouring fitted
    wavelengths, and their mean joint loss is no higher."""
    from exporters.constants import R_EDGES_CM, anisotropy
    from training.fit.dataset import fit_tones
    from training.fit.sweep import fit_tones_sweep
    from training.sim.dipole import dipole_mixture_profile

    widx = np.arange(0, 376, 16)
    wl, x, T = WAVELENGTHS_NM[widx], (WAVELENGTHS_NM[widx] - 250.0) / 750.0, 3
    ones = np.ones((T, widx.size, 1))
    a = np.stack([0.9 + 0.09 * x, 0.6 + 0.3 * x], -1) * ones * np.array([1.0, 0.99, 0.98])[:, None, None]
    s = np.stack([300 * np.exp(-1.5 * x), 60 * np.exp(-x)], -1) * ones
    w = np.array([0.6, 0.4]) * ones
    prof, R = dipole_mixture_profile(R_EDGES_CM, DIPOLE_EDGES_MFP, a.reshape(-1, 2), np.full((a.size // 2, 2), 0.8),
                                     s.reshape(-1, 2), w.reshape(-1, 2))
    prof, R = torch.tensor(prof.reshape(T, widx.size, -1)), torch.tensor(R.reshape(T, widx.size))
    args = (lut.to(dtype=torch.float64), prof, R, 0.01 * prof, torch.tensor(R_EDGES_CM), 1e6,
            torch.tensor(anisotropy(wl)), (2,))
    stats: dict = {}
    sweep = fit_tones_sweep(*args, anchor_every=8, wavelength_nm=wl, stats=stats)[2]
    near = fit_tones(*args, anchor_every=8)[2]
    fields = ("alpha", "g", "sigma_t", "weight")
    sw = {name: {f: v[f].numpy() for f in fields} for name, v in (("sweep", sweep), ("near", near))}
    order = match_along_wavelength(sw["sweep"], wl)
    np.testing.assert_array_equal(order, np.broadcast_to(np.arange(2)[None, :, None], order.shape))
    assert stats["anchors_checked"] == T * 2 * 2  # K = 1, 2 at the anchors after the first
    switch = {name: float(C.step_changes(v)[0].mean()) for name, v in sw.items()}
    assert switch["sweep"] <= switch["near"]
    assert float(sweep["joint"].mean()) <= 1.02 * float(near["joint"].mean())
    assert torch.isfinite(sweep["shape_rmse"]).all() and (sweep["weight"].sum(1) - 1).abs().max() < 1e-9
