"""The colour pipeline against colour-science's own reference path and published white points."""

import colour
import numpy as np
import pytest

from exporters import colorimetry as c
from exporters.constants import WAVELENGTHS_NM

SHAPE_1NM = colour.SpectralShape(360, 830, 1)


def _reference_illuminant(name: str) -> colour.SpectralDistribution:
    """colour-science's own illuminant SPDs at 1 nm (independent of exporters.colorimetry)."""
    if name == "A":
        return colour.sd_CIE_standard_illuminant_A(SHAPE_1NM)
    if name == "E":
        return colour.SpectralDistribution(dict.fromkeys(range(360, 831), 1.0))
    xy = colour.temperature.CCT_to_xy_CIE_D(6500 * 1.4388 / 1.4380)
    return colour.sd_CIE_illuminant_D_series(xy).copy().align(SHAPE_1NM)


def _smooth_spectra() -> list:
    """Analytic reflectances, evaluated at any wavelength (so the 1 nm reference is exact)."""
    return [
        lambda lam: 0.2 + 0.5 * np.exp(-(((lam - 600) / 80) ** 2)),
        lambda lam: 0.05 + 0.6 / (1 + np.exp(-(lam - 560) / 25)),  # skin-like rising edge
        lambda lam: 0.3 + 0.25 * np.sin(lam / 40.0),
    ]


@pytest.mark.parametrize("illuminant", ["D65", "A", "E"])
def test_xyz_matches_colour_science_integration(illuminant):
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(SHAPE_1NM)
    ill = _reference_illuminant(illuminant)
    lam_1nm = np.arange(360, 831, dtype=float)
    for spectrum in _smooth_spectra():
        sd = colour.SpectralDistribution(dict(zip(lam_1nm, spectrum(lam_1nm), strict=True)))
        reference = colour.sd_to_XYZ(sd, cmfs, ill, method="Integration") / 100.0
        ours = c.spectrum_to_xyz(spectrum(WAVELENGTHS_NM), illuminant)
        np.testing.assert_allclose(ours, reference, rtol=2e-4, atol=2e-5)


def test_uv_and_nir_samples_do_not_change_colour():
    spectrum = np.full(WAVELENGTHS_NM.size, 0.4)
    altered = spectrum.copy()
    altered[(WAVELENGTHS_NM < 360) | (WAVELENGTHS_NM > 830)] = 0.9
    np.testing.assert_array_equal(c.spectrum_to_xyz(spectrum), c.spectrum_to_xyz(altered))


@pytest.mark.parametrize(
    ("illuminant", "white"),
    [
        ("D65", (95.047, 100.0, 108.883)),  # CIE 15:2004 table
        ("A", (109.850, 100.0, 35.585)),  # CIE 15:2004 table
        ("E", (100.0, 100.0, 100.0)),
    ],
)
def test_white_points(illuminant, white):
    xyz = c.spectrum_to_xyz(np.ones(WAVELENGTHS_NM.size), illuminant) * 100
    np.testing.assert_allclose(xyz, white, atol=0.04)
    # a perfect white maps to sRGB white under every illuminant (CAT02 for A and E), Lab (100, 0, 0)
    np.testing.assert_allclose(c.spectrum_to_linear_srgb(np.ones(WAVELENGTHS_NM.size), illuminant), 1, atol=3e-4)
    np.testing.assert_allclose(c.spectrum_to_lab(np.ones(WAVELENGTHS_NM.size), illuminant), [100, 0, 0], atol=1e-6)


@pytest.mark.parametrize("illuminant", ["D65", "A", "E"])
def test_srgb_matches_colour_science(illuminant):
    rng = np.random.default_rng(1)
    xyz = rng.uniform(0.02, 0.9, size=(50, 3))
    # D65 spectra are taken as seen under sRGB's own white (no adaptation); A and E adapt from their white.
    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint if illuminant == "D65" else c.white_xy(illuminant)
    expected = colour.XYZ_to_sRGB(
        xyz, illuminant=white, chromatic_adaptation_transform="CAT02", apply_cctf_encoding=True
    )
    np.testing.assert_allclose(c.srgb_encode(c.xyz_to_linear_srgb(xyz, illuminant)), expected, atol=1e-10)


def test_srgb_transfer_function_known_values():
    # IEC 61966-2-1: the linear segment ends at 0.0031308 <-> 0.04045; 18 % grey encodes to 0.4613561.
    np.testing.assert_allclose(c.srgb_encode([0.0, 0.0031308, 0.18, 1.0]), [0.0, 0.04045, 0.4613561, 1.0], atol=2e-6)
    x = np.linspace(-0.2, 1.5, 101)
    np.testing.assert_allclose(c.srgb_decode(c.srgb_encode(x)), x, atol=1e-12)


def test_lab_and_delta_e():
    xyz = np.array([[0.2, 0.3, 0.4], [0.5, 0.4, 0.1]])
    lab = c.xyz_to_lab(xyz, "D65")
    np.testing.assert_allclose(lab, colour.XYZ_to_Lab(xyz, illuminant=c.white_xy("D65")), atol=1e-12)
    assert c.delta_e76(np.array([50.0, 0, 0]), np.array([50.0, 3, 4])) == pytest.approx(5.0)
    # Y = 0.18 is L* = 49.496 (CIE 1976 formula, 116 * 0.18^(1/3) - 16)
    assert c.xyz_to_lab(np.array([0.18 * 0.95047, 0.18, 0.18 * 1.08883]))[0] == pytest.approx(49.496, abs=1e-3)


def test_linear_srgb_round_trip_and_luminance():
    rgb = np.array([[0.1, 0.5, 0.9], [1.0, 1.0, 1.0]])
    xyz = c.linear_srgb_to_xyz(rgb)
    np.testing.assert_allclose(c.xyz_to_linear_srgb(xyz), rgb, atol=1e-12)
    np.testing.assert_allclose(xyz[:, 1], rgb @ c.SRGB_LUMINANCE, atol=2e-4)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_rejected(bad):
    spectrum = np.full(WAVELENGTHS_NM.size, 0.5)
    spectrum[10] = bad
    with pytest.raises(ValueError, match="NaN or Inf"):
        c.spectrum_to_xyz(spectrum)
    with pytest.raises(ValueError, match="NaN or Inf"):
        c.srgb_encode(np.array([0.1, bad]))


def test_wrong_length_and_illuminant_are_rejected():
    with pytest.raises(ValueError, match="376 samples"):
        c.spectrum_to_xyz(np.ones(300))
    with pytest.raises(ValueError, match="unknown illuminant"):
        c.spectrum_to_xyz(np.ones(376), "D50")
