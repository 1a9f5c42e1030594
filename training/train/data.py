"""Reading the dataset splits and the mixture fits into tensors for training.

Dataset (``training.data.store``): ``DIR/{split}.h5`` with ``tone`` (N, 5), ``R_d`` (N, 376),
``albedo_rgb`` (N, 3) linear sRGB (D65), ``done`` (N,).  Only rows marked done are used.

Fits, in either of two layouts (both read; the first one found wins):

* ``DIR/fits_{split}.h5`` (``training.train.fits``): groups ``K1``, ``K2``, ``K3``, each holding
  ``alpha``, ``sigma_t`` (cm^-1), ``g``, ``weight`` of shape (N, K, 376), and root datasets ``tone``
  (N, 5), ``done`` (N,); row i is dataset row i.
* ``DIR/{split}_fits.h5`` (``python -m training fit --dataset``, ``training.fit.dataset``): flat
  datasets ``k{K}_alpha``, ``k{K}_g``, ``k{K}_sigma_t``, ``k{K}_weight`` (N, K, 376), ``index`` (N,)
  (row in the dataset split), ``tone``, ``done``.

The tones are checked against the dataset's.

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
    """The fits file of ``split`` in ``fits_dir`` (either layout; the grouped one if neither exists)."""
    for name in (f"fits_{split}.h5", f"{split}_fits.h5"):
        if (Path(fits_dir) / name).is_file():
            return Path(fits_dir) / name
    return Path(fits_dir) / f"fits_{split}.h5"


def _f32(a: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.ascontiguousarray(a, dtype=np.float32))


def sort_by_sigma_t(targets: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Reorder the K components of every (tone, wavelength) by increasing sigma_t; arrays (N, K, W)."""
    order = np.argsort(targets["sigma_t"], axis=1, kind="stable")
    return {k: np.take_along_axis(v, order, axis=1) for k, v in targets.items()}


def load_fits(path: Path, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(index (N,), tone (N, 5), done (N,), {alpha, g, sigma_t, weight: (N, K, W)}) of the K-component
    fits in a fits file of either layout (module docstring)."""
    with h5py.File(path, "r") as f:
        if f"K{k}" in f:
            g = f[f"K{k}"]
            keys = {n: n for n in FIT_FIELDS}
        else:
            g = f
            keys = {n: f"k{k}_{n}" for n in FIT_FIELDS}
        missing = [key for key in keys.values() if key not in g]
        if missing:
            raise ValueError(f"{path}: no K={k} fits ({missing} missing)")
        arrays = {n: np.asarray(g[key][:], dtype=np.float64) for n, key in keys.items()}
        tone = np.asarray(f["tone"][:], np.float64)
        index = np.asarray(f["index"][:], np.int64) if "index" in f else np.arange(len(tone))
        return index, tone, np.asarray(f["done"][:], bool), arrays


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
        index, ftone, fdone, arrays = load_fits(fpath, k)
        if index.min(initial=0) < 0 or index.max(initial=-1) >= len(tone):
            raise ValueError(f"{fpath}: row index outside {path}")
        if not np.allclose(ftone, tone[index], rtol=0, atol=1e-12):
            raise ValueError(f"{fpath} was fitted on other tones than {path}")
        fitted = np.zeros(len(tone), bool)
        fitted[index] = fdone
        keep &= fitted
        targets = {}
        for n, v in arrays.items():
            full = np.ones((len(tone), *v.shape[1:]))  # placeholder for unfitted rows (never used)
            full[index] = v
            targets[n] = full
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
