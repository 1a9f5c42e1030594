"""The joint shape-and-amplitude loss of the paper (eq. joint_loss, shape_loss, refl_loss).

    L_shape = RMSE over radial bins of (log P_hat(r) - log P_MC(r)),   P_MC = profile / R_MC
    L_R     = (R_hat - R_MC)^2
    L_joint = L_shape + 5 L_R

with P_hat = sum_k w_k P_k and R_hat = sum_k w_k R_k (paper §4; note that the paper's P_hat weights the
normalised component profiles by w_k alone, not by w_k R_k).

Bins that enter L_shape (the mask), documented choice:

* a bin is used only if the MC profile there is > 0 and it holds at least ``min_count`` photon
  equivalents: profile * bin area * photons >= min_count (default 10, i.e. a relative noise of about
  30 % or better for unit-weight photons; absorption-weighted photons carry less weight, so the real
  count is higher).  Empty and noise-dominated bins (the far tail, and the innermost tiny bins that
  few photons hit) are thereby excluded;
* if fewer than ``MIN_BINS`` bins pass, every bin with a positive profile is used; if none has a
  positive profile (R_MC = 0), L_shape is 0 and only L_R constrains the fit.

The model can underflow (a component whose support ends inside the MC range gives P = 0 beyond it), so
the log uses P_hat + floor with floor = 1e-3 x the smallest used MC value of that problem: this leaves
the loss unchanged wherever the fit is anywhere near the data and keeps it finite, with a usable
gradient, where it is not.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

#: Weight of the reflectance term (paper: lambda_R = 5).
LAMBDA_R: float = 5.0
#: Minimum photon equivalents for a bin to enter the shape loss (see module docstring).
MIN_COUNT: float = 10.0
#: Below this many valid bins the photon-count criterion is dropped.
MIN_BINS: int = 8
#: Floor of the model profile in the log, relative to the smallest used MC value.
FLOOR_REL: float = 1e-3


@dataclass
class Target:
    """Monte Carlo targets of a batch of fitting problems (leading dims ``...``).

    ``r_cm`` (M,): the bin centres at which the model is evaluated; ``log_p`` (..., M): log of P_MC
    (0 where masked); ``mask`` (..., M) float 0/1; ``n_used`` (...,): number of used bins;
    ``floor`` (...,): the model floor (cm^-2); ``R`` (...,): R_MC.
    """

    r_cm: torch.Tensor
    log_p: torch.Tensor
    mask: torch.Tensor
    n_used: torch.Tensor
    floor: torch.Tensor
    R: torch.Tensor

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
        )

    def rows(self, idx: torch.Tensor) -> Target:
        """The targets of a subset of the problems (indices into the first axis)."""
        return Target(self.r_cm, self.log_p[idx], self.mask[idx], self.n_used[idx], self.floor[idx], self.R[idx])

    def subset(self, idx: torch.Tensor) -> Target:
        """The same targets on a subset of the radial bins (indices into the last axis)."""
        mask = self.mask[..., idx]
        return Target(self.r_cm[idx], self.log_p[..., idx], mask, mask.sum(-1), self.floor, self.R)


def make_target(
    profile: torch.Tensor,
    R_mc: torch.Tensor,
    r_edges_cm: torch.Tensor,
    photons: float,
    min_count: float = MIN_COUNT,
) -> Target:
    """Build the targets from MC outputs: ``profile`` (..., M) cm^-2, ``R_mc`` (...,), edges (M + 1,).

    Raises ValueError on NaN/Inf or negative input.
    """
    from training.sim.lut_interp import bin_centres

    if not (torch.isfinite(profile).all() and torch.isfinite(R_mc).all()):
        raise ValueError("MC profile or R_d contains NaN/Inf")
    if (profile < 0).any() or (R_mc < 0).any():
        raise ValueError("MC profile and R_d must be non-negative")
    area = torch.pi * torch.diff(r_edges_cm**2)
    positive = profile > 0
    counted = positive & (profile * area * photons >= min_count)
    few = counted.sum(-1, keepdim=True) < MIN_BINS
    mask = torch.where(few, positive, counted).to(profile.dtype)
    p_mc = profile / R_mc.clamp_min(1e-300)[..., None]
    log_p = torch.where(mask > 0, torch.log(p_mc.clamp_min(1e-300)), torch.zeros_like(p_mc))
    big = torch.full_like(p_mc, float("inf"))
    p_min = torch.where(mask > 0, p_mc, big).amin(-1)
    floor = torch.where(torch.isfinite(p_min), p_min * FLOOR_REL, torch.ones_like(p_min))
    return Target(bin_centres(r_edges_cm), log_p, mask, mask.sum(-1), floor, R_mc)


def shape_residuals(p_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """Masked log residuals scaled so that their squared sum is L_shape^2; shape (..., M)."""
    d = torch.log(p_hat + t.floor[..., None]) - t.log_p
    return d * t.mask / torch.sqrt(t.n_used.clamp_min(1.0))[..., None]


def shape_loss(p_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """L_shape: RMSE of log profiles over the used bins; shape (...,)."""
    return torch.sqrt((shape_residuals(p_hat, t) ** 2).sum(-1) + 1e-30)


def refl_loss(r_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """L_R = (R_hat - R_MC)^2; shape (...,)."""
    return (r_hat - t.R) ** 2


def joint_loss(p_hat: torch.Tensor, r_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """L_joint = L_shape + 5 L_R per problem; shape (...,)."""
    return shape_loss(p_hat, t) + LAMBDA_R * refl_loss(r_hat, t)


def refl_rel_err(r_hat: torch.Tensor, t: Target) -> torch.Tensor:
    """|R_hat - R_MC| / R_MC (R_MC floored at 1e-12 so that a dark target gives a finite number)."""
    return (r_hat - t.R).abs() / t.R.clamp_min(1e-12)
