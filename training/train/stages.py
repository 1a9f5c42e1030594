"""The three frozen stages of paper §5.2, as ``StageSpec``s for ``training.train.loop.run_stage``.

* Stage 1 trains Dec_R on (tone, R_d) pairs of the dataset with the spectral L1.
* Stage 2 trains Enc with the colour loss through the frozen Dec_R, without parameter supervision.
  Its albedos: the dataset's ``albedo_rgb`` plus ``synthetic`` colours rendered by the frozen Dec_R
  (the "neural spectral renderer" of the paper) from tones drawn uniformly in PARAM_RANGES, each
  scaled by an exposure exp(U(-j, j)) (``exposure_jitter`` j) and clamped to [0, 1], so that the
  encoder sees the whole gamut of the model and not only the few simulated tones.
* Stage 3 trains Dec_T and the slab depth c(lambda) with the frozen Dec_R.  Dec_T is fed the dataset
  tone p and R_hat = Dec_R(p): the fit targets belong to p, and ``skin_decoder.onnx`` evaluates
  Dec_T(p, Dec_R(p)) for any p; at inversion time p = Enc(A_RGB).  Ours (``encoder_share``
  > 0): a share of each batch is fed p = Enc(A_RGB) of the tone's own albedo instead, with the true tone's
  targets, so that Dec_T learns to answer what the frozen encoder gives it at inversion time (the encoder
  finds a tone of the input's colour, not the tone itself: metamers and exposure) - the network's gate
  row from RGB scores exactly that path.
"""

from __future__ import annotations

import torch

from training.fit.loss import Target
from training.model.chain import SkinChain
from training.sim.lut_interp import LookupTables
from training.train import losses as train_losses
from training.train.balance import sampling_probabilities
from training.train.data import SplitData
from training.train.loop import StageSpec
from training.train.spectral import interpolation_matrix


def stage1(model: SkinChain, train: SplitData, val: SplitData, epochs: int, batch: int, lr: float) -> StageSpec:
    def step(idx: torch.Tensor) -> dict[str, torch.Tensor]:
        loss = train_losses.spectral_l1(model.dec_r(train.tone[idx]), train.R_d[idx])
        return {"loss": loss}

    def evaluate() -> dict[str, float]:
        return {"spectral_l1": float(train_losses.spectral_l1(model.dec_r(val.tone), val.R_d))}

    return StageSpec(1, "Dec_R", [model.dec_r], len(train), batch, epochs, lr, step, evaluate)


def synthetic_albedos(model: SkinChain, n: int, exposure_jitter: float, seed: int) -> torch.Tensor:
    """n albedos (n, 3): colours of the frozen Dec_R at uniform random tones, times exp(U(-j, j)), in [0, 1]."""
    dev = model.enc.p_lo.device
    gen = torch.Generator().manual_seed(int(seed) * 7_919 + 2)
    u = torch.rand(n, model.enc.p_lo.numel(), generator=gen, dtype=torch.float32)
    scale = torch.exp((2 * torch.rand(n, 1, generator=gen, dtype=torch.float32) - 1) * exposure_jitter)
    with torch.no_grad():
        rgb = model.colour.rgb(model.dec_r(model.enc.from_unit(u.to(dev))))
    return (rgb * scale.to(dev)).clamp(0.0, 1.0)


def stage2(model: SkinChain, train: SplitData, val: SplitData, epochs: int, batch: int, lr: float,
           synthetic: int, exposure_jitter: float, seed: int, exposure_prior: float = 0.0,
           unfreeze: bool = False) -> StageSpec:
    """Stage 2; ``unfreeze`` (an ablation, not the paper's method) trains Dec_R along with Enc."""
    albedo = train.albedo_rgb.clamp(0.0, 1.0)
    if synthetic > 0:
        albedo = torch.cat([albedo, synthetic_albedos(model, synthetic, exposure_jitter, seed)])
    val_albedo = val.albedo_rgb.clamp(0.0, 1.0)

    def step(idx: torch.Tensor) -> dict[str, torch.Tensor]:
        return {"loss": train_losses.colour_loss(model, albedo[idx], exposure_prior)}

    def evaluate() -> dict[str, float]:
        return {"colour_l1": float(train_losses.colour_loss(model, val_albedo))}

    trainable = [model.enc, model.dec_r] if unfreeze else [model.enc]
    return StageSpec(2, "Enc", trainable, albedo.shape[0], batch, epochs, lr, step, evaluate)


def shape_batch(data: SplitData, idx: torch.Tensor) -> tuple[Target, torch.Tensor]:
    """The profile targets of fitted rows ``idx`` for one training step and their wavelengths: about
    ``SHAPE_WAVELENGTHS_PER_STEP`` of the profile wavelengths (``SplitData.shape_index``), every n-th from an
    offset set by the batch (deterministic, so a resumed run replays the same steps); the radial bins as
    loaded (every ``SHAPE_BIN_STRIDE``-th)."""
    n_w = data.shape_index.numel()
    every = max(1, round(n_w / train_losses.SHAPE_WAVELENGTHS_PER_STEP))
    cols = torch.arange(int(idx[0]) % every, n_w, every, device=idx.device)
    return data.shape_target.rows(idx).select(1, cols), data.shape_index[cols]


def encoder_input(model: SkinChain, albedo_rgb: torch.Tensor, p: torch.Tensor, share: float) -> torch.Tensor:
    """The tones (N, 5) Dec_T is fed: ``p`` with its first round(share N) rows replaced by the frozen
    encoder's Enc(A_RGB) of the same tones' albedos ``albedo_rgb`` (N, 3), clamped to [0, 1] as at
    inversion time (no gradient reaches Enc).  The batch order is random, so the first rows are a random
    subset.  share 0 returns ``p``."""
    n = round(share * p.shape[0])
    if n == 0:
        return p
    with torch.no_grad():
        p_hat = model.enc(albedo_rgb[:n].clamp(0.0, 1.0))
    return torch.cat([p_hat, p[n:]])


#: Validation tones per evaluation chunk in stage 3 (bounds the memory of L_shape at 376 wavelengths).
EVAL_CHUNK: int = 64


def stage3(model: SkinChain, lut: LookupTables, train: SplitData, val: SplitData, epochs: int, batch: int,
           lr: float, shape_weight: float = 0.0, dense: bool = True, weighted: bool = True,
           lambda_r: float = train_losses.LAMBDA_R, slab: bool = True, unfreeze: bool = False,
           encoder_share: float = 0.0, refl_loss: str = "absolute",
           smooth_weight: float = train_losses.LAMBDA_SMOOTH, balance: float = 0.0) -> StageSpec:
    """Stage 3; ``shape_weight`` > 0 adds the profile-shape term (needs ``SplitData.shape_target``).
    ``dense``: L_param at every wavelength, targets interpolated (``training.train.spectral``); else at the
    fitted wavelengths only.  ``weighted``: L_param weighted by the target weights (``losses.param_loss``).
    Ablations (``training.ablations``): ``lambda_r`` (paper 15), ``slab`` (the slab-depth factor in L_refl),
    ``unfreeze`` (Dec_R trains along with Dec_T).  ``encoder_share``: the share of each batch fed the
    encoder's tone (``encoder_input``); with it the validation also reports every term with all tones fed
    Enc(A_RGB) (keys ending ``_rgb``).  ``refl_loss``: L_refl's form (``losses.REFL_LOSSES``).
    ``smooth_weight``: the weight of L_smooth (the paper's lambda_smooth 0.5).  ``balance``: share of the
    tone draws by inverse local density (``training.train.balance``; 0 = every fitted tone once per epoch)."""
    ablate = {"lambda_r": lambda_r, "slab": slab, "frozen_decr": not unfreeze, "refl_loss": refl_loss,
              "lambda_smooth": smooth_weight}
    if train.targets is None:
        raise ValueError("stage 3 needs the mixture fits of the training split (--fits)")
    if shape_weight > 0 and train.shape_target is None:
        raise ValueError("a shape weight needs the training split's profiles (load_split(..., profiles=True))")
    n_w = train.R_d.shape[1]
    interp = interpolation_matrix(train.target_index.cpu().numpy(), n_w).to(train.R_d.device) if dense else None
    v_interp = (interpolation_matrix(val.target_index.cpu().numpy(), n_w).to(val.R_d.device)
                if dense and val.targets is not None else None)

    def step(idx: torch.Tensor) -> dict[str, torch.Tensor]:  # idx: positions among the fitted rows
        rows = train.fitted[idx]
        targets = {k: v[idx] for k, v in train.targets.items()}
        shape, shape_index = shape_batch(train, idx) if shape_weight > 0 else (None, None)
        p = encoder_input(model, train.albedo_rgb[rows], train.tone[rows], encoder_share)
        return train_losses.stage3_losses(model, lut, p, train.R_d[rows], targets, train.target_index,
                                          shape, shape_weight, shape_index, interp, weighted, **ablate)

    def evaluate() -> dict[str, float]:
        if val.targets is not None:
            sums: dict[str, float] = {}
            n = len(val.fitted)
            for s in range(0, n, EVAL_CHUNK):  # every term is a mean over tones: chunk means weighted by size
                part = torch.arange(s, min(s + EVAL_CHUNK, n), device=val.fitted.device)
                rows = val.fitted[part]
                st = None if val.shape_target is None else val.shape_target.rows(part)
                inputs = {"": val.tone[rows]}
                if encoder_share > 0:
                    inputs["_rgb"] = encoder_input(model, val.albedo_rgb[rows], val.tone[rows], 1.0)
                for suffix, p in inputs.items():
                    out = train_losses.stage3_losses(model, lut, p, val.R_d[rows],
                                                     {k: v[part] for k, v in val.targets.items()}, val.target_index,
                                                     st, shape_weight, val.shape_index, v_interp, weighted,
                                                     report=True, **ablate)
                    for k, v in out.items():
                        sums[k + suffix] = sums.get(k + suffix, 0.0) + float(v) * len(part) / n
            return sums
        out = model.dec_t(val.tone, model.dec_r(val.tone))
        r_hat = train_losses.lut_reflectance(model, lut, out, slab)
        return {"refl": float(train_losses.reflectance_loss(r_hat, val.R_d, refl_loss))}

    trainable = [model.dec_t] + ([model.slab] if slab else []) + ([model.dec_r] if unfreeze else [])
    probabilities = None
    if balance > 0:
        tones = train.tone[train.fitted].cpu().numpy()
        probabilities = torch.as_tensor(sampling_probabilities(tones, balance))
    return StageSpec(3, "Dec_T", trainable, len(train.fitted), batch, epochs, lr, step, evaluate, probabilities)
