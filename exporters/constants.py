"""Grids, units and tissue conventions shared by every part of the project (docs/contracts.md §1).

Units: coefficients (mu_a, mu_s, sigma_t) in cm^-1; lengths, thicknesses and radii in cm unless a
name says otherwise (``_m``, ``_mfp``, ``_nm``).  Defined once here (torch-free) and imported everywhere.
"""

from __future__ import annotations

import numpy as np

#: Spectral grid: 250, 252, ..., 1000 nm (376 samples).  docs/contracts.md §1.
WAVELENGTH_STEP_NM: float = 2.0
WAVELENGTHS_NM: np.ndarray = np.arange(250.0, 1000.0 + 1e-9, WAVELENGTH_STEP_NM)
WAVELENGTHS_NM.setflags(write=False)
N_WAVELENGTHS: int = WAVELENGTHS_NM.size  # 376

#: Radial profile binning: 512 bins, r_edges[0] = 0, r_edges[1:] log-spaced 1e-4 .. 5 cm.  docs/contracts.md §1.
N_RADIAL_BINS: int = 512
R_MIN_CM: float = 1e-4
R_MAX_CM: float = 5.0


def radial_edges(r_min: float = R_MIN_CM, r_max: float = R_MAX_CM, n_bins: int = N_RADIAL_BINS) -> np.ndarray:
    """Radial bin edges, shape (n_bins + 1,): 0 followed by ``n_bins`` log-spaced edges from r_min to r_max.

    With the defaults these are the profile edges of docs/contracts.md §1 in cm; the LUT uses the same numbers in
    mean free paths (sigma_t = 1).
    """
    return np.concatenate([[0.0], np.geomspace(r_min, r_max, n_bins)])


R_EDGES_CM: np.ndarray = radial_edges()
R_EDGES_CM.setflags(write=False)

#: Radial edges of the homogeneous lookup tables at sigma_t = 1, in mean free paths: 0, then 512 bins
#: log-spaced from 1e-3 to 1e4 mfp.  Profiles at sigma_t = 1 reach tens of mfp at high albedo (the
#: diffusion length is ~40 mfp at albedo 0.999, g = 0.8), and scaling by sigma_t = 10..1e4 cm^-1 must
#: cover r = 1e-4..5 cm: the cm edges (1e-4..5) would hold only 18 % of R at albedo 0.999.
R_EDGES_MFP: np.ndarray = radial_edges(1e-3, 1e4)
R_EDGES_MFP.setflags(write=False)

#: One refractive index for epidermis and dermis, air above (Donner & Jensen 2006; docs/contracts.md §1).
N_TISSUE: float = 1.4

#: Biophysical vector p, in this order (docs/contracts.md §1).
PARAM_NAMES: tuple[str, ...] = ("f_mel", "f_blood", "t_epi", "so2", "b_mel")
#: Default sampling ranges (deliberately wider than normal skin, as in the paper).  t_epi in cm.
PARAM_RANGES: dict[str, tuple[float, float]] = {
    "f_mel": (0.001, 0.65),
    "f_blood": (0.001, 0.25),
    "t_epi": (0.005, 0.035),
    "so2": (0.5, 1.0),
    "b_mel": (0.0, 1.0),
}


def anisotropy(wavelength_nm: np.ndarray) -> np.ndarray:
    """Henyey-Greenstein g(lambda) = 0.62 + 0.00029 * lambda[nm] (van Gemert et al. 1989; docs/contracts.md §1)."""
    return 0.62 + 0.00029 * np.asarray(wavelength_nm, dtype=np.float64)
