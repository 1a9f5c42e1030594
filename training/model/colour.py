"""Spectrum -> linear sRGB (D65) and the analytic exposure, as torch operations (paper eq. exposure).

The weights are those of ``exporters.colorimetry`` (CIE 1931 2°, D65 to 830 nm, 360-830 nm only),
precomputed once: ``rgb = M @ R`` with M = xyz_to_linear_srgb_matrix("D65") @ xyz_weights("D65"),
shape (3, 376), held as a float32 buffer so the ONNX graph carries it as a constant.

Luminance Y is taken from linear sRGB with the Rec. 709 weights ``SRGB_LUMINANCE`` for both the input
albedo and the predicted colour, so the exposure identity Y(gamma * A_hat) = Y(A_RGB) is exact (up to
float rounding) whenever Y(A_hat) >= Y_FLOOR.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from exporters.colorimetry import SRGB_LUMINANCE, xyz_to_linear_srgb_matrix, xyz_weights
from training.model.config import Y_FLOOR


def spectrum_to_rgb_matrix() -> np.ndarray:
    """M (3, 376), float64: linear sRGB (D65) of a reflectance spectrum on the project's grid."""
    return xyz_to_linear_srgb_matrix("D65") @ xyz_weights("D65")


class Colour(nn.Module):
    """Reflectance (N, 376) -> linear sRGB (N, 3) under D65, and luminance of linear sRGB."""

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("rgb_matrix", torch.tensor(spectrum_to_rgb_matrix(), dtype=torch.float32))
        self.register_buffer("luminance_weights", torch.tensor(SRGB_LUMINANCE, dtype=torch.float32))

    def rgb(self, reflectance: torch.Tensor) -> torch.Tensor:
        """Linear sRGB (N, 3) of spectra (N, 376)."""
        return reflectance @ self.rgb_matrix.T

    def luminance(self, rgb: torch.Tensor) -> torch.Tensor:
        """Relative luminance Y (N, 1) of linear sRGB (N, 3) (Y of white = 1)."""
        return (rgb * self.luminance_weights).sum(-1, keepdim=True)

    def exposure(self, albedo_rgb: torch.Tensor, predicted_rgb: torch.Tensor) -> torch.Tensor:
        """gamma = Y(A_RGB) / Y(A_hat), shape (N, 1); the divisor is floored at Y_FLOOR."""
        return self.luminance(albedo_rgb) / self.luminance(predicted_rgb).clamp_min(Y_FLOOR)
