"""Profile fidelity on the whole validation split (paper §6 "Subsurface profile fidelity", Table 3 here).

* Joint-optimised fits: the per-tone, per-wavelength L_shape (log-profile RMSE, ``training.fit.loss``)
  that ``python -m training fit --dataset DIR --out FITS`` stored in ``FITS/validation_fits.h5`` (or its
  shards ``validation_fits.shard{i}of{n}.h5``; layout in ``training/fit/dataset.py``): mean over every
  finished tone and fitted wavelength, and per band.  The paper: K = 1 0.059 -> K = 2 0.019 (-67.3 %).
* The network (an addition): ``skin_decoder.onnx`` on each validation tone's true biophysical vector,
  its mixture's profile through the LUT against the tone's MC profile (``gate.lut_mixture_shape_error``,
  both the rendered weighting sum_k w_k R_k P_k / sum_k w_k R_k, which the fitter uses, and the
  paper's text's sum_k w_k P_k).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from exporters.constants import WAVELENGTHS_NM
from training.data import store
from training.paths import portable
from training.validate.metrics import BANDS, band_mask

KS = (1, 2, 3)


def fits_files(fits_dir: Path) -> list[Path]:
    """The validation fits file(s) in ``fits_dir`` (the merged file, else its shards)."""
    fits_dir = Path(fits_dir)
    whole = fits_dir / "validation_fits.h5"
    if whole.is_file():
        return [whole]
    shards = sorted(fits_dir.glob("validation_fits.shard*of*.h5"))
    if not shards:
        raise ValueError(f"no validation_fits.h5 (or shards) in {fits_dir}: run "
                         "`python -m training fit --dataset DIR --out FITS --split validation` first.")
    return shards


def _summary(values: np.ndarray, wavelength_nm: np.ndarray = WAVELENGTHS_NM) -> dict:
    """Mean over all, and per band, of per-wavelength errors (N, W) at ``wavelength_nm``."""
    out = {"mean": float(np.mean(values)), "median": float(np.median(values))}
    for band in BANDS:
        mask = band_mask(wavelength_nm, band)
        out[band] = float(np.mean(values[:, mask])) if mask.any() else None
    return out


def fit_profile_fidelity(fits_dir: Path, dataset: Path | None = None) -> dict:
    """Table 3 from the fits: per K the mean L_shape (all, per band), the K = 1 -> 2 and 2 -> 3 reductions,
    the number of tones, and the files' attributes.  With the ``dataset`` also the fitter's own summary
    (``training.fit.dataset.summarise``: the reflectance error, the MC noise floor of L_shape and the
    excess over it)."""
    files = fits_files(fits_dir)
    per_k: dict[int, list[np.ndarray]] = {}
    attrs, n_tones, n_total, widx = {}, 0, 0, None
    for path in files:
        with h5py.File(path, "r", locking=False) as f:
            done = f["done"][:]
            n_total += done.size
            n_tones += int(done.sum())
            widx = f["wavelength_index"][:] if "wavelength_index" in f else np.arange(f["k1_shape_rmse"].shape[1])
            ks = [int(k) for k in str(f.attrs.get("ks", "1,2,3")).split(",") if k]
            for k in ks:
                if f"k{k}_shape_rmse" in f:
                    per_k.setdefault(k, []).append(f[f"k{k}_shape_rmse"][:][done].astype(np.float64))
            attrs = {k: (v.item() if hasattr(v, "item") else str(v)) for k, v in f.attrs.items()}
    if n_tones == 0:
        raise ValueError(f"the validation fits in {fits_dir} hold no finished tone yet.")
    wl = WAVELENGTHS_NM[widx]
    table = {f"K{k}": _summary(np.concatenate(v), wl) for k, v in sorted(per_k.items())}
    for a, b in ((1, 2), (2, 3)):
        if f"K{a}" in table and f"K{b}" in table:
            table[f"K{a}_to_K{b}_reduction"] = {key: 1.0 - table[f"K{b}"][key] / table[f"K{a}"][key]
                                               for key in ("mean", *BANDS) if table[f"K{a}"][key]}
    out = {"fits": table, "n_tones": n_tones, "n_tones_in_files": n_total, "n_wavelengths": int(wl.size),
           "files": [portable(p) for p in files], "attrs": attrs, "fitter_summary": None}
    if dataset is not None:
        from training.fit.dataset import summarise

        out["fitter_summary"] = summarise(Path(dataset), files)
    return out


def network_profile_fidelity(dataset_dir: Path, lut, decoder: Path, *, max_tones: int | None = None,
                             chunk: int = 8, progress: bool = False) -> dict:
    """Mean LUT-profile shape error of the decoder's mixture on the validation split (see the docstring)."""
    from training.validate.gate import Params, lut_mixture_shape_error, mc_target
    from training.validate.mitsuba_scene import decode

    path = Path(dataset_dir) / "validation.h5"
    if not path.is_file():
        raise ValueError(f"{path} not found: pass the dataset folder of `python -m training dataset`.")
    with h5py.File(path, "r") as f:
        done = np.flatnonzero(f["done"][:])
        store.check_profile_wavelengths(f, np.arange(WAVELENGTHS_NM.size), "take the network's profile row from "
                                        "a split")
        photons = float(f.attrs["photons"])
        ds_attrs = {k: (v.item() if hasattr(v, "item") else str(v)) for k, v in f.attrs.items()}
    if done.size == 0:
        raise ValueError(f"{path} holds no finished tone.")
    rows = done if max_tones is None else done[:max_tones]
    all_rows = np.arange(WAVELENGTHS_NM.size)
    errs = {"fit": [], "rendered": []}
    starts = range(0, rows.size, chunk)
    if progress:
        from tqdm import tqdm

        starts = tqdm(starts, desc="network profiles (validation split)", unit="chunk")
    for start in starts:
        sel = rows[start:start + chunk]
        with h5py.File(path, "r") as f:
            tones = f["tone"][sel]
            prof = f["profile"][sel].astype(np.float64)
            se = f["profile_stderr"][sel].astype(np.float64)
            R = f["R_d"][sel].astype(np.float64)
        for i in range(len(sel)):
            target = mc_target(lut, prof[i], R[i], se[i], photons)
            m = decode(tones[i], decoder)
            p = Params(m.alpha, m.sigma_t, m.g, m.weight)
            for weighting in errs:
                errs[weighting].append(lut_mixture_shape_error(lut, p, target, all_rows, weighting))
    return {"nn_decoder": {w: _summary(np.stack(v)) for w, v in errs.items()}, "n_tones": int(rows.size),
            "dataset": portable(dataset_dir), "dataset_attrs": ds_attrs}
