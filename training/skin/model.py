"""The two-layer biophysical skin model (paper §3, docs/contracts.md §1), vectorised over tones in torch.

A tone is the biophysical vector p = (f_mel, f_blood, t_epi [cm], so2, b_mel).  The model gives, at the
376 wavelengths of ``exporters.constants.WAVELENGTHS_NM``, for an epidermis of thickness t_epi over a
semi-infinite dermis:

* epidermis  mu_a = f_mel * [b_mel mu_a,eu + (1 - b_mel) mu_a,pheo] + (1 - f_mel) * (mu_a,base + mu_a,car,epi)
* dermis     mu_a = f_blood * (mu_a,blood + mu_a,bili) + (1 - f_blood) * (mu_a,base + w mu_a,water + mu_a,car,derm)
  with mu_a,blood = so2 mu_a,HbO2 + (1 - so2) mu_a,Hb for whole blood (150 g/L haemoglobin);
* both layers mu_s = mu_s' / (1 - g), mu_s' of the spec (SKIN_MODEL: Jacques 2013 skin), g = 0.62 + 0.00029 lambda.

Scattering and anisotropy depend on the wavelength only; the tone changes absorption and the epidermis
thickness (the dataset's reweighting relies on this).  Sources and choices: training/skin/README.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from exporters.constants import PARAM_NAMES, WAVELENGTHS_NM, anisotropy
from training.skin import constants as k
from training.skin.chromophores import grid_spectra

LN10 = math.log(10.0)


@dataclass(frozen=True)
class SkinOptics:
    """Per-layer optical properties of a batch of B tones at W wavelengths (cm^-1; t_epi in cm)."""

    mua_epi: torch.Tensor  # (B, W)
    mus_epi: torch.Tensor  # (B, W)
    g_epi: torch.Tensor  # (B, W)
    mua_derm: torch.Tensor  # (B, W)
    mus_derm: torch.Tensor  # (B, W)
    g_derm: torch.Tensor  # (B, W)
    t_epi: torch.Tensor  # (B,)
    wavelength_nm: torch.Tensor  # (W,)


def _grid(dtype: torch.dtype, device: torch.device | str | None) -> torch.Tensor:
    return torch.tensor(np.array(WAVELENGTHS_NM), dtype=dtype, device=device)


def eumelanin_mua(wavelength_nm: torch.Tensor) -> torch.Tensor:
    """Eumelanin (melanosome) absorption, cm^-1: 6.6e11 lambda^-3.33 (Jacques 1998)."""
    return k.EUMELANIN_SCALE * wavelength_nm ** (-k.EUMELANIN_EXPONENT)


def pheomelanin_mua(wavelength_nm: torch.Tensor) -> torch.Tensor:
    """Pheomelanin absorption, cm^-1: 2.9e15 lambda^-4.75 (Donner & Jensen 2006)."""
    return k.PHEOMELANIN_SCALE * wavelength_nm ** (-k.PHEOMELANIN_EXPONENT)


def baseline_mua(wavelength_nm: torch.Tensor, spec: k.SkinModelSpec = k.SKIN_MODEL) -> torch.Tensor:
    """Bloodless-tissue baseline absorption, cm^-1: offset + amplitude exp(-(lambda - centre)/width) (spec's)."""
    b = spec.baseline
    return b.offset + b.amplitude * torch.exp(-(wavelength_nm - b.centre_nm) / b.width_nm)


def reduced_scattering(wavelength_nm: torch.Tensor, spec: k.SkinModelSpec = k.SKIN_MODEL) -> torch.Tensor:
    """Reduced scattering mu_s', cm^-1: a_500 [f_ray (l/500)^-4 + (1 - f_ray)(l/500)^-b_mie] (spec's law)."""
    s = spec.scattering
    x = wavelength_nm / 500.0
    return s.a_500 * (s.f_ray * x**-4.0 + (1.0 - s.f_ray) * x ** (-s.b_mie))


def _molar_mua(eps: np.ndarray, grams_per_litre: float, molar_mass: float, like: torch.Tensor) -> torch.Tensor:
    """mu_a [cm^-1] = ln(10) * eps [cm^-1 M^-1] * C [mol/L] on the grid, as a tensor like ``like``."""
    return torch.as_tensor(LN10 * eps * grams_per_litre / molar_mass, dtype=like.dtype, device=like.device)


def chromophore_mua(dtype: torch.dtype = torch.float64, device: torch.device | str | None = None,
                    spec: k.SkinModelSpec = k.SKIN_MODEL) -> dict:
    """Every fixed absorption spectrum of the model on the grid, cm^-1, each (W,).

    Keys: eumelanin, pheomelanin, baseline, hbo2, hb (whole blood), bilirubin_blood (in whole blood),
    carotene_epi, carotene_derm, water.
    """
    wl = _grid(dtype, device)
    data = grid_spectra()
    return {
        "eumelanin": eumelanin_mua(wl),
        "pheomelanin": pheomelanin_mua(wl),
        "baseline": baseline_mua(wl, spec),
        "hbo2": _molar_mua(data["eps_hbo2"], k.HB_CONCENTRATION_G_PER_L, k.HB_MOLAR_MASS, wl),
        "hb": _molar_mua(data["eps_hb"], k.HB_CONCENTRATION_G_PER_L, k.HB_MOLAR_MASS, wl),
        "bilirubin_blood": _molar_mua(data["eps_bilirubin"], k.BILIRUBIN_G_PER_L_BLOOD, k.BILIRUBIN_MOLAR_MASS, wl),
        "carotene_epi": _molar_mua(
            data["eps_beta_carotene"], k.BETA_CAROTENE_G_PER_L_EPIDERMIS, k.BETA_CAROTENE_MOLAR_MASS, wl
        ),
        "carotene_derm": _molar_mua(
            data["eps_beta_carotene"], k.BETA_CAROTENE_G_PER_L_DERMIS, k.BETA_CAROTENE_MOLAR_MASS, wl
        ),
        "water": torch.as_tensor(data["mua_water"], dtype=dtype, device=device),
    }


def validate_tones(tones: torch.Tensor | np.ndarray) -> torch.Tensor:
    """Return tones as a (B, 5) tensor, or raise ValueError naming the first bad parameter.

    Fractions (f_mel, f_blood, so2, b_mel) must lie in [0, 1]; t_epi must be a positive thickness in cm.
    """
    if isinstance(tones, torch.Tensor):
        t = tones if torch.is_floating_point(tones) else tones.to(torch.float64)
    else:  # lists and arrays in float64: float32 would round 0.2 to 0.2000000030
        t = torch.as_tensor(np.asarray(tones, dtype=np.float64))
    if t.ndim == 1:
        t = t[None]
    if t.ndim != 2 or t.shape[1] != len(PARAM_NAMES):
        raise ValueError(f"tones must have shape (B, 5) in the order {PARAM_NAMES}; got {tuple(t.shape)}.")
    if not torch.isfinite(t).all():
        raise ValueError("tones contain NaN or Inf.")
    for i, name in enumerate(PARAM_NAMES):
        col = t[:, i]
        if name == "t_epi":
            if (col <= 0).any() or (col > 1.0).any():
                raise ValueError(f"t_epi must be a thickness in cm in (0, 1] (e.g. 0.01 = 100 um); got {col.tolist()}.")
        elif (col < 0).any() or (col > 1).any():
            raise ValueError(f"{name} is a fraction and must lie in [0, 1]; got {col.tolist()}.")
    return t


def scattering(dtype: torch.dtype = torch.float64, device: torch.device | str | None = None,
               spec: k.SkinModelSpec = k.SKIN_MODEL):
    """Wavelength-only scattering of both layers: (mu_s (W,) cm^-1, g (W,)).  The same for every tone."""
    wl = _grid(dtype, device)
    g = torch.as_tensor(anisotropy(WAVELENGTHS_NM), dtype=dtype, device=device)
    return reduced_scattering(wl, spec) / (1.0 - g), g


def absorption(
    tones: torch.Tensor | np.ndarray, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None,
    spec: k.SkinModelSpec = k.SKIN_MODEL,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Absorption of the two layers for a batch of tones: (mu_a,epi (B, W), mu_a,derm (B, W)) in cm^-1."""
    t = validate_tones(tones).to(dtype=dtype, device=device)
    f_mel, f_blood, _, so2, b_mel = (t[:, i : i + 1] for i in range(5))
    c = chromophore_mua(dtype, device, spec)
    melanin = b_mel * c["eumelanin"] + (1.0 - b_mel) * c["pheomelanin"]
    mua_epi = f_mel * melanin + (1.0 - f_mel) * (c["baseline"] + c["carotene_epi"])
    blood = so2 * c["hbo2"] + (1.0 - so2) * c["hb"] + c["bilirubin_blood"]
    bloodless = c["baseline"] + spec.dermis_water_fraction * c["water"] + c["carotene_derm"]
    mua_derm = f_blood * blood + (1.0 - f_blood) * bloodless
    return mua_epi, mua_derm


def layer_optics(
    tones: torch.Tensor | np.ndarray, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None,
    spec: k.SkinModelSpec = k.SKIN_MODEL,
) -> SkinOptics:
    """Optical properties of both layers for tones (B, 5) or (5,), at all 376 wavelengths."""
    t = validate_tones(tones).to(dtype=dtype, device=device)
    mua_epi, mua_derm = absorption(t, dtype, device, spec)
    mus, g = scattering(dtype, device, spec)
    shape = mua_epi.shape
    return SkinOptics(
        mua_epi=mua_epi,
        mus_epi=mus.expand(shape),
        g_epi=g.expand(shape),
        mua_derm=mua_derm,
        mus_derm=mus.expand(shape),
        g_derm=g.expand(shape),
        t_epi=t[:, 2].clone(),
        wavelength_nm=_grid(dtype, device),
    )
