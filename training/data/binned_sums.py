"""Per-bin sums of reweighted photon weights, over photons stored in bin order (compiled, numba).

The reweighting (``training.data.reweight``) gives every reflected photon of a channel one weight per tone;
the dataset keeps, per tone and radial bin, the sum of those weights and of their squares.  With the
photons of a channel sorted by bin, each bin is a contiguous run, so these sums are plain reductions along
memory (no scattered adds), accumulated in float64.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, fastmath=True)
def _run_sums(w: np.ndarray, lo: int, hi: int) -> tuple[float, float]:
    s1 = 0.0
    s2 = 0.0
    for j in range(lo, hi):
        v = np.float64(w[j])
        s1 += v
        s2 += v * v
    return s1, s2


@numba.njit(cache=True)
def binned_sums(weights: np.ndarray, starts: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> None:
    """Add per-bin sums of ``weights`` and of their squares into p1, p2.

    weights: (T, n) float32, the weights of n photons for T tones, photons sorted by bin; starts: (nb + 1,)
    int64, bin b holds photons starts[b]:starts[b + 1]; p1, p2: (T, nb) float32 or float64, added to.
    Each bin's sum is accumulated in float64 (in photon order) and then added.
    """
    n_tones = weights.shape[0]
    n_bins = starts.shape[0] - 1
    for t in range(n_tones):
        for b in range(n_bins):
            lo, hi = starts[b], starts[b + 1]
            if hi > lo:
                s1, s2 = _run_sums(weights[t], lo, hi)
                p1[t, b] += s1
                p2[t, b] += s2
