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
* ``sss_reconstruction``, ``component_maps``, ``sigma_t_distribution``, ``g_bimodality``: the paper's Figs. 7-9
  (``training.validate.decomposition``).
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


def _map_grid(path: Path, row_labels: list[str], columns: list[dict], title: str) -> None:
    """A grid of images: one row per subject, one column per entry of ``columns`` ({"title", "images" (S, H, W)
    scalars or (S, H, W, 3) display RGB, and for scalars "cmap", "vmin", "vmax", "label"}); a colour bar under
    each scalar column (one scale per column, shared by the subjects)."""
    plt = _plt()
    n_r, n_c = len(row_labels), len(columns)
    fig, axes = plt.subplots(n_r, n_c, figsize=(1.25 * n_c + 0.6, 1.25 * n_r + 1.1), squeeze=False,
                             constrained_layout=True)
    for j, col in enumerate(columns):
        for i in range(n_r):
            ax = axes[i, j]
            img = col["images"][i]
            im = (ax.imshow(img, interpolation="nearest") if img.ndim == 3 else
                  ax.imshow(img, cmap=col["cmap"], vmin=col["vmin"], vmax=col["vmax"], interpolation="nearest"))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(col["title"], fontsize=7)
            if j == 0:
                ax.set_ylabel(row_labels[i], fontsize=7)
        if col["images"].ndim == 3:
            bar = fig.colorbar(im, ax=axes[:, j], orientation="horizontal", fraction=0.05, pad=0.02)
            bar.ax.tick_params(labelsize=5)
            bar.set_label(col["label"], fontsize=6)
    fig.suptitle(title, fontsize=8)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _log_column(title: str, images: np.ndarray, label: str, cmap: str = "viridis") -> dict:
    logs = np.log10(np.maximum(images, 1e-30))
    return {"title": title, "images": logs, "cmap": cmap, "vmin": float(logs.min()), "vmax": float(logs.max()),
            "label": label}


def sss_reconstruction(path: Path, subjects: list[str], maps: dict[str, np.ndarray], map_nm: float,
                       reflectance_nm: tuple[float, ...]) -> None:
    """Fig. 7 of the paper: per subject (rows) the input albedo and the model's colour, then per component
    alpha and log10 sigma_t at ``map_nm`` (one scale per column over the subjects), then the model's reflectance
    at ``reflectance_nm``.  ``maps``: ``input``, ``reconstructed`` (S, H, W, 3) linear sRGB; ``alpha``,
    ``sigma_t`` (S, H, W, K); ``reflectance`` (S, H, W, len(reflectance_nm))."""
    k = maps["alpha"].shape[-1]
    cols = [{"title": "input albedo", "images": _display(maps["input"])},
            {"title": "model colour", "images": _display(maps["reconstructed"])}]
    cols += [{"title": f"α C{c + 1}", "images": maps["alpha"][..., c], "cmap": "viridis", "vmin": 0.0, "vmax": 1.0,
              "label": "α"} for c in range(k)]
    cols += [_log_column(f"σt C{c + 1}", maps["sigma_t"][..., c], "log10 σt (cm⁻¹)") for c in range(k)]
    cols += [{"title": f"R {nm:g} nm", "images": maps["reflectance"][..., j], "cmap": "magma", "vmin": 0.0,
              "vmax": float(maps["reflectance"][..., j].max()), "label": "R"} for j, nm in enumerate(reflectance_nm)]
    _map_grid(path, subjects, cols, f"K = 3 decomposition of three subjects (components named by median albedo; "
                                    f"α, σt at {map_nm:g} nm)")


def component_maps(path: Path, subjects: list[str], maps: dict[str, np.ndarray], map_nm: float) -> None:
    """Fig. 7's companion: per component the weight and the anisotropy g at ``map_nm`` (``maps`` as in
    ``sss_reconstruction``, with ``weight`` and ``g`` (S, H, W, K))."""
    k = maps["weight"].shape[-1]
    cols = [{"title": f"w C{c + 1}", "images": maps["weight"][..., c], "cmap": "cividis", "vmin": 0.0, "vmax": 1.0,
             "label": "weight"} for c in range(k)]
    cols += [{"title": f"g C{c + 1}", "images": maps["g"][..., c], "cmap": "coolwarm", "vmin": -1.0, "vmax": 1.0,
              "label": "g"} for c in range(k)]
    _map_grid(path, subjects, cols, f"Weights and anisotropy per component at {map_nm:g} nm")


def sigma_t_distribution(path: Path, wavelength_nm: np.ndarray, sigma_t: np.ndarray, mass: np.ndarray,
                         threshold_cm: float, ours: dict[str, float | None], theirs: dict[str, float]) -> None:
    """Fig. 8: the mass (``mass`` (N, W), the mixture weight) of the low-albedo component per wavelength over
    log10 sigma_t (``sigma_t`` (N, W) cm^-1), normalised per wavelength, with the threshold; beside it the share
    below the threshold per band, ours (``ours``) and the paper's (``theirs``)."""
    plt = _plt()
    logs = np.log10(np.maximum(sigma_t, 1e-30))
    edges = np.linspace(min(logs.min(), np.log10(threshold_cm)) - 0.1, logs.max() + 0.1, 81)
    hist = np.stack([np.histogram(logs[:, j], bins=edges, weights=mass[:, j])[0] for j in range(logs.shape[1])], 1)
    hist = hist / np.maximum(hist.sum(0, keepdims=True), 1e-300)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.4), gridspec_kw={"width_ratios": [3, 1]}, constrained_layout=True)
    from matplotlib.colors import PowerNorm

    im = ax.imshow(hist, origin="lower", aspect="auto", cmap="magma", norm=PowerNorm(0.5, vmin=0.0),
                   extent=[wavelength_nm[0], wavelength_nm[-1], edges[0], edges[-1]])
    ax.axhline(np.log10(threshold_cm), color="cyan", ls="--", lw=1, label=f"σt = {threshold_cm:g} cm⁻¹")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("log10 σt of C3 (cm⁻¹)")
    ax.legend(fontsize=7, loc="upper right")
    fig.colorbar(im, ax=ax, label="share of C3's mass per wavelength (sqrt scale)")
    bands = list(theirs)
    x = np.arange(len(bands))
    bx.bar(x - 0.2, [100 * (ours[b] or 0.0) for b in bands], 0.4, label="ours")
    bx.bar(x + 0.2, [100 * theirs[b] for b in bands], 0.4, label="paper")
    bx.set_xticks(x, bands)
    bx.set_ylabel(f"% of C3's mass at σt < {threshold_cm:g} cm⁻¹")
    bx.legend(fontsize=7)
    fig.suptitle("σt mass distribution of the low-albedo component (C3)", fontsize=8)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def g_bimodality(path: Path, unweighted, weighted, paper_modes: tuple[float, ...]) -> None:
    """Fig. 9: kernel densities of the low-albedo component's g (``unweighted`` and mass-``weighted``:
    objects with ``grid``, ``density``, ``modes``), their modes and the paper's."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.2), constrained_layout=True)
    for d, label, colour in ((unweighted, "samples", "C0"), (weighted, "mass-weighted", "C1")):
        ax.plot(d.grid, d.density, color=colour, label=f"{label}: modes {', '.join(f'{m:.2f}' for m in d.modes)}")
        for m in d.modes:
            ax.axvline(m, color=colour, lw=0.8, ls=":")
    for m in paper_modes:
        ax.axvline(m, color="k", lw=1, ls="--")
    ax.plot([], [], "k--", label="paper's modes")
    ax.set_xlim(-0.2, 1.0)
    ax.set_xlabel("g of C3")
    ax.set_ylabel("density")
    ax.legend(fontsize=7)
    ax.set_title("Anisotropy of the low-albedo component (C3), all tones and wavelengths", fontsize=8)
    fig.savefig(path, dpi=130)
    plt.close(fig)
