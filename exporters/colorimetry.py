"""Spectrum -> colour on the project's grid (docs/contracts.md §1): XYZ, linear sRGB, sRGB, CIE Lab, ΔE76.

Conventions (docs/contracts.md §1, docs/research/skin_optics.md §2):

* CIE 1931 2° colour-matching functions, integrated over 360-830 nm only (zero outside): 236 of the
  376 samples of ``WAVELENGTHS_NM``.  UV and NIR samples never contribute to colour.
* Illuminants: ``"D65"`` from the CIE daylight basis (colour-science's ``SDS_ILLUMINANTS['D65']``
  stops at 780 nm, so it is *not* used), ``"A"`` analytic, ``"E"`` equal energy.
* XYZ is normalised so that a perfect reflector has Y = 1 under every illuminant (domain 0-1).
* XYZ -> linear sRGB: IEC 61966-2-1 matrix (Rec. 709 primaries, D65 white); XYZ under A or E is first
  adapted to D65 with CAT02.  Lab uses the white of the illuminant the spectrum was seen under.

All matrices come from colour-science once (cached) so hot paths are plain matrix products:
no ``SpectralDistribution`` objects per call.  Every public function raises ``ValueError`` on
NaN or Inf input instead of returning NaN.
"""

from __future__ import annotations

from functools import cache
from typing import Literal

import numpy as np

from .constants import WAVELENGTHS_NM

Illuminant = Literal["D65", "A", "E"]
ILLUMINANTS: tuple[str, ...] = ("D65", "A", "E")
_OBSERVER = "CIE 1931 2 Degree Standard Observer"
#: Samples of the project grid that the CMFs cover (360-830 nm inclusive).
VISIBLE_MASK: np.ndarray = (WAVELENGTHS_NM >= 360.0) & (WAVELENGTHS_NM <= 830.0)
VISIBLE_MASK.setflags(write=False)
#: Rec. 709 luminance weights of linear sRGB (the Y row of the sRGB -> XYZ matrix).
SRGB_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _finite(x: np.ndarray | float, name: str) -> np.ndarray:
    """Return ``x`` as a float64 array, or raise ValueError naming ``name`` if any value is NaN/Inf."""
    arr = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or Inf; pass finite values (clean the input first).")
    return arr


def _result(x: np.ndarray, name: str) -> np.ndarray:
    """``x`` if every value is finite; ValueError if finite inputs overflowed float64 (values near 1e308)."""
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: the result overflows float64 (input values too large)")
    return x


def _check_illuminant(illuminant: str) -> None:
    if illuminant not in ILLUMINANTS:
        raise ValueError(f"unknown illuminant {illuminant!r}; use one of {ILLUMINANTS}.")


@cache
def illuminant_spd(illuminant: Illuminant) -> np.ndarray:
    """Relative spectral power of ``illuminant`` on the visible part of the grid, shape (236,)."""
    _check_illuminant(illuminant)
    import colour  # colour-science: imported lazily (about 1 s)

    wl = WAVELENGTHS_NM[VISIBLE_MASK]
    if illuminant == "E":
        return np.ones_like(wl)
    if illuminant == "A":
        shape = colour.SpectralShape(wl[0], wl[-1], 2)
        return colour.sd_CIE_standard_illuminant_A(shape).values.copy()
    # D65 from the daylight basis (to 830 nm); CCT corrected for the c2 change (1.4380 -> 1.4388).
    xy = colour.temperature.CCT_to_xy_CIE_D(6500.0 * 1.4388 / 1.4380)
    sd = colour.sd_CIE_illuminant_D_series(xy)
    # CIE 15: intermediate values of the daylight illuminants by linear interpolation.
    return np.interp(wl, sd.wavelengths, sd.values)


@cache
def xyz_weights(illuminant: Illuminant) -> np.ndarray:
    """Weights W (3, 376) such that ``XYZ = W @ R`` for a reflectance spectrum R on the full grid.

    Zero outside 360-830 nm; normalised so that R = 1 gives Y = 1.
    """
    import colour

    cmfs = colour.MSDS_CMFS[_OBSERVER]
    wl = WAVELENGTHS_NM[VISIBLE_MASK]
    xbar = cmfs[wl]  # exact 1 nm table values at the even wavelengths, shape (236, 3)
    weights = (xbar * illuminant_spd(illuminant)[:, None]).T
    weights /= weights[1].sum()
    full = np.zeros((3, WAVELENGTHS_NM.size))
    full[:, VISIBLE_MASK] = weights
    full.setflags(write=False)
    return full


@cache
def white_xy(illuminant: Illuminant) -> np.ndarray:
    """Chromaticity (x, y) of the illuminant's white, computed from the same weights as the spectra."""
    xyz = xyz_weights(illuminant).sum(axis=1)
    return xyz[:2] / xyz.sum()


@cache
def xyz_to_linear_srgb_matrix(illuminant: Illuminant) -> np.ndarray:
    """3x3 matrix: XYZ seen under ``illuminant`` -> linear sRGB (D65), with CAT02 for A and E."""
    import colour

    srgb = colour.RGB_COLOURSPACES["sRGB"]
    matrix = np.asarray(srgb.matrix_XYZ_to_RGB, dtype=np.float64)
    if illuminant != "D65":
        source = colour.xy_to_XYZ(white_xy(illuminant))
        target = colour.xy_to_XYZ(srgb.whitepoint)
        cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(source, target, transform="CAT02")
        matrix = matrix @ cat
    matrix.setflags(write=False)
    return matrix


def spectrum_to_xyz(reflectance: np.ndarray, illuminant: Illuminant = "D65") -> np.ndarray:
    """CIE XYZ (..., 3), Y of a perfect reflector = 1, of reflectance spectra (..., 376)."""
    _check_illuminant(illuminant)
    r = _finite(reflectance, "reflectance")
    if r.shape[-1:] != WAVELENGTHS_NM.shape:
        raise ValueError(f"reflectance must have {WAVELENGTHS_NM.size} samples on its last axis, got {r.shape}.")
    with np.errstate(over="ignore", invalid="ignore"):
        return _result(r @ xyz_weights(illuminant).T, "spectrum_to_xyz")


def xyz_to_linear_srgb(xyz: np.ndarray, illuminant: Illuminant = "D65") -> np.ndarray:
    """Linear sRGB (..., 3) of XYZ (..., 3) seen under ``illuminant`` (CAT02 to D65 for A and E)."""
    _check_illuminant(illuminant)
    with np.errstate(over="ignore", invalid="ignore"):
        return _result(_finite(xyz, "xyz") @ xyz_to_linear_srgb_matrix(illuminant).T, "xyz_to_linear_srgb")


def linear_srgb_to_xyz(rgb: np.ndarray) -> np.ndarray:
    """XYZ (D65, Y of white = 1) of linear sRGB values (..., 3)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _result(_finite(rgb, "rgb") @ np.linalg.inv(xyz_to_linear_srgb_matrix("D65")).T, "linear_srgb_to_xyz")


# The two sRGB curves are written out (IEC 61966-2-1, the same formulas as colour-science's eotf_sRGB /
# eotf_inverse_sRGB, compared in tests/test_colorimetry.py) because the add-on decodes albedo textures
# inside Blender, whose Python has numpy but not colour-science.


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """sRGB transfer function (IEC 61966-2-1) of linear values (negatives stay on the linear segment)."""
    x = _finite(linear, "linear sRGB")
    with np.errstate(invalid="ignore"):
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.abs(x) ** (1.0 / 2.4) - 0.055)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Inverse of :func:`srgb_encode`: sRGB-encoded values -> linear values."""
    v = _finite(encoded, "sRGB")
    with np.errstate(invalid="ignore", over="ignore"):
        return _result(np.where(v <= 0.04045, v / 12.92, ((np.abs(v) + 0.055) / 1.055) ** 2.4), "srgb_decode")


def xyz_to_lab(xyz: np.ndarray, illuminant: Illuminant = "D65") -> np.ndarray:
    """CIE L*a*b* (..., 3), L in 0-100, relative to the white of ``illuminant``."""
    import colour

    _check_illuminant(illuminant)
    return colour.XYZ_to_Lab(_finite(xyz, "xyz"), illuminant=white_xy(illuminant))


def delta_e76(lab_a: np.ndarray, lab_b: np.ndarray) -> np.ndarray:
    """CIE 1976 colour difference: Euclidean distance in Lab, shape (...) (computed without overflow of the
    squares; ValueError if the distance itself exceeds float64)."""
    a, b = _finite(lab_a, "lab_a"), _finite(lab_b, "lab_b")
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.abs(a - b)
        scale = np.max(d, axis=-1, keepdims=True) if d.shape[-1:] != (0,) else np.zeros(d.shape[:-1] + (1,))
        safe = np.where(scale > 0, scale, 1.0)
        dist = np.where(scale[..., 0] > 0, safe[..., 0] * np.sqrt(np.sum((d / safe) ** 2, axis=-1)), 0.0)
    return _result(dist, "delta_e76")


def spectrum_to_linear_srgb(reflectance: np.ndarray, illuminant: Illuminant = "D65") -> np.ndarray:
    """Linear sRGB (..., 3) of reflectance spectra (..., 376) under ``illuminant``."""
    return xyz_to_linear_srgb(spectrum_to_xyz(reflectance, illuminant), illuminant)


def spectrum_to_srgb(reflectance: np.ndarray, illuminant: Illuminant = "D65") -> np.ndarray:
    """sRGB-encoded colour (..., 3) of reflectance spectra; not clipped (clip for display only)."""
    return srgb_encode(spectrum_to_linear_srgb(reflectance, illuminant))


def spectrum_to_lab(reflectance: np.ndarray, illuminant: Illuminant = "D65") -> np.ndarray:
    """CIE Lab (..., 3) of reflectance spectra under ``illuminant`` (white of that illuminant)."""
    return xyz_to_lab(spectrum_to_xyz(reflectance, illuminant), illuminant)


def linear_srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIE Lab (D65 white) of linear sRGB values (..., 3): how the add-on's inputs are compared."""
    return xyz_to_lab(linear_srgb_to_xyz(rgb), "D65")
