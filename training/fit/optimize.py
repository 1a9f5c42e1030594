"""Fitting K-media mixtures to MC profiles: the paper's Adam schedule and a Levenberg-Marquardt fitter.

Both methods share the same initialisation and the same schedule of K (paper §4 "Optimization"):

1. K = 1 on the profile shape only (L_shape).  Start: a coarse search over 16 albedos at
   g = ``g_init`` (the tissue's g(lambda) when known), with sigma_t set so that the LUT profile's
   median radius matches the MC one; the best start by L_shape is refined.
2. K = 1 joint (L_shape + 5 L_R), from step 1: the row reported as "K = 1" (the paper's tables use the
   joint-optimised K = 1).
3. K = 2 joint, 7 parameters, from step 1 split into two copies at sigma_t x f and / f, w = 1/2 each
   (f = 1.5 for the paper's method; LM also tries the other starts of ``K2_SPLITS``, some giving the
   new copy another albedo, and keeps the best).
4. K = 3 joint, 11 parameters, from step 3 by splitting the dominant component (largest w) into two
   copies at sigma_t x 1.5 and / 1.5 sharing its weight (LM: every start of ``K3_SPLITS``, and K = 2
   itself, as a duplicated component, where no K = 3 start does better).

``method="paper"``: Adam, lr 1e-2, cosine schedule to 0; K = 2 3,000 steps and K = 3 10,000 steps as in
the paper; K = 1 stages 1,000 steps each (the paper does not say).

``method="lm"``: Levenberg-Marquardt (Marquardt's diagonal scaling, per-problem damping, a step is
kept only if it lowers L_joint) on the 3-11 parameters, batched small dense solves with torch.linalg.
L_joint = sqrt(S/n) + 5 dR^2 (dR = the reflectance residual in units of ``Target.r_scale``) is not a
sum of squares; we Gauss-Newton the sum of squares
S/n + c dR^2 with c = 10 L_shape re-evaluated every iteration, whose gradient is parallel to that of
L_joint at the current point, so its stationary points are those of L_joint (an IRLS-style
reweighting; hand-written because no well-kept torch library offers batched LM).  The Jacobian of
the per-component profiles comes from ``LookupTables.profile_grad`` (explicit derivatives of the
interpolant w.r.t. alpha, g, log sigma_t, all K components at once); the mixture and the log are
differentiated by hand.

Both methods evaluate the model only on the radial bins that some problem of the batch uses (the
others are masked out of the loss, so this changes nothing); ``bin_stride`` > 1 keeps every n-th of
those during the fit (an approximation; the final metrics always use all bins).

Everything is batched over the leading problem axis (tones x wavelengths) and runs on CPU or CUDA.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import torch

from training.fit import loss as fit_loss
from training.fit.mixture import MIX_R_EPS, Mixture, g_bounds, mix, pack, profile_weights, unpack
from training.sim.lut_interp import LookupTables

#: Adam schedule of the paper (steps per stage) and its learning rate.
PAPER_STEPS: dict[str, int] = {"k1_shape": 1000, "k1_joint": 1000, "k2": 3000, "k3": 10000}
PAPER_LR: float = 1e-2
#: Width of the g interval [0, ISOTROPIC_G] of isotropic fits (``fit_schedule(isotropic=True)``): g = 0 to
#: well below what the LUT resolves, through the same bounded map as the anisotropic fits.
ISOTROPIC_G: float = 1e-6
#: Levenberg-Marquardt iterations per stage (upper bounds; stops early when converged).
LM_ITERS: dict[str, int] = {"k1_shape": 30, "k1_joint": 30, "k2": 60, "k3": 80}
#: LM iterations per K from a warm start (``fit_schedule(warm=...)``): on 8 laptop-dataset tones x 94
#: wavelengths (anchors every 12th) the mean shape and joint losses equal those of 30/60/80 iterations
#: to 3 digits at a third of the time.
WARM_LM_ITERS: dict[str, int] = {"k1_joint": 12, "k2": 15, "k3": 20}
#: LM with several starts: every start gets this many iterations (per stage), then only the best one
#: per problem goes on (successive halving in one round).  Tuned on the benchmark's MC problems.
LM_PROBE_ITERS: dict[str, int] = {"k1_joint": 15, "k2": 15, "k3": 30}
#: Starts of the K = 2 and K = 3 stages (the paper's method uses the first only): each is (rank of the
#: component split, sigma_t factor, albedo of the new copy or None = same).  LM keeps the best.
#: The loss is multimodal (a low-albedo second medium is often the better basin), hence the spread.
K2_SPLITS: tuple[tuple[int, float, float | None], ...] = (
    (0, 1.5, None),
    (0, 10.0, None),
    (0, 1.0, 0.1),
    (0, 1.0, 0.9),
    (0, 3.0, 0.9),
    (0, 10.0, 0.5),
)
K3_SPLITS: tuple[tuple[int, float, float | None], ...] = (
    (0, 1.5, None),
    (0, 3.0, None),
    (0, 1.0, 0.5),
    (0, 1.0, 0.9),
    (0, 3.0, 0.9),
    (1, 1.0, 0.1),
    (1, 10.0, 0.5),
    (1, 10.0, None),
)


@dataclass
class FitResult:
    """One K of a schedule: parameters and metrics per problem (shape (B,) unless stated)."""

    k: int
    theta: torch.Tensor  # (B, 4K - 1)
    mixture: Mixture  # fields (B, K)
    shape_rmse: torch.Tensor
    refl_rel_err: torch.Tensor
    joint: torch.Tensor
    noise: torch.Tensor  # L_shape of the MC noise alone (loss.Target.noise)
    work: float  # model evaluations per problem spent up to this K (incl. the stages it starts from)
    seconds: float
    extra: dict = field(default_factory=dict)


class Problem:
    """A batch of B fitting problems against one LUT: evaluation, metrics and the LM Jacobian."""

    def __init__(self, lut: LookupTables, target: fit_loss.Target, weighting: str = "rendered",
                 g_range: tuple[float, float] | None = None):
        self.lut = lut
        self.target = target
        self.weighting = weighting  # mixture.mix: "rendered" (ours) or "paper" (sum_k w_k P_k; Adam only)
        self.g_lo, self.g_hi = g_bounds(lut) if g_range is None else g_range
        self.evals = 0

    def mixture(self, theta: torch.Tensor, k: int) -> Mixture:
        return unpack(theta, k, self.g_lo, self.g_hi)

    def predict(self, theta: torch.Tensor, k: int, t: fit_loss.Target | None = None):
        """(P_hat (B, M), R_hat (B,)) at the target's bin centres."""
        t = self.target if t is None else t
        m = self.mixture(theta, k)
        self.evals += theta.shape[0]
        p_k = self.lut.profile(t.r_cm, m.alpha, m.g, m.sigma_t)
        return mix(p_k, self.lut.reflectance(m.alpha, m.g), m.w, self.weighting)

    def merit(self, theta: torch.Tensor, k: int, shape_only: bool, t: fit_loss.Target | None = None) -> torch.Tensor:
        t = self.target if t is None else t
        p, r = self.predict(theta, k, t)
        s = fit_loss.shape_loss(p, t)
        return s if shape_only else s + fit_loss.LAMBDA_R * fit_loss.refl_loss(r, t)

    def metrics(self, theta: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(L_shape, |dR|/R, L_joint) on all bins."""
        with torch.no_grad():
            p, r = self.predict(theta, k)
            s = fit_loss.shape_loss(p, self.target)
            return s, fit_loss.refl_rel_err(r, self.target), s + fit_loss.LAMBDA_R * fit_loss.refl_loss(r, self.target)

    # -------------------------------------------------------------- Jacobian for LM
    def residuals_jacobian(self, theta: torch.Tensor, k: int, shape_only: bool, t: fit_loss.Target):
        """Residual vector (B, M + 1) and its Jacobian (B, M + 1, 4K - 1) w.r.t. theta."""
        m = self.mixture(theta, k)
        p_k, pa, pg, ps = self.lut.profile_grad(t.r_cm, m.alpha, m.g, m.sigma_t)
        r_k, ra, rg = self.lut.reflectance_grad(m.alpha, m.g)
        self.evals += 3 * theta.shape[0]  # value + derivatives: about three evaluations
        # chain rule to the raw parameters: alpha = sigmoid(a), g = lo + (hi - lo) sigmoid(b), s = log sigma
        da = m.alpha * (1 - m.alpha)
        u = (m.g - self.g_lo) / (self.g_hi - self.g_lo)
        db = (self.g_hi - self.g_lo) * u * (1 - u)
        dpa, dpb, dps = pa * da[..., None], pg * db[..., None], ps
        dra, drb, drs = ra * da, rg * db, torch.zeros_like(r_k)
        w = m.w  # (B, K)
        p_hat, r_hat = mix(p_k, r_k, w)
        den = p_hat + t.floor[:, None]  # (B, M)
        scale = t.mask / torch.sqrt(t.n_used.clamp_min(1.0))[:, None]  # (B, M)
        res_s = (torch.log(den) - t.log_p) * scale
        # P_hat = sum v_k P_k with v_k = w_k R'_k / sum_j w_j R'_j (R' = R + MIX_R_EPS, mixture.mix):
        #   dP_hat/dx_k = v_k dP_k/dx_k + (w_k dR_k/dx_k / sum_j w_j R'_j) (P_k - P_hat)   for x = a, b, s
        #   dP_hat/dz_k = v_k (P_k - P_hat)                                                 (softmax logit)
        v = profile_weights(r_k, w)
        vk = v[..., None]  # (B, K, 1)
        dev = p_k - p_hat[:, None, :]  # (B, K, M)
        u = (w / (w * (r_k + MIX_R_EPS)).sum(-1, keepdim=True))[..., None]  # (B, K, 1)
        cols_p = [vk * dpa + u * dra[..., None] * dev, vk * dpb + u * drb[..., None] * dev, vk * dps]
        cols_r = [w * dra, w * drb, w * drs]  # d R_hat: (B, K)
        if k > 1:
            cols_p.append((vk * dev)[:, 1:])
            cols_r.append((w * (r_k - r_hat[:, None]))[:, 1:])
        jp = torch.cat(cols_p, dim=1).transpose(1, 2) * (scale / den)[..., None]  # (B, M, P)
        jr = torch.cat(cols_r, dim=1)  # (B, P)
        if shape_only:
            c = torch.zeros_like(r_hat)
        else:  # IRLS weight: grad of S/n + c dR^2 parallel to grad of L_joint (module docstring)
            l_s = torch.sqrt((res_s**2).sum(-1))
            c = 2.0 * fit_loss.LAMBDA_R * l_s.clamp_min(1e-3)
        sc = torch.sqrt(c)
        sc = sc / t.r_scale
        res = torch.cat([res_s, (sc * (r_hat - t.R))[:, None]], dim=1)
        jac = torch.cat([jp, (sc[:, None] * jr)[:, None, :]], dim=1)
        return res, jac


# ------------------------------------------------------------------ initialisation and splitting
def _median_log_radius(cdf: torch.Tensor, log_edges: torch.Tensor) -> torch.Tensor:
    """log radius where the cumulative fraction ``cdf`` (..., M) (at the bins' outer edges) reaches 1/2."""
    total = cdf[..., -1:].clamp_min(1e-300)
    c = (cdf / total).contiguous()
    half = torch.full_like(c[..., :1], 0.5)
    i = torch.searchsorted(c, half).clamp(1, c.shape[-1] - 1)
    c0, c1 = torch.gather(c, -1, i - 1), torch.gather(c, -1, i)
    e0, e1 = log_edges[i], log_edges[i + 1]  # outer edges of bins i-1 and i
    t = ((0.5 - c0) / (c1 - c0).clamp_min(1e-300)).clamp(0, 1)
    return (e0 + t * (e1 - e0))[..., 0]


def initial_k1(
    lut: LookupTables,
    profile: torch.Tensor,
    r_edges_cm: torch.Tensor,
    g_init: torch.Tensor,
    prob: Problem,
    shape_only: bool = True,
) -> torch.Tensor:
    """A K = 1 start (B, 3): the best of 16 albedos by L_shape (or L_joint if not ``shape_only``), at
    g = ``g_init`` and sigma_t from the median radius."""
    dt, dev = lut.P.dtype, lut.P.device
    alphas = 1.0 - torch.logspace(math.log10(0.7), -4, 16, dtype=dt, device=dev)
    B = profile.shape[0]
    area_mc = torch.pi * torch.diff(r_edges_cm**2)
    med_mc = _median_log_radius(torch.cumsum(profile * area_mc, -1), torch.log(r_edges_cm.clamp_min(1e-300)))
    area_lut = torch.pi * torch.diff(lut.r_edges_mfp**2)
    log_e_lut = torch.log(lut.r_edges_mfp.clamp_min(1e-300))
    margin = min(1e-3, (prob.g_hi - prob.g_lo) / 4)  # a fixed g (isotropic fits) has a range of ~0
    g_b = g_init.clamp(prob.g_lo + margin, prob.g_hi - margin)
    best_theta, best = None, None
    for a in alphas:
        al = torch.full((B,), float(a), dtype=dt, device=dev)
        rows = lut.profile_rows(al, g_b)
        med_lut = _median_log_radius(torch.cumsum(rows * area_lut, -1), log_e_lut)
        sigma = torch.exp(med_lut - med_mc)
        m = Mixture(al[:, None], g_b[:, None], sigma[:, None], torch.ones_like(al)[:, None])
        theta = pack(m, prob.g_lo, prob.g_hi)
        val = prob.merit(theta, 1, shape_only=shape_only)
        if best is None:
            best_theta, best = theta, val
        else:
            better = val < best
            best_theta = torch.where(better[:, None], theta, best_theta)
            best = torch.where(better, val, best)
    return best_theta


def split(
    theta: torch.Tensor, k: int, prob: Problem, factor: float, rank: int = 0, alpha_new: float | None = None
) -> torch.Tensor:
    """K -> K + 1 components: a component becomes two copies at sigma_t x / factor sharing its weight.

    ``rank`` 0 splits the dominant component (largest w, the paper's rule), 1 the second largest, ...
    ``alpha_new``: if given, the albedo of the new copy (a start in another basin of the loss).
    Works on the raw parameters, so with ``factor`` 1 the mixture is exactly the K-component one.
    """
    a, b, s = theta[:, :k], theta[:, k : 2 * k], theta[:, 2 * k : 3 * k]
    logits = torch.cat([torch.zeros_like(a[:, :1]), theta[:, 3 * k :]], dim=-1)
    j = logits.argsort(-1, descending=True)[:, rank : rank + 1]  # (B, 1)

    def take(x):
        return torch.gather(x, -1, j)

    lf, half = math.log(factor), math.log(2.0)
    a_add = take(a) if alpha_new is None else torch.full_like(take(a), math.log(alpha_new / (1 - alpha_new)))
    s_new = s.scatter(-1, j, take(s) + lf)
    logits = logits.scatter(-1, j, take(logits) - half)
    logits = torch.cat([logits, take(logits)], -1)
    z = logits[:, 1:] - logits[:, :1]
    return torch.cat([a, a_add, b, take(b), s_new, take(s) - lf, z], dim=-1)


# ------------------------------------------------------------------ optimisers
def adam(
    prob: Problem,
    theta0: torch.Tensor,
    k: int,
    steps: int,
    shape_only: bool,
    lr: float = PAPER_LR,
    t: fit_loss.Target | None = None,
    trace_every: int = 0,
) -> tuple[torch.Tensor, list]:
    """Adam with a cosine schedule to 0 over ``steps`` on the summed per-problem losses (independent)."""
    theta = theta0.detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([theta], lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(steps, 1))
    trace = []
    for i in range(steps):
        opt.zero_grad(set_to_none=True)
        val = prob.merit(theta, k, shape_only, t)
        val.sum().backward()
        prob.evals += 2 * theta.shape[0]  # the backward pass costs about two evaluations
        opt.step()
        sched.step()
        if trace_every and (i + 1) % trace_every == 0:
            trace.append((i + 1, val.detach().clone()))
    return theta.detach(), trace


#: LM keeps the raw albedo / anisotropy / weight parameters within +-RAW_BOX: beyond it the sigmoid and
#: softmax saturate (alpha within 6e-6 of 1), the Jacobian column vanishes and a problem cannot come back.
RAW_BOX: float = 12.0


def _box(theta: torch.Tensor, k: int) -> torch.Tensor:
    """Clamp the raw alpha, g and weight parameters to +-RAW_BOX (log sigma_t stays unbounded)."""
    ab, s, z = theta[:, : 2 * k], theta[:, 2 * k : 3 * k], theta[:, 3 * k :]
    return torch.cat([ab.clamp(-RAW_BOX, RAW_BOX), s, z.clamp(-RAW_BOX, RAW_BOX)], dim=-1)


def levenberg_marquardt(
    prob: Problem,
    theta0: torch.Tensor,
    k: int,
    iters: int,
    shape_only: bool,
    t: fit_loss.Target | None = None,
    rtol: float = 1e-6,
    patience: int = 3,
) -> torch.Tensor:
    """Batched Levenberg-Marquardt on the joint (or shape-only) loss; see the module docstring.

    A problem stops (and is no longer evaluated) once ``patience`` accepted steps in a row lowered its
    loss by less than ``rtol`` (relative), or once rejected steps drove its damping above 1e8.
    """
    t = prob.target if t is None else t
    theta = _box(theta0.detach(), k)
    B, P = theta.shape
    mu = torch.full((B,), 1e-2, dtype=theta.dtype, device=theta.device)
    stall = torch.zeros(B, dtype=torch.long, device=theta.device)
    eye = torch.eye(P, dtype=theta.dtype, device=theta.device)
    act = torch.arange(B, device=theta.device)
    with torch.no_grad():
        cur = prob.merit(theta, k, shape_only, t)
        for _ in range(iters):
            if act.numel() == 0:
                break
            th, ta, m_a = theta[act], t.rows(act), mu[act]
            res, jac = prob.residuals_jacobian(th, k, shape_only, ta)
            A = jac.transpose(1, 2) @ jac
            grad = (jac.transpose(1, 2) @ res[..., None])[..., 0]
            D = torch.diagonal(A, dim1=1, dim2=2).clamp_min(1e-10)
            lhs = A + (m_a[:, None] * D)[:, :, None] * eye + 1e-12 * eye
            step = torch.linalg.solve(lhs, -grad[..., None])[..., 0]
            step = torch.nan_to_num(step, nan=0.0, posinf=0.0, neginf=0.0).clamp(-5.0, 5.0)
            cand = _box(th + step, k)
            val = prob.merit(cand, k, shape_only, ta)
            c_a = cur[act]
            ok = torch.isfinite(val) & (val < c_a)
            gain = torch.where(ok, (c_a - val) / c_a.clamp_min(1e-30), torch.zeros_like(val))
            theta[act] = torch.where(ok[:, None], cand, th)
            cur[act] = torch.where(ok, val, c_a)
            mu[act] = torch.where(ok, m_a * 0.3, m_a * 4.0).clamp(1e-9, 1e9)
            tiny = ok & (gain < rtol)  # rejected steps only raise the damping; they do not count here
            stall[act] = torch.where(tiny, stall[act] + 1, torch.where(ok, 0, stall[act]))
            act = act[(stall[act] < patience) & (mu[act] < 1e8)]
    return theta


# ------------------------------------------------------------------ schedules
def no_worse_than_fewer(prob: Problem, theta: torch.Tensor, fewer: torch.Tensor, k: int,
                        t: fit_loss.Target) -> torch.Tensor:
    """The K = ``k`` fits ``theta`` (B, 4k - 1), each replaced by the K = k - 1 fit ``fewer`` (B, 4k - 5) with a
    duplicated component (``split`` at ratio 1.0: the same profile) wherever that scores better on ``prob``'s
    merit over ``t``; (B, 4k - 1).  A mixture of more components is then never a worse fit than one of fewer."""
    with torch.no_grad():
        dup = split(fewer, k - 1, prob, 1.0)
        worse = prob.merit(theta, k, False, t) > prob.merit(dup, k, False, t)
    return torch.where(worse[:, None], dup, theta)


def fit_schedule(
    lut: LookupTables,
    profile: torch.Tensor,
    R_mc: torch.Tensor,
    r_edges_cm: torch.Tensor,
    photons: float,
    g_init: torch.Tensor | None = None,
    ks: tuple[int, ...] = (1, 2, 3),
    method: str = "lm",
    steps: dict[str, int] | None = None,
    bin_stride: int = 1,
    stderr: torch.Tensor | None = None,
    relative_refl: bool = True,
    warm: dict[int, torch.Tensor] | None = None,
    weighting: str = "rendered",
    isotropic: bool = False,
) -> dict[int, FitResult]:
    """Fit K = 1, 2, 3 mixtures to B MC problems (``profile`` (B, M) cm^-2, ``R_mc`` (B,)).

    ``method``: "paper" (Adam schedule) or "lm" (Levenberg-Marquardt); ``steps`` overrides the
    per-stage step / iteration counts (keys of ``PAPER_STEPS``).  ``g_init`` (B,): the starting g.
    ``stderr`` (B, M): the profile's standard errors, which choose the bins of the loss; ``relative_refl``:
    the relative reflectance term (default) or the paper's absolute one (``loss.make_target``).
    ``warm`` {K: theta (B, 4K - 1)} (LM only): warm starts, e.g. the fits of a neighbouring wavelength;
    each K is then one LM run from its warm start instead of the schedule's search and splits, and
    K = 2 and 3 fall back to the K - 1 fit (a duplicated component) where that is better.
    ``weighting``: the mixture profile (``mixture.mix``): "rendered" (ours) or "paper" (its §4 text, with
    the Adam method only: the LM Jacobian is the rendered form's).  ``isotropic``: g held at 0 (within
    ``ISOTROPIC_G``; the paper's §8 ablation after Chiang 2016; the LUT's g axis must hold 0).
    Returns {K: FitResult}; all K up to max(ks) are computed (each K starts from the previous one).
    """
    if method not in ("paper", "lm"):
        raise ValueError(f"unknown method {method!r} (paper | lm)")
    if weighting == "paper" and method != "paper":
        raise ValueError("the paper's mixture profile (sum_k w_k P_k) is fitted with method 'paper' only")
    g_range = None
    if isotropic:
        if not lut.g_range[0] <= 0.0 <= lut.g_range[1]:
            raise ValueError(f"isotropic fits need g = 0 on the LUT's g axis {lut.g_range}")
        g_range = (0.0, ISOTROPIC_G)
    if any(k not in (1, 2, 3) for k in ks):
        raise ValueError(f"K must be in 1, 2, 3; got {ks}")
    dt, dev = lut.P.dtype, lut.P.device
    profile, R_mc = profile.to(dev, dt), R_mc.to(dev, dt)
    r_edges_cm = r_edges_cm.to(dev, dt)
    if stderr is not None:
        stderr = stderr.to(dev, dt)
    target = fit_loss.make_target(profile, R_mc, r_edges_cm, photons, stderr=stderr, relative_refl=relative_refl)
    prob = Problem(lut, target, weighting, g_range)
    # the loss only sees used bins: evaluate the model on the bins some problem of the batch uses
    used = torch.nonzero(target.mask.any(0)).squeeze(1)
    if used.numel() == 0:
        used = torch.arange(target.r_cm.shape[0], device=dev)
    t_fit = target.subset(used[::bin_stride])
    B = R_mc.shape[0]
    g0 = torch.zeros_like(R_mc) if g_init is None else g_init.to(dev, dt)
    n = dict(PAPER_STEPS if method == "paper" else LM_ITERS)
    n.update(steps or {})

    def run(theta, k, key, shape_only):
        if method == "paper":
            return adam(prob, theta, k, n[key], shape_only, t=t_fit)[0]
        return levenberg_marquardt(prob, theta, k, n[key], shape_only, t=t_fit)

    def run_multi(starts: list[torch.Tensor], k, key):
        """Paper: the first start only.  LM: all starts batched together, the best per problem kept."""
        if method == "paper" or len(starts) == 1:
            return run(starts[0], k, key, False)
        ns, B = len(starts), starts[0].shape[0]
        probe = min(LM_PROBE_ITERS[key], n[key])
        th = levenberg_marquardt(prob, torch.cat(starts), k, probe, False, t=t_fit.repeat(ns))
        with torch.no_grad():
            val = prob.merit(th, k, False, t_fit.repeat(ns)).reshape(ns, B)
        best = val.argmin(0)
        th = th.reshape(ns, B, -1)[best, torch.arange(B, device=th.device)]
        return levenberg_marquardt(prob, th, k, n[key] - probe, False, t=t_fit)

    out: dict[int, FitResult] = {}

    def record(k, theta, evals, seconds):
        s, rr, j = prob.metrics(theta, k)
        out[k] = FitResult(k, theta, prob.mixture(theta, k), s, rr, j, target.noise, evals / B, seconds)

    if warm is not None:
        if method != "lm" or sorted(warm) != list(range(1, max(ks) + 1)):
            raise ValueError(f"warm starts need method 'lm' and one theta per K = 1..{max(ks)}")
        t0, prev = time.perf_counter(), None
        for k in range(1, max(ks) + 1):
            th = levenberg_marquardt(prob, warm[k].to(dev, dt), k, n["k1_joint" if k == 1 else f"k{k}"], False,
                                     t=t_fit)
            if prev is not None:
                th = no_worse_than_fewer(prob, th, prev, k, t_fit)
            record(k, th, prob.evals, time.perf_counter() - t0)
            prev = th
        return {k: v for k, v in out.items() if k in ks}

    t0 = time.perf_counter()
    theta1s = run(initial_k1(lut, profile, r_edges_cm, g0, prob), 1, "k1_shape", True)
    base_evals, base_time = prob.evals, time.perf_counter() - t0

    if 1 in ks:
        t1 = time.perf_counter()
        starts = [theta1s]
        if method == "lm":  # a second start: the coarse search judged by the joint loss
            starts.append(initial_k1(lut, profile, r_edges_cm, g0, prob, shape_only=False))
        th = run_multi(starts, 1, "k1_joint")
        record(1, th, prob.evals, base_time + time.perf_counter() - t1)
    kmax = max(ks)
    if kmax >= 2:
        prob.evals = base_evals
        t2 = time.perf_counter()
        starts2 = [split(theta1s, 1, prob, f, r, a) for r, f, a in K2_SPLITS]
        if method == "lm" and 1 in out:  # also from the joint K = 1 (where the shape-only start is far off in R)
            starts2.append(split(out[1].theta, 1, prob, 1.5))
        th2 = run_multi(starts2, 2, "k2")
        if method == "lm" and 1 in out:
            th2 = no_worse_than_fewer(prob, th2, out[1].theta, 2, t_fit)
        record(2, th2, prob.evals, base_time + time.perf_counter() - t2)
        if kmax >= 3:
            t3 = time.perf_counter()
            th3 = run_multi([split(th2, 2, prob, f, r, a) for r, f, a in K3_SPLITS], 3, "k3")
            if method == "lm":
                th3 = no_worse_than_fewer(prob, th3, th2, 3, t_fit)
            record(3, th3, prob.evals, out[2].seconds + time.perf_counter() - t3)
    return {k: v for k, v in out.items() if k in ks}
