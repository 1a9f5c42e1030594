"""Physical trends along a melanin sweep: the shipped decoder against the Monte Carlo ground truth.

    python -m training.validate.trends --lut LUT.npz [--photons 20000] [--out DIR] [--model-dir DIR]

The paper (§6) reads its pooled parameters as "alpha decreases with melanin, sigma_t increases (shorter
mean free path)".  Whether sigma_t of an *equivalent homogeneous medium* must rise with melanin is a
property of the two-layer skin, not of the network, so this checks it without the network or the
fitter: for each tone of a melanin sweep (the other parameters at ``SWEEP_BASE``) the Monte Carlo gives
R_d and the median reflected radius r50 (cm) at 450-650 nm; the K = 1 medium with the model's g(lambda)
that matches both through the LUT has the albedo that gives R_d and sigma_t = r50_LUT(alpha, g) [mfp] /
r50 [cm].  Printed beside it: the decoder's component-weighted alpha and sigma_t (``skin_decoder.onnx``).

All tones share one reweighted walk (``training.data.reweight``, the dataset's estimator) and the
epidermis thickness of ``SWEEP_BASE``; the seed is fixed.  Writes ``DIR/trends.json`` and
``DIR/fig_trends.png`` with ``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM, anisotropy
from training.paths import SHIPPED_MODEL_DIR as DEFAULT_MODEL_DIR

#: f_blood, t_epi [cm], so2, b_mel of the sweep (a typical adult: 3 % blood, 120 um epidermis).
SWEEP_BASE: tuple[float, float, float, float] = (0.03, 0.012, 0.75, 0.7)
SWEEP_F_MEL: tuple[float, ...] = (0.002, 0.01, 0.03, 0.08, 0.15, 0.3)
#: Wavelengths of the comparison: 450-650 nm every 10 nm (the visible band of the trend test).
TREND_NM = np.arange(450.0, 651.0, 10.0)


def median_radius(profile: np.ndarray | torch.Tensor, r_edges: np.ndarray | torch.Tensor) -> np.ndarray:
    """Radius (units of ``r_edges`` (M + 1,)) within which half of the reflected power of ``profile``
    (..., M) (per unit area, constant within each bin) leaves; linear in the area within the crossing bin."""
    p = np.asarray(profile, dtype=np.float64)
    e = np.asarray(r_edges, dtype=np.float64)
    area = np.pi * np.diff(e**2)
    cum = np.cumsum(np.clip(p, 0.0, None) * area, axis=-1)
    total = cum[..., -1:]
    if (total <= 0).any():
        raise ValueError("median_radius: a profile has no reflected power")
    frac = cum / total
    j = np.argmax(frac >= 0.5, axis=-1)[..., None]
    lo = np.where(j > 0, np.take_along_axis(frac, np.maximum(j - 1, 0), -1), 0.0)
    hi = np.take_along_axis(frac, j, -1)
    t = (0.5 - lo) / np.maximum(hi - lo, 1e-300)
    r2 = e[j] ** 2 + t * (e[j + 1] ** 2 - e[j] ** 2)
    return np.sqrt(r2)[..., 0]


def albedo_for_reflectance(lut, R: np.ndarray, g: np.ndarray, iters: int = 60) -> np.ndarray:
    """The single-scattering albedo whose LUT reflectance R(alpha, g) equals ``R`` (same shape as ``g``
    after broadcasting), by bisection (R is increasing in alpha); clamped to the LUT's albedo range."""
    R_t, g_t = (torch.tensor(np.array(x, dtype=np.float64)) for x in np.broadcast_arrays(R, g))
    lo = torch.full_like(R_t, float(lut.albedo[0]))
    hi = torch.full_like(R_t, float(lut.albedo[-1]))
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        below = lut.reflectance(mid, g_t) < R_t
        lo, hi = torch.where(below, mid, lo), torch.where(below, hi, mid)
    return (0.5 * (lo + hi)).numpy()


def equivalent_medium(lut, R: np.ndarray, r50_cm: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(alpha, sigma_t [cm^-1]) of the K = 1 medium with anisotropy ``g`` whose R and median reflected
    radius match ``R`` and ``r50_cm`` (same shapes)."""
    alpha = albedo_for_reflectance(lut, R, g)
    rows = lut.profile_rows(torch.as_tensor(alpha), torch.as_tensor(np.broadcast_to(g, alpha.shape).copy()))
    r50_mfp = median_radius(rows.numpy(), lut.r_edges_mfp.numpy())
    return alpha, r50_mfp / r50_cm


def sweep_tones(f_mel: tuple[float, ...] = SWEEP_F_MEL) -> np.ndarray:
    """(n, 5) biophysical vectors of the sweep."""
    return np.array([[m, *SWEEP_BASE] for m in f_mel], dtype=np.float64)


def monte_carlo(tones: np.ndarray, photons: int, seed: int = 0) -> dict[str, np.ndarray]:
    """R_d (n, 376) and profile (n, 376, 512) cm^-2 of the tones, one reweighted walk (same t_epi)."""
    from training.data.reweight import baseline_absorption, reweight, walk

    if len(np.unique(tones[:, 2])) != 1:
        raise ValueError("the sweep's tones must share one epidermis thickness (one walk)")
    traj = walk(photons, seed=seed, mua0=baseline_absorption(tones), levels_cm=tones[:1, 2])
    return reweight(traj, tones)


def decoder_means(decoder: Path, tones: np.ndarray, cols: np.ndarray) -> dict[str, np.ndarray]:
    """Component-weighted alpha and sigma_t [cm^-1] of ``skin_decoder.onnx`` at wavelength columns ``cols``:
    (n, len(cols)) each."""
    from exporters.inference import run_decoder

    out = run_decoder(tones, decoder)
    w = out["weight"][..., cols]
    return {"alpha": (w * out["alpha"][..., cols]).sum(1), "sigma_t": (w * out["sigma_t"][..., cols]).sum(1)}


def trends(lut, decoder: Path, photons: int, f_mel: tuple[float, ...] = SWEEP_F_MEL) -> dict:
    """The comparison of the module docstring; per tone, means over ``TREND_NM``."""
    tones = sweep_tones(f_mel)
    cols = np.searchsorted(WAVELENGTHS_NM, TREND_NM)
    mc = monte_carlo(tones, photons)
    R = mc["R_d"][:, cols]
    r50 = median_radius(mc["profile"][:, cols], R_EDGES_CM)
    alpha_eq, sigma_eq = equivalent_medium(lut, R, r50, np.broadcast_to(anisotropy(TREND_NM), R.shape))
    net = decoder_means(decoder, tones, cols)
    rows = [{"f_mel": float(t[0]), "R": float(R[i].mean()), "r50_mm": float(10 * r50[i].mean()),
             "alpha_equivalent": float(alpha_eq[i].mean()), "sigma_t_equivalent": float(sigma_eq[i].mean()),
             "alpha_decoder": float(net["alpha"][i].mean()), "sigma_t_decoder": float(net["sigma_t"][i].mean())}
            for i, t in enumerate(tones)]
    return {"base": dict(zip(("f_blood", "t_epi_cm", "so2", "b_mel"), SWEEP_BASE, strict=True)),
            "wavelength_nm": [float(TREND_NM[0]), float(TREND_NM[-1])], "photons": photons, "tones": rows}


def markdown(result: dict) -> str:
    """The result as a markdown table."""
    head = ("| f_mel | R | r50 (mm) | alpha, K = 1 equivalent | sigma_t (cm^-1), K = 1 equivalent "
            "| alpha, decoder | sigma_t (cm^-1), decoder |\n|---|---|---|---|---|---|---|\n")
    return head + "".join(
        f"| {r['f_mel']:g} | {r['R']:.3f} | {r['r50_mm']:.3f} | {r['alpha_equivalent']:.4f} | "
        f"{r['sigma_t_equivalent']:.0f} | {r['alpha_decoder']:.4f} | {r['sigma_t_decoder']:.0f} |\n"
        for r in result["tones"])


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = [r["f_mel"] for r in result["tones"]]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4), constrained_layout=True)
    for key, label in (("equivalent", "K = 1 equivalent of the MC"), ("decoder", "decoder (weighted)")):
        ax[0].plot(m, [r[f"alpha_{key}"] for r in result["tones"]], "o-", label=label)
        ax[1].plot(m, [r[f"sigma_t_{key}"] for r in result["tones"]], "o-", label=label)
    for a, name in zip(ax, ("albedo", "sigma_t (cm^-1)"), strict=True):
        a.set_xscale("log")
        a.set_xlabel("melanin fraction f_mel")
        a.set_ylabel(f"{name}, mean 450-650 nm")
    ax[1].legend()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m training.validate.trends", description=__doc__.splitlines()[0])
    p.add_argument("--lut", type=Path, required=True, help="LUT .npz of `python -m training lut`")
    p.add_argument("--photons", type=int, default=20000, help="photons per wavelength of the shared walk")
    p.add_argument("--model-dir", type=Path, default=DEFAULT_MODEL_DIR, help="folder with skin_decoder.onnx")
    p.add_argument("--out", type=Path, default=None, help="folder for trends.json and fig_trends.png")
    args = p.parse_args(argv)
    from training.sim.lut_interp import LookupTables

    try:
        if args.photons < 100:
            raise ValueError("--photons must be >= 100")
        lut = LookupTables.load(args.lut, dtype=torch.float64)
        result = trends(lut, args.model_dir / "skin_decoder.onnx", args.photons)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(markdown(result))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "trends.json").write_text(json.dumps(result, indent=2))
        plot(result, args.out / "fig_trends.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
