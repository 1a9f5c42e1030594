"""Where the dataset's tones lie in colour: the sampling of ``training.data.sampling`` against the uniform one
it replaced and against measured skin.

    python -m training.realskin.distribution [--out FILE.png] [--tones 2000] [--photons 4000] [--json]

Each tone's albedo colour (CIE Lab, D65) comes from one small reweighted walk in the dataset's geometry
(diffuse light, specular excluded; every 10 nm over 360-830 nm, the colour range, linearly interpolated
onto the 2 nm grid), cached like the realskin walks.  Measured skin: the NIST odd subjects shipped with
``training.realskin`` (their rough-surface specular part removed).  Printed: the share of tones at
L* < 10 (near-black), in the skin-colour region ``SKIN_REGION``, and the L* percentiles.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from exporters.colorimetry import spectrum_to_lab, spectrum_to_srgb
from exporters.constants import WAVELENGTHS_NM
from training.data.reweight import Trajectories, baseline_absorption, reweight, walk
from training.data.sampling import training_tones, validation_tones

#: Visible channels of the colour walk: 360, 370, ..., 830 nm (indices into the 2 nm grid).
COLOUR_CHANNELS = np.arange(55, 291, 5)
#: Skin colours, CIE Lab under D65: L* 25-75 and hue angle h_ab 20-80 deg.  Measured forearms span L* 39-72
#: (NIST odd subjects, h_ab 47-65 deg); the darkest skin classes of Chardon et al. 1991's individual typology
#: angle reach L* ~ 25-30 and light skin ~ 70-75 (Del Bino & Bernerd 2013, BJD 169 S3:33).
SKIN_REGION = {"L_star": (25.0, 75.0), "hue_deg": (20.0, 80.0)}


def colour_walk(photons: int, seed: int, cache: Path | None) -> Trajectories:
    """The dataset-geometry walk at ``COLOUR_CHANNELS``, from ``cache`` when it holds it."""
    path = None if cache is None else cache / f"colour_walk_{photons}_{seed}_{baseline_absorption().sum():.6f}.npz"
    if path is not None and path.exists():
        return Trajectories.load(path)
    traj = walk(photons, seed=seed, mua0=baseline_absorption(), channels=COLOUR_CHANNELS)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        traj.save(path)
    return traj


def tone_colours(traj: Trajectories, tones: np.ndarray, chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """CIE Lab (N, 3) and display sRGB (N, 3, clipped to [0, 1]) of the albedo of tones (N, 5) (t_epi on
    the dataset's levels), D65."""
    lab, rgb = [], []
    for i in range(0, len(tones), chunk):
        r = reweight(traj, tones[i : i + chunk])["R_d"]
        full = np.stack([np.interp(WAVELENGTHS_NM, WAVELENGTHS_NM[traj.channels], row) for row in r])
        lab.append(spectrum_to_lab(full))
        rgb.append(np.clip(spectrum_to_srgb(full), 0.0, 1.0))
    return np.concatenate(lab), np.concatenate(rgb)


def in_skin_region(lab: np.ndarray) -> np.ndarray:
    """Which colours (N, 3) lie in ``SKIN_REGION`` (N,) bool."""
    hue = np.degrees(np.arctan2(lab[:, 2], lab[:, 1]))
    (l_lo, l_hi), (h_lo, h_hi) = SKIN_REGION["L_star"], SKIN_REGION["hue_deg"]
    return (lab[:, 0] >= l_lo) & (lab[:, 0] <= l_hi) & (hue >= h_lo) & (hue <= h_hi)


def shares(lab: np.ndarray) -> dict:
    """Near-black and skin-region shares and L* percentiles (5, 25, 50, 75, 95) of colours (N, 3)."""
    return {"near_black_L_lt_10": round(float(np.mean(lab[:, 0] < 10)), 4),
            "skin_region": round(float(np.mean(in_skin_region(lab))), 4),
            "L_star_percentiles": np.percentile(lab[:, 0], [5, 25, 50, 75, 95]).round(1).tolist()}


def measured_skin_lab() -> np.ndarray:
    """CIE Lab (S, 3) of the shipped measured spectra without their specular part."""
    from training.realskin.geometry import rough_specular
    from training.realskin.measurements import read_measurements
    from training.realskin.report import measured_lab

    return measured_lab(read_measurements(), rough_specular())


def figure(path: Path, colours: dict[str, tuple[np.ndarray, np.ndarray]], measured: np.ndarray) -> None:
    """L* histograms and the a*-L* plane of each sampling, with the measured skin colours."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 1 + len(colours), figsize=(4.2 * (1 + len(colours)), 3.8))
    bins = np.linspace(0, 90, 46)
    for (name, (lab, _)), colour in zip(colours.items(), ("0.5", "tab:blue"), strict=False):
        axes[0].hist(lab[:, 0], bins=bins, histtype="step", lw=1.6, color=colour, density=True, label=name)
    axes[0].hist(measured[:, 0], bins=bins, color="tab:orange", alpha=0.5, density=True, label="measured skin (NIST)")
    axes[0].axvspan(0, 10, color="k", alpha=0.08)
    axes[0].set(xlabel="albedo L* (D65)", ylabel="density", title="lightness")
    axes[0].legend(fontsize=7)
    for ax, (name, (lab, rgb)) in zip(axes[1:], colours.items(), strict=True):
        ax.scatter(lab[:, 1], lab[:, 0], s=4, c=rgb, edgecolors="none")
        ax.scatter(measured[:, 1], measured[:, 0], s=14, facecolors="none", edgecolors="k", lw=0.6,
                   label="measured skin (NIST)")
        s = shares(lab)
        ax.set(xlabel="a*", ylabel="L*", xlim=(-5, 45), ylim=(0, 90),
               title=f"{name}\nL*<10: {s['near_black_L_lt_10']:.0%}, skin region: {s['skin_region']:.0%}")
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m training.realskin.distribution", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, help="figure (PNG)")
    p.add_argument("--tones", type=int, default=2000, help="tones of each sampling (default 2000)")
    p.add_argument("--photons", type=int, default=4000, help="photons per wavelength of the colour walk")
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--json", action="store_true", help="print JSON only")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    cache = Path(os.environ.get("SPECTRAL_SKIN_SSS_CACHE", Path.home() / ".cache" / "spectral_skin_sss"))
    traj = colour_walk(args.photons, args.seed, cache / "distribution")
    colours = {"uniform (before)": tone_colours(traj, training_tones(args.tones, 1, skin_weighted=False)),
               "skin-weighted (training)": tone_colours(traj, training_tones(args.tones, 1)),
               "skin-weighted (validation)": tone_colours(traj, validation_tones(args.tones, 2))}
    measured = measured_skin_lab()
    report = {name: shares(lab) for name, (lab, _) in colours.items()} | {"measured skin (NIST odd)": shares(measured)}
    report["settings"] = {"tones": args.tones, "photons": args.photons, "seed": args.seed,
                          "skin_region": SKIN_REGION}
    if args.out is not None:
        figure(args.out, {k: v for k, v in colours.items() if "validation" not in k}, measured)
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
