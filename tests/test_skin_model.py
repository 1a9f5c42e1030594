"""The skin model against published formula values, the raw chromophore sources and physical trends."""

import math

import numpy as np
import pytest
import torch

from exporters.constants import WAVELENGTHS_NM
from training.skin import constants, model
from training.skin.chromophores import DATA_DIR, grid_spectra, read_table
from training.skin.tones import load_tones


def at(spectrum: torch.Tensor, nm: float) -> float:
    return float(spectrum[..., int(round((nm - 250) / 2))].reshape(-1)[0])


def test_melanin_published_values():
    wl = torch.tensor([500.0, 694.0], dtype=torch.float64)
    # Jacques 1998 (OMLC): a melanosome absorbs 6.6e11 * 500^-3.33 = 679 cm^-1 at 500 nm.
    assert float(model.eumelanin_mua(wl)[0]) == pytest.approx(679.0, rel=2e-3)
    # Donner & Jensen 2006 pheomelanin 2.9e14 lambda^-4.75 mm^-1 -> at 694 nm 9.25 mm^-1 = 92.5 cm^-1
    assert float(model.pheomelanin_mua(wl)[1]) == pytest.approx(2.9e14 * 694.0**-4.75 * 10, rel=1e-9)
    assert float(model.pheomelanin_mua(wl)[1]) == pytest.approx(92.5, rel=2e-3)


def test_baseline_published_values():
    wl = torch.tensor([250.0, 350.0, 1000.0], dtype=torch.float64)
    base = model.baseline_mua(wl, constants.JACQUES_1998)
    # Jacques 1998 (OMLC): 0.47 mm^-1 at 350 nm, 2.0 mm^-1 at 250 nm; tends to 0.0244 mm^-1 in the NIR
    assert float(base[0]) == pytest.approx(20.0, rel=0.03)
    assert float(base[1]) == pytest.approx(4.7, rel=0.01)
    assert float(base[2]) == pytest.approx(0.244, abs=1e-3)
    # the adopted model keeps the exponential and halves the NIR offset (training/skin/README.md)
    adopted = model.baseline_mua(wl)
    assert float(adopted[1]) == pytest.approx(4.7 - 0.244 + 0.12, rel=0.01)
    assert float(adopted[2]) == pytest.approx(0.12, abs=1e-3)


def test_scattering_and_anisotropy_published_values():
    wl = torch.tensor([250.0, 500.0, 850.0, 1000.0], dtype=torch.float64)
    # Jacques 1998: mu_s' = 2e5 lambda^-1.5 + 2e12 lambda^-4 = 49.9 cm^-1 at 500 nm, 11.9 at 850 nm
    old = model.reduced_scattering(wl, constants.JACQUES_1998)
    assert float(old[1]) == pytest.approx(49.9, abs=0.05)
    assert float(old[2]) == pytest.approx(2e5 * 850**-1.5 + 2e12 * 850**-4, rel=1e-12)
    # Jacques 2013 Table 2 (skin): 46.0 (lambda/500)^-1.421 -> 46.0 at 500 nm, 21.6 at 850 nm
    new = model.reduced_scattering(wl)
    assert float(new[1]) == pytest.approx(46.0, rel=1e-12)
    assert float(new[2]) == pytest.approx(21.6, abs=0.05)
    # Bashkatov as tabled by Jacques 2013: 1.1e12 lambda^-4 + 73.7 lambda^-0.22 (36.4 cm^-1 at 500 nm)
    bash = model.reduced_scattering(wl, constants.SkinModelSpec("b", constants.BASHKATOV_SCATTERING,
                                                                constants.JACQUES_1998_BASELINE))
    assert float(bash[1]) == pytest.approx(1.1e12 * 500**-4 + 73.7 * 500**-0.22, rel=0.01)
    assert float(bash[3]) == pytest.approx(1.1e12 * 1000**-4 + 73.7 * 1000**-0.22, rel=0.02)
    mus, g = model.scattering()
    # van Gemert 1989: g = 0.6925 at 250 nm, 0.765 at 500 nm, 0.91 at 1000 nm
    assert [at(g, 250), at(g, 500), at(g, 1000)] == pytest.approx([0.6925, 0.765, 0.91], abs=1e-12)
    assert at(mus, 500) == pytest.approx(46.0 / (1 - 0.765), rel=1e-3)


def test_blood_absorption_uses_150_g_per_litre():
    # Prahl (OMLC): mu_a = 2.303 * eps * 150 / 64500 for whole blood; eps_HbO2(414 nm) = 524280 cm^-1/M
    c = model.chromophore_mua()
    assert at(c["hbo2"], 414) == pytest.approx(math.log(10) * 524280 * 150 / 64500, rel=1e-9)
    # the isosbestic point near 800 nm: oxy and deoxy blood absorb alike (about 4 cm^-1)
    assert at(c["hbo2"], 800) == pytest.approx(at(c["hb"], 800), rel=0.1)
    assert 3.0 < at(c["hbo2"], 800) < 5.0


def test_grid_table_matches_raw_sources():
    grid = grid_spectra()
    _, hb = read_table(DATA_DIR / "hemoglobin_molar_ext_prahl.csv")
    np.testing.assert_array_equal(hb[:, 0], WAVELENGTHS_NM)
    np.testing.assert_array_equal(grid["eps_hbo2"], hb[:, 1])
    np.testing.assert_array_equal(grid["eps_hb"], hb[:, 2])
    # bilirubin: box average over +-1 nm of the clipped 0.25 nm source (recomputed here independently)
    _, bili = read_table(DATA_DIR / "bilirubin_molar_ext_photochemcad.csv")
    for nm in (300, 450, 460, 500):
        window = (bili[:, 0] >= nm - 1) & (bili[:, 0] <= nm + 1)
        expected = np.clip(bili[window, 1], 0, None).mean()
        assert grid["eps_bilirubin"][(nm - 250) // 2] == pytest.approx(expected, rel=0.02)
    # water: log-linear interpolation of Segelstein
    _, water = read_table(DATA_DIR / "water_mua_segelstein.csv")
    for nm in (500, 750, 980):
        expected = np.exp(np.interp(nm, water[:, 0], np.log(water[:, 1])))
        assert grid["mua_water"][(nm - 250) // 2] == pytest.approx(expected, rel=0.02)
    assert np.all(grid["eps_bilirubin"][WAVELENGTHS_NM > 700] == 0)


def test_layer_composition_follows_the_formulas():
    tone = [0.2, 0.05, 0.01, 0.8, 0.6]
    optics = model.layer_optics(tone)
    c = model.chromophore_mua()
    nm = 550
    melanin = 0.6 * at(c["eumelanin"], nm) + 0.4 * at(c["pheomelanin"], nm)
    epi = 0.2 * melanin + 0.8 * (at(c["baseline"], nm) + at(c["carotene_epi"], nm))
    blood = 0.8 * at(c["hbo2"], nm) + 0.2 * at(c["hb"], nm) + at(c["bilirubin_blood"], nm)
    derm = 0.05 * blood + 0.95 * (at(c["baseline"], nm) + 0.65 * at(c["water"], nm) + at(c["carotene_derm"], nm))
    assert at(optics.mua_epi, nm) == pytest.approx(epi, rel=1e-12)
    assert at(optics.mua_derm, nm) == pytest.approx(derm, rel=1e-12)
    assert optics.mua_epi.shape == (1, 376) and optics.t_epi.item() == 0.01


def test_physical_trends():
    tones = load_tones()
    optics = model.layer_optics(tones.select("representative").values)
    visible = slice((400 - 250) // 2, (700 - 250) // 2)
    # darker representative tones absorb more in the epidermis at every visible wavelength
    assert torch.all(torch.diff(optics.mua_epi[:, visible], dim=0) > 0)
    # haemoglobin Q bands of oxygenated blood: 542 and 577 nm are local maxima of dermal absorption
    oxy = model.layer_optics([0.01, 0.1, 0.01, 1.0, 0.7]).mua_derm[0]
    assert at(oxy, 542) > at(oxy, 560) < at(oxy, 576)
    for tensor in (optics.mua_epi, optics.mua_derm, optics.mus_epi, optics.mus_derm):
        assert torch.isfinite(tensor).all() and (tensor > 0).all()


@pytest.mark.parametrize(
    ("tone", "message"),
    [
        ([1.2, 0.1, 0.01, 0.7, 0.7], "f_mel"),
        ([0.1, -0.1, 0.01, 0.7, 0.7], "f_blood"),
        ([0.1, 0.1, 0.0, 0.7, 0.7], "t_epi"),
        ([0.1, 0.1, 0.01, float("nan"), 0.7], "NaN"),
        ([0.1, 0.1, 0.01], "shape"),
    ],
)
def test_bad_tones_are_rejected(tone, message):
    with pytest.raises(ValueError, match=message):
        model.layer_optics(tone)


def test_tone_table():
    tones = load_tones()
    assert len(tones.select("representative").names) == 10 and len(tones.select("outlier").names) == 10
    rep = tones.select("representative").values
    assert rep[0, 0] == 0.001 and rep[-1, 0] == 0.65 and np.all(np.diff(rep[:, 0]) > 0)
