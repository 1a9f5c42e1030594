"""Tone sampling (docs/contracts.md §1): scrambled Halton for training, uniform random for validation.

Both draw points of the unit cube (Halton's low discrepancy is the stratification: every coordinate's
marginal is evenly covered, and so is every 2-D projection) and map them onto the biophysical ranges
with ``unit_to_tones``:

* **log scale for the melanin and blood fractions** (``LOG_SCALED``), linear for t_epi, so2 and b_mel.
  Colour responds to a fraction roughly through its logarithm (light skin differs from very light skin by
  a factor of a few in f_mel, not by 0.3 in it): drawn uniformly, 43 % of the tones were near-black
  (L* < 10) and 20 % had skin colours (L* 25-75, hue 20-80 deg); log-uniform over the same box, 9-10 %
  and 67 %.
* **a skin core**: a share ``CORE_SHARE`` of the tones (picked by a sixth coordinate) is drawn from
  ``CORE_RANGES``, the part of the box where the model's colours are skin's (f_mel <= 0.2, L* >~ 25 in
  this model; f_blood in the physiological 0.2-7 %), the rest from the whole box (``PARAM_RANGES``),
  which stays covered.  Together: about 7 % near-black and 73 % skin colours
  (``python -m training.realskin.distribution``; docs/research/dataset.md).

The epidermis thickness is then snapped to ``T_EPI_LEVELS_CM`` so that every stored tone is simulated
exactly at its stored thickness, and tones of one level share scattering trajectories.
"""

from __future__ import annotations

import numpy as np

from exporters.constants import PARAM_NAMES, PARAM_RANGES

#: Quantised epidermis thicknesses, cm: 16 levels from 50 to 350 um in 20 um steps.
T_EPI_LEVELS_CM: np.ndarray = np.round(np.linspace(0.005, 0.035, 16), 6)
T_EPI_LEVELS_CM.setflags(write=False)
#: Lower and upper bounds (5,) of the biophysical vector, docs/contracts.md §1 order (its default sampling ranges).
PARAM_LOW = np.array([PARAM_RANGES[name][0] for name in PARAM_NAMES])
PARAM_HIGH = np.array([PARAM_RANGES[name][1] for name in PARAM_NAMES])
#: Parameters drawn log-uniformly over their range (the others uniformly).
LOG_SCALED: tuple[str, ...] = ("f_mel", "f_blood")
_LOG = np.array([name in LOG_SCALED for name in PARAM_NAMES])
#: Share of the tones drawn from the skin core ``CORE_RANGES`` instead of the whole box.
CORE_SHARE = 0.25
#: The skin core: the whole box but f_mel <= 0.2 (L* >~ 25 in this model: f_mel 0.15 gives R ~ 0.044 in the
#: visible, docs/research/training.md, "Physical trends") and f_blood 0.002-0.07 (physiological blood
#: volume fraction, Jacques 2013
#: PMB 58:R37 Table 3 and the skin-optics notes' 0.2-7 %).
CORE_RANGES: dict[str, tuple[float, float]] = {**PARAM_RANGES, "f_mel": (0.001, 0.2), "f_blood": (0.002, 0.07)}
CORE_LOW = np.array([CORE_RANGES[name][0] for name in PARAM_NAMES])
CORE_HIGH = np.array([CORE_RANGES[name][1] for name in PARAM_NAMES])
#: Coordinates of a sampling point: the five parameters and the core/box selector.
N_UNIT = len(PARAM_NAMES) + 1
_T_EPI = PARAM_NAMES.index("t_epi")


def quantise_thickness(tones: np.ndarray) -> np.ndarray:
    """Copy of ``tones`` (N, 5) with t_epi snapped to the nearest level of ``T_EPI_LEVELS_CM``."""
    out = np.array(tones, dtype=np.float64, copy=True)
    nearest = np.abs(out[:, _T_EPI, None] - T_EPI_LEVELS_CM[None]).argmin(axis=1)
    out[:, _T_EPI] = T_EPI_LEVELS_CM[nearest]
    return out


def unit_to_tones(unit: np.ndarray, skin_weighted: bool = True) -> np.ndarray:
    """Tones (N, 5) of points ``unit`` (N, ``N_UNIT``) of the unit cube (module docstring): the last
    coordinate below ``CORE_SHARE`` picks the skin core, the first five place the tone in its ranges,
    log-uniformly for the ``LOG_SCALED`` fractions; t_epi quantised.  ``skin_weighted=False``: uniform over
    ``PARAM_RANGES`` (the selector is ignored)."""
    u = np.asarray(unit, dtype=np.float64)
    if u.ndim != 2 or u.shape[1] != N_UNIT:
        raise ValueError(f"unit points must have shape (N, {N_UNIT}); got {u.shape}")
    p = u[:, : len(PARAM_NAMES)]
    if not skin_weighted:
        return quantise_thickness(PARAM_LOW + p * (PARAM_HIGH - PARAM_LOW))
    core = (u[:, -1] < CORE_SHARE)[:, None]
    lo, hi = np.where(core, CORE_LOW, PARAM_LOW), np.where(core, CORE_HIGH, PARAM_HIGH)
    tones = lo + p * (hi - lo)
    tones[:, _LOG] = np.exp(np.log(lo[:, _LOG]) + p[:, _LOG] * np.log(hi[:, _LOG] / lo[:, _LOG]))
    return quantise_thickness(np.clip(tones, lo, hi))  # exp(log(x)) may round a hair outside


def training_tones(n: int, seed: int, skin_weighted: bool = True) -> np.ndarray:
    """``n`` training tones (n, 5): scrambled Halton through ``unit_to_tones``."""
    if n < 1:
        raise ValueError(f"need at least one tone, got n={n}")
    from scipy.stats import qmc  # here, not at the top: scipy.stats takes ~1.5 s to import, and every command that
    # builds a model imports this module

    return unit_to_tones(qmc.Halton(d=N_UNIT, scramble=True, seed=seed).random(n), skin_weighted)


def validation_tones(n: int, seed: int, skin_weighted: bool = True) -> np.ndarray:
    """``n`` validation tones (n, 5): uniform random points through ``unit_to_tones`` (seed differs from
    training)."""
    if n < 1:
        raise ValueError(f"need at least one tone, got n={n}")
    return unit_to_tones(np.random.default_rng(seed).random((n, N_UNIT)), skin_weighted)
