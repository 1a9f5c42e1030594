"""``python -m training swatches --out FILE.png``: simulated colours of the representative and outlier tones."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from exporters.cli_io import OneLineParser
from exporters.colorimetry import spectrum_to_srgb
from training.commands.options import atomic_file, check_output_file, command, count
from training.skin.tones import ToneSet, load_tones


def simulate_spectra(tones: np.ndarray, photons: int, seed: int, device: str = "cpu") -> np.ndarray:
    """Total diffuse reflectance R_d (N, 376) of each tone by Monte Carlo (diffuse illumination)."""
    from training.data.simulate import simulate_direct

    return simulate_direct(tones, photons, seed, device)["R_d"]


def plot_swatches(tone_set: ToneSet, srgb: np.ndarray, out: Path, title: str) -> None:
    """One square per tone, representative tones on the first row, outliers on the second."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = ["representative", "outlier"]
    fig, axes = plt.subplots(2, 10, figsize=(13, 4.4))
    for row, kind in enumerate(kinds):
        members = [i for i, k in enumerate(tone_set.kinds) if k == kind]
        for col, ax in enumerate(axes[row]):
            ax.set_axis_off()
            if col >= len(members):
                continue
            i = members[col]
            ax.imshow(np.clip(srgb[i], 0, 1)[None, None, :])
            f_mel, f_blood = tone_set.values[i, 0], tone_set.values[i, 1]
            ax.set_title(f"{tone_set.names[i]}\nmel {f_mel:.3g}\nblood {f_blood:.3g}", fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    with atomic_file(out) as f:
        fig.savefig(f, dpi=120, format=out.suffix.lstrip(".").lower())
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training swatches", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write")
    parser.add_argument("--photons", type=count, default=2000, help="photons per wavelength per tone")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=count, default=1,
                        help="torch CPU threads (1 is fastest for the walker on a busy 2-core machine)")
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    return parser


@command("swatches")
def main(argv: list[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_output_file(args.out, "--out", suffixes=(".png",))
    import torch

    torch.set_num_threads(max(1, args.threads))
    tone_set = load_tones()
    spectra = simulate_spectra(tone_set.values, args.photons, args.seed, args.device)
    srgb = spectrum_to_srgb(spectra, "D65")
    plot_swatches(tone_set, srgb, args.out,
                  f"Monte Carlo skin colours (D65, sRGB), {args.photons} photons per wavelength")
    for name, rgb in zip(tone_set.names, srgb, strict=True):
        print(f"{name}  sRGB {np.round(np.clip(rgb, 0, 1) * 255).astype(int).tolist()}")
    print(f"wrote {args.out}")
    return 0
