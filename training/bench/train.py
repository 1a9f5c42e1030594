"""Benchmarks of the shipped model and of training (collected by ``python -m training bench``).

* ONNX inference throughput of ``blender_addon/models/skin_inversion.onnx`` with onnxruntime on 2 CPU
  threads (texels/s, batches of 4,096 skin-like colours); anchor: the same model in torch eager mode
  on 2 threads (the export's point is to be at least as fast without torch).
* Training step time of stage 3 (paper-sized Dec_T, batch 64) with the default loss: the paper's
  L_param + L_refl (LUT, slab factor) + L_smooth on 94 fitted wavelengths, plus the profile term
  (``--shape-weight 1``: the rendered mixture at every 6th of them, every 2nd radial bin) on the CPU;
  anchor: a step of the same network with a plain MSE loss on the same targets, i.e. what the LUT,
  smoothness and profile terms add.  The paper's loss alone is timed too (notes).
Timings on the shared 2-core machine are taken under contention from other jobs.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from training.paths import SHIPPED_MODEL_DIR

MODEL_DIR = SHIPPED_MODEL_DIR
BATCH = 4096


def _timeit(fn, repeats: int) -> float:
    fn()  # warm-up
    t0 = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t0) / repeats


def _interleaved(fns: list, repeats: int) -> list[float]:
    """Median seconds per call of each of ``fns``, timed in turns (one call of each per round) so that
    the load of a shared machine falls on all of them alike."""
    for fn in fns:
        fn()  # warm-up
    times = [[] for _ in fns]
    for _ in range(repeats):
        for fn, t in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            fn()
            t.append(time.perf_counter() - t0)
    return [float(np.median(t)) for t in times]


def _skin_like(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.array([0.45, 0.30, 0.24], np.float32)
    return (base * rng.uniform(0.2, 1.4, (n, 1)) * rng.uniform(0.85, 1.15, (n, 3))).clip(0, 1).astype(np.float32)


def bench_inference(quick: bool) -> dict:
    path = MODEL_DIR / "skin_inversion.onnx"
    row = {"workload": f"skin_inversion.onnx inference, batches of {BATCH} texels, 2 CPU threads",
           "ours": "", "anchor": "", "ratio": "", "error": "", "notes": ""}
    if not path.is_file():
        row["error"] = f"{path} missing (run `python -m training export`)"
        return row
    from exporters.inference import onnx_session

    x = _skin_like(BATCH)
    sess = onnx_session(path, threads=2)
    repeats = 2 if quick else 10
    t_ort = _timeit(lambda: sess.run(None, {"albedo_rgb": x}), repeats)
    row["ours"] = f"{BATCH / t_ort:,.0f} texels/s (onnxruntime)"
    import json

    from training.model import ModelConfig, SkinChain

    arch = json.loads((MODEL_DIR / "skin_inversion.json").read_text())["architecture"]
    torch.manual_seed(0)
    model = SkinChain(ModelConfig.from_dict(arch)).eval()  # same architecture; speed does not depend on weights
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    xt = torch.from_numpy(x)
    with torch.no_grad():
        t_torch = _timeit(lambda: model.invert(xt), repeats)
    torch.set_num_threads(threads)
    row["anchor"] = f"{BATCH / t_torch:,.0f} texels/s (same architecture in torch eager)"
    row["ratio"] = f"{t_torch / t_ort:.2f}x"
    row["notes"] = f"1 texel = 5 + 1 + 376 + 4 K 376 float32 outputs (K = {arch['k']})"
    return row


def bench_training_step(quick: bool) -> dict:
    from exporters.constants import R_EDGES_CM
    from training.fit.loss import make_target
    from training.fit.mixture import mix
    from training.model import ModelConfig, SkinChain
    from training.sim.dipole import dipole_lut
    from training.sim.lut_interp import LookupTables, bin_centres
    from training.train import losses as train_losses
    from training.train.spectral import interpolation_matrix

    torch.manual_seed(0)
    model = SkinChain(ModelConfig())
    lut = LookupTables.from_arrays(**dipole_lut(), dtype=torch.float32)
    n = 64
    p = model.enc.from_unit(torch.rand(n, 5))
    R = torch.rand(n, 376) * 0.5
    fitted = torch.arange(0, 376, 4)  # the shipped model's fits: every 4th wavelength
    with torch.no_grad():
        tgt = model.dec_t(p, model.dec_r(p))
    targets = {k: tgt[k][..., fitted].clone() * (1.0 if k == "weight" else 0.9)
               for k in ("alpha", "g", "sigma_t", "weight")}
    interp = interpolation_matrix(fitted.numpy(), 376)
    edges = torch.tensor(R_EDGES_CM)
    lut64 = LookupTables.from_arrays(**dipole_lut(), dtype=torch.float64)

    def shape_at(cols: torch.Tensor):  # the profile targets at wavelengths cols, as stages.shape_batch sees them
        with torch.no_grad():  # the targets' rendered mixture (the shape term's cost, not its value)
            a, g, st, w = (tgt[k][..., cols].transpose(1, 2).double() for k in ("alpha", "g", "sigma_t", "weight"))
            prof, refl = mix(lut64.profile(bin_centres(edges), a, g, st), lut64.reflectance(a, g), w)
        shape = make_target(prof * refl[..., None], refl, edges, 1e5, stderr=0.01 * prof * refl[..., None])
        return shape.subset(torch.arange(0, shape.r_cm.numel(), train_losses.SHAPE_BIN_STRIDE)).to(dtype=torch.float32)

    dense_cols = torch.arange(0, 376, round(376 / train_losses.SHAPE_WAVELENGTHS_PER_STEP))  # every few of all 376
    per_step = train_losses.SHAPE_WAVELENGTHS_PER_STEP
    fitted_cols = fitted[torch.arange(0, fitted.numel(), round(fitted.numel() / per_step))]
    shapes = {True: shape_at(dense_cols), False: shape_at(fitted_cols)}
    params = list(model.dec_t.parameters()) + list(model.slab.parameters())
    opt = torch.optim.Adam(params, lr=1e-4)

    def full_step(shape_weight: float = 1.0, dense: bool = True):
        opt.zero_grad()
        cols = dense_cols if dense else fitted_cols
        train_losses.stage3_losses(model, lut, p, R, targets, fitted, shapes[dense] if shape_weight else None,
                                   shape_weight, cols, interp if dense else None, weighted=dense)["loss"].backward()
        opt.step()

    def mse_step():
        opt.zero_grad()
        out = model.dec_t(p, model.dec_r(p).detach())
        torch.nn.functional.mse_loss(out["alpha"][..., fitted], targets["alpha"]).backward()
        opt.step()

    repeats = 3 if quick else 20
    t_full, t_fitted, t_paper, t_mse = _interleaved(
        [full_step, lambda: full_step(dense=False), lambda: full_step(0.0, dense=False), mse_step], repeats)
    return {"workload": f"stage-3 training step, paper-sized Dec_T (4 x 768, K=3), batch {n}, CPU "
                        f"({torch.get_num_threads()} threads)",
            "ours": f"{t_full * 1e3:.0f} ms/step", "anchor": f"{t_mse * 1e3:.0f} ms/step (same net, plain MSE)",
            "ratio": f"{t_full / t_mse:.2f}x", "error": "",
            "notes": f"default loss = L_param (weighted, targets interpolated to all 376 wavelengths from every 4th) "
                     f"+ 15 L_refl (LUT, slab factor) + 0.5 L_smooth + L_shape ({len(dense_cols)} of 376 wavelengths, "
                     f"every 2nd bin); with --targets fitted (L_param and L_shape at the fitted wavelengths only) "
                     f"{t_fitted * 1e3:.0f} ms/step; the paper's loss alone {t_paper * 1e3:.0f} ms/step; dipole LUT "
                     "for timing"}


def benchmarks(quick: bool) -> list[dict]:
    return [bench_inference(quick), bench_training_step(quick)]


if __name__ == "__main__":
    for r in benchmarks(quick=True):
        print(r)
