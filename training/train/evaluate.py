"""Validation metrics of a trained chain (the numbers the model card reports).

On the tones of a split (float64 colour maths through ``exporters.colorimetry``):

* ``decr_spectral_l1``: mean |Dec_R(p) - R_MC| over tones and 376 wavelengths (true p).
* ``enc_delta_e76``: the inversion's colour round trip, Lab(gamma * rgb(Dec_R(Enc(A)))) vs Lab(A),
  A the tone's MC albedo; mean, median, max over tones.
* ``exposure_error``: |gamma - 1|, the brightness error beside the round trip (A is the colour of a tone of
  the skin model, so the right exposure is 1); mean, median, max.
* ``mixture_delta_e76``: colour of the predicted mixture as a semi-infinite renderer sees it,
  gamma * rgb(sum_k w_k R_LUT(alpha_k, g_k)) (no slab factor), vs A; mean, median, max.
* ``mixture_vs_mc_delta_e76``: the same mixture spectrum without exposure for the true p
  (skin_decoder's path) vs the MC spectrum's colour; mean, median, max.
* ``inversion_mixture_vs_mc_delta_e76``: the mixture of the inversion from A (skin_inversion's path), without
  exposure, vs the MC spectrum's colour - the validation gate's "K = 3 NN, RGB in" on these tones.
* ``p_abs_err``: mean |Enc(A) - p| per biophysical parameter (informative: Enc has no parameter
  supervision and the inverse is ambiguous).
"""

from __future__ import annotations

import numpy as np
import torch

from exporters.colorimetry import delta_e76, linear_srgb_to_lab, spectrum_to_lab, spectrum_to_linear_srgb
from exporters.constants import PARAM_NAMES
from training.model.chain import SkinChain
from training.sim.lut_interp import LookupTables
from training.train.data import SplitData


def _stats(x: np.ndarray) -> dict[str, float]:
    return {"mean": float(np.mean(x)), "median": float(np.median(x)), "max": float(np.max(x))}


def mixture_reflectance(lut: LookupTables, out: dict[str, torch.Tensor]) -> torch.Tensor:
    """sum_k w_k R_LUT(alpha_k, g_k) (N, W): the semi-infinite mixture's reflectance."""
    return (out["weight"] * lut.reflectance(out["alpha"], out["g"])).sum(1)


@torch.no_grad()
def evaluate_split(model: SkinChain, data: SplitData, lut: LookupTables | None) -> dict:
    """Metrics of ``model`` on ``data`` (see module docstring); ``lut`` None skips the mixture rows."""
    model.eval()
    A = data.albedo_rgb.double().cpu().numpy()
    lab_a = linear_srgb_to_lab(np.clip(A, 0.0, 1.0))
    res: dict = {"n_tones": len(data)}
    refl_true = model.dec_r(data.tone)
    res["decr_spectral_l1"] = float((refl_true - data.R_d).abs().mean())
    inv = model.invert(data.albedo_rgb)
    gamma = inv["exposure"].double().cpu().numpy()
    rgb_hat = spectrum_to_linear_srgb(inv["reflectance"].double().cpu().numpy(), "D65") * gamma
    res["enc_delta_e76"] = _stats(delta_e76(linear_srgb_to_lab(rgb_hat), lab_a))
    res["exposure_error"] = _stats(np.abs(gamma[:, 0] - 1.0))
    err = (inv["biophysical"] - data.tone).abs().mean(0).cpu().numpy()
    res["p_abs_err"] = {name: float(v) for name, v in zip(PARAM_NAMES, err, strict=True)}
    if lut is not None:
        mix = mixture_reflectance(lut, inv).double().cpu().numpy()
        rgb_mix = spectrum_to_linear_srgb(mix, "D65") * gamma
        res["mixture_delta_e76"] = _stats(delta_e76(linear_srgb_to_lab(rgb_mix), lab_a))
        dec = model.decode(data.tone)
        mix_true = mixture_reflectance(lut, dec).double().cpu().numpy()
        lab_mc = spectrum_to_lab(data.R_d.double().cpu().numpy(), "D65")
        res["mixture_vs_mc_delta_e76"] = _stats(delta_e76(spectrum_to_lab(mix_true, "D65"), lab_mc))
        res["inversion_mixture_vs_mc_delta_e76"] = _stats(delta_e76(spectrum_to_lab(mix, "D65"), lab_mc))
    return res
