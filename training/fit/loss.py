"""The joint shape-and-amplitude loss of the paper (eq. joint_loss, shape_loss, refl_loss).

    L_shape = RMSE over radial bins of (log P_hat(r) - log P_MC(r)),   P_MC = profile / R_MC
    L_R     = ((R_hat - R_MC) / R_MC)^2      (the paper: (R_hat - R_MC)^2; see below)
    L_joint = L_shape + 5 L_R

with P_hat = sum_k w_k R_k P_k / sum_k w_k R_k and R_hat = sum_k w_k R_k (``mixture.mix``: the
normalised profile of the issue's R_d^fit(r) and of a renderer that picks medium k with probability w_k;
the paper's §4 text weights the normalised component profiles by w_k alone).

The reflectance term is relative by default (``relative_refl=True`` in ``make_target``; the paper's
absolute form with ``relative_refl=False``, ``fit --refl-loss paper``).  With the absolute form a
dark tone (R_MC ~ 0.01) gets almost no weight on R: at 100 % error 5 (0.01)^2 = 5e-4 against an
L_shape of ~0.2, and on the laptop dataset the K = 2 fits reached mean |dR|/R of 350 % while the
shape barely changed.  The relative form weighs every tone alike; at the same 5 x, 3 % error costs
0.0045.

Bins that enter L_shape (the mask), documented choice:

* without standard errors: a bin is used if it holds at least ``min_count`` photon equivalents,
  profile * bin area * photons >= min_count (default 10; about 30 % relative noise for unit-weight
  photons);
* with the Monte Carlo standard errors (``stderr``, which every dataset and ``simulate`` file stores):
  a bin is used if it holds at least ``min_count`` photon equivalents *of the paper's simulation*
  (``REFERENCE_PHOTONS`` = 10^6 per wavelength: profile * area >= 1e-5) and our estimate there is at
  least as good (relative standard error <= ``MAX_REL_STDERR`` = 1/sqrt(10)).  The reweighted
  dataset gives every bin a positive value: its far tails, carried by photons with weights down to
  1e-35, are accurate but 40 decades below the peak, and no direct simulation would resolve them;
  fitted in log space they would dominate L_shape.  The energy threshold keeps the radial range the
  paper's data resolves, so our L_shape measures what the paper's does;
* if fewer than ``MIN_BINS`` bins pass, the ``MIN_BINS`` positive bins holding the most energy (among
  those with acceptable noise, if any) are used; if no bin is positive (R_MC = 0), L_shape is 0 and
  only L_R constrains the fit.

The model can underflow (a component whose support ends inside the MC range gives P = 0 beyond it), so
the log uses P_hat + floor with floor = 1e-3 x the smallest used MC value of that problem: this leaves
the loss unchanged wherever the fit is anywhere near the data and keeps it finite, with a usable
gradient, where it is not.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch

#: Weight of the reflectance term (paper: lambda_R = 5).
LAMBDA_R: float = 5.0
#: Minimum photon equivalents for a bin to enter the shape loss (see module docstring).
MIN_COUNT: float = 10.0
#: The same noise criterion through the standard error: the relative noise of MIN_COUNT unit-weight photons.
MAX_REL_STDERR: float = MIN_COUNT**-0.5
#: Photons per wavelength of the paper's dataset: the radial range its profiles resolve (module docstring).
REFERENCE_PHOTONS: float = 1e6
#: Below this many valid bins the photon-count criterion is dropped.
MIN_BINS: int = 8
#: Floor of the model profile in the log, relative to the smallest used MC value.
FLOOR_REL: float = 1e-3


@dataclass
class Target:
    """Monte Carlo targets of a batch of fitting problems (leading dims ``...``).

    ``r_cm`` (M,): the bin centres at which the model is evaluated; ``log_p`` (..., M): log of P_MC
    (0 where masked); ``mask`` (..., M) float 0/1; ``n_used`` (...,): number of used bins;
    ``floor`` (...,): the model floor (cm^-2); ``R`` (...,): R_MC; ``r_scale`` (...,): the unit of the
    reflectance residual (R_MC floored at 1e-6 for the relative term, 1 for the paper's absolute one);
    ``noise`` (...,): the L_shape that the Monte Carlo noise of the used bins alone gives, sqrt(mean of
    (stderr / profile)^2) (or 1/count without standard errors): a fit cannot be expected to go below it.
    """

    r_cm: torch.Tensor
    log_p: torch.Tensor
    mask: torch.Tensor
    n_used: torch.Tensor
    floor: torch.Tensor
    R: torch.Tensor
    r_scale: torch.Tensor
    noise: torch.Tensor

    def repeat(self, n: int) -> Target:
        """The batch repeated ``n`` times along the first axis (for multi-start fits)."""
        rep = [n] + [1] * (self.log_p.dim() - 1)
        return Target(
            self.r_cm,
            self.log_p.repeat(rep),
            self.mask.repeat(rep),
            self.n_used.repeat(n),
            self.floor.repeat(n),
            self.R.repeat(n),
            self.r_scale.repeat(n),
            self.noise.repeat(n),
        )

    def to(self, device: str | torch.device | None = None, dtype: torch.dtype | None = None) -> Target:
        """The same targets on another device and/or floating dtype."""
        return Target(*(getattr(self, f.name).to(device=device, dtype=dtype) for f in fields(self)))

    def rows(self, idx: torch.Tensor) -> Target:
        """The targets of a subset of the problems (integer indices into the first axis)."""
        return self.select(0, idx)

    def select(self, dim: int, idx: torch.Tensor) -> Target:
        """The targets of a subset of the problems along leading dimension ``dim`` (e.g. wavelengths)."""
        pick = lambda x: x.index_select(dim, idx)  # noqa: E731
        return Target(self.r_cm, pick(self.log_p), pick(self.mask), pick(self.n_used), pick(self.floor),
                      pick(self.R), pick(self.r_scale), pick(self.noise))

    def subset(self, idx: torch.Tensor) -> Target:
        """The same targets on a subset of the radial bins (indices into the last axis)."""
        mask = self.mask[..., idx]
        return Target(self.r_cm[idx], self.log_p[..., idx], mask, mask.sum(-1), self.floor, self.R, self.r_scale,
                      self.noise)


def make_target(
    profile: torch.Tensor,
    R_mc: torch.Tensor,
    r_edges_cm: torch.Tensor,
    photons: float,
    min_count: float = MIN_COUNT,
    stderr: torch.Tensor | None = None,
    relative_refl: bool = True,
) -> Target:
    """Build the targets from MC outputs: ``profile`` (..., M) cm^-2, ``R_mc`` (...,), edges (M + 1,).

    ``stderr`` (..., M) cm^-2: the profile's standard errors; when given, the bins are chosen by
    relative error, otherwise by photon count (module docstring).  ``relative_refl``: L_R relative to
    R_MC (default) or the paper's absolute squared error.  Raises ValueError on NaN/Inf or
    negative input.
    """
    from training.sim.lut_interp import bin_centres

    if not (torch.isfinite(profile).all() and torch.isfinite(R_mc).all()):
        raise ValueError("MC profile or R_d contains NaN/Inf")
    if (profile < 0).any() or (R_mc < 0).any():
        raise ValueError("MC profile and R_d must be non-negative")
    positive = profile > 0
    energy = profile * (torch.pi * torch.diff(r_edges_cm**2))  # per bin, per unit incident power
    if stderr is None:
        ok = positive
        counted = energy * photons >= min_count
        rel = torch.rsqrt((energy * photons).clamp_min(1e-300))
    else:
        if stderr.shape != profile.shape or not torch.isfinite(stderr).all() or (stderr < 0).any():
            raise ValueError("profile stderr must be finite, non-negative and shaped like the profile")
        ok = positive & (stderr <= MAX_REL_STDERR * profile)
        rel = stderr / profile.clamp_min(1e-300)
        counted = ok & (energy * REFERENCE_PHOTONS >= min_count)
    few = counted.sum(-1, keepdim=True) < MIN_BINS
    score = torch.where(ok, energy, torch.zeros_like(energy)) + torch.where(positive, energy, 0.0) * 1e-300
    kth = torch.topk(score, min(MIN_BINS, score.shape[-1]), dim=-1).values[..., -1:]
    mask = torch.where(few, positive & (score >= kth) & (score > 0), counted).to(profile.dtype)
    p_mc = profile / R_mc.clamp_min(1e-300)[..., None]
    log_p = torch.where(mask > 0, torch.log(p_mc.clamp_min(1e-300)), torch.zeros_like(p_mc))
    big = torch.full_like(p_mc, float("inf"))
    p_min = torch.where(mask > 0, p_mc, big).amin(-1)
    floor = torch.where(torch.isfinite(p_min), p_min * FLOOR_REL, torch.ones_like(p_min))
    r_scale = R_mc.clamp_min(1e-6) if relative_refl else torch.ones_like(R_mc)
    n_used = mask.sum(-1)
    noise = torch.sqrt((mask * torch.where(mask > 0, rel, 0.0) ** 2).sum(-1) / n_used.clamp_min(1.0))
    return Target(bin_centres(r_edges_cm), log_p, mask, n_used, floor, R_mc, r_scale, noise)


def shape_residuals(p_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """Masked log residuals scaled so that their squared sum is L_shape^2; shape (..., M).  Masked bins
    take no log at all (a model value of 0 there gives 0, with a zero gradient, not 0 x inf = NaN)."""
    den = torch.where(t.mask > 0, p_hat + t.floor[..., None], torch.ones_like(p_hat))
    d = torch.log(den) - t.log_p
    return d * t.mask / torch.sqrt(t.n_used.clamp_min(1.0))[..., None]


def shape_loss(p_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """L_shape: RMSE of log profiles over the used bins; shape (...,)."""
    return torch.sqrt((shape_residuals(p_hat, t) ** 2).sum(-1) + 1e-30)


def refl_loss(r_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """L_R = ((R_hat - R_MC) / r_scale)^2 (module docstring); shape (...,)."""
    return ((r_hat - t.R) / t.r_scale) ** 2


def joint_loss(p_hat: torch.Tensor, r_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """L_joint = L_shape + 5 L_R per problem; shape (...,)."""
    return shape_loss(p_hat, t) + LAMBDA_R * refl_loss(r_hat, t)


def shape_excess(shape_rmse: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
    """The part of L_shape that the MC noise does not explain, sqrt(max(L_shape^2 - noise^2, 0)): the
    model error, if the noise of each bin is independent of the misfit (same shape as the inputs)."""
    return torch.sqrt((shape_rmse**2 - noise**2).clamp_min(0.0))


def refl_rel_err(r_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """|R_hat - R_MC| / R_MC (R_MC floored at 1e-12 so that a dark target gives a finite number)."""
    return (r_hat - t.R).abs() / t.R.clamp_min(1e-12)
