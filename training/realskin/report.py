"""Tables, JSON and the figure of ``python -m training realskin``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from exporters.cli_io import atomic_file
from exporters.colorimetry import spectrum_to_lab
from exporters.constants import PARAM_NAMES
from training.realskin.fit import BANDS_NM, FIT_BAND_NM, SubjectFit, at_edge
from training.realskin.measurements import Measurements, diffuse_on_grid


def measured_lab(meas: Measurements, specular: float) -> np.ndarray:
    """CIE Lab (D65) of each measured spectrum without its specular part (S, 3)."""
    return spectrum_to_lab(diffuse_on_grid(meas, specular))


def measured_lightness(meas: Measurements, specular: float) -> np.ndarray:
    """CIE L* (D65) of each measured spectrum without its specular part (S,)."""
    return measured_lab(meas, specular)[:, 0]


def _mean(fits: list[SubjectFit], band: str) -> float:
    return float(np.mean([f.rmse[band] for f in fits]))


def brightness_predictability(p: np.ndarray, exposure: np.ndarray) -> dict | None:
    """How much of the between-subject brightness spread a function of the five parameters could carry.

    ln(exposure) (S,) — the free-exposure factors — regressed linearly on the free fits' (ln f_mel, ln f_blood, t_epi,
    so2, b_mel) (S, 5), scored leave-one-out: R² = 1 − Σ(y − ŷ₋ᵢ)² / Σ(y − ȳ)² (1: predicted; ≤ 0: not at all).
    A low R² says the spread is not a smooth (here: linear) function of the fitted p, so a skin model whose scattering
    depends on the wavelength and on p cannot remove it; it needs a degree of freedom p does not have. The fitted p of a
    model with such a law would differ somewhat: this is evidence, not proof. None for fewer than 10 subjects (too
    few to score six coefficients).
    """
    if len(exposure) < 10:
        return None
    y = np.log(np.asarray(exposure, dtype=np.float64))
    p = np.asarray(p, dtype=np.float64)
    a = np.column_stack([np.ones(len(y)), np.log(p[:, 0]), np.log(p[:, 1]), p[:, 2:]])
    # Written by hand: one small least-squares regression scored leave-one-out; scikit-learn's cross_val_predict
    # does the same but is not a dependency of the project, and this is its only use.
    predicted = np.empty_like(y)
    for i in range(len(y)):
        keep = np.arange(len(y)) != i
        predicted[i] = a[i] @ np.linalg.lstsq(a[keep], y[keep], rcond=None)[0]
    spread = float(((y - y.mean()) ** 2).sum())
    r2 = 1.0 - float(((y - predicted) ** 2).sum()) / spread if spread > 0 else 0.0
    return {"sd_ln_exposure": round(float(y.std()), 4), "loo_r2_from_p": round(r2, 3)}


def summary(names, lightness, mc_fixed, mc_free, dec_fixed=None, dec_free=None, settings: dict | None = None) -> dict:
    """The JSON report (docs/contracts.md §2 keys, plus the free-exposure fits, the decoder's and run's settings)."""
    scaled = mc_fixed[0].scattering_scale is not None
    subjects = []
    for i, name in enumerate(names):
        f, g = mc_fixed[i], mc_free[i]
        row = {"name": name, "L_star": round(float(lightness[i]), 2),
               **{f"rmse_{b}": round(f.rmse[b], 5) for b in BANDS_NM},
               "exposure_free": round(g.exposure, 4), "p": [round(float(v), 5) for v in f.p],
               "rmse_400_1000_free": round(g.rmse["400_1000"], 5), "p_free": [round(float(v), 5) for v in g.p],
               "at_edge": [n for n, e in zip(PARAM_NAMES, at_edge(f.p), strict=True) if e]}
        if scaled:
            row["scattering_scale"] = round(f.scattering_scale, 4)
            row["scattering_scale_free"] = round(g.scattering_scale, 4)
        if dec_fixed is not None:
            row["decoder"] = {"rmse_400_1000": round(dec_fixed[i].rmse["400_1000"], 5),
                              "exposure_free": round(dec_free[i].exposure, 4),
                              "rmse_400_1000_free": round(dec_free[i].rmse["400_1000"], 5),
                              "p": [round(float(v), 5) for v in dec_fixed[i].p]}
        subjects.append(row)
    out = {"subjects": subjects, "mean_rmse_400_1000": round(_mean(mc_fixed, "400_1000"), 5),
           "mean": {b: round(_mean(mc_fixed, b), 5) for b in BANDS_NM},
           "mean_free": {b: round(_mean(mc_free, b), 5) for b in BANDS_NM},
           "exposure_free_range": [round(min(f.exposure for f in mc_free), 4),
                                   round(max(f.exposure for f in mc_free), 4)],
           "edge_share": dict(zip(PARAM_NAMES, at_edge(np.array([f.p for f in mc_fixed])).mean(0).round(3).tolist(),
                                  strict=True)),
           "param_names": list(PARAM_NAMES), "fit_band_nm": list(FIT_BAND_NM)}
    spread = brightness_predictability(np.array([f.p for f in mc_free]), np.array([f.exposure for f in mc_free]))
    if spread is not None:
        out["brightness_spread"] = spread
    if scaled:
        k = np.array([f.scattering_scale for f in mc_fixed])
        out["scattering_scale"] = {"range": [round(float(k.min()), 4), round(float(k.max()), 4)],
                                   "median": round(float(np.median(k)), 4)}
    if dec_fixed is not None:
        out["decoder"] = {"mean": {b: round(_mean(dec_fixed, b), 5) for b in BANDS_NM},
                          "mean_free": {b: round(_mean(dec_free, b), 5) for b in BANDS_NM},
                          "exposure_free_range": [round(min(f.exposure for f in dec_free), 4),
                                                  round(max(f.exposure for f in dec_free), 4)]}
    if settings:
        out["settings"] = settings
    return out


def markdown(report: dict) -> str:
    """The per-subject table and the means, as Markdown."""
    dec, scaled = "decoder" in report, "scattering_scale" in report
    head = ("| subject | L* | RMSE UV | Vis | NIR | 400–1000 | f_mel | f_blood | t_epi (µm) | so2 | b_mel "
            + ("| scattering scale " if scaled else "")
            + "| exposure (free) | RMSE free |" + (" decoder RMSE | decoder exposure |" if dec else ""))
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for s in report["subjects"]:
        p = s["p"]
        row = (f"| {s['name']} | {s['L_star']:.1f} | {s['rmse_uv']:.4f} | {s['rmse_vis']:.4f} | {s['rmse_nir']:.4f} "
               f"| {s['rmse_400_1000']:.4f} | {p[0]:.4f} | {p[1]:.4f} | {p[2] * 1e4:.0f} | {p[3]:.2f} | {p[4]:.2f} "
               + (f"| {s['scattering_scale']:.3f} " if scaled else "")
               + f"| {s['exposure_free']:.3f} | {s['rmse_400_1000_free']:.4f} |")
        if dec:
            row += f" {s['decoder']['rmse_400_1000']:.4f} | {s['decoder']['exposure_free']:.3f} |"
        lines.append(row)
    m, mf = report["mean"], report["mean_free"]
    lines += ["", f"Mean RMSE at exposure 1 (Monte Carlo): UV {m['uv']:.4f}, Vis {m['vis']:.4f}, NIR {m['nir']:.4f}, "
              f"400–1000 nm **{m['400_1000']:.4f}**; exposure free: 400–1000 nm {mf['400_1000']:.4f} at factors "
              f"{report['exposure_free_range'][0]:.3f}–{report['exposure_free_range'][1]:.3f}.",
              "Share of subjects whose fitted parameter (exposure 1) is at an edge of its range: "
              + ", ".join(f"{n} {v:.0%}" for n, v in report["edge_share"].items()) + "."]
    if "brightness_spread" in report:
        b = report["brightness_spread"]
        lines.append(f"Brightness spread between subjects: sd of ln(free factor) {b['sd_ln_exposure']:.3f}; "
                     "the share of it that the free fits' five parameters predict (linear, leave-one-out R²): "
                     f"{b['loo_r2_from_p']:.2f}.")
    if scaled:
        k = report["scattering_scale"]
        lines.append(f"Per-subject scattering scale (exposure 1): {k['range'][0]:.3f}–{k['range'][1]:.3f} "
                     f"(median {k['median']:.3f}), searched in {report['settings']['scattering_scale_range']}.")
    if dec:
        d = report["decoder"]
        lines.append(f"Shipped decoder: 400–1000 nm {d['mean']['400_1000']:.4f} at exposure 1, "
                     f"{d['mean_free']['400_1000']:.4f} free at factors {d['exposure_free_range'][0]:.3f}–"
                     f"{d['exposure_free_range'][1]:.3f}.")
    return "\n".join(lines) + "\n"


def figure(path: Path, wavelength_nm: np.ndarray, measured: np.ndarray, names, lightness, mc_fixed,
           dec_fixed=None) -> None:
    """Measured against modelled spectra for the lightest, the median and the darkest subject."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = np.argsort(lightness)
    picks = [("light", order[-1]), ("medium", order[len(order) // 2]), ("dark", order[0])]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for ax, (label, i) in zip(axes, picks, strict=True):
        ax.plot(wavelength_nm, measured[i], "k-", lw=1.6, label="measured (NIST)")
        k = mc_fixed[i].scattering_scale
        ax.plot(wavelength_nm, mc_fixed[i].model, "C0-", lw=1.2,
                label="Monte Carlo fit, exposure 1" + ("" if k is None else f", scattering × {k:.2f}"))
        if dec_fixed is not None:
            ax.plot(wavelength_nm, dec_fixed[i].model, "C3--", lw=1.0, label="shipped decoder fit, exposure 1")
        ax.axvspan(wavelength_nm[0], FIT_BAND_NM[0], color="0.93", lw=0)
        ax.set_title(f"{label}: {names[i]} (L* {lightness[i]:.0f}), RMSE {mc_fixed[i].rmse['400_1000']:.3f}")
        ax.set_xlabel("wavelength (nm)")
    axes[0].set_ylabel("reflectance (specular included)")
    axes[0].legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    with atomic_file(path) as f:
        fig.savefig(f, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)


def write(out: Path, report: dict, md: str) -> None:
    """realskin.json and realskin.md in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    for name, text in (("realskin.json", json.dumps(report, indent=1) + "\n"), ("realskin.md", md)):
        with atomic_file(out / name, "w") as f:
            f.write(text)
