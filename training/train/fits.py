"""Stopgap: fit a whole dataset split with ``training.fit`` into the fits file the trainer reads.

``python -m training fit --dataset`` (owned by the fitting part) is the real command; until it exists,
the trainer's first model is made with this module:

    python -m training.train.fits --dataset DIR --lut LUT.npz --out DIR [--split train|validation|both]

It calls ``training.fit.optimize.fit_schedule`` (Levenberg-Marquardt by default) on every
(tone, wavelength) of the split and writes ``DIR/fits_{split}.h5`` in the format of
``training.train.data`` (groups K1..K3 with alpha, sigma_t (cm^-1), g, weight (N, K, 376),
shape_rmse and refl_rel_err (N, 376); root ``tone``, ``done``).  Resumable: tones are fitted a chunk
at a time and marked done; a killed run continues where it stopped.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import torch
from tqdm import tqdm

from exporters.constants import N_WAVELENGTHS, anisotropy
from training.fit.optimize import fit_schedule
from training.sim.lut_interp import LookupTables
from training.train.data import dataset_file, fits_file

KS: tuple[int, ...] = (1, 2, 3)


def _create(path: Path, tone: np.ndarray, attrs: dict) -> None:
    tmp = path.with_suffix(".tmp")
    n = len(tone)
    with h5py.File(tmp, "w") as f:
        f.create_dataset("tone", data=tone)
        f.create_dataset("done", data=np.zeros(n, bool))
        for k in KS:
            g = f.create_group(f"K{k}")
            for name in ("alpha", "sigma_t", "g", "weight"):
                g.create_dataset(name, shape=(n, k, N_WAVELENGTHS), dtype="f4")
            for name in ("shape_rmse", "refl_rel_err"):
                g.create_dataset(name, shape=(n, N_WAVELENGTHS), dtype="f4")
        f.attrs.update(attrs)
    tmp.rename(path)


def fit_split(dataset_dir: Path, split: str, lut: LookupTables, out_dir: Path, *, method: str = "lm",
              chunk_tones: int = 2, bin_stride: int = 1, progress: bool = True) -> Path:
    """Fit every simulated tone of ``split`` that is not fitted yet; returns the fits file.

    ``bin_stride`` > 1 fits on every n-th radial bin (faster; the stored metrics use all bins).
    """
    src = dataset_file(dataset_dir, split)
    with h5py.File(src, "r") as f:
        tone = np.asarray(f["tone"][:], np.float64)
        sim_done = np.asarray(f["done"][:], bool)
        photons = int(f.attrs["photons"])
        r_edges = np.asarray(f["r_edges_cm"][:], np.float64)
        wl = np.asarray(f["wavelength_nm"][:], np.float64)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = fits_file(out_dir, split)
    attrs = {"dataset": str(src), "method": method, "photons": photons, "bin_stride": bin_stride,
             "created_by": "training.train.fits"}
    if not path.exists():
        _create(path, tone, attrs)
    with h5py.File(path, "r") as f:
        if not np.array_equal(f["tone"][:], tone):
            raise ValueError(f"{path} holds other tones than {src}: use another --out")
        todo = np.flatnonzero(sim_done & ~f["done"][:])
    dt, dev = lut.P.dtype, lut.P.device
    g0 = torch.tensor(anisotropy(wl), dtype=dt, device=dev)
    bar = tqdm(total=int(sim_done.sum()), initial=int(sim_done.sum()) - len(todo), desc=f"fit {split}",
               disable=not progress)
    for start in range(0, len(todo), chunk_tones):
        rows = todo[start : start + chunk_tones]
        t0 = time.perf_counter()
        with h5py.File(src, "r") as f:
            prof = np.stack([f["profile"][r] for r in rows]).reshape(-1, r_edges.size - 1)
            R = np.stack([f["R_d"][r] for r in rows]).reshape(-1)
        fits = fit_schedule(lut, torch.tensor(prof, dtype=dt, device=dev), torch.tensor(R, dtype=dt, device=dev),
                            torch.tensor(r_edges, dtype=dt, device=dev), float(photons),
                            g_init=g0.repeat(len(rows)), ks=KS, method=method, bin_stride=bin_stride)
        with h5py.File(path, "r+") as f:
            for k in KS:
                m, grp = fits[k].mixture, f[f"K{k}"]
                for name, val in (("alpha", m.alpha), ("sigma_t", m.sigma_t), ("g", m.g), ("weight", m.w)):
                    arr = val.detach().cpu().numpy().reshape(len(rows), N_WAVELENGTHS, k).transpose(0, 2, 1)
                    if not np.all(np.isfinite(arr)):
                        raise ValueError(f"fit produced non-finite {name} for rows {rows.tolist()}")
                    for i, r in enumerate(rows):
                        grp[name][r] = arr[i]
                for name in ("shape_rmse", "refl_rel_err"):
                    arr = getattr(fits[k], name).detach().cpu().numpy().reshape(len(rows), N_WAVELENGTHS)
                    for i, r in enumerate(rows):
                        grp[name][r] = arr[i]
            done = f["done"][:]
            done[rows] = True
            f["done"][:] = done
            f.flush()
        bar.set_postfix(s_per_tone=f"{(time.perf_counter() - t0) / len(rows):.1f}")
        bar.update(len(rows))
    bar.close()
    return path


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m training.train.fits", description=__doc__.splitlines()[0])
    p.add_argument("--dataset", type=Path, required=True)
    p.add_argument("--lut", type=Path, required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--split", choices=("train", "validation", "both"), default="both")
    p.add_argument("--method", choices=("lm", "paper"), default="lm")
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--seed", type=int, default=0, help="torch seed (the fit itself is deterministic)")
    p.add_argument("--bin-stride", type=int, default=1, help="fit on every n-th radial bin (speed)")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (small problems: 1 is fastest)")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)
    torch.manual_seed(args.seed)
    torch.set_num_threads(max(1, args.threads))
    try:
        if args.device == "cuda" and not torch.cuda.is_available():
            raise ValueError("--device cuda: no CUDA device available")
        lut = LookupTables.load(args.lut, dtype=torch.float64, device=args.device)
        for split in ("train", "validation") if args.split == "both" else (args.split,):
            print(fit_split(args.dataset, split, lut, args.out, method=args.method, bin_stride=args.bin_stride,
                            progress=not args.no_progress))
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
