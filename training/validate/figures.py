"""Figures of the validation (matplotlib, PNG), like the paper's; every function takes plain arrays.

* ``k_progression``: ground truth, joint-optimised K = 1, 2, 3, the network and the baselines for the
  representative tones, each cell the *edge image* of ``metrics`` (the slab lit left of the middle,
  +-2 mm; colour and the light carried into the shadow) with its Delta E76 against the ground truth.
* ``spectral_parameters``: the decoder's alpha(lambda), sigma_t(lambda) and weights per component, median and
  inter-quartile band over the tones given.
* ``cross_sections``: the ground truth's exitance around a point of entry (top view, +-2 mm, log scale
  normalised to each cell's peak) per wavelength (columns) and tone (rows).
* ``reflectance_and_profiles``: R_d(lambda) of the tones (left) and profile heat maps
  log10 r^2 R_d(r, lambda) of a few tones with the log-ratio of the K = 1 and K = 3 fits to it (right).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from exporters.colorimetry import srgb_encode
from exporters.constants import R_EDGES_CM


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _display(linear_rgb: np.ndarray) -> np.ndarray:
    """Linear sRGB -> displayable sRGB in [0, 1] (clipped; exposure 1: a perfect white reflector is white)."""
    return np.clip(srgb_encode(np.clip(linear_rgb, 0.0, None)), 0.0, 1.0)


def k_progression(path: Path, tone_names: list[str], row_labels: list[str], edge_rgb: np.ndarray,
                  delta_e: np.ndarray, edge_delta_e: np.ndarray, exposure: float = 2.0) -> None:
    """``edge_rgb`` (rows, tones, P, 3) linear sRGB, row 0 the ground truth; ``delta_e`` and ``edge_delta_e``
    (rows, tones) (row 0 ignored).  Images are shown at ``exposure`` x (skin reflects 0.003-0.5)."""
    plt = _plt()
    n_rows, n_tones, n_px, _ = edge_rgb.shape
    height = max(8, n_px // 3)
    fig, axes = plt.subplots(n_rows, n_tones, figsize=(1.05 * n_tones + 2.2, 0.62 * n_rows + 0.9), squeeze=False)
    for r in range(n_rows):
        for t in range(n_tones):
            ax = axes[r, t]
            img = np.repeat(_display(exposure * edge_rgb[r, t])[None], height, axis=0)
            ax.imshow(img, interpolation="nearest", aspect="auto")
            ax.set_xticks([])
            ax.set_yticks([])
            if r > 0:
                ax.text(0.5, 0.06, f"{delta_e[r, t]:.1f} | {edge_delta_e[r, t]:.1f}", transform=ax.transAxes,
                        ha="center", va="bottom", fontsize=6, color="white",
                        bbox=dict(facecolor="black", alpha=0.5, pad=0.5, lw=0))
            if r == 0:
                ax.set_title(tone_names[t], fontsize=7)
            if t == 0:
                ax.set_ylabel(row_labels[r], fontsize=6, rotation=0, ha="right", va="center")
    fig.suptitle(f"Edge images (slab lit left of the middle, +-2 mm, D65, exposure x{exposure:g});\n"
                 "numbers: Delta E76 vs the Monte Carlo ground truth of the slab colour | of the edge image",
                 fontsize=7)
    fig.tight_layout(pad=0.3, rect=(0.02, 0, 1, 0.95))
    fig.savefig(path, dpi=130)
    plt.close(fig)


def spectral_parameters(path: Path, wavelength_nm: np.ndarray, alpha: np.ndarray, sigma_t: np.ndarray,
                        weight: np.ndarray, title: str) -> None:
    """``alpha``, ``sigma_t``, ``weight`` (N, K, W) of N tones: median and IQR per component."""
    plt = _plt()
    k = alpha.shape[1]
    colours = plt.cm.viridis(np.linspace(0.1, 0.85, k))
    fig, axes = plt.subplots(3, 1, figsize=(7, 6.4), sharex=True, gridspec_kw={"height_ratios": [2, 2, 1]})
    for c in range(k):
        for ax, data in zip(axes, (alpha[:, c], sigma_t[:, c], weight[:, c]), strict=True):
            q1, med, q3 = np.percentile(data, [25, 50, 75], axis=0)
            ax.plot(wavelength_nm, med, color=colours[c], lw=1.2, label=f"component {c + 1}")
            ax.fill_between(wavelength_nm, q1, q3, color=colours[c], alpha=0.25, lw=0)
    axes[0].set_ylabel("single-scattering\nalbedo alpha")
    axes[1].set_ylabel("extinction\nsigma_t (cm^-1)")
    axes[1].set_yscale("log")
    axes[2].set_ylabel("weight w")
    axes[2].set_xlabel("wavelength (nm)")
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def rebin(profile: np.ndarray, factor: int, edges: np.ndarray = R_EDGES_CM) -> tuple[np.ndarray, np.ndarray]:
    """Merge ``factor`` adjacent radial bins (area-weighted means) for display: (profile (..., NB / factor),
    edges (NB / factor + 1,))."""
    area = np.pi * np.diff(edges**2)
    nb = (profile.shape[-1] // factor) * factor
    power = (profile[..., :nb] * area[:nb]).reshape(*profile.shape[:-1], -1, factor).sum(-1)
    new_edges = edges[: nb + 1 : factor]
    return power / (np.pi * np.diff(new_edges**2)), new_edges


def exitance_image(profile: np.ndarray, edges: np.ndarray = R_EDGES_CM, half_width_cm: float = 0.2,
                   pixels: int = 65) -> np.ndarray:
    """Top view (pixels, pixels) of a radial profile (NB,) cm^-2 on ``edges`` around the entry point."""
    x = np.linspace(-half_width_cm, half_width_cm, pixels)
    r = np.hypot(*np.meshgrid(x, x))
    idx = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, profile.size - 1)
    return profile[idx]


def cross_sections(path: Path, tone_names: list[str], wavelength_nm: np.ndarray, profiles: np.ndarray,
                   decades: float = 4.0) -> None:
    """``profiles`` (tones, wavelengths, 512): ground-truth exitance images, log10 over ``decades``."""
    plt = _plt()
    n_t, n_w, _ = profiles.shape
    coarse, edges = rebin(profiles, 8)  # 64 radial bins: less Monte Carlo noise per displayed ring
    fig, axes = plt.subplots(n_t, n_w, figsize=(0.9 * n_w + 0.8, 0.9 * n_t + 0.5), squeeze=False)
    for t in range(n_t):
        for j in range(n_w):
            img = exitance_image(coarse[t, j], edges)
            peak = img.max()
            logi = np.log10(np.clip(img / peak, 10.0**-decades, None)) if peak > 0 else np.full(img.shape, -decades)
            ax = axes[t, j]
            ax.imshow(logi, cmap="inferno", vmin=-decades, vmax=0, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if t == 0:
                ax.set_title(f"{wavelength_nm[j]:.0f} nm", fontsize=7)
            if j == 0:
                ax.set_ylabel(tone_names[t], fontsize=7)
    fig.suptitle(f"Ground-truth exitance around a point of entry (+-2 mm, log10 of the peak-normalised value, "
                 f"{decades:g} decades)", fontsize=7)
    fig.tight_layout(pad=0.3, rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=130)
    plt.close(fig)


def reflectance_and_profiles(path: Path, wavelength_nm: np.ndarray, tone_names: list[str], R_d: np.ndarray,
                             srgb: np.ndarray, heat_tones: list[int], profiles: np.ndarray, used: np.ndarray,
                             fit_profiles: dict[str, np.ndarray]) -> None:
    """Left: R_d (tones, W) in each tone's colour ``srgb`` (tones, 3).  Right: for the tones ``heat_tones``,
    log10 r^2 profile (W, 512) and log10(fit / MC) of each entry of ``fit_profiles`` (label -> (tones, W, 512)),
    shown on the bins the fitter's loss uses (``used``, boolean like ``profiles``), blank elsewhere."""
    plt = _plt()
    n_h = len(heat_tones)
    n_c = 1 + len(fit_profiles)
    fig = plt.figure(figsize=(4 + 2.4 * n_c, max(3.2, 2.0 * n_h)))
    grid = fig.add_gridspec(n_h, 1 + n_c, width_ratios=[1.6] + [1] * n_c)
    ax = fig.add_subplot(grid[:, 0])
    for t in range(len(tone_names)):
        ax.plot(wavelength_nm, R_d[t], color=np.clip(srgb[t], 0, 1), lw=1.3, label=tone_names[t])
    ax.set_yscale("log")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("R_d (ground truth)")
    ax.legend(fontsize=6, ncol=2)
    centres = np.sqrt(R_EDGES_CM[:-1] * R_EDGES_CM[1:])
    centres[0] = R_EDGES_CM[1] / 2
    extent = [np.log10(centres[0]), np.log10(centres[-1]), wavelength_nm[-1], wavelength_nm[0]]
    for i, t in enumerate(heat_tones):
        prof = np.where(used[t] & (profiles[t] > 0), profiles[t], np.nan)
        # light per unit log radius, r^2 R_d(r), normalised per wavelength: where each wavelength's light exits
        per_log_r = prof * centres**2
        with warnings.catch_warnings(), np.errstate(invalid="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)  # wavelengths with no resolved bin stay blank
            lp = np.log10(per_log_r / np.nanmax(per_log_r, axis=1, keepdims=True))
        a = fig.add_subplot(grid[i, 1])
        a.imshow(lp, aspect="auto", extent=extent, cmap="magma", vmin=-4, vmax=0)
        a.set_title(f"{tone_names[t]}: log10 r² R_d(r) (MC, per-λ max)", fontsize=7)
        for j, (label, fp) in enumerate(fit_profiles.items()):
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.log10(fp[t] / prof)
            ratio[~np.isfinite(ratio)] = np.nan
            b = fig.add_subplot(grid[i, 2 + j])
            b.imshow(ratio, aspect="auto", extent=extent, cmap="RdBu_r", vmin=-1, vmax=1)
            b.set_title(f"log10({label} / MC)", fontsize=7)
            b.tick_params(labelsize=6)
        a.tick_params(labelsize=6)
        a.set_ylabel("wavelength (nm)", fontsize=7)
    fig.text(0.6, 0.005, "log10 r (cm)", fontsize=7)
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)
