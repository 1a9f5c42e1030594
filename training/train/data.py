"""Reading the dataset splits and the mixture fits into tensors for training.

Dataset (``training.data.store``): ``DIR/{split}.h5`` with ``tone`` (N, 5), ``R_d`` (N, 376),
``albedo_rgb`` (N, 3) linear sRGB (D65), ``done`` (N,).  Only rows marked done are used.

Fits (written by ``python -m training fit --dataset``, or by ``training.train.fits`` meanwhile):
``DIR/fits_{split}.h5`` with groups ``K1``, ``K2``, ``K3``, each holding ``alpha``, ``sigma_t`` (cm^-1),
``g``, ``weight`` of shape (N, K, 376), and root datasets ``tone`` (N, 5), ``done`` (N,).  Rows match
the dataset's rows (checked through ``tone``).

Component order: the fitter's component order is arbitrary (it depends on which start won), so the
targets are sorted per (tone, wavelength) by increasing sigma_t before training.  The network's
component k therefore learns "the k-th slowest-decaying medium", a well-defined function of the tone.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import torch

FIT_FIELDS: tuple[str, ...] = ("alpha", "g", "sigma_t", "weight")


@dataclass
class SplitData:
    """One split in memory (float32 tensors): tone (N, 5), R_d (N, W), albedo_rgb (N, 3), and the
    sorted fit targets (N, K, W) per name in ``FIT_FIELDS`` when fits were loaded."""

    tone: torch.Tensor
    R_d: torch.Tensor
    albedo_rgb: torch.Tensor
    targets: dict[str, torch.Tensor] | None = None
    photons: int = 0

    def __len__(self) -> int:
        return int(self.tone.shape[0])

    def to(self, device: str | torch.device) -> SplitData:
        t = None if self.targets is None else {k: v.to(device) for k, v in self.targets.items()}
        return SplitData(self.tone.to(device), self.R_d.to(device), self.albedo_rgb.to(device), t, self.photons)


def dataset_file(dataset_dir: Path, split: str) -> Path:
    return Path(dataset_dir) / f"{split}.h5"


def fits_file(fits_dir: Path, split: str) -> Path:
    return Path(fits_dir) / f"fits_{split}.h5"


def _f32(a: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.ascontiguousarray(a, dtype=np.float32))


def sort_by_sigma_t(targets: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Reorder the K components of every (tone, wavelength) by increasing sigma_t; arrays (N, K, W)."""
    order = np.argsort(targets["sigma_t"], axis=1, kind="stable")
    return {k: np.take_along_axis(v, order, axis=1) for k, v in targets.items()}


def load_fits(path: Path, k: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(tone (N, 5), done (N,), {alpha, g, sigma_t, weight: (N, K, W)}) of group ``K{k}`` of a fits file."""
    with h5py.File(path, "r") as f:
        group = f"K{k}"
        if group not in f:
            raise ValueError(f"{path} has no group {group!r} (groups: {sorted(f.keys())})")
        g = f[group]
        missing = [n for n in FIT_FIELDS if n not in g]
        if missing:
            raise ValueError(f"{path}:{group} lacks {missing}")
        arrays = {n: np.asarray(g[n][:], dtype=np.float64) for n in FIT_FIELDS}
        return np.asarray(f["tone"][:], np.float64), np.asarray(f["done"][:], bool), arrays


def load_split(dataset_dir: Path, split: str, fits_dir: Path | None = None, k: int = 3) -> SplitData:
    """Load the done rows of ``split`` (and, with ``fits_dir``, the rows fitted too, with targets)."""
    path = dataset_file(dataset_dir, split)
    if not path.is_file():
        raise ValueError(f"no dataset split {path}: run `python -m training dataset` first")
    with h5py.File(path, "r") as f:
        done = np.asarray(f["done"][:], bool)
        tone = np.asarray(f["tone"][:], np.float64)
        R_d = np.asarray(f["R_d"][:], np.float64)
        rgb = np.asarray(f["albedo_rgb"][:], np.float64)
        photons = int(f.attrs.get("photons", 0))
    keep = done.copy()
    targets = None
    if fits_dir is not None:
        fpath = fits_file(fits_dir, split)
        if not fpath.is_file():
            raise ValueError(f"no fits {fpath}: run `python -m training fit --dataset` (or training.train.fits)")
        ftone, fdone, arrays = load_fits(fpath, k)
        if ftone.shape != tone.shape or not np.allclose(ftone, tone, rtol=0, atol=1e-12):
            raise ValueError(f"{fpath} was fitted on other tones than {path}")
        keep &= fdone
        targets = arrays
    if not keep.any():
        raise ValueError(f"{path}: no usable rows (simulated{' and fitted' if fits_dir else ''})")
    for name, arr in (("R_d", R_d[keep]), ("albedo_rgb", rgb[keep])):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{path}: non-finite {name}")
    t = None
    if targets is not None:
        kept = sort_by_sigma_t({n: v[keep] for n, v in targets.items()})
        for n, v in kept.items():
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{fits_file(fits_dir, split)}: non-finite {n} in group K{k}")
        t = {n: _f32(v) for n, v in kept.items()}
    return SplitData(_f32(tone[keep]), _f32(R_d[keep]), _f32(rgb[keep]), t, photons)
