"""The validation gate's pieces against independent references (training/validate: metrics, baselines, gate).

* the gate renderer reproduces the ground-truth colour of a medium that *is* the ground truth: the epidermis
  of a tone as a homogeneous semi-infinite slab, by adding-doubling (iadpython, independent) and by the biophysical
  simulator's layered path (two identical layers), vs our K = 1 mixture render — colour and edge image;
* the albedo-inversion baselines round-trip: albedo in -> medium -> rendered albedo out;
* the baselines' extinction follows the published formulas (typed here, not taken from the module);
* metric definitions on cases with known answers; Table 3 aggregation on a fits file written here.
"""

from __future__ import annotations

import math

import h5py
import iadpython as iad
import numpy as np
import pytest
import torch

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.sim.medium import LayeredMedium
from training.sim.transport import simulate
from training.skin.model import layer_optics
from training.validate import baselines as bl
from training.validate import metrics as M
from training.validate.mixture import mixture_reflectance
from training.validate.profile_set import fit_profile_fidelity

VIS_NM = np.arange(380.0, 781.0, 25.0)  # 17 visible wavelengths (colour interpolates onto the grid)
#: R03 of tones.csv; its epidermis (alpha 0.95-0.98 in the visible) is the test medium: light enough for a
#: colour with little noise, absorbing enough for short walks.
TONE_R03 = np.array([0.012, 0.020, 0.010, 0.75, 0.75])


def _iad_diffuse(alpha: float, g: float) -> float:
    """Diffuse-illumination R_d of a thick slab, n = 1.4, specular part removed (adding-doubling)."""
    s = lambda a: iad.Sample(a=a, b=1000, g=g, n=1.4, n_above=1.0, n_below=1.0, quad_pts=32).rt()[2]  # noqa: E731
    return s(alpha) - s(0.0)


def _epidermis(wavelength_nm: np.ndarray):
    """mu_a, mu_s, g (W,) of R03's epidermis at the wavelengths (linear interpolation of the 2 nm grid)."""
    o = layer_optics(TONE_R03)
    pick = lambda t: np.interp(wavelength_nm, WAVELENGTHS_NM, t.numpy().ravel())  # noqa: E731
    return pick(o.mua_epi), pick(o.mus_epi), pick(o.g_epi)


@pytest.fixture(scope="module")
def medium_renders():
    """A homogeneous medium (R03's epidermis, semi-infinite) by our gate renderer, by the biophysical
    simulator's layered path (two identical layers) and by adding-doubling, at 21 visible wavelengths."""
    wl = np.arange(380.0, 781.0, 20.0)
    mua, mus, g = _epidermis(wl)
    alpha, sigma_t = mus / (mua + mus), mua + mus
    photons = 8000
    ours = mixture_reflectance(alpha, sigma_t, g, np.ones_like(alpha), photons=photons, seed=3,
                               r_edges_cm=R_EDGES_CM)
    layered = LayeredMedium(mua=np.stack([mua, mua]), mus=np.stack([mus, mus]), g=np.stack([g, g]),
                            thickness=torch.tensor([0.012, math.inf], dtype=torch.float64), n_medium=1.4)
    sim = simulate(layered, photons, seed=4)
    ref = np.array([_iad_diffuse(a, gg) for a, gg in zip(alpha, g, strict=True)])
    return wl, ours, sim, ref


def test_gate_renderer_reproduces_a_ground_truth_medium(medium_renders):
    wl, ours, sim, ref = medium_renders
    # per wavelength within noise of adding-doubling (independent of our Monte Carlo)
    assert np.all(np.abs(ours.R_d - ref) < 4 * ours.R_d_stderr + 2e-3), (ours.R_d, ref)
    # colour: our renderer vs adding-doubling, and vs the biophysical simulator's layered path
    floor_ref = M.noise_floor(ref, np.zeros_like(ref), ours.R_d_stderr, wl)
    floor_sim = M.noise_floor(sim.R_d, sim.R_d_stderr, ours.R_d_stderr, wl)
    assert floor_ref < 0.8 and floor_sim < 0.8, (floor_ref, floor_sim)  # enough photons for the check to bite
    assert M.delta_e(ours.R_d, ref, wl) < 3 * floor_ref + 0.3
    assert M.delta_e(ours.R_d, sim.R_d, wl) < 3 * floor_sim + 0.3
    # the edge image sees the same translucency: profiles of the same medium by two code paths
    de_edge = M.edge_delta_e(ours.profile, ours.R_d, sim.profile, sim.R_d, wl)
    assert de_edge < 1.5, de_edge


def test_edge_image_of_a_medium_differs_when_translucency_differs(medium_renders):
    # the same colour with a 10x shorter mean free path is visibly different across the edge
    wl, ours, _, _ = medium_renders
    mua, mus, g = _epidermis(wl)
    alpha = mus / (mua + mus)
    short = mixture_reflectance(alpha, 10 * (mua + mus), g, np.ones_like(alpha), photons=4000, seed=5,
                                r_edges_cm=R_EDGES_CM)
    # scale invariance of a semi-infinite slab's R_d, per wavelength within the two runs' noise (their colour
    # difference from noise alone is dE76 0.5-1.1 at these photon counts)
    assert np.all(np.abs(short.R_d - ours.R_d) < 4 * np.hypot(short.R_d_stderr, ours.R_d_stderr) + 1e-3)
    assert M.edge_delta_e(short.profile, short.R_d, ours.profile, ours.R_d, wl) > 2.0


@pytest.mark.parametrize("method", bl.METHODS)
def test_baseline_round_trip(method):
    # albedo in -> the baseline's per-wavelength medium -> rendered by the gate -> albedo out
    rgb = np.array([0.42, 0.27, 0.21])
    wl = np.arange(380.0, 781.0, 20.0)
    m = bl.baseline_medium(method, rgb, 0.01, wl)
    res = mixture_reflectance(m.alpha, m.sigma_t, m.g, np.ones_like(m.alpha), photons=4000, seed=7)
    out = M.linear_srgb(res.R_d, wl)
    se = M.linear_srgb(res.R_d + res.R_d_stderr, wl) - out  # one standard error, per channel
    # tolerance: 4 standard errors + 0.01 (the table's interpolation and 20 nm sampling of the upsampled albedo)
    assert np.all(np.abs(out - rgb) < 4 * np.abs(se) + 0.01), (out, rgb)


def test_baseline_extinction_follows_the_published_formulas():
    rgb, scale, wl = np.array([0.5, 0.35, 0.3]), 0.02, np.array([450.0, 550.0, 650.0, 780.0])
    ch = bl.baseline_medium("chiang2016", rgb, scale, wl)
    wr = bl.baseline_medium("wrenninge2017", rgb, scale, wl)
    a = ch.albedo
    s = 1.9 - a + 3.5 * (a - 0.8) ** 2  # Burley 2015 / Chiang et al. 2016
    np.testing.assert_allclose(ch.sigma_t, 1.0 / (100 * ch.radius_m * s), rtol=1e-12)
    np.testing.assert_allclose(ch.g, 0.0)
    # Cycles >= 3.0 random walk: d = r / (4 pi), sigma_t = 1 / (d (1 - g)), r in metres -> cm^-1
    np.testing.assert_allclose(wr.sigma_t, 4 * np.pi / (100 * wr.radius_m * (1 - bl.WRENNINGE_G)), rtol=1e-12)
    # the radius spectrum stays within Blender's channel radii times the scale
    assert np.all((ch.radius_m >= 0.1 * scale - 1e-12) & (ch.radius_m <= 1.0 * scale + 1e-12))
    # Chiang's published polynomial at A = 0.5: 1 - exp(-5.09406 * 0.5 + 2.61188 * 0.25 - 4.31805 * 0.125)
    assert bl.chiang_published_alpha(0.5) == pytest.approx(1 - math.exp(-2.54703 + 0.65297 - 0.53975625), rel=1e-12)


def test_upsampled_albedo_keeps_its_colour():
    rgb = np.array([0.6, 0.4, 0.3])
    wl = WAVELENGTHS_NM
    np.testing.assert_allclose(M.linear_srgb(bl.upsample(rgb, wl), wl), rgb, atol=2e-3)


def test_bad_baseline_input_is_refused():
    with pytest.raises(ValueError, match="unknown baseline"):
        bl.baseline_medium("burley", [0.5, 0.4, 0.3], 0.01, VIS_NM)
    with pytest.raises(ValueError, match="positive"):
        bl.baseline_medium("chiang2016", [0.5, 0.4, 0.3], 0.0, VIS_NM)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        bl.baseline_medium("chiang2016", [1.5, 0.4, 0.3], 0.01, VIS_NM)


# ------------------------------------------------------------------------------------------ metrics
def test_edge_exitance_of_a_point_like_profile():
    # all light leaves within 1 um of the entry point: a pixel sees R where lit and nothing in the shadow
    edges = R_EDGES_CM
    prof = np.zeros((2, edges.size - 1))
    area0 = np.pi * edges[1] ** 2
    prof[:, 0] = np.array([0.3, 0.1]) / area0
    x = M.edge_positions_cm()
    e = M.edge_exitance(prof, np.array([0.3, 0.1]), x)
    np.testing.assert_allclose(e[x < 0], np.broadcast_to([0.3, 0.1], e[x < 0].shape), rtol=1e-12)
    np.testing.assert_allclose(e[x > 0], 0.0, atol=1e-15)


def test_edge_exitance_of_light_beyond_the_table():
    # light exiting beyond 5 cm (R_d larger than the profile's sum) reaches both sides half and half
    prof = np.zeros((1, R_EDGES_CM.size - 1))
    e = M.edge_exitance(prof, np.array([0.2]), np.array([-0.1, 0.1]))
    np.testing.assert_allclose(e[:, 0], [0.1, 0.1], rtol=2e-2)


def test_spectral_angle_and_delta_e():
    a = np.array([1.0, 0.0, 0.0])
    assert M.spectral_angle(a, np.array([0.0, 2.0, 0.0])) == pytest.approx(math.pi / 2)
    assert M.spectral_angle(a, 3 * a) == pytest.approx(0.0, abs=1e-12)
    spec = np.linspace(0.2, 0.5, VIS_NM.size)
    assert M.delta_e(spec, spec, VIS_NM) == pytest.approx(0.0, abs=1e-12)
    assert M.noise_floor(spec, np.zeros_like(spec), np.zeros_like(spec), VIS_NM) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="NaN"):
        M.delta_e(spec * np.nan, spec, VIS_NM)


def test_band_edges():
    wl = np.array([250.0, 398.0, 400.0, 698.0, 700.0, 1000.0])
    assert M.band_mask(wl, "UV").tolist() == [True, True, False, False, False, False]
    assert M.band_mask(wl, "Vis").tolist() == [False, False, True, True, False, False]
    assert M.band_mask(wl, "NIR").tolist() == [False, False, False, False, True, True]


def test_relative_reduction():
    assert M.relative_reduction(0.059, 0.019) == pytest.approx(0.678, abs=1e-3)


# ------------------------------------------------------------------------------------------ Table 3
def test_profile_fidelity_from_a_fits_file(tmp_path):
    # a validation fits file in the fitter's layout (training/fit/dataset.py), written here
    n, widx = 5, np.arange(0, 376, 4)
    rng = np.random.default_rng(0)
    errs = {k: rng.uniform(0.01, 0.1, (n, widx.size)) / k for k in (1, 2, 3)}
    done = np.array([True, True, False, True, True])
    with h5py.File(tmp_path / "validation_fits.h5", "w") as f:
        f["index"] = np.arange(n)
        f["done"] = done
        f["wavelength_index"] = widx
        for k in (1, 2, 3):
            f[f"k{k}_shape_rmse"] = errs[k].astype(np.float32)
        f.attrs["ks"] = "1,2,3"
    rec = fit_profile_fidelity(tmp_path)
    assert rec["n_tones"] == 4 and rec["n_wavelengths"] == widx.size
    k1, k2 = errs[1][done].astype(np.float32).mean(), errs[2][done].astype(np.float32).mean()
    assert rec["fits"]["K1"]["mean"] == pytest.approx(k1, rel=1e-6)
    assert rec["fits"]["K2"]["mean"] == pytest.approx(k2, rel=1e-6)
    assert rec["fits"]["K1_to_K2_reduction"]["mean"] == pytest.approx(1 - k2 / k1, rel=1e-6)
    uv = WAVELENGTHS_NM[widx] < 400
    assert rec["fits"]["K1"]["UV"] == pytest.approx(errs[1][done][:, uv].astype(np.float32).mean(), rel=1e-6)
    with pytest.raises(ValueError, match="validation_fits"):
        fit_profile_fidelity(tmp_path / "nothing")


def test_lut_render_is_the_tables_mixture_in_closed_form():
    """``gate.lut_render`` of a K = 2 mixture through a LUT filled from the dipole (albedo and g on the table's
    nodes) against the dipole mixture in closed form (``training.sim.dipole``): R_d, and the profile in cm^-2
    wherever it holds light (radial interpolation between bin centres only)."""
    from training.sim.dipole import dipole_lut, dipole_mixture_profile
    from training.sim.lut_interp import LookupTables
    from training.validate.gate import Params, lut_render

    tab = dipole_lut()
    lut = LookupTables.from_arrays(**tab)
    alpha = np.array([[tab["albedo"][30]] * 3, [tab["albedo"][36]] * 3])  # (K, W)
    g = np.array([[tab["g"][9]] * 3, [tab["g"][10]] * 3])
    sigma_t = np.array([[80.0, 150.0, 400.0], [30.0, 60.0, 90.0]])
    w = np.array([[0.3, 0.5, 0.8], [0.7, 0.5, 0.2]])
    out = lut_render(lut, Params(alpha, sigma_t, g, w))
    ref_prof, ref_r = dipole_mixture_profile(R_EDGES_CM, tab["r_edges_mfp"], alpha.T, g.T, sigma_t.T, w.T)
    np.testing.assert_allclose(out["R_d"], ref_r, rtol=1e-6)
    assert np.all(out["R_d_stderr"] == 0) and np.all(out["truncated"] == 0)
    lit = ref_prof > 1e-6 * ref_prof.max(axis=1, keepdims=True)
    np.testing.assert_allclose(out["profile"][lit], ref_prof[lit], rtol=0.03)
