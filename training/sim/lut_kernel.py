"""The LUT's profile and its derivatives for the fitter, compiled (numba): ``LookupTables.profile_grad`` on CPU
tensors.

``profile_grad`` in torch builds, for each problem, the whole tabulated row (NR radial values) at its (alpha, g) and
its two derivative rows, then gathers the two radial neighbours of each of the M requested radii: a few dozen
small tensor operations per call.  This kernel computes the same interpolant for each (problem, radius) straight
from the table's eight corner values around it, in one pass and with the same arithmetic (the same expressions in
the same order, float64), so its outputs equal torch's to rounding (``tests/test_lut_interp.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _cell(grid, idx, x):
    """(idx, t, inside, inv_h) for ``x`` in the cell from node ``idx`` (clamped to the grid's cells)."""
    n = grid.shape[0]
    idx = min(max(idx, 0), n - 2)
    g0 = grid[idx]
    inv_h = 1.0 / (grid[idx + 1] - g0)
    t = min(max((x - g0) * inv_h, 0.0), 1.0)
    inside = 1.0 if (x >= grid[0] and x <= grid[n - 1]) else 0.0
    return idx, t, inside, inv_h


@numba.njit(cache=True, inline="always")
def _axis(grid, x):
    """(idx, t, inside, inv_h) of ``lut_interp._axis_weights`` for one value."""
    return _cell(grid, np.searchsorted(grid, x, side="right") - 1, x)


@numba.njit(cache=True, inline="always")
def _radial(lc, uniform, dlog, x):
    """(idx, t, inside, inv_h) of ``LookupTables._radial_weights`` for one log radius."""
    if not uniform:
        return _axis(lc, x)
    return _cell(lc, 0 if x < lc[1] else int(math.floor((x - lc[1]) / dlog)) + 1, x)


@numba.njit(cache=True, inline="always")
def _rows_at(P, ia, ig, ir, ta, tg, da, dg):
    """The bilinear row value and its albedo and g derivatives at radial index ir (``profile_grad``'s rows)."""
    p00, p01, p10, p11 = P[ia, ig, ir], P[ia, ig + 1, ir], P[ia + 1, ig, ir], P[ia + 1, ig + 1, ir]
    lo = p00 + (p01 - p00) * tg
    hi = p10 + (p11 - p10) * tg
    return lo + (hi - lo) * ta, (hi - lo) * da, ((p01 - p00) * (1 - ta) + (p11 - p10) * ta) * dg


@numba.njit(cache=True)
def profile_grad_kernel(P, albedo, g_grid, lc, uniform, dlog, log_r_max, log_r, alpha, g, sigma_t,
                        val, d_alpha, d_g, d_log_s):
    """Fill val, d_alpha, d_g, d_log_s (B, M) for B problems (alpha, g, sigma_t (B,), sigma_t already clamped)
    at M radii given as log_r (M,) = log(max(r_cm, 1e-300)); P (NA, NG, NR), lc (NR,) the log bin centres."""
    for b in range(alpha.shape[0]):
        ia, ta, qa, ha = _axis(albedo, alpha[b])
        ig, tg, qg, hg = _axis(g_grid, g[b])
        da, dg = ha * qa, hg * qg
        s = sigma_t[b]
        log_s = math.log(s)
        s2_in = s * s
        for m in range(log_r.shape[0]):
            x = log_r[m] + log_s
            ir, tr, qr, hr = _radial(lc, uniform, dlog, x)
            s2 = s2_in * (1.0 if x <= log_r_max else 0.0)
            v0, a0, g0 = _rows_at(P, ia, ig, ir, ta, tg, da, dg)
            v1, a1, g1 = _rows_at(P, ia, ig, ir + 1, ta, tg, da, dg)
            v = v0 + (v1 - v0) * tr
            val[b, m] = v * s2
            d_alpha[b, m] = (a0 + (a1 - a0) * tr) * s2
            d_g[b, m] = (g0 + (g1 - g0) * tr) * s2
            d_log_s[b, m] = (2.0 * v + (v1 - v0) * hr * qr) * s2


@numba.njit(cache=True, inline="always")
def _row_value(P, ia, ig, ir, ta, tg):
    """``profile_rows``' bilinear value at radial index ir."""
    p0 = P[ia, ig, ir] * (1 - tg) + P[ia, ig + 1, ir] * tg
    p1 = P[ia + 1, ig, ir] * (1 - tg) + P[ia + 1, ig + 1, ir] * tg
    return p0 * (1 - ta) + p1 * ta


@numba.njit(cache=True)
def profile_kernel(P, albedo, g_grid, lc, uniform, dlog, log_r_max, log_r, alpha, g, sigma_t, val):
    """Fill val (B, M) with ``LookupTables.profile`` for B problems (alpha, g, sigma_t (B,), sigma_t already
    clamped) at M radii given as log_r (M,) = log(max(r_cm, 1e-300))."""
    for b in range(alpha.shape[0]):
        ia, ta, _, _ = _axis(albedo, alpha[b])
        ig, tg, _, _ = _axis(g_grid, g[b])
        s = sigma_t[b]
        log_s = math.log(s)
        for m in range(log_r.shape[0]):
            x = log_r[m] + log_s
            ir, tr, _, _ = _radial(lc, uniform, dlog, x)
            v = _row_value(P, ia, ig, ir, ta, tg) * (1 - tr) + _row_value(P, ia, ig, ir + 1, ta, tg) * tr
            val[b, m] = (v if x <= log_r_max else 0.0) * (s * s)
