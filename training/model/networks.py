"""The three networks of the chained decoder (paper §5.1): Enc, Dec_R and Dec_T, plus the slab depth.

Shapes: N texels / tones, W = 376 wavelengths, K mixture components.

* ``Encoder``: linear-sRGB albedo (N, 3) -> biophysical p_hat (N, 5), BioSkin's 3 -> 70 -> 70 -> 5
  MLP, tanh hidden, sigmoid output mapped onto ``PARAM_RANGES`` (t_epi in cm): linearly, or for the
  ``ModelConfig.log_params`` (f_mel, f_blood) log-linearly.
* ``ReflectanceDecoder`` (Dec_R): p (N, 5) -> R_hat (N, W) in (0, 1), 5 -> H -> H -> W, tanh hidden,
  sigmoid output.  p enters normalised to [-1, 1] over ``PARAM_RANGES`` (the log params on a log scale).
* ``TranslucencyDecoder`` (Dec_T): (p, R_hat) (N, 5 + W = 381) -> the K-media mixture per wavelength,
  an L-layer MLP (paper: 4 layers, 768 hidden, tanh).  Its N x (4 K W) outputs are mapped:
  alpha = sigmoid in (0, 1); g = sigmoid onto ``g_range``; sigma_t = exp of a sigmoid onto
  [ln lo, ln hi] of ``sigma_t_range_cm`` (a log range, cm^-1); weight = softmax over K of raw logits,
  then low-passed along wavelength by a fixed normalised Gaussian (``ModelConfig.weight_smoothing_nm``,
  edges extended by their last value), which keeps every weight vector a convex combination of valid ones.
  It also returns the normalised coordinates ``u`` (N, 4, K, W) in which the losses compare
  parameters: alpha, (g - lo)/(hi - lo), (ln sigma_t - ln lo)/(ln hi - ln lo), weight.
* ``SlabDepth``: c(lambda) > 0 (W,), cm, stored as its log, initialised at 0.30 (paper eq. slab_factor).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from exporters.constants import WAVELENGTH_STEP_NM
from training.model.config import SLAB_C, SLAB_DEPTH_INIT, ModelConfig

#: Channel order of Dec_T's outputs along axis 1 of the raw / normalised tensors.
DECT_CHANNELS: tuple[str, ...] = ("alpha", "g", "sigma_t", "weight")


def mlp(sizes: list[int]) -> nn.Sequential:
    """Linear layers of the given sizes with tanh between them (none after the last)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.Tanh())
    return nn.Sequential(*layers)


class _ParamScale(nn.Module):
    """Holds the biophysical ranges (lo, hi) (5,) as buffers, and the scale the networks see them on:
    linear, or logarithmic for ``cfg.log_params`` (``training.model.config``)."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        ranges = [cfg.param_ranges[name] for name in cfg.param_names]
        self.register_buffer("p_lo", torch.tensor([r[0] for r in ranges], dtype=torch.float32))
        self.register_buffer("p_span", torch.tensor([r[1] - r[0] for r in ranges], dtype=torch.float32))
        is_log = [name in cfg.log_params for name in cfg.param_names]
        q = [(math.log(r[0]), math.log(r[1])) if lg else r for r, lg in zip(ranges, is_log, strict=True)]
        # derived from the config, not state: checkpoints made before the log scale load unchanged
        self.register_buffer("log_mask", torch.tensor(is_log), persistent=False)
        self.register_buffer("q_lo", torch.tensor([a for a, _ in q], dtype=torch.float32), persistent=False)
        self.register_buffer("q_span", torch.tensor([b - a for a, b in q], dtype=torch.float32), persistent=False)

    def normalise(self, p: torch.Tensor) -> torch.Tensor:
        """p (N, 5) in physical units -> [-1, 1] over the sampling ranges (log scale for the log params)."""
        # the log only sees the log params (1 elsewhere): log(0) of a linear one (b_mel = 0) would give a NaN
        # gradient through torch.where even though its value is not selected
        safe = torch.where(self.log_mask, torch.maximum(p, self.p_lo), torch.ones_like(p))
        q = torch.where(self.log_mask, torch.log(safe), p)
        return 2.0 * (q - self.q_lo) / self.q_span - 1.0

    def from_unit(self, u: torch.Tensor) -> torch.Tensor:
        """u (N, 5) in [0, 1] -> physical p (log params: log-uniform in u)."""
        q = self.q_lo + self.q_span * u
        return torch.where(self.log_mask, torch.exp(q), q)


class Encoder(_ParamScale):
    """Enc: A_RGB (N, 3) linear sRGB -> p_hat (N, 5) within PARAM_RANGES."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__(cfg)
        self.net = mlp([3, cfg.enc_hidden, cfg.enc_hidden, len(cfg.param_names)])

    def forward(self, albedo_rgb: torch.Tensor) -> torch.Tensor:
        return self.from_unit(torch.sigmoid(self.net(albedo_rgb)))


class ReflectanceDecoder(_ParamScale):
    """Dec_R: p (N, 5) -> R_hat (N, W) in (0, 1)."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__(cfg)
        self.net = mlp([len(cfg.param_names), cfg.decr_hidden, cfg.decr_hidden, cfg.n_wavelengths])

    def forward(self, p: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.net(self.normalise(p)))


def gaussian_taps(sigma_steps: float) -> torch.Tensor:
    """(2 h + 1,) float32 taps of a Gaussian of standard deviation ``sigma_steps`` grid steps, cut at
    h = ceil(4 sigma) and normalised to sum 1; sigma 0: the identity (one tap)."""
    if sigma_steps <= 0:
        return torch.ones(1)
    h = math.ceil(4 * sigma_steps)
    x = torch.arange(-h, h + 1, dtype=torch.float64)
    taps = torch.exp(-0.5 * (x / sigma_steps) ** 2)
    return (taps / taps.sum()).float()


class TranslucencyDecoder(_ParamScale):
    """Dec_T: (p (N, 5), R_hat (N, W)) -> alpha, g, sigma_t (cm^-1), weight, each (N, K, W), and u."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__(cfg)
        self.k, self.w = cfg.k, cfg.n_wavelengths
        n_in = len(cfg.param_names) + cfg.n_wavelengths
        self.net = mlp([n_in] + [cfg.dect_hidden] * (cfg.dect_layers - 1) + [4 * cfg.k * cfg.n_wavelengths])
        g_lo, g_hi = cfg.g_range
        s_lo, s_hi = cfg.sigma_t_range_cm
        self.register_buffer("g_bounds", torch.tensor([g_lo, g_hi - g_lo], dtype=torch.float32))
        self.register_buffer("log_sigma_bounds", torch.tensor([math.log(s_lo), math.log(s_hi / s_lo)],
                                                              dtype=torch.float32))
        # Not persistent: fixed by the config, so checkpoints made before it load unchanged.
        self.register_buffer("weight_kernel", gaussian_taps(cfg.weight_smoothing_nm / WAVELENGTH_STEP_NM),
                             persistent=False)

    def smooth_weights(self, weight: torch.Tensor) -> torch.Tensor:
        """(N, K, W) weights low-passed along W by ``weight_kernel``, the ends extended by their last value."""
        taps = self.weight_kernel.numel()
        if taps == 1:
            return weight
        n, k, w = weight.shape
        padded = F.pad(weight.reshape(n * k, 1, w), (taps // 2, taps // 2), mode="replicate")
        return F.conv1d(padded, self.weight_kernel.view(1, 1, taps)).reshape(n, k, w)

    def forward(self, p: torch.Tensor, reflectance: torch.Tensor) -> dict[str, torch.Tensor]:
        raw = self.net(torch.cat([self.normalise(p), reflectance], dim=-1))
        raw = raw.reshape(-1, 4, self.k, self.w)
        unit = torch.sigmoid(raw[:, :3])  # alpha, g, sigma_t in [0, 1]
        weight = self.smooth_weights(torch.softmax(raw[:, 3], dim=1))
        alpha = unit[:, 0]
        g = self.g_bounds[0] + self.g_bounds[1] * unit[:, 1]
        sigma_t = torch.exp(self.log_sigma_bounds[0] + self.log_sigma_bounds[1] * unit[:, 2])
        u = torch.cat([unit, weight[:, None]], dim=1)
        return {"alpha": alpha, "g": g, "sigma_t": sigma_t, "weight": weight, "u": u}

    def to_unit(self, alpha: torch.Tensor, g: torch.Tensor, sigma_t: torch.Tensor,
                weight: torch.Tensor) -> torch.Tensor:
        """Physical parameters (N, K, W) -> normalised coordinates u (N, 4, K, W), the inverse of forward's map.

        Values outside the ranges map outside [0, 1] (no clamping: a target beyond the range still
        pulls the prediction towards the nearest bound).
        """
        ug = (g - self.g_bounds[0]) / self.g_bounds[1]
        us = (torch.log(sigma_t) - self.log_sigma_bounds[0]) / self.log_sigma_bounds[1]
        return torch.stack([alpha, ug, us, weight], dim=1)


class SlabDepth(nn.Module):
    """Learned per-wavelength slab depth c(lambda) (W,), cm, and the factor 1 - exp(-C sigma_t c)."""

    def __init__(self, n_wavelengths: int, init: float = SLAB_DEPTH_INIT) -> None:
        super().__init__()
        self.log_c = nn.Parameter(torch.full((n_wavelengths,), math.log(init)))

    def depth(self) -> torch.Tensor:
        return torch.exp(self.log_c)

    def factor(self, sigma_t: torch.Tensor) -> torch.Tensor:
        """1 - exp(-C sigma_t c(lambda)) for sigma_t (..., W) in cm^-1; in [0, 1)."""
        return -torch.expm1(-SLAB_C * sigma_t * self.depth())
