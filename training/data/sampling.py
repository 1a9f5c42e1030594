"""Tone sampling (SPEC §1): scrambled Halton for training, uniform random for validation.

Both sample the default ranges of ``exporters.constants.PARAM_RANGES`` uniformly (Halton's low
discrepancy is the stratification: every parameter's marginal is evenly covered, and so is every
2-D projection).  The epidermis thickness is then snapped to ``T_EPI_LEVELS_CM`` so that every stored
tone is simulated exactly at its stored thickness, and tones of one level share scattering trajectories.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from exporters.constants import PARAM_NAMES, PARAM_RANGES

#: Quantised epidermis thicknesses, cm: 16 levels from 50 to 350 um in 20 um steps.
T_EPI_LEVELS_CM: np.ndarray = np.round(np.linspace(0.005, 0.035, 16), 6)
T_EPI_LEVELS_CM.setflags(write=False)
#: Lower and upper bounds (5,) of the biophysical vector in SPEC order (the default sampling ranges).
PARAM_LOW = np.array([PARAM_RANGES[name][0] for name in PARAM_NAMES])
PARAM_HIGH = np.array([PARAM_RANGES[name][1] for name in PARAM_NAMES])
_T_EPI = PARAM_NAMES.index("t_epi")


def quantise_thickness(tones: np.ndarray) -> np.ndarray:
    """Copy of ``tones`` (N, 5) with t_epi snapped to the nearest level of ``T_EPI_LEVELS_CM``."""
    out = np.array(tones, dtype=np.float64, copy=True)
    nearest = np.abs(out[:, _T_EPI, None] - T_EPI_LEVELS_CM[None]).argmin(axis=1)
    out[:, _T_EPI] = T_EPI_LEVELS_CM[nearest]
    return out


def training_tones(n: int, seed: int) -> np.ndarray:
    """``n`` training tones (n, 5): scrambled Halton over the SPEC ranges, t_epi quantised."""
    if n < 1:
        raise ValueError(f"need at least one tone, got n={n}")
    unit = qmc.Halton(d=len(PARAM_NAMES), scramble=True, seed=seed).random(n)
    return quantise_thickness(PARAM_LOW + unit * (PARAM_HIGH - PARAM_LOW))


def validation_tones(n: int, seed: int) -> np.ndarray:
    """``n`` validation tones (n, 5): uniform random over the SPEC ranges (seed differs from training)."""
    if n < 1:
        raise ValueError(f"need at least one tone, got n={n}")
    unit = np.random.default_rng(seed).random((n, len(PARAM_NAMES)))
    return quantise_thickness(PARAM_LOW + unit * (PARAM_HIGH - PARAM_LOW))
