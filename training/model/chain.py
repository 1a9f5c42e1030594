"""The chained model Enc -> Dec_R -> Dec_T with the analytic exposure, and its defined input domain.

``SkinChain.invert(albedo_rgb)`` runs the whole chain (what ``skin_inversion.onnx`` computes) and
``SkinChain.decode(p)`` the spectral part (what ``skin_decoder.onnx`` computes).

Input domain (the behaviour the ONNX graphs carry, documented in the model card and docs/dev/conventions.md):

* ``albedo_rgb`` (N, 3), linear sRGB.  A row with any NaN or +-Inf component is replaced, as a whole,
  by ``FALLBACK_ALBEDO_RGB`` (a mid skin tone); then every component is clamped to [0, 1] (an albedo
  is a reflectance).  The exposure is computed from this sanitised colour, so for inputs inside
  [0, 1]^3 Y(exposure * A_hat) = Y(albedo_rgb).  The exporters layer is expected to reject non-finite
  pixels with a clear error *before* calling the graph; the fallback only guarantees that the graph
  itself never emits NaN/Inf.
* ``biophysical`` (N, 5): a row with a non-finite component is replaced by the centre of the
  sampling ranges; then each component is clamped to its ``PARAM_RANGES`` interval.
"""

from __future__ import annotations

import torch
from torch import nn

from training.model.colour import Colour
from training.model.config import FALLBACK_ALBEDO_RGB, ModelConfig
from training.model.networks import Encoder, ReflectanceDecoder, SlabDepth, TranslucencyDecoder

#: Largest finite float32: |x| <= this is False exactly for NaN and +-Inf (exports as Abs/LessOrEqual).
_F32_MAX = 3.4028234663852886e38

#: ONNX output names (docs/contracts.md §3), in graph order.
INVERSION_OUTPUTS: tuple[str, ...] = ("biophysical", "exposure", "reflectance", "alpha", "sigma_t", "g", "weight")
DECODER_OUTPUTS: tuple[str, ...] = ("reflectance", "alpha", "sigma_t", "g", "weight")


def replace_nonfinite_rows(x: torch.Tensor, fallback: torch.Tensor) -> torch.Tensor:
    """Rows of ``x`` (N, C) with any NaN/Inf replaced by ``fallback`` (C,); ONNX-exportable."""
    ok = (torch.abs(x) <= _F32_MAX).to(x.dtype).amin(dim=-1, keepdim=True) > 0.5
    return torch.where(ok, x, fallback)


class SkinChain(nn.Module):
    """Enc, Dec_R, Dec_T, the slab depth c(lambda) and the colour head, for one ``ModelConfig``."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.enc = Encoder(cfg)
        self.dec_r = ReflectanceDecoder(cfg)
        self.dec_t = TranslucencyDecoder(cfg)
        self.slab = SlabDepth(cfg.n_wavelengths)
        self.colour = Colour()
        self.register_buffer("fallback_rgb", torch.tensor(FALLBACK_ALBEDO_RGB, dtype=torch.float32))
        p_mid = self.enc.p_lo + 0.5 * self.enc.p_span
        self.register_buffer("fallback_p", p_mid.clone())

    # ------------------------------------------------------------------ input domain
    def sanitise_rgb(self, albedo_rgb: torch.Tensor) -> torch.Tensor:
        """Non-finite rows -> fallback colour, then clamp to [0, 1] (module docstring)."""
        return replace_nonfinite_rows(albedo_rgb, self.fallback_rgb).clamp(0.0, 1.0)

    def sanitise_p(self, p: torch.Tensor) -> torch.Tensor:
        """Non-finite rows -> centre of the ranges, then clamp each component to its range."""
        p = replace_nonfinite_rows(p, self.fallback_p)
        return torch.minimum(torch.maximum(p, self.enc.p_lo), self.enc.p_lo + self.enc.p_span)

    # ------------------------------------------------------------------ chain
    def exposure_of(self, albedo_rgb: torch.Tensor, reflectance: torch.Tensor) -> torch.Tensor:
        """gamma = Y(A_RGB) / Y(A_hat) (N, 1) for sanitised albedos and predicted spectra."""
        return self.colour.exposure(albedo_rgb, self.colour.rgb(reflectance))

    def decode(self, p: torch.Tensor) -> dict[str, torch.Tensor]:
        """p (N, 5) -> reflectance (N, W) and the mixture alpha, g, sigma_t (cm^-1), weight (N, K, W)."""
        p = self.sanitise_p(p)
        reflectance = self.dec_r(p)
        out = self.dec_t(p, reflectance)
        out["reflectance"] = reflectance
        return out

    def invert(self, albedo_rgb: torch.Tensor) -> dict[str, torch.Tensor]:
        """A_RGB (N, 3) -> biophysical (N, 5), exposure (N, 1) and everything ``decode`` returns."""
        a = self.sanitise_rgb(albedo_rgb)
        p = self.enc(a)
        out = self.decode(p)
        out["biophysical"] = p
        out["exposure"] = self.exposure_of(a, out["reflectance"])
        return out


class InversionGraph(nn.Module):
    """What ``skin_inversion.onnx`` computes: albedo_rgb -> docs/contracts.md §3 outputs (INVERSION_OUTPUTS order)."""

    def __init__(self, model: SkinChain) -> None:
        super().__init__()
        self.model = model

    def forward(self, albedo_rgb: torch.Tensor) -> tuple[torch.Tensor, ...]:
        out = self.model.invert(albedo_rgb)
        return tuple(out[name] for name in INVERSION_OUTPUTS)


class DecoderGraph(nn.Module):
    """What ``skin_decoder.onnx`` computes: biophysical -> docs/contracts.md §3 outputs (DECODER_OUTPUTS order)."""

    def __init__(self, model: SkinChain) -> None:
        super().__init__()
        self.model = model

    def forward(self, biophysical: torch.Tensor) -> tuple[torch.Tensor, ...]:
        out = self.model.decode(biophysical)
        return tuple(out[name] for name in DECODER_OUTPUTS)
