"""The validation metrics of paper §6 on spectra sampled at a subset of the 376-sample grid.

Definitions (our choices where the paper is silent are marked *choice*):

* **Colour** (Table 1): the total diffuse reflectance R_d(lambda) of a semi-infinite slab under uniform
  illumination is a flat image, so the gate's "D65 -> sRGB image" of a configuration is one colour.  R_d
  is rendered at the validation wavelengths, linearly interpolated onto the 2 nm grid inside 360-830 nm
  (flat beyond the first / last rendered wavelength; *choice*: renders every 4 nm by default), seen
  under D65 and converted to CIE Lab with D65's white (``exporters.colorimetry``; the Lab of the
  unclipped sRGB colour, identical to the sRGB-image route for in-gamut colours).  Delta E is CIE 1976.
* **Edge image** (*choice*, an addition to the paper's gate that sees translucency): the slab lit on the
  half-plane x < 0 only.  The exitance at a distance x from the light's edge is
  M(x) = sum_i profile_i * area_i * f(x, r_i) with f(x, r) = arccos(clip(x / r, -1, 1)) / pi the
  fraction of the circle of radius r around the pixel that is lit (plus the light beyond the last
  radial edge, at r = 5 cm).  Far into the light M = R_d; in the shadow only light carried under the
  edge arrives.  Pixels every ``EDGE_STEP_CM`` over +-``EDGE_HALF_WIDTH_CM`` (the paper's +-2 mm
  insets); Delta E76 per pixel (Lab with the white of a perfect reflector) averaged over the pixels.
* **SAM** (spectral angle): arccos(<a, b> / (|a| |b|)) over the validation wavelengths in the visible
  band, in radians; insensitive to a common scale.
* **Bands**: UV [250, 400) nm, Vis [400, 700) nm, NIR [700, 1000] nm (*choice* for the shared edges, the
  same as the fitter's summary, ``training.fit.dataset.BANDS``).
* **MC noise floor** of a Delta E: the mean Delta E between the ground truth's colour and the same colour
  perturbed by Gaussian noise with the combined standard errors of both renders (``NOISE_DRAWS`` draws):
  what a configuration that reproduced the ground truth exactly would score.
"""

from __future__ import annotations

import numpy as np

from exporters.colorimetry import delta_e76, spectrum_to_lab, spectrum_to_linear_srgb
from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM

#: Spectral bands of Table 2 (nm): name -> (low, high, include_low, include_high).
BANDS: dict[str, tuple[float, float, bool, bool]] = {
    "UV": (250.0, 400.0, True, False),
    "Vis": (400.0, 700.0, True, False),
    "NIR": (700.0, 1000.0, True, True),
}
#: Range of the colour matching functions (exporters.colorimetry.VISIBLE_MASK).
COLOUR_RANGE_NM: tuple[float, float] = (360.0, 830.0)
#: Edge image: half width and pixel step (cm): +-2 mm at 50 um.
EDGE_HALF_WIDTH_CM: float = 0.2
EDGE_STEP_CM: float = 0.005
#: Draws of the noise-floor estimate.
NOISE_DRAWS: int = 64


def band_mask(wavelength_nm: np.ndarray, band: str) -> np.ndarray:
    """Boolean mask (W,) of the wavelengths in ``band`` (a key of BANDS)."""
    if band not in BANDS:
        raise ValueError(f"unknown band {band!r}; use one of {list(BANDS)}.")
    lo, hi, inc_lo, inc_hi = BANDS[band]
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    above = wl >= lo if inc_lo else wl > lo
    below = wl <= hi if inc_hi else wl < hi
    return above & below


def _check_finite(name: str, x) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or Inf.")
    return a


def to_grid(values, wavelength_nm) -> np.ndarray:
    """Spectra (..., W) at ``wavelength_nm`` (W,) -> (..., 376) on the grid by linear interpolation, flat
    beyond the ends (only 360-830 nm matters for colour)."""
    v = _check_finite("spectrum", values)
    wl = _check_finite("wavelength_nm", wavelength_nm)
    if wl.ndim != 1 or v.shape[-1] != wl.size or wl.size < 1:
        raise ValueError(f"spectra {v.shape} do not match the {wl.size} wavelengths.")
    if wl.size > 1 and np.any(np.diff(wl) <= 0):
        raise ValueError("wavelengths must increase.")
    flat = v.reshape(-1, wl.size)
    out = np.stack([np.interp(WAVELENGTHS_NM, wl, row) for row in flat])
    return out.reshape(*v.shape[:-1], WAVELENGTHS_NM.size)


def lab(values, wavelength_nm) -> np.ndarray:
    """CIE Lab (..., 3) under D65 of reflectance spectra (..., W) at ``wavelength_nm``."""
    return spectrum_to_lab(to_grid(values, wavelength_nm), "D65")


def linear_srgb(values, wavelength_nm) -> np.ndarray:
    """Linear sRGB (..., 3) under D65 of reflectance spectra (..., W) at ``wavelength_nm``."""
    return spectrum_to_linear_srgb(to_grid(values, wavelength_nm), "D65")


def delta_e(a, b, wavelength_nm) -> np.ndarray:
    """Delta E76 between the D65 colours of spectra ``a`` and ``b`` (..., W)."""
    return delta_e76(lab(a, wavelength_nm), lab(b, wavelength_nm))


def noise_floor(reference, reference_se, other_se, wavelength_nm, *, seed: int = 0,
                draws: int = NOISE_DRAWS) -> float:
    """Mean Delta E76 that Monte Carlo noise alone produces (see the module docstring); (W,) inputs."""
    ref = _check_finite("reference", reference)
    se = np.hypot(_check_finite("reference_se", reference_se), _check_finite("other_se", other_se))
    rng = np.random.default_rng(seed)
    noisy = np.clip(ref + rng.standard_normal((draws, ref.size)) * se, 0.0, None)
    return float(np.mean(delta_e(noisy, np.broadcast_to(ref, noisy.shape), wavelength_nm)))


def spectral_angle(a, b, mask=None) -> float:
    """Spectral angle (radians) between spectra ``a`` and ``b`` (W,) over ``mask`` (default all)."""
    x, y = _check_finite("a", a), _check_finite("b", b)
    if mask is not None:
        x, y = x[mask], y[mask]
    nx, ny = np.linalg.norm(x), np.linalg.norm(y)
    if nx == 0 or ny == 0:
        raise ValueError("spectral angle of an all-zero spectrum is undefined.")
    return float(np.arccos(np.clip(np.dot(x, y) / (nx * ny), -1.0, 1.0)))


def edge_positions_cm(half_width_cm: float = EDGE_HALF_WIDTH_CM, step_cm: float = EDGE_STEP_CM) -> np.ndarray:
    """Pixel centres (cm) across the light's edge; negative = lit side."""
    n = int(round(half_width_cm / step_cm))
    return (np.arange(-n, n) + 0.5) * step_cm


def edge_exitance(profile, R_d, x_cm=None, r_edges_cm: np.ndarray = R_EDGES_CM) -> np.ndarray:
    """Exitance M(x, lambda) (P, W) of a slab lit on x < 0 with unit irradiance (module docstring).

    ``profile`` (W, NB) cm^-2 and ``R_d`` (W,) of one configuration (the light beyond the last edge,
    R_d - sum profile * area, is placed at the last edge)."""
    prof = _check_finite("profile", profile)
    r = _check_finite("R_d", R_d)
    x = edge_positions_cm() if x_cm is None else _check_finite("x_cm", x_cm)
    edges = np.asarray(r_edges_cm, dtype=np.float64)
    if prof.shape != (r.size, edges.size - 1):
        raise ValueError(f"profile must have shape (W, {edges.size - 1}), got {prof.shape}.")
    area = np.pi * np.diff(edges**2)
    centre = np.sqrt(0.5 * (edges[:-1] ** 2 + edges[1:] ** 2))  # the radius halving each annulus
    power = prof * area  # (W, NB): light leaving each annulus
    beyond = np.clip(r - power.sum(-1), 0.0, None)
    radii = np.r_[centre, edges[-1]]
    frac = np.arccos(np.clip(x[:, None] / radii[None], -1.0, 1.0)) / np.pi  # (P, NB + 1)
    return frac[:, :-1] @ power.T + frac[:, -1:] * beyond[None]


def edge_lab(profile, R_d, wavelength_nm, x_cm=None) -> np.ndarray:
    """Lab (P, 3) of the edge image's pixels under D65."""
    return lab(edge_exitance(profile, R_d, x_cm), wavelength_nm)


def edge_delta_e(profile_a, R_a, profile_b, R_b, wavelength_nm) -> float:
    """Mean over the edge image's pixels of Delta E76 between configurations a and b."""
    return float(np.mean(delta_e76(edge_lab(profile_a, R_a, wavelength_nm), edge_lab(profile_b, R_b, wavelength_nm))))


def relative_reduction(before: float, after: float) -> float:
    """1 - after / before (a fraction; 0.673 = 67.3 %)."""
    if not before > 0:
        raise ValueError("the reference error must be > 0 to express a reduction.")
    return float(1.0 - after / before)
