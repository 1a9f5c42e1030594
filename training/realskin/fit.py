"""Least-squares fits of the biophysical parameters to measured spectra (training.realskin).

Each subject's spectrum y (C,) is fitted over ``FIT_BAND_NM`` by

* exposure fixed at 1:  min_p  || F(p) - y ||
* exposure free:        min_{p, s}  || S + s (F(p) - S) - y ||   (s scales the subsurface part; the
  specular S is the surface's, not the tissue's)
* optionally with a per-subject scattering scale k (``scale_range``): F(p, k), both layers' scattering times k
  (``MonteCarloForward`` takes k as a sixth tone column) — a diagnostic of the model's missing degrees of freedom

with F a forward model (``forward``) and p inside the docs/contracts.md §1 box.  Search space: log f_mel, log f_blood
(colour is most sensitive at small fractions), t_epi, so2, b_mel (then log k, log s where fitted).  Starts:
the best of 1,024 scrambled-Halton tones for each subject (evaluated once for all subjects), then scipy's bounded
trust-region least squares from the best three; its Jacobian is taken by forward differences, all six
(seven) points in one batched forward call.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import least_squares
from scipy.stats import qmc

from training.data.sampling import PARAM_HIGH, PARAM_LOW

#: Wavelengths fitted (and the acceptance's RMSE band), nm.
FIT_BAND_NM = (400.0, 1000.0)
#: Reported bands, nm (lower edge included, upper excluded except for the last).
BANDS_NM: dict[str, tuple[float, float]] = {
    "uv": (250.0, 400.0), "vis": (400.0, 700.0), "nir": (700.0, 1000.0), "400_1000": (400.0, 1000.0),
}
#: Exposure search range of the free fit (a factor on the subsurface reflectance).
EXPOSURE_RANGE = (0.2, 5.0)
N_CANDIDATES = 1024
N_STARTS = 3
#: Extra starting scattering scales of the best start when k is fitted.
SCALE_STARTS = (0.8, 1.25)
_LOG = (0, 1)  # f_mel and f_blood are searched in log space

Forward = Callable[[torch.Tensor], torch.Tensor]


@dataclass
class SubjectFit:
    """One subject's fit: tone p (5,), exposure (1 when fixed), model spectrum (C,), RMSE per band, scattering
    scale k (None when not fitted)."""

    name: str
    p: np.ndarray
    exposure: float
    model: np.ndarray
    rmse: dict[str, float]
    scattering_scale: float | None = None


def band_rmse(model: np.ndarray, measured: np.ndarray, wavelength_nm: np.ndarray) -> dict[str, float]:
    """RMSE of model - measured (C,) in each band of ``BANDS_NM`` (NaN for a band without samples)."""
    out = {}
    for name, (lo, hi) in BANDS_NM.items():
        m = (wavelength_nm >= lo) & ((wavelength_nm < hi) if hi < FIT_BAND_NM[1] else (wavelength_nm <= hi))
        out[name] = float(np.sqrt(np.mean((model[m] - measured[m]) ** 2))) if m.any() else float("nan")
    return out


def at_edge(p: np.ndarray, tol: float = 0.02) -> np.ndarray:
    """Which fitted parameters (..., 5) lie within ``tol`` of their search range's width from an edge.

    Measured in the search space: log f_mel and log f_blood (a fraction of 0.0012 is at the 0.001 edge,
    0.01 is not), linear t_epi, so2 and b_mel.
    """
    lo, hi = _x_bounds(False)
    x = np.array(p, dtype=np.float64, copy=True)
    x[..., _LOG] = np.log(x[..., _LOG])
    w = tol * (hi - lo)
    return (x - lo < w) | (hi - x < w)


def _to_p(x: np.ndarray) -> np.ndarray:
    p = np.array(x[..., :5], dtype=np.float64, copy=True)
    p[..., _LOG] = np.exp(p[..., _LOG])
    return p


def _x_bounds(free: bool, scale_range: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Search box: log f_mel, log f_blood, t_epi, so2, b_mel, [log k], [log exposure]."""
    lo, hi = PARAM_LOW.copy(), PARAM_HIGH.copy()
    lo[list(_LOG)], hi[list(_LOG)] = np.log(lo[list(_LOG)]), np.log(hi[list(_LOG)])
    if scale_range is not None:
        lo, hi = np.r_[lo, np.log(scale_range[0])], np.r_[hi, np.log(scale_range[1])]
    if free:
        lo, hi = np.r_[lo, np.log(EXPOSURE_RANGE[0])], np.r_[hi, np.log(EXPOSURE_RANGE[1])]
    return lo, hi


def _evaluate(forward: Forward, x: np.ndarray, specular: float, free: bool = False, scaled: bool = False,
              chunk: int = 64) -> np.ndarray:
    """Model spectra (N, C) at search points x (N, 5 [+ log k if ``scaled``] [+ log exposure if ``free``])."""
    out = []
    for i in range(0, len(x), chunk):
        xi = x[i : i + chunk]
        tones = _to_p(xi)
        if scaled:
            tones = np.concatenate([tones, np.exp(xi[:, 5:6])], axis=1)
        with torch.no_grad():
            r = forward(torch.as_tensor(tones)).numpy()
        if free:
            r = specular + np.exp(xi[:, -1:]) * (r - specular)
        out.append(r)
    return np.concatenate(out)


def _starts(forward: Forward, y: np.ndarray, band: np.ndarray, specular: float, free: bool, seed: int) -> np.ndarray:
    """The N_STARTS best Halton candidates per subject (scattering scale 1): (S, N_STARTS, 5|6)."""
    lo, hi = _x_bounds(False)
    x = lo + qmc.Halton(d=5, scramble=True, seed=seed).random(N_CANDIDATES) * (hi - lo)
    r = _evaluate(forward, x, specular)[:, band]  # (N, C)
    yb = y[:, band]
    if free:  # best exposure of each candidate in closed form, clipped to its range
        d, t = r - specular, yb - specular
        s = np.clip((t @ d.T) / np.maximum((d * d).sum(1), 1e-12), *EXPOSURE_RANGE)  # (S, N)
        err = ((specular + s[:, :, None] * d[None] - yb[:, None]) ** 2).sum(-1)
    else:
        err = ((r[None] - yb[:, None]) ** 2).sum(-1)
    best = np.argsort(err, axis=1)[:, :N_STARTS]
    starts = x[best]
    if free:
        starts = np.concatenate([starts, np.log(np.take_along_axis(s, best, 1))[..., None]], axis=-1)
    return starts


def _scaled_starts(starts: np.ndarray) -> np.ndarray:
    """Starts (S, N, 5|6) with a log k column after the tone: every start at k = 1, the best also at
    ``SCALE_STARTS`` (S, N + len(SCALE_STARTS), 6|7)."""
    at_one = np.insert(starts, 5, 0.0, axis=-1)
    extra = np.stack([np.insert(starts[:, 0], 5, np.log(k), axis=-1) for k in SCALE_STARTS], axis=1)
    return np.concatenate([at_one, extra], axis=1)


def fit_subjects(forward: Forward, names: list[str] | tuple[str, ...], measured: np.ndarray,
                 wavelength_nm: np.ndarray, specular: float, free: bool, seed: int = 0,
                 scale_range: tuple[float, float] | None = None) -> list[SubjectFit]:
    """Fit every subject's spectrum (S, C) at ``wavelength_nm`` (C,); exposure free or fixed at 1.

    ``scale_range`` (lo, hi): also fit a per-subject scattering scale k in it (``forward`` must take a sixth
    tone column, as ``MonteCarloForward`` does).
    """
    band = (wavelength_nm >= FIT_BAND_NM[0]) & (wavelength_nm <= FIT_BAND_NM[1])
    scaled = scale_range is not None
    lo, hi = _x_bounds(free, scale_range)
    eps = 1e-4 * (hi - lo)
    starts = _starts(forward, measured, band, specular, free, seed)
    if scaled:
        starts = _scaled_starts(starts)
    fits = []
    for name, y, x0s in zip(names, measured, starts, strict=True):
        def resid(x, y=y):
            return _evaluate(forward, x[None], specular, free, scaled)[0, band] - y[band]

        def jac(x, y=y):
            h = np.where(x + eps <= hi, eps, -eps)  # step inward at the upper bound
            pts = np.vstack([x, x + np.diag(h)])
            r = _evaluate(forward, pts, specular, free, scaled)[:, band]
            return ((r[1:] - r[0]) / h[:, None]).T

        best = None
        for x0 in x0s:
            sol = least_squares(resid, np.clip(x0, lo + eps, hi - eps), jac=jac, bounds=(lo, hi), method="trf",
                                x_scale=hi - lo, max_nfev=60)
            if best is None or sol.cost < best.cost:
                best = sol
        model = _evaluate(forward, best.x[None], specular, free, scaled)[0]
        fits.append(SubjectFit(name=name, p=_to_p(best.x), exposure=float(np.exp(best.x[-1])) if free else 1.0,
                               model=model, rmse=band_rmse(model, y, wavelength_nm),
                               scattering_scale=float(np.exp(best.x[5])) if scaled else None))
    return fits
