"""Fit every tone x wavelength of a dataset split (``python -m training fit --dataset DIR``).

Input: the split files of ``python -m training dataset`` (``DIR/train.h5``, ``DIR/validation.h5``;
training/data/store.py), which must be complete.  Output, per split, ``OUT/<split>_fits.h5`` (or
``<split>_fits.shard{i}of{n}.h5`` with ``--shard i/n``), one row per tone of the shard:

    index (N,) position in the split; tone (N, 5);
    k{K}_alpha, k{K}_g, k{K}_sigma_t [cm^-1], k{K}_weight: (N, K, 376) float32;
    k{K}_shape_rmse, k{K}_refl_rel_err, k{K}_joint: (N, 376) float32;
    done (N,) bool; attributes: ks, method, lut (path), lut_sha256, dataset attributes.

Resumable: tones are fitted a chunk at a time and marked done; rerunning the same command skips them,
and a file made with other settings is never overwritten (ValueError).  Shards take every n-th tone.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import torch
from tqdm import tqdm

from exporters.constants import anisotropy
from exporters.maps import sha256_file
from training.fit.optimize import fit_schedule
from training.sim.lut_interp import LookupTables

SPLITS = ("train", "validation")



def out_path(out: Path, split: str, shard: tuple[int, int]) -> Path:
    i, n = shard
    return out / (f"{split}_fits.h5" if n == 1 else f"{split}_fits.shard{i}of{n}.h5")


def _create(path: Path, tones: np.ndarray, index: np.ndarray, ks: tuple[int, ...], w: int, attrs: dict) -> None:
    tmp = path.with_suffix(".tmp")
    n = len(index)
    with h5py.File(tmp, "w") as f:
        f.create_dataset("index", data=index)
        f.create_dataset("tone", data=tones)
        f.create_dataset("done", data=np.zeros(n, bool))
        for k in ks:
            for name in ("alpha", "g", "sigma_t", "weight"):
                f.create_dataset(f"k{k}_{name}", shape=(n, k, w), dtype="f4")
            for name in ("shape_rmse", "refl_rel_err", "joint"):
                f.create_dataset(f"k{k}_{name}", shape=(n, w), dtype="f4")
        f.attrs.update(attrs)
    tmp.rename(path)


def _check(path: Path, index: np.ndarray, attrs: dict) -> None:
    with h5py.File(path, "r") as f:
        for key, val in attrs.items():
            if str(f.attrs.get(key)) != str(val):
                raise ValueError(f"{path} was made with {key}={f.attrs.get(key)!r}, not {val!r}: use another --out")
        if not np.array_equal(f["index"][:], index):
            raise ValueError(f"{path} holds other tones than this run: use another --out")


def fit_split(
    dataset: Path,
    split: str,
    lut: LookupTables,
    lut_path: Path,
    ks: tuple[int, ...],
    out: Path,
    *,
    method: str = "lm",
    shard: tuple[int, int] = (0, 1),
    chunk_tones: int = 4,
    steps: dict[str, int] | None = None,
    progress: bool = True,
) -> Path:
    """Fit one split of ``dataset`` into ``out`` (see the module docstring); returns the output path."""
    src = dataset / f"{split}.h5"
    if not src.is_file():
        raise ValueError(f"{src} not found (run `python -m training dataset` and merge its shards first)")
    with h5py.File(src, "r") as f:
        if not f["done"][:].all():
            raise ValueError(f"{src} is incomplete: finish the dataset first")
        n_all = f["tone"].shape[0]
        tones_all = f["tone"][:]
        wl = f["wavelength_nm"][:]
        edges = f["r_edges_cm"][:]
        photons = float(f.attrs["photons"])
        src_attrs = {f"dataset_{k}": str(v) for k, v in f.attrs.items()}
    i, n = shard
    index = np.arange(n_all)[i::n]
    attrs = {
        "ks": ",".join(map(str, ks)),
        "method": method,
        "lut_sha256": sha256_file(lut_path),
        "shard": f"{i}/{n}",
        **src_attrs,
    }
    path = out_path(out, split, shard)
    out.mkdir(parents=True, exist_ok=True)
    if path.exists():
        _check(path, index, attrs)
    else:
        _create(path, tones_all[index], index, ks, len(wl), {**attrs, "lut": str(lut_path)})
    with h5py.File(path, "r") as f:
        todo = np.flatnonzero(~f["done"][:])
    dt, dev = lut.P.dtype, lut.P.device
    g0 = torch.tensor(anisotropy(wl), dtype=dt, device=dev)
    e = torch.tensor(edges, dtype=dt, device=dev)
    bar = tqdm(total=len(index), initial=len(index) - len(todo), desc=f"fit {split} {i}/{n}", disable=not progress)
    for start in range(0, len(todo), chunk_tones):
        rows = todo[start : start + chunk_tones]
        with h5py.File(src, "r") as f:
            prof = np.stack([f["profile"][index[r]] for r in rows]).astype(np.float64)  # (T, W, 512)
            R = np.stack([f["R_d"][index[r]] for r in rows]).astype(np.float64)  # (T, W)
        T, W = R.shape
        fits = fit_schedule(
            lut,
            torch.tensor(prof.reshape(T * W, -1), dtype=dt, device=dev),
            torch.tensor(R.reshape(-1), dtype=dt, device=dev),
            e,
            photons,
            g_init=g0.repeat(T),
            ks=ks,
            method=method,
            steps=steps,
        )
        with h5py.File(path, "r+") as f:
            for k in ks:
                fk, m = fits[k], fits[k].mixture
                for name, val in (("alpha", m.alpha), ("g", m.g), ("sigma_t", m.sigma_t), ("weight", m.w)):
                    arr = val.reshape(T, W, k).permute(0, 2, 1).cpu().numpy().astype(np.float32)
                    for j, r in enumerate(rows):
                        f[f"k{k}_{name}"][r] = arr[j]
                for name in ("shape_rmse", "refl_rel_err", "joint"):
                    arr = getattr(fk, name).reshape(T, W).cpu().numpy().astype(np.float32)
                    for j, r in enumerate(rows):
                        f[f"k{k}_{name}"][r] = arr[j]
            done = f["done"][:]
            done[rows] = True
            f["done"][:] = done
            f.flush()
        bar.update(len(rows))
    bar.close()
    return path
