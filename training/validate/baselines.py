"""RGB albedo-inversion baselines of production renderers, as per-wavelength media for the gate.

Both take what an artist has: the skin's RGB albedo (linear sRGB, D65; here the ground truth's colour)
and one fixed RGB scattering radius, and make one homogeneous medium per colour channel.

* **Chiang 2016** (Chiang, Kutz, Burley, "Practical and Controllable Subsurface Scattering for Production
  Path Tracing", SIGGRAPH Talks 2016; Cycles <= 2.93 "Random Walk"): isotropic (g = 0);
  single-scattering albedo from the albedo A by an inversion of the slab's reflectance; extinction
  sigma_t = 1 / (d s(A)) with the scattering distance d = the radius and Burley's
  s(A) = 1.9 - A + 3.5 (A - 0.8)^2.
* **Wrenninge 2017** (Wrenninge, Villemin, Hery, "Path Traced Subsurface Scattering using Anisotropic
  Phase Functions and Non-Exponential Free Flights", Pixar TM 17-07; Cycles >= 3.0 "Random Walk"):
  anisotropic, g = ``WRENNINGE_G``; albedo inverted at that g; sigma_t = 1 / (d (1 - g)) with
  d = radius / (4 pi) (Cycles 5.0's mapping, ``exporters.cycles.rw_sigma_t_from_radius``).

**The albedo inversion** is done *exactly for the gate's boundary* (n = 1.4 smooth Fresnel, diffuse
light, specular excluded: ``exporters.reflectance_tables.albedo_for_reflectance("model", A, g)``),
i.e. each method's best case.  The published polynomials (Chiang's
alpha = 1 - exp(-5.09406 A + 2.61188 A^2 - 4.31805 A^3), Wrenninge's fit in ``exporters.cycles``) were
fitted for their renderers' index-matched boundaries; under ours they render much darker
(:func:`published_darkening` measures by how much), which would only add a colour error that has
nothing to do with translucency.

**RGB -> spectrum** (*choice*): the albedo A(lambda) and the radius r(lambda) are upsampled with
Mallett & Yuksel 2019 (colour-science's sRGB basis: three non-negative spectra summing to one, so a
reflectance in [0, 1]^3 stays in [0, 1] and its D65 colour is reproduced); the basis is defined on
380-780 nm and held flat beyond.  Each wavelength then gets its own medium.  Outside the visible band
the baselines define nothing meaningful (they are RGB methods), so UV / NIR metrics skip them.

**The radius** (*choice*): Blender's default Subsurface Radius (1.0, 0.2, 0.1) times one Subsurface
Scale S (metres, scene unit 1 m).  S is either given or calibrated once per method on one medium
tone (:func:`calibrate_scale`: the S that minimises the visible-band profile shape error against
the Monte Carlo ground truth through the LUT), the fixed "artist" setting then used for every tone.
Blender's own default scale is 0.05 m (``BLENDER_DEFAULT_SCALE_M``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import torch

from exporters import cycles, reflectance_tables
from training.validate.metrics import band_mask

#: Blender's default Subsurface Radius of the Principled BSDF (R, G, B), multiplied by the Subsurface Scale.
BLENDER_RADIUS: tuple[float, float, float] = (1.0, 0.2, 0.1)
#: Blender's default Subsurface Scale (m).
BLENDER_DEFAULT_SCALE_M: float = 0.05
#: Anisotropy of the Wrenninge baseline: the skin model's g(lambda) = 0.62 + 0.00029 lambda near 620 nm,
#: where skin's translucency shows (0.78 at 550 nm, 0.82 at 700 nm).
WRENNINGE_G: float = 0.8
#: Scales searched by the calibration (m).
CALIBRATION_SCALES_M: np.ndarray = np.geomspace(1e-4, 0.3, 40)
METHODS: tuple[str, ...] = ("chiang2016", "wrenninge2017")
LABELS: dict[str, str] = {"chiang2016": "Chiang 2016 (isotropic albedo inversion)",
                          "wrenninge2017": f"Wrenninge 2017 (albedo inversion, g = {WRENNINGE_G})"}


@cache
def _basis() -> tuple[np.ndarray, np.ndarray]:
    from colour.recovery import MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019 as basis

    return np.asarray(basis.wavelengths, dtype=np.float64), np.asarray(basis.values, dtype=np.float64)


def upsample(rgb, wavelength_nm) -> np.ndarray:
    """Spectra (..., W) at ``wavelength_nm`` from linear-sRGB triples (..., 3) (Mallett & Yuksel 2019)."""
    x = np.asarray(rgb, dtype=np.float64)
    if x.shape[-1] != 3 or not np.all(np.isfinite(x)):
        raise ValueError(f"rgb must be finite (..., 3) triples, got shape {x.shape}.")
    wl_b, b = _basis()
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    at = np.stack([np.interp(wl, wl_b, b[:, c]) for c in range(3)], axis=-1)  # (W, 3)
    return x @ at.T


def burley_s(albedo) -> np.ndarray:
    """Burley's scaling factor s(A) = 1.9 - A + 3.5 (A - 0.8)^2 (Chiang et al. 2016)."""
    a = np.asarray(albedo, dtype=np.float64)
    return 1.9 - a + 3.5 * (a - 0.8) ** 2


def chiang_published_alpha(albedo) -> np.ndarray:
    """Chiang et al. 2016's polynomial fit alpha(A) (for their renderer's boundary; not used by the gate)."""
    a = np.asarray(albedo, dtype=np.float64)
    return 1.0 - np.exp(a * (-5.09406 + a * (2.61188 - 4.31805 * a)))


@dataclass(frozen=True)
class BaselineMedium:
    """One homogeneous medium per wavelength: ``alpha``, ``sigma_t`` (cm^-1), ``g`` (W,); the upsampled
    albedo ``albedo`` (W,) and radius ``radius_m`` (W,) it came from."""

    alpha: np.ndarray
    sigma_t: np.ndarray
    g: np.ndarray
    albedo: np.ndarray
    radius_m: np.ndarray


def _check(method: str, scale_m: float) -> None:
    if method not in METHODS:
        raise ValueError(f"unknown baseline {method!r}; use one of {METHODS}.")
    if not (np.isfinite(scale_m) and scale_m > 0):
        raise ValueError(f"the Subsurface Scale must be a positive number of metres, got {scale_m}.")


def baseline_medium(method: str, albedo_rgb, scale_m: float, wavelength_nm) -> BaselineMedium:
    """The per-wavelength medium of ``method`` for one linear-sRGB albedo (3,) and Subsurface Scale (m)."""
    _check(method, scale_m)
    a_rgb = np.asarray(albedo_rgb, dtype=np.float64)
    if a_rgb.shape != (3,) or not np.all(np.isfinite(a_rgb)) or a_rgb.min() < 0 or a_rgb.max() > 1:
        raise ValueError(f"albedo_rgb must be 3 linear-sRGB values in [0, 1], got {a_rgb.tolist()}.")
    albedo = np.clip(upsample(a_rgb, wavelength_nm), 0.0, 1.0)
    radius_m = upsample(np.asarray(BLENDER_RADIUS) * scale_m, wavelength_nm)
    g = 0.0 if method == "chiang2016" else WRENNINGE_G
    alpha = reflectance_tables.albedo_for_reflectance("model", albedo, g)
    if method == "chiang2016":
        sigma_t = 1.0 / (radius_m * cycles.CM_PER_M * burley_s(albedo))
    else:
        sigma_t = cycles.rw_sigma_t_from_radius(radius_m, g, unit_scale_m=1.0)
    return BaselineMedium(alpha=alpha, sigma_t=sigma_t, g=np.full_like(alpha, g), albedo=albedo, radius_m=radius_m)


def published_darkening(method: str, albedo_rgb, wavelength_nm) -> float:
    """Visible-band mean of R_gate(alpha_published(A)) / A: how much darker the published polynomial's
    medium renders under the gate's boundary than the albedo it was given (1 = exact)."""
    _check(method, 1.0)
    albedo = np.clip(upsample(np.asarray(albedo_rgb, dtype=np.float64), wavelength_nm), 1e-6, 1.0)
    if method == "chiang2016":
        g, alpha = 0.0, chiang_published_alpha(albedo)
    else:
        g, alpha = WRENNINGE_G, cycles.rw_albedo_forward(albedo, WRENNINGE_G)
    r = reflectance_tables.reflectance("model", alpha, g)
    vis = band_mask(wavelength_nm, "Vis")
    return float(np.mean(r[vis] / albedo[vis]))


def lut_shape_error(lut, medium: BaselineMedium, target, rows: np.ndarray) -> float:
    """Mean L_shape (training.fit.loss) of one medium per wavelength against MC targets, over ``rows``."""
    from training.fit import loss as fit_loss

    dt = lut.P.dtype
    t = target.rows(torch.as_tensor(rows))
    p = lut.profile(t.r_cm, torch.as_tensor(medium.alpha[rows], dtype=dt), torch.as_tensor(medium.g[rows], dtype=dt),
                    torch.as_tensor(medium.sigma_t[rows], dtype=dt))
    return float(fit_loss.shape_loss(p, t).mean())


def calibrate_scale(method: str, lut, albedo_rgb, wavelength_nm, target,
                    scales_m: np.ndarray = CALIBRATION_SCALES_M) -> tuple[float, list[float]]:
    """The Subsurface Scale (m) of ``scales_m`` that minimises the visible-band mean profile shape error of
    ``method``'s medium against one tone's MC targets (``training.fit.loss.Target`` of its profiles at
    ``wavelength_nm``); returns (best scale, the errors at every scale)."""
    rows = np.flatnonzero(band_mask(wavelength_nm, "Vis"))
    if rows.size == 0:
        raise ValueError("calibration needs validation wavelengths in the visible band (400-700 nm).")
    errors = [lut_shape_error(lut, baseline_medium(method, albedo_rgb, float(s), wavelength_nm), target, rows)
              for s in scales_m]
    return float(scales_m[int(np.argmin(errors))]), [float(e) for e in errors]
