"""Radial profile estimators from tallied exits: the plain histogram and CDF-based conservative resampling.

The paper (§3) records the radial profile in 512 log bins "with CDF-based conservative resampling",
reported as 4x lower RMSR than uniform binning and 2x lower than a kernel density estimate at 10^5
photons; it gives no further detail.  Our construction (hand-written: no library offers a conservative,
count-adaptive CDF resampler for weighted tallies), ``cdf_resample``:

1. From the tallies of each channel: the energy of every bin (sum of exit weights / photons) and its
   effective photon count n_i = (sum w)^2 / sum w^2 (Kish's effective sample size; = the photon count
   for unit weights).
2. Knots on the bin edges: the cumulative energy C(r) is kept exactly at a knot placed whenever at
   least ``min_count`` effective photons have been collected since the previous knot or the interval
   spans ``max_span`` bins (so knots are one bin apart where the profile is well sampled and spread
   out, up to ``max_span`` bins, where it is sparse), at the first edge
   (r_1: the bin [0, r_1] keeps its tallied energy) and at the outer edge of the last bin that holds
   any light (nothing is spread beyond the photons' reach).
3. Between knots C is interpolated monotonically (PCHIP in log r: no overshoot, so every bin gets
   energy >= 0) and the bins' energies are the differences of C at their edges.

Conservative: the energy between consecutive knots, hence the total (R_d minus what exits beyond the
last edge), is the tallied one to rounding.  Where every bin holds ``min_count`` effective photons the
result is the histogram itself; the estimator only smooths where the histogram is noisy.  Bias: the
profile's curvature in log r over a knot interval, small for the smooth profiles of turbid media.
The knots are chosen from the data, so the estimate is not a fixed linear map of the histogram.
"""

from __future__ import annotations

import math

import numpy as np

#: Effective photons per knot interval of ``cdf_resample`` (relative noise of an interval's energy
#: ~ 1 / sqrt(MIN_COUNT) = 3.5 %).  MIN_COUNT and MAX_SPAN were chosen on the cases of ``python -m training
#: resampling`` at 10^5 photons (a sweep of min_count 50-1600 x max_span 4-32 bins: span 8 best, min_count
#: 800 and 1600 within 7 % of each other; docs/validation/resampling.md).
MIN_COUNT: int = 800
#: Widest knot interval of ``cdf_resample``, in bins (8 profile bins = 0.07 decades of r): bounds the bias
#: where the profile falls steeply and photons are sparse (without it, RMSR in the tails grows past 1).
MAX_SPAN: int = 8


def histogram_profile(energy: np.ndarray, r_edges: np.ndarray) -> np.ndarray:
    """The plain histogram: bin energies (..., NB) per unit incident power over bin areas -> cm^-2."""
    return energy / (math.pi * np.diff(r_edges**2))


def _knots(energy: np.ndarray, n_eff: np.ndarray, min_count: float, max_span: int) -> np.ndarray:
    """Edge indices (into the NB + 1 edges) kept exactly, for one channel (see the module docstring).

    Walking out from bin 1, a knot closes the interval when it holds ``min_count`` effective photons or
    spans ``max_span`` bins; a last interval holding under half of ``min_count`` joins the previous one
    (unless that would exceed ``max_span`` bins).
    """
    nb = energy.size
    filled = np.flatnonzero(energy > 0)
    if filled.size == 0:
        return np.array([0, nb])
    last = int(filled[-1]) + 1  # outer edge of the last bin holding light
    knots, acc, start = [0, 1], 0.0, 1
    for i in range(1, last):
        acc += n_eff[i]
        if acc >= min_count or i + 1 - start >= max_span:
            knots.append(i + 1)
            acc, start = 0.0, i + 1
    if knots[-1] != last:
        if acc < min_count / 2 and len(knots) > 2 and last - knots[-2] <= max_span:
            knots[-1] = last
        else:
            knots.append(last)
    knots.append(nb)
    return np.unique(np.array(knots))


def cdf_resample(energy: np.ndarray, energy_sq: np.ndarray, r_edges: np.ndarray, photons: int,
                 min_count: float = MIN_COUNT, max_span: int = MAX_SPAN) -> np.ndarray:
    """CDF-based conservative resampling of tallied bin energies (module docstring) -> profile cm^-2.

    ``energy`` (..., NB): sum of exit weights per bin / photons (per unit incident power);
    ``energy_sq`` (..., NB): sum of squared exit weights per bin / photons; ``r_edges`` (NB + 1,) cm,
    starting at 0, log-spaced from the second edge on (any increasing edges work; PCHIP runs in log r).
    Returns the profile (..., NB) per unit area, with sum(profile * area) = sum(energy) per channel.
    """
    from scipy.interpolate import PchipInterpolator

    if min_count <= 0:
        raise ValueError(f"min_count must be > 0, got {min_count}")
    energy = np.asarray(energy, dtype=np.float64)
    energy_sq = np.asarray(energy_sq, dtype=np.float64)
    if energy.shape != energy_sq.shape or energy.shape[-1] != r_edges.size - 1:
        raise ValueError(f"energy {energy.shape}, energy_sq {energy_sq.shape} and {r_edges.size} edges disagree")
    log_r = np.log(r_edges[1:])  # edges 1..NB; edge 0 (r = 0) is a knot on its own
    flat_e = energy.reshape(-1, energy.shape[-1])
    flat_s = energy_sq.reshape(flat_e.shape)
    out = np.empty_like(flat_e)
    for c, (e, s) in enumerate(zip(flat_e, flat_s, strict=True)):
        n_eff = photons * np.where(s > 0, e * e / np.where(s > 0, s, 1.0), 0.0)
        knots = _knots(e, n_eff, min_count, max_span)
        cum = np.concatenate([[0.0], np.cumsum(e)])
        inner = knots[knots >= 1]
        c_edges = np.empty(r_edges.size)
        c_edges[0] = 0.0
        if inner.size >= 2:
            c_edges[1:] = PchipInterpolator(log_r[inner - 1], cum[inner])(np.clip(log_r, log_r[inner[0] - 1],
                                                                                  log_r[inner[-1] - 1]))
        else:
            c_edges[1:] = cum[1:]
        c_edges[knots] = cum[knots]  # exact at the knots (PCHIP passes through them; rounding aside)
        out[c] = np.clip(np.diff(c_edges), 0.0, None)
    return histogram_profile(out.reshape(energy.shape), r_edges)


def cdf_resample_profile(profile: np.ndarray, stderr: np.ndarray, r_edges: np.ndarray, photons: int,
                         min_count: float = MIN_COUNT, max_span: int = MAX_SPAN) -> np.ndarray:
    """``cdf_resample`` of a tallied profile given as (profile, profile_stderr) (..., NB) cm^-2 over
    ``photons``, as ``simulate`` and the dataset write them (``training.sim.transport.mean_stderr``):
    the per-photon sums are recovered as energy = profile x area and energy_sq = (stderr x area)^2
    (photons - 1) + energy^2.  Returns the resampled profile (..., NB) cm^-2."""
    area = math.pi * np.diff(r_edges**2)
    e = np.asarray(profile, dtype=np.float64) * area
    e2 = (np.asarray(stderr, dtype=np.float64) * area) ** 2 * max(photons - 1, 1) + e * e
    return cdf_resample(e, e2, r_edges, photons, min_count, max_span)


def kde_profile(r: np.ndarray, w: np.ndarray, photons: int, r_edges: np.ndarray) -> np.ndarray:
    """Weighted Gaussian KDE (scipy, Scott's bandwidth) of log exit radius, as a profile (NB,) cm^-2.

    ``r`` (n,) exit radii (cm, > 0), ``w`` (n,) exit weights, ``photons`` launched.  The bins' energies
    are the KDE's integrals between the edges' log radii (the first bin from -inf); the mass the kernel
    puts beyond the last edge is lost, as it is for photons exiting there.
    """
    from scipy.stats import gaussian_kde

    nb = r_edges.size - 1
    if r.size < 2:
        return np.zeros(nb)
    kde = gaussian_kde(np.log(np.maximum(r, 1e-300)), weights=w)
    lo = np.concatenate([[-np.inf], np.log(r_edges[1:-1])])
    hi = np.log(r_edges[1:])
    mass = np.array([kde.integrate_box_1d(a, b) for a, b in zip(lo, hi, strict=True)])
    return histogram_profile(mass * w.sum() / photons, r_edges)
