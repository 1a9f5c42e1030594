"""``python -m training train``: the frozen staged training of Enc, Dec_R and Dec_T (paper §5.2).

    python -m training train --dataset DIR --fits DIR --lut LUT.npz --out RUNDIR
        [--stage 1|2|3|all] [--epochs E1,E2,E3] [--batch B1,B2,B3] [--lr L1,L2,L3] [--k 3]
        [--size paper|small|tiny] [--enc-hidden H] [--synthetic N] [--seed S] [--device cpu|cuda]
        [--targets dense|fitted] [--uniform-param] [--encoder-share F] [--refl-loss absolute|log] [--smooth-weight S]
        [--balance B]
        [--lambda-r 15] [--no-slab-factor] [--unfreeze] [--data-every N]
        [--checkpoint-interval SECONDS] [--no-progress]

--dataset: folder with train.h5 and validation.h5 (``python -m training dataset``).
--fits: the --out folder of `python -m training fit --dataset` (train_fits.h5, optionally validation_fits.h5; stage 3).
--lut: the lookup tables of ``python -m training lut`` (stage 3's reflectance loss; its g axis bounds g).
Killing the job and running the same command again resumes from the last checkpoint.
--size: paper = the paper's networks (Dec_R 512, Dec_T 4 x 768); small / tiny = narrower networks for
quick experiments and tests.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.commands.options import (
    check_input,
    check_output_folder,
    command,
    count,
    error_status,
    fraction,
    in_range,
    non_negative_float,
    non_negative_int,
    output_lock,
    positive_float,
    require,
    triple,
)
from training.model.config import SIZES, WEIGHT_SMOOTHING_NM, ModelConfig
from training.paths import portable_command
from training.train.run import TrainConfig, train


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training train", description=__doc__.splitlines()[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--dataset", type=Path, required=True)
    p.add_argument("--fits", type=Path, default=None)
    p.add_argument("--lut", type=Path, required=True)
    p.add_argument("--out", type=Path, required=True, help="run folder (created; resumed if it exists)")
    p.add_argument("--stage", choices=("1", "2", "3", "all"), default="all")
    d = TrainConfig()
    p.add_argument("--epochs", type=lambda s: triple(s, count), default=d.epochs, help="E or E1,E2,E3")
    p.add_argument("--batch", type=lambda s: triple(s, count), default=d.batch, help="B or B1,B2,B3")
    p.add_argument("--lr", type=lambda s: triple(s, positive_float), default=d.lr, help="L or L1,L2,L3")
    p.add_argument("--synthetic", type=non_negative_int, default=d.synthetic,
                   help="stage 2: albedos rendered by Dec_R")
    p.add_argument("--exposure-jitter", type=non_negative_float, default=d.exposure_jitter,
                   help="stage 2: synthetic albedos scaled by exp(U(-j, j))")
    p.add_argument("--exposure-prior", type=non_negative_float, default=d.exposure_prior,
                   help="stage 2: weight of mean |ln exposure| in the colour loss (0: the paper's loss)")
    p.add_argument("--shape-weight", type=non_negative_float, default=d.shape_weight,
                   help="stage 3: weight of the rendered profile-shape loss L_shape (0: the paper's loss)")
    p.add_argument("--targets", choices=("dense", "fitted"), default=d.targets,
                   help="stage 3: dense = fits matched along wavelength, L_param and L_shape at all 376 wavelengths "
                        "(default); fitted = sorted by sigma_t, at the fitted wavelengths only")
    p.add_argument("--uniform-param", action="store_true",
                   help="stage 3: L_param without weighting each component's alpha, g, sigma_t by its weight")
    p.add_argument("--encoder-share", type=fraction, default=d.encoder_share,
                   help="stage 3 (ours): share of each batch whose Dec_T input is the frozen encoder's tone for the "
                        "tone's RGB albedo, as at inversion time, instead of the true tone (0 = the paper)")
    p.add_argument("--refl-loss", choices=("absolute", "log"), default=d.refl_loss,
                   help="stage 3: L_refl as the paper's mean |R_hat - R_MC| (absolute) or ours on log reflectance "
                        "(log: a dark tone's colour weighs as much as a light one's)")
    p.add_argument("--smooth-weight", type=non_negative_float, default=d.smooth_weight,
                   help="stage 3: weight of L_smooth, the mean |change| of Dec_T's normalised outputs per 2 nm step "
                        "(the paper's lambda_smooth 0.5)")
    p.add_argument("--balance", type=fraction, default=d.balance,
                   help="stage 3 (ours): share of the tone draws by inverse local density in the parameter box, so "
                        "that its sparse corners are learnt more often (0: every fitted tone once per epoch; "
                        "training/train/balance.py)")
    a = p.add_argument_group("ablations of the paper's §5 (python -m training ablations; defaults = the paper)")
    a.add_argument("--lambda-r", type=non_negative_float, default=d.lambda_r,
                   help="stage 3: weight of L_refl (paper 15)")
    a.add_argument("--no-slab-factor", action="store_true", help="stage 3: L_refl without the slab-depth factor")
    a.add_argument("--unfreeze", action="store_true", help="stages 2-3: Dec_R trains along (paper: frozen)")
    a.add_argument("--data-every", type=count, default=d.data_every,
                   help="stages 2-3: learn from every n-th training tone only (20: the paper's 20x less data)")
    p.add_argument("--k", type=in_range(1, 3, integer=True), default=3, help="mixture components (fits group K{k})")
    p.add_argument("--size", choices=sorted(SIZES), default="paper")
    p.add_argument("--enc-hidden", type=count, default=None,
                   help="Enc's hidden width, overriding the size's (paper and BioSkin: 70)")
    p.add_argument("--weight-smoothing-nm", type=non_negative_float, default=WEIGHT_SMOOTHING_NM,
                   help="standard deviation (nm) of the fixed Gaussian low-pass of Dec_T's mixture weights along "
                        "wavelength (0: none, the paper's decoder); it bounds a weight's change per 2 nm step by "
                        "0.133 at 6 nm")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--checkpoint-interval", type=non_negative_float, default=0.0,
                   help="seconds between checkpoints (0: after every epoch; the last epoch is always saved)")
    p.add_argument("--eval-every", type=count, default=1,
                   help="validation metrics after every n-th epoch and the last (monitoring only; stage 3's "
                        "validation on the 1,000 laptop tones costs several times a training epoch)")
    p.add_argument("--threads", type=non_negative_int, default=0, help="torch CPU threads (0: torch's default)")
    p.add_argument("--no-progress", action="store_true")
    return p


@command("train")
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    want = (1, 2, 3) if args.stage == "all" else (int(args.stage),)
    require(3 not in want or args.fits is not None,
            "stage 3 needs --fits DIR (train_fits.h5 of `python -m training fit --dataset`)")
    check_input(args.dataset, "--dataset", "folder")
    check_input(args.lut, "--lut", "npz")
    inputs = [("--dataset", args.dataset), ("--lut", args.lut)]
    if args.fits is not None:
        check_input(args.fits, "--fits", "folder")
        inputs.append(("--fits", args.fits))
    for folder in (args.dataset, args.fits):
        for path in sorted(folder.glob("*.h5")) if folder is not None else ():
            check_input(path, "HDF5 file", "h5")
    check_output_folder(args.out, "--out", inputs=tuple(inputs))
    import torch

    if args.threads > 0:
        torch.set_num_threads(args.threads)
    want = (1, 2, 3) if args.stage == "all" else (int(args.stage),)
    size = dict(SIZES[args.size], **({} if args.enc_hidden is None else {"enc_hidden": args.enc_hidden}))
    mcfg = ModelConfig(k=args.k, weight_smoothing_nm=args.weight_smoothing_nm, **size)
    tcfg = TrainConfig(seed=args.seed, epochs=args.epochs, batch=args.batch, lr=args.lr,
                       synthetic=args.synthetic, exposure_jitter=args.exposure_jitter,
                       exposure_prior=args.exposure_prior, shape_weight=args.shape_weight, targets=args.targets,
                       weighted_param=not args.uniform_param, lambda_r=args.lambda_r,
                       slab_factor=not args.no_slab_factor, unfreeze=args.unfreeze, data_every=args.data_every,
                       encoder_share=args.encoder_share, refl_loss=args.refl_loss,
                       smooth_weight=args.smooth_weight, balance=args.balance)
    command = portable_command("python -m training train", argv)
    try:
        if 3 in want and args.fits is None:
            raise ValueError("stage 3 needs --fits DIR (train_fits.h5 of `python -m training fit --dataset`)")
        for path in (args.dataset, args.lut) + ((args.fits,) if args.fits else ()):
            if not path.exists():
                raise ValueError(f"no such file or folder: {path}")
        args.out.mkdir(parents=True, exist_ok=True)
        with output_lock(args.out, "--out"):
            record = train(args.out, args.dataset, args.fits, args.lut, want=want, mcfg=mcfg, tcfg=tcfg,
                           device=args.device, progress=not args.no_progress,
                           checkpoint_interval_s=args.checkpoint_interval, command=command,
                           eval_every=args.eval_every)
    except ValueError as exc:
        return error_status(exc)
    for stage, row in record.get("losses", {}).items():
        parts = ", ".join(f"{k} {v:.4g}" for k, v in row.items() if k.startswith(("train_", "val_")))
        print(f"{stage}: {parts}")
    if "metrics" in record:
        v = record["metrics"]["validation"]
        print(f"validation colour dE76 (encoder round trip): mean {v['enc_delta_e76']['mean']:.3f}")
        print(f"wrote {args.out / 'model.pt'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
