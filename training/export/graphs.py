"""ONNX graphs of the trained chain (docs/contracts.md §3) and their check against torch with onnxruntime.

* ``skin_inversion.onnx``: input ``albedo_rgb`` float32 (N, 3) -> ``biophysical`` (N, 5), ``exposure``
  (N, 1), ``reflectance`` (N, 376), ``alpha``, ``sigma_t`` (cm^-1), ``g``, ``weight`` (N, K, 376).
* ``skin_decoder.onnx``: input ``biophysical`` float32 (N, 5) -> ``reflectance``, ``alpha``, ``sigma_t``,
  ``g``, ``weight``.
N is dynamic.  Input handling (NaN/Inf rows, clamping) is part of the graphs: see ``training.model.chain``.

Weight storage: float32, or float16 when the two files together would exceed the size budget (the
paper-sized Dec_T alone is ~20 MB in float32 and both graphs carry it).  With float16 storage the
weights are cast to float32 inside the graph and all arithmetic stays float32; the graph then computes
exactly the torch model whose weights were rounded to float16 (``half_rounded``), which is the model
the parity check compares against.  What the rounding costs is measured separately (``rounding_cost``).

Exporter: torch's TorchScript-based ``torch.onnx.export(dynamo=False)`` (the dynamo exporter needs
onnxscript, which is not a dependency), opset 17.
"""

from __future__ import annotations

import copy
import io
import warnings

import numpy as np
import onnx
import torch
import torch.nn.functional as F
from torch import nn

from exporters.constants import WAVELENGTH_STEP_NM, WAVELENGTHS_NM
from exporters.inference import onnx_session
from training.model.chain import DECODER_OUTPUTS, INVERSION_OUTPUTS, DecoderGraph, InversionGraph, SkinChain

OPSET: int = 17
#: Parity tolerance between torch and onnxruntime: absolute, except relative for sigma_t (contract-sized
#: values up to 1e5 cm^-1) and exposure (a ratio that can exceed 1 for non-skin colours).
PARITY_TOL: float = 1e-4
RELATIVE_OUTPUTS: tuple[str, ...] = ("sigma_t", "exposure")


class HalfLinear(nn.Module):
    """A Linear layer whose weights are stored in float16 and cast to float32 for the product."""

    def __init__(self, lin: nn.Linear) -> None:
        super().__init__()
        self.register_buffer("weight", lin.weight.detach().to(torch.float16).clone())
        self.register_buffer("bias", lin.bias.detach().to(torch.float16).clone())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.linear(x, self.weight.to(torch.float32), self.bias.to(torch.float32))


def half_rounded(model: SkinChain) -> SkinChain:
    """A copy of ``model`` with every Linear layer stored in float16 (``HalfLinear``)."""
    m = copy.deepcopy(model).cpu().eval()
    for parent in list(m.modules()):
        for name, child in list(parent.named_children()):
            if isinstance(child, nn.Linear):
                setattr(parent, name, HalfLinear(child))
    return m


def _export_bytes(graph: nn.Module, example: torch.Tensor, input_name: str, outputs: tuple[str, ...],
                  fold: bool) -> bytes:
    """``fold``: constant folding (off for float16 storage: it would fold the casts into float32 weights)."""
    buf = io.BytesIO()
    axes = {input_name: {0: "N"}} | {name: {0: "N"} for name in outputs}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
        torch.onnx.export(graph, (example,), buf, dynamo=False, input_names=[input_name], output_names=list(outputs),
                          dynamic_axes=axes, opset_version=OPSET, do_constant_folding=fold)
    return buf.getvalue()


def output_shapes(k: int) -> dict[str, tuple]:
    """docs/contracts.md §3 shapes of every graph output ("N" is the dynamic batch)."""
    w = WAVELENGTHS_NM.size
    return {"biophysical": ("N", 5), "exposure": ("N", 1), "reflectance": ("N", w), "alpha": ("N", k, w),
            "sigma_t": ("N", k, w), "g": ("N", k, w), "weight": ("N", k, w)}


def _declare_output_shapes(proto: onnx.ModelProto, k: int) -> None:
    """Write the static output dims (the exporter's shape inference leaves K and W symbolic after reshapes)."""
    shapes = output_shapes(k)
    for out in proto.graph.output:
        dims = out.type.tensor_type.shape.dim
        want = shapes[out.name]
        if len(dims) != len(want):
            raise RuntimeError(f"output {out.name} has rank {len(dims)}, docs/contracts.md §3 says {len(want)}")
        for d, v in zip(dims, want, strict=True):
            if v == "N":
                d.dim_param = "N"
            else:
                d.dim_value = v


def _with_metadata(data: bytes, model: SkinChain, doc: str, weights: str) -> bytes:
    proto = onnx.load_from_string(data)
    _declare_output_shapes(proto, model.cfg.k)
    proto.doc_string = doc
    meta = {
        "K": str(model.cfg.k),
        "wavelength_nm": f"{WAVELENGTHS_NM[0]:g}:{WAVELENGTHS_NM[-1]:g}:{WAVELENGTH_STEP_NM:g}",
        "n_wavelengths": str(WAVELENGTHS_NM.size),
        "biophysical": ",".join(model.cfg.param_names) + " (t_epi in cm)",
        "units": "sigma_t cm^-1; alpha, g, weight, reflectance dimensionless; albedo_rgb linear sRGB (D65)",
        "weights_dtype": weights,
    }
    for k, v in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = k, v
    onnx.checker.check_model(proto)
    return proto.SerializeToString()


def export_graphs(model: SkinChain, weights: str = "float32") -> dict[str, bytes]:
    """Serialised ``skin_inversion.onnx`` and ``skin_decoder.onnx`` of ``model`` (weights float32|float16)."""
    if weights not in ("float32", "float16"):
        raise ValueError(f"weights must be float32 or float16, got {weights!r}")
    m = half_rounded(model) if weights == "float16" else copy.deepcopy(model).cpu().eval()
    fold = weights == "float32"
    inv = _export_bytes(InversionGraph(m), torch.rand(4, 3), "albedo_rgb", INVERSION_OUTPUTS, fold)
    p0 = m.enc.p_lo + 0.5 * m.enc.p_span
    dec = _export_bytes(DecoderGraph(m), p0.repeat(4, 1), "biophysical", DECODER_OUTPUTS, fold)
    return {
        "skin_inversion.onnx": _with_metadata(inv, m, "Linear-sRGB skin albedo -> biophysical tone, exposure, "
                                              "spectral reflectance and K-media SSS mixture "
                                              "(docs/contracts.md §3).", weights),
        "skin_decoder.onnx": _with_metadata(dec, m, "Biophysical tone -> spectral reflectance and K-media SSS "
                                            "mixture (docs/contracts.md §3).", weights),
    }


def parity_inputs(model: SkinChain, n: int, seed: int) -> dict[str, np.ndarray]:
    """n random linear-sRGB colours in [0, 1]^3 and n random tones within PARAM_RANGES (float32)."""
    rng = np.random.default_rng(seed)
    lo, span = model.enc.p_lo.cpu().numpy(), model.enc.p_span.cpu().numpy()
    return {"albedo_rgb": rng.random((n, 3), dtype=np.float32),
            "biophysical": (lo + span * rng.random((n, lo.size))).astype(np.float32)}


def _max_err(ref: np.ndarray, got: np.ndarray, relative: bool) -> float:
    diff = np.abs(ref.astype(np.float64) - got.astype(np.float64))
    if relative:
        diff = diff / np.maximum(np.abs(ref.astype(np.float64)), 1e-30)
    return float(diff.max())


@torch.no_grad()
def parity(model: SkinChain, graphs: dict[str, bytes], weights: str, n: int = 10_000, seed: int = 0,
           batch: int = 2_500) -> dict[str, dict[str, float]]:
    """Max |torch - onnxruntime| per output of each graph over ``n`` random inputs (relative for sigma_t
    and exposure).  The torch side is the exported model itself (float16-rounded if so stored)."""
    ref_model = half_rounded(model) if weights == "float16" else copy.deepcopy(model).cpu().eval()
    inputs = parity_inputs(model, n, seed)
    result: dict[str, dict[str, float]] = {}
    for fname, wrapper, in_name, outs in (
        ("skin_inversion.onnx", InversionGraph, "albedo_rgb", INVERSION_OUTPUTS),
        ("skin_decoder.onnx", DecoderGraph, "biophysical", DECODER_OUTPUTS),
    ):
        sess, g = onnx_session(graphs[fname], threads=2), wrapper(ref_model)
        errs = dict.fromkeys(outs, 0.0)
        for s in range(0, n, batch):
            x = inputs[in_name][s : s + batch]
            got = sess.run(list(outs), {in_name: x})
            ref = [t.numpy() for t in g(torch.from_numpy(x))]
            for name, r, o in zip(outs, ref, got, strict=True):
                errs[name] = max(errs[name], _max_err(r, o, name in RELATIVE_OUTPUTS))
        result[fname] = errs
    return result


def parity_failures(errors: dict[str, dict[str, float]], tol: float | None = None) -> list[str]:
    """'file:output error > tol' for every output over the tolerance (default PARITY_TOL)."""
    tol = PARITY_TOL if tol is None else tol
    return [f"{f}:{name} {e:.3g} > {tol:g}" for f, errs in errors.items() for name, e in errs.items() if not e <= tol]


@torch.no_grad()
def rounding_cost(model: SkinChain, n: int = 10_000, seed: int = 0) -> dict[str, float]:
    """What float16 weight storage costs: max |fp32 - fp16-rounded| per inversion output (relative for
    sigma_t and exposure) and the colour difference (mean / max ΔE76) of exposure * rgb(reflectance)."""
    from exporters.colorimetry import delta_e76, linear_srgb_to_lab

    full, half = copy.deepcopy(model).cpu().eval(), half_rounded(model)
    x = torch.from_numpy(parity_inputs(model, n, seed)["albedo_rgb"])
    a, b = full.invert(x), half.invert(x)
    out = {name: _max_err(a[name].numpy(), b[name].numpy(), name in RELATIVE_OUTPUTS) for name in INVERSION_OUTPUTS}
    rgb_a = (full.colour.rgb(a["reflectance"]) * a["exposure"]).double().numpy()
    rgb_b = (half.colour.rgb(b["reflectance"]) * b["exposure"]).double().numpy()
    de = delta_e76(linear_srgb_to_lab(np.clip(rgb_a, 0, None)), linear_srgb_to_lab(np.clip(rgb_b, 0, None)))
    out["colour_delta_e76_mean"] = float(de.mean())
    out["colour_delta_e76_max"] = float(de.max())
    return out
