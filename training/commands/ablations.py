"""``python -m training ablations``: the paper's ablations, each trained and gated alike (``training.ablations.run``).

    python -m training ablations --out DIR --dataset DIR --fits DIR --lut LUT.npz
        [--size small] [--epochs 300,100,100] [--shape-weight 0] [--gt-photons 50000] [--device cpu|cuda]
    python -m training ablations --out DIR --quick        # smoke test: builds its own smoke dataset, LUT, fits

writes ``DIR/ablations.md`` and ``DIR/ablations.json`` (the paper's numbers beside ours, with a verdict per
claim); the runs are ``DIR/runs/<configuration>``, the gate's ground truth and fits ``DIR/cache``.  Running
the same command again continues where it stopped; another scale in the same DIR is refused.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.commands.options import (
    check_input,
    check_output_folder,
    command,
    count,
    error_status,
    non_negative_float,
    output_lock,
    require,
    triple,
)
from training.paths import portable_command


def build_parser() -> argparse.ArgumentParser:
    from training.ablations.run import Scale
    from training.model.config import SIZES

    d = Scale()
    p = OneLineParser(prog="python -m training ablations", description=__doc__.splitlines()[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--out", type=Path, required=True, help="output folder (resumed if it exists)")
    p.add_argument("--quick", action="store_true",
                   help="smoke test (~1-2 min): the smoke dataset preset, a tiny LUT and quick fits built in "
                        "DIR/cache unless given, tiny networks, 3 epochs, 4 gate tones")
    p.add_argument("--dataset", type=Path, default=None, help="dataset folder (python -m training dataset)")
    p.add_argument("--fits", type=Path, default=None, help="fits folder (python -m training fit --dataset)")
    p.add_argument("--lut", type=Path, default=None, help="LUT .npz (python -m training lut)")
    p.add_argument("--size", choices=sorted(SIZES), default=None, help=f"networks (default {d.size}; quick tiny)")
    p.add_argument("--epochs", type=lambda s: triple(s, count), default=None,
                   help=f"E or E1,E2,E3 (default {','.join(map(str, d.epochs))}; quick 3)")
    p.add_argument("--shape-weight", type=non_negative_float, default=None,
                   help="stage 3's L_shape weight in every configuration (default 0: the paper's loss)")
    p.add_argument("--gt-photons", type=count, default=None,
                   help=f"gate ground-truth photons per wavelength (default {d.gt_photons}; quick 400)")
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu", help="training device (the gate: CPU)")
    p.add_argument("--threads", type=count, default=1, help="torch CPU threads")
    p.add_argument("--no-progress", action="store_true")
    return p


def _quick_inputs(cache: Path, args, progress: bool) -> tuple[Path, Path, Path]:
    """--quick without inputs: the smoke dataset preset, the validate --quick LUT and quick fits, in ``cache``."""
    from training.commands.dataset import main as dataset_main
    from training.commands.fit import main as fit_main
    from training.commands.validate import _quick_lut

    dataset = args.dataset or cache / "dataset"
    if args.dataset is None and not (dataset / "validation.h5").is_file():
        if dataset_main(["--preset", "smoke", "--out", str(dataset), "--no-progress"]) != 0:
            raise ValueError("building the smoke dataset failed")
    lut = args.lut or _quick_lut(cache, progress)
    fits = args.fits or cache / "fits"
    if args.fits is None and not (fits / "validation_fits.h5").is_file():
        if fit_main(["--dataset", str(dataset), "--lut", str(lut), "--out", str(fits), "--wavelength-stride", "16",
                     "--anchor-every", "6", "--no-progress"]) != 0:
            raise ValueError("fitting the smoke dataset failed")
    return dataset, fits, lut


def _check_paths(args: argparse.Namespace) -> None:
    """InputError for missing, truncated or disguised inputs and an --out that cannot be the output folder."""
    require(args.quick or all(getattr(args, n) is not None for n in ("dataset", "fits", "lut")),
            "give --dataset, --fits and --lut (or --quick for the smoke test)")
    inputs = []
    for name, kind in (("dataset", "folder"), ("fits", "folder"), ("lut", "npz")):
        path = getattr(args, name)
        if path is not None:
            check_input(path, f"--{name}", kind)
            inputs.append((f"--{name}", path))
            for h5 in sorted(path.glob("*.h5")) if kind == "folder" else ():
                check_input(h5, "HDF5 file", "h5")
    check_output_folder(args.out, "--out", inputs=tuple(inputs))


@command("ablations")
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    _check_paths(args)
    import torch

    from training.ablations.run import QUICK, Scale, run

    torch.set_num_threads(max(1, args.threads))
    progress = not args.no_progress
    scale = QUICK if args.quick else Scale()
    for name in ("size", "shape_weight", "gt_photons"):
        if getattr(args, name) is not None:
            scale = replace(scale, **{name: getattr(args, name)})
    if args.epochs is not None:
        scale = replace(scale, epochs=tuple(args.epochs))
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        with output_lock(args.out, "--out"):
            if args.quick:
                dataset, fits, lut = _quick_inputs(args.out / "cache", args, progress)
            else:
                dataset, fits, lut = args.dataset, args.fits, args.lut
            record = run(args.out, dataset, fits, lut, scale, quick=args.quick, device=args.device,
                         progress=progress, command=portable_command("python -m training ablations", argv))
    except ValueError as exc:
        return error_status(exc)
    for c in record["claims"]:
        print(f"{c['claim']}: {c['verdict']}")
    print(f"wrote {args.out / 'ablations.md'} and ablations.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
