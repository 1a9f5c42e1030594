"""A tiny synthetic dataset + fits + LUT in the real file formats, for tests and benchmarks ONLY.

NOT PHYSICS.  The spectra and mixture targets are smooth made-up functions of the tone, so that the
training machinery (stages, checkpoints, resume, export) can be exercised in seconds without the
Monte Carlo simulator.  The LUT is the analytic diffusion-dipole table of ``training.sim.dipole``.
Files are written with the dataset's own store (``training.data.store``) and the fits layout read by
``training.train.data``.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import torch

from exporters.colorimetry import spectrum_to_linear_srgb
from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.data import store
from training.data.sampling import training_tones, validation_tones
from training.fit.mixture import mix
from training.sim.dipole import dipole_lut
from training.sim.lut_interp import LookupTables, bin_centres


def toy_spectra(tones: np.ndarray) -> np.ndarray:
    """Made-up smooth reflectance (N, 376) in (0, 0.7): darker with melanin, a dip near 560 nm with blood."""
    x = (WAVELENGTHS_NM[None, :] - 600.0) / 80.0
    base = 0.6 / (1.0 + np.exp(-x))
    mel = np.exp(-4.0 * tones[:, :1] * (700.0 / WAVELENGTHS_NM[None, :]) ** 3)
    blood = 1.0 - 2.0 * tones[:, 1:2] * np.exp(-(((WAVELENGTHS_NM[None, :] - 560.0) / 30.0) ** 2))
    return np.clip(0.02 + base * mel * blood, 1e-3, 0.9)


def toy_targets(tones: np.ndarray, k: int) -> dict[str, np.ndarray]:
    """Made-up mixture targets (N, K, 376): alpha near 0.9-0.99, g 0.8, sigma_t 10^(1.5..3.5), w by k."""
    n, w = len(tones), WAVELENGTHS_NM.size
    lam = (WAVELENGTHS_NM - 250.0) / 750.0
    ks = np.arange(k)[None, :, None]
    alpha = 0.9 + 0.09 * lam[None, None, :] * (1 - tones[:, None, :1]) * np.ones((n, k, w))
    g = np.full((n, k, w), 0.8)
    sigma_t = 10.0 ** (1.5 + ks + 0.5 * tones[:, None, 1:2]) * np.ones((n, k, w))
    logits = -ks + tones[:, None, 3:4]
    weight = np.exp(logits) / np.exp(logits).sum(1, keepdims=True) * np.ones((n, k, w))
    return {"alpha": alpha, "g": g, "sigma_t": sigma_t, "weight": weight}


def toy_profiles(lut: LookupTables, tones: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Radial profiles (N, 376, 512) cm^-2 whose shape is the rendered K = 3 mixture of ``toy_targets``
    (``mixture.mix`` through ``lut``) and whose integral is the toy reflectance ``R`` (N, 376)."""
    t = {k: torch.as_tensor(v).transpose(1, 2) for k, v in toy_targets(tones, 3).items()}  # (N, 376, K)
    p_k = lut.profile(bin_centres(torch.tensor(R_EDGES_CM)), t["alpha"], t["g"], t["sigma_t"])
    p_hat, _ = mix(p_k, lut.reflectance(t["alpha"], t["g"]), t["weight"])
    return (p_hat * torch.as_tensor(R)[..., None]).numpy()


def write_toy(root: Path, n_train: int = 32, n_validation: int = 8) -> tuple[Path, Path, Path]:
    """Write ``root/dataset/{train,validation}.h5``, ``root/fits/{split}_fits.h5`` and ``root/lut.npz``.

    Returns (dataset_dir, fits_dir, lut_path).  The profiles have the shape of the K = 3 targets'
    mixture (``toy_profiles``), with standard errors of 1 %.
    """
    data_dir, fits_dir = root / "dataset", root / "fits"
    data_dir.mkdir(parents=True, exist_ok=True)
    fits_dir.mkdir(parents=True, exist_ok=True)
    lut_path = root / "lut.npz"
    np.savez(lut_path, **dipole_lut())
    lut = LookupTables.load(lut_path)
    for split, tones in (("train", training_tones(n_train, 1)), ("validation", validation_tones(n_validation, 2))):
        path = data_dir / f"{split}.h5"
        store.create(path, tones, np.arange(len(tones)), {"preset": "toy", "split": split, "photons": 0,
                                                          "seed": 0, "shard": "0/1", "method": "toy",
                                                          "n_total": len(tones), "created_by": "training.train.toy"})
        R = toy_spectra(tones)
        rows = np.arange(len(tones))
        profile = toy_profiles(lut, tones, R)
        store.write_rows(path, rows, {"R_d": R, "R_d_stderr": np.zeros_like(R), "profile": profile,
                                      "profile_stderr": 0.01 * profile,
                                      "albedo_rgb": spectrum_to_linear_srgb(R, "D65")})
        # the fitter's layout; like a `fit --max-tones --wavelength-stride 2` run: the training split's
        # last quarter of tones is not fitted and the targets are at every 2nd wavelength
        n_fit = len(tones) - (len(tones) // 4 if split == "train" else 0)
        widx = np.arange(0, R.shape[1], 2)
        with h5py.File(fits_dir / f"{split}_fits.h5", "w") as f:
            f.create_dataset("index", data=np.arange(n_fit))
            f.create_dataset("tone", data=tones[:n_fit])
            f.create_dataset("done", data=np.ones(n_fit, bool))
            f.create_dataset("wavelength_index", data=widx)
            for k in (1, 2, 3):
                for name, arr in toy_targets(tones[:n_fit], k).items():
                    f.create_dataset(f"k{k}_{name}", data=arr[..., widx].astype(np.float32))
    return data_dir, fits_dir, lut_path
