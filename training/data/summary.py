"""``python -m training dataset --summary --out DIR``: what a built dataset holds, as JSON and a figure.

summary.json: per split the tone count, photons, estimator, simulation time (walk + reweighting), size
on disk; summary.png: the colour gamut of the tones (CIE a*b* and L*b* under D65, each dot in its own
colour) and R_d spectra of the ten representative tones (``training/skin/tones.csv``, t_epi snapped to
the dataset's levels), reweighted from the training split's walk.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from exporters.colorimetry import linear_srgb_to_lab, srgb_encode
from exporters.constants import WAVELENGTHS_NM
from training.data.build import SPLITS
from training.data.reweight import Trajectories, reweight, walk_seconds
from training.data.sampling import quantise_thickness
from training.skin.tones import load_tones


def _folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) if path.exists() else 0


def split_summary(out: Path, split: str) -> dict:
    """Counts, settings, times and sizes of one finished split in ``out``."""
    path = out / f"{split}.h5"
    with h5py.File(path, "r") as f:
        attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
        done = int(f["done"][:].sum())
    walk_dir = out / f"trajectories_{split}"
    walk_s = walk_seconds(walk_dir)
    return {
        "tones": done, "of": int(attrs["n_total"]), "photons": int(attrs["photons"]), "method": attrs["method"],
        "reweight_or_simulate_s": float(attrs.get("seconds", float("nan"))), "walk_s": walk_s,
        "file_bytes": path.stat().st_size + _folder_bytes(out / f"{split}.blocks"),  # a blocked split's data too
        "walk_bytes": _folder_bytes(walk_dir),
    }


def write_summary(out: Path) -> dict:
    """Write ``out``/summary.json and summary.png for the splits present; returns the JSON record."""
    record = {split: split_summary(out, split) for split in SPLITS if (out / f"{split}.h5").exists()}
    if not record:
        raise ValueError(f"no split files in {out}: build the dataset first.")
    (out / "summary.json").write_text(json.dumps(record, indent=1))
    albedo = np.concatenate([h5py.File(out / f"{s}.h5", "r")["albedo_rgb"][:] for s in record])
    spectra = None
    walk_dir = out / "trajectories_train"
    if walk_dir.exists() and any(walk_dir.glob("chunk*.npz")):
        traj = Trajectories.concat([Trajectories.load(p) for p in sorted(walk_dir.glob("chunk*.npz"))])
        reps = load_tones().select("representative")
        spectra = (reps.names, reweight(traj, quantise_thickness(reps.values))["R_d"], traj.photons)
    _plot(out / "summary.png", albedo, spectra, record)
    return record


def _plot(path: Path, albedo: np.ndarray, spectra, record: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lab = linear_srgb_to_lab(albedo)
    colours = np.clip(srgb_encode(np.clip(albedo, 0, 1)), 0, 1)
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    axes[0].scatter(lab[:, 1], lab[:, 2], c=colours, s=4)
    axes[0].set(xlabel="a*", ylabel="b*", title="tone gamut (CIE Lab, D65)")
    axes[1].scatter(lab[:, 2], lab[:, 0], c=colours, s=4)
    axes[1].set(xlabel="b*", ylabel="L*", title="lightness vs yellowness")
    if spectra is not None:
        names, r_d, photons = spectra
        for name, r in zip(names, r_d, strict=True):
            axes[2].plot(WAVELENGTHS_NM, r, label=name)
        axes[2].set(xlabel="wavelength (nm)", ylabel="R_d", ylim=(0, None),
                    title=f"representative tones, reweighted ({photons:,} photons)")
        axes[2].legend(fontsize=7, ncol=2)
    counts = ", ".join(f"{split} {v['tones']:,}" for split, v in record.items())
    fig.suptitle(f"skin-tone dataset: {counts} tones")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
