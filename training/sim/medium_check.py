"""The value checks of a layered medium (``training.sim.medium.LayeredMedium``) on plain arrays, torch-free."""

from __future__ import annotations

import math

import numpy as np


def check_layer_values(mua: np.ndarray, mus: np.ndarray, g: np.ndarray, thickness: np.ndarray,
                       n_medium: float, n_below: float) -> None:
    """Raise ValueError unless the properties describe a medium the walker can simulate.

    mua, mus (L, W) cm^-1 >= 0, g (L, W) in [-0.99, 0.99], all finite; thickness (L,) cm > 0, only the last
    may be inf, and a semi-infinite last layer needs mua + mus > 0 in every channel; n_medium, n_below in [1, 3].
    Shapes are the caller's to check.
    """
    for name, a in (("mua", mua), ("mus", mus), ("g", g)):
        if not np.isfinite(a).all():
            raise ValueError(f"{name} contains NaN or Inf")
    if (mua < 0).any() or (mus < 0).any():
        raise ValueError("mua and mus must be >= 0 (cm^-1)")
    if (np.abs(g) > 0.99 + 1e-6).any():
        raise ValueError("g must lie in [-0.99, 0.99]")
    if np.isnan(thickness).any() or (thickness <= 0).any():
        raise ValueError("layer thicknesses must be > 0 cm")
    if np.isinf(thickness[:-1]).any():
        raise ValueError("only the last layer may be semi-infinite (thickness inf)")
    if np.isinf(thickness[-1]) and (mua[-1] + mus[-1] <= 0).any():
        raise ValueError("a semi-infinite last layer needs mua + mus > 0 in every channel")
    for name, v in (("n_medium", float(n_medium)), ("n_below", float(n_below))):
        if not (math.isfinite(v) and 1.0 <= v <= 3.0):
            raise ValueError(f"{name} must be a refractive index in [1, 3], got {v}")
