"""The mixture of K homogeneous media evaluated through the lookup tables (paper eq. mixture).

    R_d^fit(r) = sum_k w_k R(alpha_k, g_k) P(r | alpha_k, g_k, sigma_t,k)

Parameterisation (unconstrained vector ``theta`` of 4K - 1 numbers per problem, layout
``[a_1..a_K, b_1..b_K, s_1..s_K, z_2..z_K]``):

* alpha_k = sigmoid(a_k) in (0, 1);
* g_k = g_lo + (g_hi - g_lo) sigmoid(b_k), with (g_lo, g_hi) the LUT's g range intersected with
  [-0.99, 0.99];
* sigma_t,k = exp(s_k) in cm^-1, unbounded as in the paper (no clamping);
* w = softmax(0, z_2, ..., z_K): the first logit is fixed at 0, so K = 1, 2, 3 have 3, 7, 11 free
  parameters, the paper's counts, and the least-squares problem has no null direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from training.sim.lut_interp import LookupTables

#: Bound of |g| for the bounded map (paper: (-0.99, 0.99) or the LUT's range, whichever is narrower).
G_ABS_MAX: float = 0.99


def n_params(k: int) -> int:
    """Number of free parameters of a K-component mixture (4K - 1)."""
    return 4 * k - 1


def g_bounds(lut: LookupTables) -> tuple[float, float]:
    """The anisotropy interval of the bounded map: the LUT's g range within [-0.99, 0.99]."""
    lo, hi = lut.g_range
    return max(lo, -G_ABS_MAX), min(hi, G_ABS_MAX)


@dataclass
class Mixture:
    """Physical parameters of a batch of mixtures; each field has shape (..., K)."""

    alpha: torch.Tensor
    g: torch.Tensor
    sigma_t: torch.Tensor  # cm^-1
    w: torch.Tensor  # sums to 1 over the last axis

    @property
    def k(self) -> int:
        return self.alpha.shape[-1]


def unpack(theta: torch.Tensor, k: int, g_lo: float, g_hi: float) -> Mixture:
    """Map the unconstrained ``theta`` (..., 4K - 1) to physical parameters (see module docstring)."""
    if theta.shape[-1] != n_params(k):
        raise ValueError(f"theta has {theta.shape[-1]} parameters, K={k} needs {n_params(k)}")
    a, b, s, z = theta[..., :k], theta[..., k : 2 * k], theta[..., 2 * k : 3 * k], theta[..., 3 * k :]
    logits = torch.cat([torch.zeros_like(a[..., :1]), z], dim=-1)
    return Mixture(
        alpha=torch.sigmoid(a),
        g=g_lo + (g_hi - g_lo) * torch.sigmoid(b),
        sigma_t=torch.exp(s),
        w=torch.softmax(logits, dim=-1),
    )


def pack(m: Mixture, g_lo: float, g_hi: float, eps: float = 1e-7) -> torch.Tensor:
    """Inverse of ``unpack`` (values at the bounds are pulled inside by ``eps``); shape (..., 4K - 1)."""
    alpha = m.alpha.clamp(eps, 1 - eps)
    u = ((m.g - g_lo) / (g_hi - g_lo)).clamp(eps, 1 - eps)
    logw = torch.log(m.w.clamp_min(1e-12))
    z = logw[..., 1:] - logw[..., :1]
    return torch.cat([torch.logit(alpha), torch.logit(u), torch.log(m.sigma_t), z], dim=-1)


def components(lut: LookupTables, m: Mixture, r_cm: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-component normalised profiles P_k(r) (..., K, M) in cm^-2 and reflectances R_k (..., K).

    ``r_cm``: the radii (cm) at which to evaluate, shape (M,) (bin centres for binned targets).
    """
    return lut.profile(r_cm, m.alpha, m.g, m.sigma_t), lut.reflectance(m.alpha, m.g)


#: The fitter's mixture profile, recorded where fits are cached (training.validate) so that fits made with
#: another one are not reused: "w_k R_k" = sum_k w_k R_k P_k / sum_k w_k R_k ("w_k": the
#: paper's §4 text, sum_k w_k P_k).
PROFILE_WEIGHTING: str = "w_k R_k"

#: Added to every R_k in the profile weights v_k, so that v stays defined (and sums to 1) when all R_k
#: vanish (alpha -> 0); it shifts v by less than 1e-10 wherever R_k > 1e-2.
MIX_R_EPS: float = 1e-12


def profile_weights(r_k: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """v_k = w_k R_k / sum_j w_j R_j (..., K): the share of the exiting light that medium k carries."""
    wr = w * (r_k + MIX_R_EPS)
    return wr / wr.sum(-1, keepdim=True)


#: The mixture profiles ``mix`` knows: "rendered" (ours, the default) and "paper" (its §4 text, sum_k w_k P_k).
WEIGHTINGS: tuple[str, ...] = ("rendered", "paper")


def mix(p_k: torch.Tensor, r_k: torch.Tensor, w: torch.Tensor, weighting: str = "rendered"
        ) -> tuple[torch.Tensor, torch.Tensor]:
    """The mixture's normalised profile P_hat = sum_k w_k R_k P_k / sum_k w_k R_k (..., M) and its
    reflectance R_hat = sum_k w_k R_k (...).

    P_hat is ``radial_profile`` / R_hat: the profile that a renderer picking medium k with probability w_k
    produces, and the issue's R_d^fit(r) normalised.  (The paper's §4 text writes sum_k w_k P_k, which
    differs from the rendered profile whenever the components' R_k differ; fitted that way, K = 2 and 3
    rendered worse profiles than K = 1 - see docs/research/fitting.md.)  ``weighting="paper"``
    returns that sum_k w_k P_k / sum_k w_k instead (the gate's "paper as written" fits)."""
    if weighting == "paper":
        return (w[..., None] * p_k).sum(-2) / w.sum(-1, keepdim=True).clamp_min(1e-300), (w * r_k).sum(-1)
    if weighting != "rendered":
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    v = profile_weights(r_k, w)
    return (v[..., None] * p_k).sum(-2), (w * r_k).sum(-1)


def radial_profile(lut: LookupTables, m: Mixture, r_cm: torch.Tensor) -> torch.Tensor:
    """The mixture's radial exitance R_d^fit(r) = sum_k w_k R_k P_k(r), cm^-2, shape (..., M)."""
    p_k, r_k = components(lut, m, r_cm)
    return (m.w[..., None] * r_k[..., None] * p_k).sum(-2)
