"""``python -m training fit``: fit mixtures of K homogeneous media to simulated tones (docs/contracts.md §2).

    python -m training fit --tone-file TONE.npz --lut LUT.npz --k 1,2,3 --json
        prints {"fits": [{"K": 1, "shape_rmse": ..., "refl_rel_err": ...}, ...]}: means over the
        wavelengths of the tone file (376 for ``python -m training simulate``).
    python -m training fit --dataset DIR --lut LUT.npz --k 1,2,3 --out DIR [--split train,validation]
        [--shard I/N] [--wavelength-stride S] [--anchor-every A] [--continuity sweep|anchors] [--max-tones M]
        [--select first|lightness] [--reuse DIR]:
        every tone x wavelength of the dataset's complete split files into OUT/<split>_fits.h5
        (training/fit/dataset.py); resumable, shardable; ``--scheduler local:N | tcp://HOST:PORT | slurm``
        fits the chunks on a Dask cluster instead (``training.cluster``), into the same files.
    python -m training fit --dataset DIR --out DIR --summary: mean errors per split, K and band of those
        fits, with the Monte Carlo noise floor of the shape error; writes OUT/summary.json.

The LUT is ``--lut`` or, if not given, the file named by the environment variable SKIN_SSS_LUT.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from exporters.cli_io import OneLineParser
from exporters.constants import anisotropy
from training.cluster import engine
from training.commands.options import (
    atomic_file,
    check_input,
    check_output_file,
    check_output_folder,
    command,
    count,
    error_status,
    non_negative_int,
    output_lock,
    parse_shard,
    shard_part,
)
from training.fit.optimize import fit_schedule
from training.sim.lut_interp import LookupTables

TONE_KEYS = ("wavelength_nm", "R_d", "r_edges_cm", "profile", "photons")


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="python -m training fit",
        description="Fit mixtures of K homogeneous media to MC profiles through the lookup tables (paper §4).",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--tone-file", type=Path, help="output of `python -m training simulate` (.npz)")
    src.add_argument("--dataset", type=Path, help="dataset folder of `python -m training dataset`")
    p.add_argument("--lut", type=Path, default=None, help="LUT .npz of `python -m training lut` (or $SKIN_SSS_LUT)")
    p.add_argument("--k", default="1,2,3", help="comma-separated K values among 1, 2, 3 (default 1,2,3)")
    p.add_argument(
        "--method",
        choices=("lm", "paper"),
        default="lm",
        help="lm: Levenberg-Marquardt (default, fast); paper: the paper's Adam schedule",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="--tone-file: write the fitted parameters to this .npz; --dataset: output folder",
    )
    p.add_argument("--split", default="train,validation", help="--dataset: splits to fit (default both)")
    p.add_argument("--shard", type=parse_shard, default=(0, 1), help="--dataset: fit tones i, i+n, i+2n, ... (I/N)")
    p.add_argument("--chunk-tones", type=count, default=16, help="--dataset: tones fitted per batch")
    p.add_argument("--wavelength-stride", type=count, default=1,
                   help="--dataset: fit every n-th wavelength (default 1: all 376)")
    p.add_argument("--anchor-every", type=non_negative_int, default=0,
                   help="--dataset: full schedule at every n-th fitted wavelength, warm starts from the nearest "
                        "one elsewhere (default 0: full schedule everywhere; 12 is ~4x faster, same losses)")
    p.add_argument("--continuity", choices=("sweep", "anchors"), default=None,
                   help="--dataset: sweep = each wavelength warm-started from the previous one, components matched "
                        "along wavelength (default with --method lm); anchors = from the nearest anchor "
                        "(the older fits; the default with --method paper)")
    p.add_argument("--max-tones", type=count, default=None, help="--dataset: fit n tones of each split (see --select)")
    p.add_argument("--select", choices=("first", "lightness"), default="first",
                   help="--dataset with --max-tones: the first n tones (default), or an equal share of each "
                        "5-unit band of the albedo's L* (more light skin than the split holds)")
    p.add_argument("--reuse", type=Path, default=None,
                   help="--dataset: copy the tones that the fits in this folder hold with the same settings "
                        "instead of fitting them again (e.g. to extend a --max-tones run to the whole split)")
    p.add_argument("--refl-loss", choices=("relative", "paper"), default="relative",
                   help="reflectance term: ((R_hat - R)/R)^2 (default) or the paper's (R_hat - R)^2")
    p.add_argument("--summary", action="store_true",
                   help="--dataset: do not fit; print (and write OUT/summary.json) the mean errors per split, K "
                        "and band of the fits in --out, with the MC noise floor of the shape error")
    p.add_argument("--no-progress", action="store_true")
    engine.add_option(p)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--seed", type=int, default=0, help="torch seed (the fit itself is deterministic)")
    p.add_argument(
        "--threads",
        type=count,
        default=1,
        help="torch CPU threads (default 1: the problems are small; more threads mostly contend)",
    )
    return p


def _parse_k(text: str) -> tuple[int, ...]:
    try:
        ks = tuple(sorted({int(x) for x in text.split(",") if x.strip()}))
    except ValueError:
        raise ValueError(f"--k must be comma-separated integers, got {text!r}") from None
    if not ks or any(k not in (1, 2, 3) for k in ks):
        raise ValueError(f"--k values must be among 1, 2, 3, got {text!r}")
    return ks


def load_tone(path: Path) -> dict[str, np.ndarray]:
    """Read a tone file and check its keys and shapes (ValueError with the problem otherwise)."""
    with np.load(path) as d:
        missing = [k for k in TONE_KEYS if k not in d]
        if missing:
            raise ValueError(f"{path}: not a tone file of `python -m training simulate`, missing {missing}")
        out = {k: np.asarray(d[k], dtype=np.float64) for k in TONE_KEYS}
        if "profile_stderr" in d:  # written by `simulate`; chooses the bins of the loss (fit/loss.py)
            out["profile_stderr"] = np.asarray(d["profile_stderr"], dtype=np.float64)
    w, nb = out["wavelength_nm"].shape[0], out["r_edges_cm"].shape[0] - 1
    if out["R_d"].shape != (w,) or out["profile"].shape != (w, nb):
        raise ValueError(f"{path}: inconsistent shapes R_d {out['R_d'].shape}, profile {out['profile'].shape}")
    return out


def fit_tone_file(
    tone_path: Path, lut: LookupTables, ks: tuple[int, ...], method: str = "lm", relative_refl: bool = True
) -> tuple[list[dict], dict]:
    """Fit one tone file; returns (summary rows per K, arrays of fitted parameters per K)."""
    d = load_tone(tone_path)
    dt, dev = lut.P.dtype, lut.P.device
    fits = fit_schedule(
        lut,
        torch.tensor(d["profile"], dtype=dt, device=dev),
        torch.tensor(d["R_d"], dtype=dt, device=dev),
        torch.tensor(d["r_edges_cm"], dtype=dt, device=dev),
        float(d["photons"]),
        g_init=torch.tensor(anisotropy(d["wavelength_nm"]), dtype=dt, device=dev),
        ks=ks,
        method=method,
        stderr=None if d.get("profile_stderr") is None else torch.tensor(d["profile_stderr"], dtype=dt, device=dev),
        relative_refl=relative_refl,
    )
    rows, arrays = [], {"wavelength_nm": d["wavelength_nm"]}
    for k in ks:
        f = fits[k]
        rows.append(
            {
                "K": k,
                "shape_rmse": float(f.shape_rmse.mean()),
                "refl_rel_err": float(f.refl_rel_err.mean()),
                "joint_loss": float(f.joint.mean()),
                "seconds": round(f.seconds, 3),
            }
        )
        m = f.mixture
        for name in ("alpha", "g", "sigma_t", "w"):
            arrays[f"k{k}_{name}"] = getattr(m, name).T.cpu().numpy()  # (K, W)
        arrays[f"k{k}_shape_rmse"] = f.shape_rmse.cpu().numpy()
        arrays[f"k{k}_refl_rel_err"] = f.refl_rel_err.cpu().numpy()
    return rows, arrays


def _fit_dataset(args: argparse.Namespace, ks: tuple[int, ...], lut_path: Path) -> int:
    from training.fit.dataset import SPLITS, fit_split

    if args.out is None:
        raise ValueError("--dataset needs --out DIR")
    splits = [s for s in args.split.split(",") if s]
    bad = [s for s in splits if s not in SPLITS]
    if bad or not splits:
        raise ValueError(f"--split must name some of {SPLITS}, got {args.split!r}")
    if args.chunk_tones < 1:
        raise ValueError("--chunk-tones must be >= 1")
    if args.summary:
        return _summary(args.dataset, args.out, splits)
    shard = args.shard
    if args.scheduler is not None and shard != (0, 1):
        raise ValueError("--shard and --scheduler exclude each other: the cluster takes every chunk")
    # on a cluster the workers load the LUT
    lut = None if args.scheduler else LookupTables.load(lut_path, dtype=torch.float64, device=args.device)
    shared = [args.dataset.resolve(), lut_path.resolve()]  # what the workers read
    args.out.mkdir(parents=True, exist_ok=True)
    with output_lock(args.out, "--out", shard_part(shard)), \
            engine.job(args.scheduler, "fit", shared=shared, threads=max(1, args.threads),
                       progress=not args.no_progress) as job:
        paths = {}
        for split in splits:
            paths[split] = fit_split(
                args.dataset,
                split,
                lut,
                lut_path,
                ks,
                args.out,
                method=args.method,
                shard=shard,
                chunk_tones=args.chunk_tones,
                wavelength_stride=args.wavelength_stride,
                anchor_every=args.anchor_every,
                max_tones=args.max_tones,
                select=args.select,
                relative_refl=args.refl_loss == "relative",
                reuse=args.reuse,
                progress=not args.no_progress,
                job=job,
                device=args.device,
                continuity=args.continuity or ("sweep" if args.method == "lm" else "anchors"),
            )
            if job is None:
                print(f"{split}: {paths[split]}")
        if job is not None:
            job.wait()
            print("\n".join(f"{split}: {path}" for split, path in paths.items()))
    return 0


def _summary(dataset: Path, out: Path, splits: list[str]) -> int:
    from training.fit.dataset import summarise

    result = {}
    for split in splits:
        files = sorted(out.glob(f"{split}_fits*.h5"))
        if files:
            result[split] = summarise(dataset, files)
    if not result:
        raise ValueError(f"no fits files in {out}: run `python -m training fit --dataset ... --out {out}` first")
    (out / "summary.json").write_text(json.dumps(result, indent=2))
    print(json.dumps(result))
    return 0


def _check_paths(args: argparse.Namespace) -> None:
    """InputError for a missing, truncated or disguised input and an output that cannot be written."""
    lut = args.lut or (Path(os.environ["SKIN_SSS_LUT"]) if os.environ.get("SKIN_SSS_LUT") else None)
    if lut is not None and not (args.dataset is not None and args.summary):
        check_input(lut, "--lut" if args.lut else "$SKIN_SSS_LUT", "npz")
    if args.tone_file is not None:
        check_input(args.tone_file, "--tone-file", "npz")
        if args.out is not None:
            check_output_file(args.out, "--out", suffixes=(".npz",), overwrite=False, overwrite_option=None,
                              inputs=(("--tone-file", args.tone_file), ("--lut", lut)))
        return
    check_input(args.dataset, "--dataset", "folder")
    if args.reuse is not None:
        check_input(args.reuse, "--reuse", "folder")
    if args.out is None:
        return
    if args.summary:
        check_input(args.out, "--out", "folder")
    else:
        check_output_folder(args.out, "--out", inputs=(("--dataset", args.dataset),))
    for folder in {args.dataset, args.out} | ({args.reuse} if args.reuse else set()):
        for path in sorted(Path(folder).glob("*.h5")) if Path(folder).is_dir() else ():
            check_input(path, "HDF5 file", "h5")


@command("fit")
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    _check_paths(args)
    torch.manual_seed(args.seed)
    if args.device == "cpu":
        torch.set_num_threads(max(1, args.threads))
    try:
        ks = _parse_k(args.k)
        if args.scheduler is not None and args.dataset is None:
            raise ValueError("--scheduler runs `fit --dataset` on a cluster; a --tone-file is fitted here")
        if args.device == "cuda" and args.scheduler is None and not torch.cuda.is_available():
            raise ValueError("--device cuda: no CUDA device available")
        if args.dataset is not None and args.summary:  # reads the fits files only
            return _fit_dataset(args, ks, Path())
        lut_path = args.lut or (Path(os.environ["SKIN_SSS_LUT"]) if os.environ.get("SKIN_SSS_LUT") else None)
        if lut_path is None:
            raise ValueError("give --lut LUT.npz (from `python -m training lut`) or set SKIN_SSS_LUT")
        if not lut_path.is_file():
            raise ValueError(f"no such file: {lut_path}")
        if args.dataset is not None:
            return _fit_dataset(args, ks, lut_path)
        if not args.tone_file.is_file():
            raise ValueError(f"no such file: {args.tone_file}")
        lut = LookupTables.load(lut_path, dtype=torch.float64, device=args.device)
        t0 = time.perf_counter()
        rows, arrays = fit_tone_file(args.tone_file, lut, ks, args.method, args.refl_loss == "relative")
        seconds = time.perf_counter() - t0
    except (ValueError, engine.TaskError) as exc:
        return error_status(exc)
    if args.out is not None:
        with atomic_file(args.out) as f:
            np.savez(f, **arrays)
    if args.json:
        print(json.dumps({"fits": rows, "method": args.method, "seconds": round(seconds, 3)}))
    else:
        for r in rows:
            print(
                f"K={r['K']}: shape RMSE {r['shape_rmse']:.4f}, |dR|/R {r['refl_rel_err']:.4f} "
                f"(joint {r['joint_loss']:.4f}, {r['seconds']:.1f} s)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
