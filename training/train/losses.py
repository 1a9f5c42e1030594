"""The training losses of the three stages (paper §5.2-5.3).

Shapes: N tones, W wavelengths, K components; ``u`` tensors are Dec_T's normalised coordinates
(N, 4, K, W) with channels (alpha, g, sigma_t, weight), see ``training.model.networks``.

* Stage 1: spectral L1, mean |R_hat - R_d| over tones and all 376 wavelengths.
* Stage 2: colour L1, mean |A_RGB - gamma * CMF(Dec_R(Enc(A_RGB)))| with the analytic exposure gamma,
  plus an optional prior on |ln gamma| (``colour_loss``; 0 is the paper's loss).
* Stage 3: L = L_param + LAMBDA_R L_refl + LAMBDA_SMOOTH L_smooth (paper eq. total_loss):
  - L_param = (1/|C|) sum_c phi_c Huber(u_c, u*_c), each channel averaged over its elements, phi_alpha
    = 2, others 1.  Comparing in ``u`` puts sigma_t on a log scale (a difference of 0.05 is a factor
    exp(0.05 ln 1e6) = 2.0 in sigma_t) and g on its range.  Huber's transition HUBER_DELTA = 0.05 (our
    choice; the paper gives none): L1-like beyond it.  Where: at every wavelength, the targets
    interpolated from the fitted ones (``training.train.spectral``), or at the fitted
    wavelengths only (``fit --wavelength-stride`` fits every n-th), which teaches Dec_T a comb.
    Weighted (ours; ``weighted=True``): the alpha, g and sigma_t terms of component k count
    with the target's weight w*_k (times K, so that equal weights give the unweighted mean): a component
    with w ~ 0 adds nothing to the profile, so its fitted alpha, g, sigma_t are whatever the optimiser
    left there, and pulling the decoder toward them only teaches it noise.  The weight channel itself
    counts in full.
  - L_refl = mean |sum_k w_k R(alpha_k, g_k) (1 - exp(-C sigma_t,k c(lambda))) - R_MC| (eq. lrefl_lut
    with the slab-depth factor of eq. slab_factor), R from the LUT (bilinear).
  - L_smooth = mean |u[..., l + 1] - u[..., l]| over all channels (finite differences over lambda).  The
    paper writes ||grad_lambda theta||_1 with lambda_smooth = 0.5 and does not say over what it sums; as a
    mean over steps, channels and tones, 0.5 is weak beside L_shape and L_refl: the rebuild's decoders
    moved by 0.1 of each channel's range per 2 nm step (docs/research/training.md, "L_smooth");
    ``lambda_smooth`` (``train --smooth-weight``) sets it.
  - Ours, not the paper's: + shape_weight L_shape, the fitter's profile loss (``training.fit.loss``) of
    the decoded mixture's rendered profile sum_k w_k R_k P_k / sum_k w_k R_k against the Monte Carlo
    profile, at the fitted wavelengths (``profile_shape_loss``).  Why: the fits are degenerate - very
    different (alpha, g, sigma_t, w) give the same profile, and the fitter's choice jumps between them
    from tone to tone - so L_param alone regresses to their average, which is no solution (measured on
    the laptop model: NIR g pinned at 0, rendered profile shape 2.2 against the fits' 0.16).  L_shape
    scores what a renderer sees; L_param keeps the decoder near the fits.  shape_weight 0 is the paper.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from training.fit import loss as fit_loss
from training.fit.mixture import mix
from training.model.chain import SkinChain
from training.sim.lut_interp import LookupTables
from training.train.spectral import interpolate

LAMBDA_R: float = 15.0
LAMBDA_SMOOTH: float = 0.5
PHI: tuple[float, float, float, float] = (2.0, 1.0, 1.0, 1.0)  # alpha, g, sigma_t, weight
HUBER_DELTA: float = 0.05
#: Cost of L_shape in a training step (our choice, see the module docstring): a batch sees about
#: SHAPE_WAVELENGTHS_PER_STEP of the profile wavelengths (every n-th, n = their count / this, rounded; the
#: offset changes from batch to batch: every 6th of 94 fitted ones, every 24th of all 376) and every
#: SHAPE_BIN_STRIDE-th radial bin (the training split's targets are loaded so); validation uses all bins.
SHAPE_WAVELENGTHS_PER_STEP: int = 16
SHAPE_BIN_STRIDE: int = 2
#: The validation L_shape of each epoch, with dense targets: every 2nd of the 376 wavelengths (the fitted
#: every 4th and the midpoints between them), all bins; at all 376 the evaluation alone cost 0.5x a laptop
#: epoch (measured in docs/research/training.md).
VALIDATION_SHAPE_EVERY: int = 2


def spectral_l1(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    return (pred - target).abs().mean()


#: L_refl's forms: the paper's absolute L1, and ours on log reflectance (``reflectance_loss``)
REFL_LOSSES = ("absolute", "log")
#: floor of both sides of the log form: far below any reflectance the gate sees (a near-black tone's R_d in the
#: visible is ~3e-3), so that a tone's UV, where R_d reaches 1e-5, does not dominate the mean
LOG_REFL_FLOOR = 1e-4


def reflectance_loss(pred: torch.Tensor, target: torch.Tensor, form: str = "absolute") -> torch.Tensor:
    """L_refl over (N, W) spectra: "absolute" mean |R_hat - R| (the paper); "log" mean |ln(R_hat + f) - ln(R + f)|,
    f = ``LOG_REFL_FLOOR``: a relative error, so a dark tone's colour counts as much as a light one's (CIE L*
    is ~ Y^(1/3): the same absolute error is a larger Delta E the darker the tone)."""
    if form == "absolute":
        return spectral_l1(pred, target)
    if form == "log":
        return (torch.log(pred + LOG_REFL_FLOOR) - torch.log(target + LOG_REFL_FLOOR)).abs().mean()
    raise ValueError(f"L_refl form must be one of {REFL_LOSSES}, got {form!r}")


def colour_loss(model: SkinChain, albedo_rgb: torch.Tensor, exposure_prior: float = 0.0) -> torch.Tensor:
    """|A - gamma * rgb(Dec_R(Enc(A)))|_1 (mean) + exposure_prior * mean |ln gamma|, for albedos already in
    the model's domain.  The prior (0 = the paper) prefers, among tones of the input's chromaticity, the
    one of its brightness: without it the encoder is free to answer a light colour with a dark tone at
    exposure 50 (measured on the laptop model), which fits the colour and nothing else."""
    refl = model.dec_r(model.enc(albedo_rgb))
    rgb = model.colour.rgb(refl)
    gamma = model.colour.exposure(albedo_rgb, rgb)
    loss = (albedo_rgb - gamma * rgb).abs().mean()
    if exposure_prior > 0:
        loss = loss + exposure_prior * torch.log(gamma.clamp_min(1e-6)).abs().mean()
    return loss


def param_loss(u: torch.Tensor, u_target: torch.Tensor, weighted: bool = False) -> torch.Tensor:
    """(1/|C|) sum_c phi_c mean Huber(u_c, u*_c) over the 4 channels of (N, 4, K, W) tensors; ``weighted``:
    the alpha, g, sigma_t terms times K w*_k (module docstring)."""
    per = F.huber_loss(u, u_target, reduction="none", delta=HUBER_DELTA)
    if weighted:
        w = u_target[:, 3:4]  # (N, 1, K, W)
        per = per * torch.cat([u.shape[2] * w.expand(-1, 3, -1, -1), torch.ones_like(w)], dim=1)
    per = per.mean(dim=(0, 2, 3))  # (4,)
    phi = torch.tensor(PHI, dtype=u.dtype, device=u.device)
    return (phi * per).mean()


def lut_reflectance(model: SkinChain, lut: LookupTables, out: dict[str, torch.Tensor], slab: bool = True
                    ) -> torch.Tensor:
    """R_hat_LUT (N, W) = sum_k w_k R(alpha_k, g_k) (1 - exp(-C sigma_t,k c(lambda))); without the slab-depth
    factor (``slab`` False, the paper's "without this correction" ablation) sum_k w_k R(alpha_k, g_k)."""
    r_k = lut.reflectance(out["alpha"], out["g"])
    if slab:
        r_k = r_k * model.slab.factor(out["sigma_t"])
    return (out["weight"] * r_k).sum(1)


def profile_shape_loss(lut: LookupTables, out: dict[str, torch.Tensor], target: fit_loss.Target,
                       target_index: torch.Tensor | None) -> torch.Tensor:
    """Mean L_shape of the decoded mixtures (``out`` (N, K, W) tensors) at ``target_index`` (Wf,) (None: all
    W) against ``target`` (leading dims (N, Wf)), with the fitter's rendered mixture (``mixture.mix``)."""
    def at_targets(x: torch.Tensor) -> torch.Tensor:  # (N, K, W) -> (N, Wf, K)
        return (x if target_index is None else x[..., target_index]).transpose(1, 2)

    alpha, g, sigma_t, w = (at_targets(out[k]) for k in ("alpha", "g", "sigma_t", "weight"))
    p_hat, _ = mix(lut.profile(target.r_cm, alpha, g, sigma_t), lut.reflectance(alpha, g), w)
    return fit_loss.shape_loss(p_hat, target).mean()


def smooth_loss(u: torch.Tensor) -> torch.Tensor:
    return (u[..., 1:] - u[..., :-1]).abs().mean()


def stage3_losses(model: SkinChain, lut: LookupTables, p: torch.Tensor, R_mc: torch.Tensor,
                  targets: dict[str, torch.Tensor], target_index: torch.Tensor | None = None,
                  shape_target: fit_loss.Target | None = None, shape_weight: float = 0.0,
                  shape_index: torch.Tensor | None = None, interp: torch.Tensor | None = None,
                  weighted: bool = False, report: bool = False, lambda_r: float = LAMBDA_R, slab: bool = True,
                  frozen_decr: bool = True, refl_loss: str = "absolute",
                  lambda_smooth: float = LAMBDA_SMOOTH) -> dict[str, torch.Tensor]:
    """All stage-3 terms for true tones ``p`` (N, 5), MC reflectance (N, W) and fit targets (N, K, Wf) at
    the wavelengths ``target_index`` (Wf,) (None: all W).  ``interp`` (Wf, W) (``spectral.interpolation_matrix``):
    L_param compares at all W with the targets interpolated; None: at ``target_index`` only.  ``weighted``:
    L_param weighted by the target weights (module docstring).  L_refl and L_smooth use all W.  With
    ``shape_target`` (leading dims (N, Ws)) L_shape is reported, at ``shape_index`` (Ws,) (None:
    ``target_index``), and added with ``shape_weight``.  "param" is the L_param optimised; with ``report``
    both variants are returned too ("param_plain", "param_weighted").  Ablations (``training.ablations``):
    ``lambda_r`` the weight of L_refl (paper 15), ``slab`` False drops the slab-depth factor from L_refl,
    ``frozen_decr`` False lets the gradient reach Dec_R (unfrozen in stage 3); ``refl_loss`` L_refl's form
    (``reflectance_loss``); ``lambda_smooth`` the weight of L_smooth (paper 0.5)."""
    with torch.set_grad_enabled(torch.is_grad_enabled() and not frozen_decr):
        refl = model.dec_r(p)  # frozen Dec_R (the paper) unless unfrozen
    out = model.dec_t(p, refl)
    u_t = model.dec_t.to_unit(targets["alpha"], targets["g"], targets["sigma_t"], targets["weight"])
    if interp is not None:
        u, u_t = out["u"], interpolate(u_t, interp)
    else:
        u = out["u"] if target_index is None else out["u"][..., target_index]
    l_param = param_loss(u, u_t, weighted)
    l_refl = reflectance_loss(lut_reflectance(model, lut, out, slab), R_mc, refl_loss)
    l_smooth = smooth_loss(out["u"])
    total = l_param + lambda_r * l_refl + lambda_smooth * l_smooth
    terms = {"param": l_param, "refl": l_refl, "smooth": l_smooth}
    if report:
        terms.update(param_plain=param_loss(u, u_t), param_weighted=param_loss(u, u_t, weighted=True))
    if shape_target is not None:
        index = target_index if shape_index is None else shape_index
        terms["shape"] = profile_shape_loss(lut, out, shape_target, index)
        if shape_weight > 0:
            total = total + shape_weight * terms["shape"]
    return {"loss": total, **terms}
