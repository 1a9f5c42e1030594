"""Differentiable interpolation of the homogeneous-medium lookup tables (paper §4, eq. separability).

The tables (docs/contracts.md §2, written by ``python -m training lut``) describe a semi-infinite homogeneous
medium at sigma_t = 1:

* ``albedo`` (NA,), ``g`` (NG,): the grid axes, increasing, possibly non-uniform (the albedo axis is
  denser near 1).  Every lookup goes through ``searchsorted``; no uniform spacing is assumed.
* ``r_edges_mfp`` (513,): radial bin edges in mean free paths, 0 then 512 log-spaced edges.
* ``R`` (NA, NG): total diffuse reflectance (dimensionless).
* ``P`` (NA, NG, 512): the normalised radial profile, per unit area (mfp^-2), averaged over each bin,
  with sum P * pi (r1^2 - r0^2) = 1.

Interpolation (hand-written: no well-kept library offers batched, differentiable, non-uniform
trilinear lookups in torch):

* ``reflectance``: bilinear in (albedo, g).
* ``profile``: trilinear in (albedo, g, log r).  Each bin value is placed at the bin's geometric
  centre sqrt(r0 r1); the first bin [0, r1] is placed at r1 / sqrt(2), the radius that halves its
  area.  Between centres the interpolant is linear in ``log r``; below the first centre it holds the
  first bin's value; between the last centre and the last edge it holds the last value; beyond the last
  edge it is 0 (nothing is tabulated there).
* sigma_t is clamped to ``SIGMA_T_RANGE`` (1e-100..1e100 cm^-1; 1e-18..1e18 for float32 tables), where
  sigma_t^2 is still finite.
* Extinction enters by the separability of a homogeneous medium (Chiang et al. 2016; paper eq.
  separability): P(r | alpha, g, sigma_t) = sigma_t^2 P(sigma_t r | alpha, g, 1), r in cm, sigma_t in
  cm^-1, result in cm^-2.
* Outside the (albedo, g) grid the value at the nearest grid edge is held (zero gradient there).  Tables
  loaded from a file ending at albedo >= 0.999 are first extended analytically up to albedo 1
  (``training.sim.lut_extend``), so no albedo lies beyond them;
  inside, the interpolation weights are not clamped, so gradients flow everywhere in the interior.

Binned form (``profile_binned``): by default the interpolant is evaluated at the geometric centre of
each target bin (the same centre convention as the table, so with target bins equal to the table bins
at sigma_t = 1 it returns the table exactly).  For bins with a log width of 2.1 % (docs/contracts.md §1) the
difference to the exact area average of the interpolant is second order in the bin width: measured on
dipole tables (``tests/test_lut_interp.py``) the median is 6e-7 relative, and it reaches 4e-4 in steep
exponential tails (|d ln P / d ln r| ~ 5); far below the Monte Carlo noise of any bin.  It is larger
only in the first bin (which spans [0, r1]) and in a bin straddling the end of the tabulated support.
``n_sub > 1`` integrates instead: a midpoint rule in area (r^2) with ``n_sub`` sub-samples per bin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

#: sigma_t is clamped to this range (cm^-1) in the profile lookups: beyond it sigma_t^2 over- or underflows
#: float64 (inf * 0 = NaN).  At 1e100 cm^-1 the whole profile lies inside 1e-96 cm of the origin.  Tables
#: in float32 use 1e-18..1e18 (``_clamp_sigma``).
SIGMA_T_RANGE: tuple[float, float] = (1e-100, 1e100)


def _clamp_sigma(sigma_t: torch.Tensor) -> torch.Tensor:
    """sigma_t within SIGMA_T_RANGE, narrowed to where sigma_t^2 is finite and normal in its dtype."""
    fi = torch.finfo(sigma_t.dtype)
    lo = max(SIGMA_T_RANGE[0], 10.0 ** math.ceil(math.log10(math.sqrt(fi.tiny)) + 1))
    hi = min(SIGMA_T_RANGE[1], 10.0 ** math.floor(math.log10(math.sqrt(fi.max)) - 1))
    return sigma_t.clamp(lo, hi)
#: Keys of the LUT .npz file (docs/contracts.md §2).
LUT_KEYS: tuple[str, ...] = ("albedo", "g", "r_edges_mfp", "R", "P")


def bin_centres(edges: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
    """Representative radius of each radial bin, shape (n,) for ``edges`` of shape (n + 1,).

    Geometric centre sqrt(r0 r1) for bins with r0 > 0; r1 / sqrt(2) (the area-halving radius) for a
    bin starting at 0.  Units are those of ``edges``.
    """
    lib = torch if isinstance(edges, torch.Tensor) else np
    r0, r1 = edges[:-1], edges[1:]
    geo = lib.sqrt(r0 * r1)
    return lib.where(r0 > 0, geo, r1 / math.sqrt(2.0))


def _axis_weights(grid: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Lower index, fractional position, inside-indicator and 1/spacing of ``x`` on the increasing ``grid``.

    Returns ``(idx, t, inside, inv_h)``: idx in [0, len(grid) - 2], t in [0, 1] (clamped outside the grid
    so that the edge value is held), ``inside`` 1.0 where ``x`` lies within the grid (else 0.0, where
    the derivative of the interpolant is 0) and ``inv_h`` = 1 / (grid[idx + 1] - grid[idx]).  ``t`` is
    differentiable w.r.t. ``x`` in the interior.
    """
    n = grid.shape[0]
    xd = x.detach().contiguous()
    idx = torch.searchsorted(grid, xd, right=True) - 1
    idx = idx.clamp(0, n - 2)
    g0 = grid[idx]
    inv_h = 1.0 / (grid[idx + 1] - g0)
    raw = (x - g0) * inv_h
    inside = ((xd >= grid[0]) & (xd <= grid[-1])).to(grid.dtype)
    return idx, raw.clamp(0.0, 1.0), inside, inv_h


@dataclass
class LookupTables:
    """The (albedo, g) lookup tables of a homogeneous semi-infinite medium at sigma_t = 1.

    Attributes (torch tensors): ``albedo`` (NA,), ``g`` (NG,), ``r_edges_mfp`` (NR + 1,), ``R`` (NA, NG),
    ``P`` (NA, NG, NR) in mfp^-2.  Derived: ``log_centres`` (NR,), log of the bin centres in mfp;
    ``log_r_max`` the log of the last edge.
    """

    albedo: torch.Tensor
    g: torch.Tensor
    r_edges_mfp: torch.Tensor
    R: torch.Tensor
    P: torch.Tensor

    def __post_init__(self) -> None:
        na, ng = self.albedo.shape[0], self.g.shape[0]
        nr = self.r_edges_mfp.shape[0] - 1
        if na < 2 or ng < 2 or nr < 2:
            raise ValueError(f"LUT axes need >= 2 points each, got albedo {na}, g {ng}, radial bins {nr}")
        if self.R.shape != (na, ng) or self.P.shape != (na, ng, nr):
            raise ValueError(f"LUT shapes inconsistent: R {tuple(self.R.shape)}, P {tuple(self.P.shape)}")
        for name in ("albedo", "g", "r_edges_mfp"):
            if not bool(torch.all(torch.diff(getattr(self, name)) > 0)):
                raise ValueError(f"LUT axis {name!r} must be strictly increasing")
        if not (bool(torch.isfinite(self.R).all()) and bool(torch.isfinite(self.P).all())):
            raise ValueError("LUT contains NaN or Inf")
        self.albedo_extended = False  # set by ``load`` when it added the analytic rows above the last albedo
        self.log_centres = torch.log(bin_centres(self.r_edges_mfp))
        self.log_r_max = float(torch.log(self.r_edges_mfp[-1]))
        # Fast path: log-spaced edges put the centres from index 1 on a uniform grid in log r, where the
        # interval index is a floor instead of a binary search (the hot spot of the fitter).
        d = torch.diff(self.log_centres[1:])
        self._uniform_log = bool(d.numel() > 0 and torch.allclose(d, d.mean(), rtol=1e-9, atol=0))
        self._dlog = float(d.mean()) if d.numel() else 1.0

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(
        cls,
        albedo: np.ndarray,
        g: np.ndarray,
        r_edges_mfp: np.ndarray,
        R: np.ndarray,
        P: np.ndarray,
        dtype: torch.dtype = torch.float64,
        device: str | torch.device = "cpu",
    ) -> LookupTables:
        """Build from numpy arrays (see the class docstring for shapes)."""
        arrs = [np.array(a, dtype=np.float64, order="C") for a in (albedo, g, r_edges_mfp, R, P)]
        return cls(*(torch.as_tensor(a, dtype=dtype, device=device) for a in arrs))

    @classmethod
    def load(
        cls, path: str | Path, dtype: torch.dtype = torch.float64, device: str | torch.device = "cpu",
        extend_albedo: bool = True,
    ) -> LookupTables:
        """Load a LUT .npz written by ``python -m training lut`` (docs/contracts.md §2).

        ``extend_albedo``: a table ending at albedo >= ``lut_extend.EXTEND_FROM`` gets analytic rows up to
        albedo 1 (``training.sim.lut_extend``; the file is not changed); ``self.albedo_extended`` says
        whether it did."""
        from training.sim.lut_extend import EXTEND_FROM
        from training.sim.lut_extend import extend_albedo as extend

        with np.load(path) as data:
            missing = [k for k in LUT_KEYS if k not in data]
            if missing:
                raise ValueError(f"{path}: not a LUT file, missing keys {missing}")
            arrays = {k: data[k] for k in LUT_KEYS}
        if not (extend_albedo and EXTEND_FROM <= float(arrays["albedo"][-1]) < 1.0):
            return cls.from_arrays(*arrays.values(), dtype=dtype, device=device)
        arrays = extend(**arrays)  # new float64 arrays: handed to torch without another copy
        lut = cls(*(torch.as_tensor(arrays[k], dtype=dtype, device=device) for k in LUT_KEYS))
        lut.albedo_extended = True
        return lut

    def to(self, device: str | torch.device | None = None, dtype: torch.dtype | None = None) -> LookupTables:
        """A copy on ``device`` with floating dtype ``dtype`` (either may be None = unchanged)."""
        ts = (self.albedo, self.g, self.r_edges_mfp, self.R, self.P)
        out = LookupTables(*(t.to(device=device, dtype=dtype) for t in ts))
        out.albedo_extended = self.albedo_extended
        return out

    @property
    def g_range(self) -> tuple[float, float]:
        """The tabulated anisotropy range (first, last grid value)."""
        return float(self.g[0]), float(self.g[-1])

    # ------------------------------------------------------------------ lookups
    def _radial_weights(self, x: torch.Tensor):
        """``_axis_weights`` on the log bin centres, by arithmetic where they are uniform past index 0."""
        lc = self.log_centres
        if not self._uniform_log:
            return _axis_weights(lc, x)
        n = lc.shape[0]
        xd = x.detach()
        j = torch.floor((xd - lc[1]) / self._dlog).to(torch.int64) + 1
        idx = torch.where(xd < lc[1], torch.zeros_like(j), j).clamp_(0, n - 2)
        g0 = lc[idx]
        inv_h = 1.0 / (lc[idx + 1] - g0)
        t = ((x - g0) * inv_h).clamp(0.0, 1.0)
        inside = ((xd >= lc[0]) & (xd <= lc[-1])).to(lc.dtype)
        return idx, t, inside, inv_h

    def _corners(self, alpha: torch.Tensor, g: torch.Tensor):
        ia, ta, _, _ = _axis_weights(self.albedo, alpha)
        ig, tg, _, _ = _axis_weights(self.g, g)
        return ia, ta, ig, tg

    def reflectance(self, alpha: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        """Total diffuse reflectance R(alpha, g), bilinear; shape = broadcast(alpha, g)."""
        alpha, g = torch.broadcast_tensors(*self._as_tensors(alpha, g))
        ia, ta, ig, tg = self._corners(alpha, g)
        R = self.R
        r0 = R[ia, ig] * (1 - tg) + R[ia, ig + 1] * tg
        r1 = R[ia + 1, ig] * (1 - tg) + R[ia + 1, ig + 1] * tg
        return r0 * (1 - ta) + r1 * ta

    def profile_rows(self, alpha: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        """The tabulated profile bilinearly interpolated in (alpha, g): shape broadcast(alpha, g) + (NR,).

        Values per unit area in mfp^-2 (sigma_t = 1), one per table bin.
        """
        alpha, g = torch.broadcast_tensors(*self._as_tensors(alpha, g))
        ia, ta, ig, tg = self._corners(alpha, g)
        P = self.P
        ta, tg = ta[..., None], tg[..., None]
        p0 = P[ia, ig] * (1 - tg) + P[ia, ig + 1] * tg
        p1 = P[ia + 1, ig] * (1 - tg) + P[ia + 1, ig + 1] * tg
        return p0 * (1 - ta) + p1 * ta

    def profile(self, r_cm: torch.Tensor, alpha: torch.Tensor, g: torch.Tensor, sigma_t: torch.Tensor) -> torch.Tensor:
        """Normalised radial profile P(r | alpha, g, sigma_t) = sigma_t^2 P_LUT(sigma_t r | alpha, g), cm^-2.

        ``r_cm``: radii in cm, shape (..., M) (r >= 0); ``alpha``, ``g``, ``sigma_t`` (cm^-1): shapes
        broadcastable to the same leading dims (...).  Returns shape broadcast(...) + (M,).  On a float64 table
        on the CPU, with r_cm 1-D and no gradient to carry, computed by ``training.sim.lut_kernel`` (the same
        values, one compiled pass).
        """
        alpha, g, sigma_t = self._as_tensors(alpha, g, sigma_t)
        r_cm = self._as_tensors(r_cm)[0]
        lead = torch.broadcast_shapes(alpha.shape, g.shape, sigma_t.shape, r_cm.shape[:-1])
        if self._compiled(alpha, g, sigma_t) and r_cm.dim() == 1:
            from training.sim.lut_kernel import profile_kernel

            return self._run_compiled(profile_kernel, 1, r_cm, *(t.expand(lead) for t in (alpha, g, sigma_t)))[0]
        rows = self.profile_rows(alpha.expand(lead), g.expand(lead))  # lead + (NR,)
        sig = _clamp_sigma(sigma_t.expand(lead))
        # log radius in mfp; r = 0 maps to a huge negative number (holds the first bin).
        log_r = torch.log(r_cm.clamp_min(1e-300)).expand(*lead, r_cm.shape[-1])
        x = log_r + torch.log(sig)[..., None]
        ir, tr, _, _ = self._radial_weights(x)
        v0 = torch.gather(rows, -1, ir)
        v1 = torch.gather(rows, -1, ir + 1)
        val = v0 * (1 - tr) + v1 * tr
        val = torch.where(x <= self.log_r_max, val, torch.zeros((), dtype=val.dtype, device=val.device))
        return val * (sig * sig)[..., None]

    def profile_binned(
        self,
        r_edges_cm: torch.Tensor,
        alpha: torch.Tensor,
        g: torch.Tensor,
        sigma_t: torch.Tensor,
        n_sub: int = 1,
    ) -> torch.Tensor:
        """Profile for radial bins with edges ``r_edges_cm`` (shape (M + 1,)), cm^-2, shape (..., M).

        ``n_sub == 1``: value at each bin's centre (``bin_centres``).  ``n_sub > 1``: area average by a
        midpoint rule in r^2 with ``n_sub`` samples per bin.  See the module docstring for the error.
        """
        edges = self._as_tensors(r_edges_cm)[0]
        if n_sub <= 1:
            return self.profile(bin_centres(edges), alpha, g, sigma_t)
        u0, u1 = edges[:-1] ** 2, edges[1:] ** 2
        frac = (torch.arange(n_sub, dtype=edges.dtype, device=edges.device) + 0.5) / n_sub
        r_sub = torch.sqrt(u0[:, None] + (u1 - u0)[:, None] * frac)  # (M, n_sub)
        vals = self.profile(r_sub.reshape(-1), alpha, g, sigma_t)
        return vals.reshape(*vals.shape[:-1], -1, n_sub).mean(-1)

    # ------------------------------------------------------------------ explicit derivatives
    def reflectance_grad(self, alpha: torch.Tensor, g: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(R, dR/dalpha, dR/dg) of the bilinear interpolant, without autograd (for Gauss-Newton).

        ``alpha`` and ``g`` must already have the same shape, dtype and device as the table.
        """
        ia, ta, qa, ha = _axis_weights(self.albedo, alpha)
        ig, tg, qg, hg = _axis_weights(self.g, g)
        R = self.R
        r00, r01, r10, r11 = R[ia, ig], R[ia, ig + 1], R[ia + 1, ig], R[ia + 1, ig + 1]
        lo = r00 + (r01 - r00) * tg
        hi = r10 + (r11 - r10) * tg
        val = lo + (hi - lo) * ta
        d_a = (hi - lo) * ha * qa
        d_g = ((r01 - r00) * (1 - ta) + (r11 - r10) * ta) * hg * qg
        return val, d_a, d_g

    def profile_grad(
        self, r_cm: torch.Tensor, alpha: torch.Tensor, g: torch.Tensor, sigma_t: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """``profile`` and its derivatives w.r.t. alpha, g and log(sigma_t), without autograd.

        Forward-mode derivatives written out for the Gauss-Newton fitter (autograd's forward mode goes
        through slow Python decompositions here).  ``r_cm`` (M,); ``alpha``, ``g``, ``sigma_t`` of one
        common shape (...) with the table's dtype/device.  Each output has shape (..., M); units cm^-2
        (per unit of the differentiated parameter).  Piecewise derivatives: one-sided at knots, 0
        where a value is held.  Compiled (``training.sim.lut_kernel``) on a float64 table on the CPU when no
        gradient is to be carried, as ``profile``.
        """
        if self._compiled(alpha, g, sigma_t):
            from training.sim.lut_kernel import profile_grad_kernel

            return self._run_compiled(profile_grad_kernel, 4, r_cm, alpha, g, sigma_t)
        ia, ta, qa, ha = _axis_weights(self.albedo, alpha)
        ig, tg, qg, hg = _axis_weights(self.g, g)
        P = self.P
        p00, p01, p10, p11 = P[ia, ig], P[ia, ig + 1], P[ia + 1, ig], P[ia + 1, ig + 1]
        tg_, ta_ = tg[..., None], ta[..., None]
        lo = p00 + (p01 - p00) * tg_
        hi = p10 + (p11 - p10) * tg_
        rows = lo + (hi - lo) * ta_
        rows_a = (hi - lo) * (ha * qa)[..., None]
        rows_g = ((p01 - p00) * (1 - ta_) + (p11 - p10) * ta_) * (hg * qg)[..., None]
        sigma_t = _clamp_sigma(sigma_t)
        log_s = torch.log(sigma_t)
        x = torch.log(r_cm.clamp_min(1e-300)) + log_s[..., None]
        ir, tr, qr, hr = self._radial_weights(x)
        support = (x <= self.log_r_max).to(x.dtype)
        s2 = (sigma_t * sigma_t)[..., None] * support

        def radial(rows_):
            v0, v1 = torch.gather(rows_, -1, ir), torch.gather(rows_, -1, ir + 1)
            return v0, v1, v0 + (v1 - v0) * tr

        v0, v1, val = radial(rows)
        d_log_s = (2.0 * val + (v1 - v0) * hr * qr) * s2
        return val * s2, radial(rows_a)[2] * s2, radial(rows_g)[2] * s2, d_log_s

    def _compiled(self, *inputs: torch.Tensor) -> bool:
        """Whether lookups of ``inputs`` go through ``training.sim.lut_kernel``: float64 tables on the CPU and no
        gradient to carry (the kernels give torch's values to rounding, without autograd)."""
        return (self.P.device.type == "cpu" and self.P.dtype == torch.float64
                and not (torch.is_grad_enabled() and any(t.requires_grad for t in inputs)))

    def _run_compiled(self, kernel, n_out: int, r_cm: torch.Tensor, alpha: torch.Tensor, g: torch.Tensor,
                      sigma_t: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """``n_out`` outputs of shape alpha.shape + (M,) of a ``lut_kernel`` kernel at radii r_cm (M,)."""
        lead = alpha.shape
        flat = [t.detach().reshape(-1).contiguous().numpy() for t in (alpha, g, _clamp_sigma(sigma_t))]
        log_r = torch.log(r_cm.clamp_min(1e-300)).contiguous().numpy()
        out = [np.empty((flat[0].size, log_r.size)) for _ in range(n_out)]
        kernel(self.P.numpy(), self.albedo.numpy(), self.g.numpy(), self.log_centres.numpy(), self._uniform_log,
               self._dlog, self.log_r_max, log_r, *flat, *out)
        return tuple(torch.from_numpy(o).reshape(*lead, log_r.size) for o in out)

    def _as_tensors(self, *xs) -> list[torch.Tensor]:
        """Convert inputs to tensors on the table's device and dtype; reject NaN / Inf."""
        out = []
        for x in xs:
            t = torch.as_tensor(x, dtype=self.P.dtype, device=self.P.device)
            if not bool(torch.isfinite(t.detach()).all()):
                raise ValueError("LUT lookup got NaN or Inf input")
            out.append(t)
        return out
