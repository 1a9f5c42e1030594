"""Fit targets at every wavelength: linear interpolation along wavelength in Dec_T's unit space.

The fits exist at every ``fit --wavelength-stride``-th wavelength.  Supervising Dec_T there only left
the wavelengths between them to the reflectance and smoothness terms, and the decoder learnt a comb
(its parameters jump at the fitted wavelengths: ``training.validate.coherence``).  Stage 3 therefore
compares Dec_T with targets at all 376 wavelengths, interpolated linearly from the fitted ones in the
normalised coordinates u in which L_param compares (``TranslucencyDecoder.to_unit``: alpha, g on its
range, ln sigma_t on its range, weight): sigma_t is interpolated geometrically, and the interpolated
weights still sum to 1.  Beyond the first and last fitted wavelength the nearest one is repeated.
The targets must be matched along wavelength (``training.fit.matching``) for this to interpolate one
medium, not two.
"""

from __future__ import annotations

import numpy as np
import torch


def interpolation_matrix(index: np.ndarray | torch.Tensor, n: int) -> torch.Tensor:
    """(Wf, n) float32 matrix M such that ``x @ M`` linearly interpolates values ``x`` (..., Wf) given at the
    increasing wavelength indices ``index`` (Wf,) to every index 0..n-1 (constant beyond the ends)."""
    idx = np.asarray(index, dtype=np.float64)
    if idx.ndim != 1 or idx.size == 0 or np.any(np.diff(idx) <= 0) or idx[0] < 0 or idx[-1] >= n:
        raise ValueError(f"index must be increasing integers within 0..{n - 1}, got {idx[:5]}...")
    eye = np.eye(idx.size)
    grid = np.arange(n, dtype=np.float64)
    # column j of M holds the interpolation weights of the fitted values at grid point j
    m = np.stack([np.interp(grid, idx, eye[i]) for i in range(idx.size)])
    return torch.as_tensor(m, dtype=torch.float32)


def interpolate(u: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """u (..., Wf) at the fitted wavelengths -> (..., n) at every wavelength (``interpolation_matrix``)."""
    return u @ matrix.to(dtype=u.dtype, device=u.device)
