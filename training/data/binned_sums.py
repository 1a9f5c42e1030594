"""Per-bin sums of reweighted photon weights, over photons stored in bin order (compiled, numba).

The reweighting (``training.data.reweight``) gives every reflected photon of a channel one weight per tone,
exp(a L_l + b L + log w) with L_l the photon's path above the tone's epidermis level l, L its whole path and w
its recorded weight; the dataset keeps, per tone and radial bin, the sum of those weights and of their
squares.  With the photons of a channel sorted by bin, each bin is a contiguous run, so these sums are plain
reductions along memory (no scattered adds), accumulated in float64.  The exponential is evaluated in float32
by Cody-Waite reduction to 2^k e^y, |y| <= ln(2) / 2, and a degree-7 Taylor polynomial for e^y (relative error
below 3e-7 over the range used, float32 rounding's size), written so that the compiler vectorises it.
"""

from __future__ import annotations

import numba
import numpy as np

#: Exponents are kept in [EXP_MIN, EXP_MAX]: below, weights < 4.4e-38 (a bias below 1e-31 for 1e6 photons), near
#: float32's smallest normal number (the weights are never denormal, so they do not depend on a thread's
#: flush-to-zero mode); above, none arises (weights at a tone's absorption are at most 1).
EXP_MIN, EXP_MAX = -86.0, 88.0


@numba.njit(cache=True, fastmath=True)
def _weights(c1, c2, log_w, a, b, scale_bits, out):
    """out (n,) float32 <- exp(clip(a c1 + b c2 + log_w, EXP_MIN, EXP_MAX)); scale_bits (n,) int32 scratch."""
    a32, b32 = np.float32(a), np.float32(b)
    lo, hi = np.float32(EXP_MIN), np.float32(EXP_MAX)
    for j in range(c1.shape[0]):
        e = min(max(a32 * c1[j] + b32 * c2[j] + log_w[j], lo), hi)
        x = e * np.float32(1.4426950408889634)  # log2(e)
        k = np.floor(x + np.float32(0.5))
        y = (x - k) * np.float32(0.6931471805599453)
        p = np.float32(1.0) + y * (np.float32(1.0) + y * (np.float32(1 / 2) + y * (np.float32(1 / 6) + y * (
            np.float32(1 / 24) + y * (np.float32(1 / 120) + y * (np.float32(1 / 720) + y * np.float32(1 / 5040)))))))
        scale_bits[j] = (np.int32(k) + np.int32(127)) << np.int32(23)  # the float32 2^k
        out[j] = p
    scale = scale_bits.view(np.float32)
    for j in range(c1.shape[0]):
        out[j] *= scale[j]


@numba.njit(cache=True, fastmath=True)
def _tile_bin_sums(w, starts, first_bin, j0, j1, s1, s2):
    """s1[k], s2[k] += sums of w and w^2 over the photons of bin k in the tile j0:j1 (w[0] is photon j0), for
    the bins from ``first_bin`` on that hold photons of the tile (float64)."""
    nb = starts.shape[0] - 1
    k = first_bin
    while k < nb and starts[k] < j1:
        acc1 = 0.0
        acc2 = 0.0
        for j in range(max(starts[k], j0) - j0, min(starts[k + 1], j1) - j0):
            v = np.float64(w[j])
            acc1 += v
            acc2 += v * v
        s1[k] += acc1
        s2[k] += acc2
        k += 1


#: Photons per tile of ``reweighted_bin_sums``: a tile's rows (17 paths and the log weights, float32, ~280 kB)
#: stay in a core's L2 cache while every tone of the call passes over them.
TILE_PHOTONS = 4096


@numba.njit(cache=True)
def reweighted_bin_sums(cum: np.ndarray, log_w: np.ndarray, level: np.ndarray, a: np.ndarray, b: np.ndarray,
                        starts: np.ndarray, s1: np.ndarray, s2: np.ndarray) -> None:
    """Add, per tone and bin, the sums of the photons' weights and of their squares into s1, s2.

    cum: (S, n) float32, row l the photons' path above level l (cm), row S - 1 the whole path; log_w: (n,) float32
    log of the recorded weights; photons sorted by bin, bin k holding photons starts[k]:starts[k + 1] (starts
    (nb + 1,) int64).  Tone t weighs a photon exp(a[t] cum[level[t]] + b[t] cum[S - 1] + log_w) (a, b (T,) cm^-1,
    level (T,) int64).  s1, s2: (T, nb) float64, added to.

    The photons are taken in tiles of ``TILE_PHOTONS``, every tone passing over a tile while it is in cache (one
    pass per tone over a whole channel, ~100 MB of rows at the `paper` preset, runs at memory speed).
    """
    n = log_w.shape[0]
    nb = starts.shape[0] - 1
    scale_bits = np.empty(TILE_PHOTONS, np.int32)
    w = np.empty(TILE_PHOTONS, np.float32)
    total = cum[cum.shape[0] - 1]
    first_bin = 0
    for j0 in range(0, n, TILE_PHOTONS):
        j1 = min(j0 + TILE_PHOTONS, n)
        while first_bin < nb - 1 and starts[first_bin + 1] <= j0:  # the first bin with photons in this tile
            first_bin += 1
        m = j1 - j0
        for t in range(a.shape[0]):
            _weights(cum[level[t], j0:j1], total[j0:j1], log_w[j0:j1], a[t], b[t], scale_bits[:m], w[:m])
            _tile_bin_sums(w, starts, first_bin, j0, j1, s1[t], s2[t])


@numba.njit(cache=True)
def cumulative_paths(path_cm: np.ndarray, order: np.ndarray) -> np.ndarray:
    """(S, n) float32: row l the path above level l of photons ``order`` (the running sum of their per-slab paths
    ``path_cm`` (N, S) float32 over slabs 0..l, in float32 as ``np.cumsum``), photons in the given order."""
    n, n_slabs = order.shape[0], path_cm.shape[1]
    out = np.empty((n_slabs, n), np.float32)
    for j in range(n):
        acc = np.float32(0.0)
        row = path_cm[order[j]]
        for s in range(n_slabs):
            acc += row[s]
            out[s, j] = acc
    return out
