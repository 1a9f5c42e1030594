"""``python -m training validate``: the paper's validation (docs/contracts.md §6).

    python -m training validate --out DIR [--quick] [--lut LUT] [--dataset DIR --fits FITS] [--photons N]
        [--gt-photons N] [--renderer lut|mc] [--model-dir blender_addon/models] [--update-card] [--threads 1]
        [--overwrite]

writes ``DIR/tables.md``, ``DIR/tables.json`` and the figures ``DIR/fig_*.png`` (``training.validate.run``;
the gate is cached in ``DIR/cache``, so rerunning the same command after a kill continues;
``--scheduler local:N | tcp://HOST:PORT | slurm`` walks the ground truth and fits and renders the tones
on a Dask cluster, into the same cache).  The LUT is
``--lut`` or ``$SKIN_SSS_LUT``; ``--quick`` without one builds a tiny Monte Carlo LUT in ``DIR/cache``.
``--update-card`` writes the headline numbers into the model card's ``validation`` entry.

    python -m training validate --mitsuba --out docs/figures [--overwrite]

renders the teaser-like Mitsuba 3 strips (``training.validate.strips``).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.cluster import engine
from training.commands.options import (
    check_input,
    check_output_folder,
    command,
    count,
    error_status,
    non_negative_int,
    output_lock,
    positive_float,
)
from training.paths import SHIPPED_MODEL_DIR, portable_command
from training.validate import mitsuba_scene as em

DEFAULT_MODEL_DIR = SHIPPED_MODEL_DIR


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training validate", description="Reproduce the paper's validation.")
    p.add_argument("--out", type=Path, help="output folder (tables.md, tables.json, fig_*.png, cache/)")
    p.add_argument("--quick", action="store_true",
                   help="smoke test: 4 tones, every 20 nm, few photons, few fitter iterations (a test runs it)")
    p.add_argument("--lut", type=Path, default=None, help="LUT .npz of `python -m training lut` (or $SKIN_SSS_LUT)")
    p.add_argument("--dataset", type=Path, default=None, help="dataset folder (Table 3: validation.h5)")
    p.add_argument("--fits", type=Path, default=None,
                   help="fits folder of `python -m training fit --dataset` (Table 3: validation_fits.h5)")
    p.add_argument("--model-dir", type=Path, default=DEFAULT_MODEL_DIR,
                   help="folder with skin_inversion.onnx, skin_decoder.onnx and the card skin_inversion.json")
    p.add_argument("--photons", type=non_negative_int, default=None,
                   help="Monte Carlo render photons per component and wavelength, the check of the tables' renders "
                        "(default 2000; quick 150; 0 skips them)")
    p.add_argument("--gt-photons", type=count, default=None,
                   help="ground-truth photons per wavelength (default 500000, the paper's; quick 400)")
    p.add_argument("--renderer", choices=("lut", "mc"), default="lut",
                   help="what renders the gate's slabs: the lookup tables (default, noise-free) or our Monte Carlo")
    p.add_argument("--wavelength-step-nm", type=count, default=None,
                   help="validation wavelengths every N nm, a multiple of 2 (default 4; quick 20)")
    p.add_argument("--tones", default=None, help="comma-separated tone names of tones.csv (default: all 20)")
    p.add_argument("--fit-method", choices=("lm", "paper"), default="lm", help="the fitter's method")
    p.add_argument("--anchor-every", type=non_negative_int, default=4,
                   help="fitter anchors (full schedule) every n-th wavelength, warm starts between (0 = all full)")
    p.add_argument("--baseline-scale", type=positive_float, default=None,
                   help="Subsurface Scale (m) of the albedo-inversion baselines (default: calibrated on R05)")
    p.add_argument("--nn-profile-tones", type=count, default=None,
                   help="with --dataset: validation tones for the network's profile row (default all)")
    p.add_argument("--update-card", action="store_true", help="write the headline numbers into the model card")
    p.add_argument("--threads", type=count, default=1, help="torch / onnxruntime threads")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu",), default="cpu", help="the gate runs on the CPU")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs in --out")
    p.add_argument("--no-progress", action="store_true")
    engine.add_option(p)
    m = p.add_argument_group("--mitsuba strips")
    m.add_argument("--mitsuba", action="store_true", help="render the teaser-like Mitsuba 3 strips (PNG) into --out")
    m.add_argument("--size", type=count, default=64, help="pixels per tone (square)")
    m.add_argument("--spp", type=count, default=48, help="samples per pixel per wavelength (split over components)")
    m.add_argument("--variant", default="auto",
                   help="Mitsuba variant (auto: llvm_ad_rgb if libLLVM 19 is installed, else scalar_rgb)")
    m.add_argument("--decoder", type=Path, default=em.DEFAULT_DECODER, help="skin_decoder.onnx (--mitsuba)")
    return p


def _mitsuba(args) -> int:
    if args.size < 8 or args.spp < 1:
        print("error: --size must be >= 8 pixels and --spp >= 1.", file=sys.stderr)
        return 2
    from training.validate.strips import StripConfig, render_strips

    config = StripConfig(size=args.size, spp=args.spp, variant=None if args.variant == "auto" else args.variant,
                         seed=args.seed, decoder=str(args.decoder))
    try:
        rec = render_strips(args.out, config, overwrite=args.overwrite, progress=not args.no_progress)
    except (ValueError, FileExistsError, em.MitsubaUnavailable) as exc:
        return error_status(exc)
    for band, values in rec["translucency"].items():
        print(f"{band:6s} translucency " + " ".join(f"{n}={v:.4f}" for n, v in zip(rec["tones"], values, strict=True)))
    print(f"wrote {args.out} ({rec['config']['variant']}, {rec['seconds']:.0f} s)")
    return 0


def _quick_lut(out: Path, progress: bool) -> Path:
    """A tiny Monte Carlo LUT for --quick (built once into DIR/cache)."""
    from training.sim.lut import build_lut
    from training.validate.run import QUICK_LUT

    path = out / "quick_lut.npz"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        q = QUICK_LUT
        build_lut(str(path), q["albedo_n"], q["g_n"], q["photons"], seed=0, max_steps=q["max_steps"],
                  progress=False, log=(lambda s: print(s, file=sys.stderr)) if progress else (lambda s: None))
    return path


def _options(args):
    from training.validate import gate as G
    from training.validate import run as R

    if args.threads < 1:
        raise ValueError("--threads must be >= 1.")
    step_nm = args.wavelength_step_nm or (2 * R.QUICK["wavelength_step"] if args.quick else 4)
    if step_nm < 2 or step_nm % 2:
        raise ValueError("--wavelength-step-nm must be a positive multiple of 2 (the grid's step).")
    tones = tuple(t.strip() for t in args.tones.split(",") if t.strip()) if args.tones else (
        R.QUICK_TONES if args.quick else R.FULL_TONES)
    kw = dict(R.QUICK) if args.quick else {}
    kw["wavelength_step"] = step_nm // 2
    if args.photons is not None:
        kw["photons"] = args.photons
    if args.gt_photons is not None:
        kw["gt_photons"] = args.gt_photons
    G.gate_tones(tones)  # unknown names: ValueError now, not after the LUT has loaded
    config = G.GateConfig(tones=tones, fit_method=args.fit_method, seed=args.seed, anchor_every=args.anchor_every,
                          baseline_scale_m=args.baseline_scale, renderer=args.renderer, **kw)
    lut = args.lut or (Path(os.environ["SKIN_SSS_LUT"]) if os.environ.get("SKIN_SSS_LUT") else None)
    if lut is None:
        if not args.quick:
            raise ValueError("give --lut LUT.npz (or set $SKIN_SSS_LUT): the fits of the gate need the LUT.")
        lut = _quick_lut(args.out, not args.no_progress)
    if not Path(lut).is_file():
        raise ValueError(f"LUT {lut}: no such file.")
    for name in ("dataset", "fits"):
        path = getattr(args, name)
        if path is not None and not path.is_dir():
            raise ValueError(f"--{name} {path}: no such folder.")
    command = portable_command("python -m training validate", sys.argv[2:]) \
        if len(sys.argv) > 1 and sys.argv[1] == "validate" else "python -m training validate (called from Python)"
    return R.Options(out=args.out, config=config, lut=Path(lut), model_dir=args.model_dir, dataset=args.dataset,
                     fits=args.fits, threads=args.threads, overwrite=args.overwrite, progress=not args.no_progress,
                     quick=args.quick, nn_profile_tones=args.nn_profile_tones, command=command,
                     scheduler=args.scheduler)


def _summary(record: dict) -> str:
    rows = record["gate"]["rows"]
    lines = [f"{'configuration':46s} {'dE rep':>7s} {'dE all':>7s} {'edge rep':>8s}"]
    for row in rows.values():
        fmt = lambda v: "—" if v is None else f"{v:.2f}"  # noqa: E731
        lines.append(f"{row['label']:46s} {fmt(row['delta_e']['representative']):>7s} {fmt(row['delta_e']['all']):>7s} "
                     f"{fmt(row['delta_e_edge']['representative']):>8s}")
    return "\n".join(lines)


def _check_paths(args: argparse.Namespace) -> None:
    """InputError for missing, truncated or disguised inputs and an --out that cannot be the output folder."""
    inputs = []
    lut = args.lut or (Path(os.environ["SKIN_SSS_LUT"]) if os.environ.get("SKIN_SSS_LUT") else None)
    if lut is not None:
        check_input(lut, "--lut" if args.lut else "$SKIN_SSS_LUT", "npz")
        inputs.append(("--lut", lut))
    for name in ("dataset", "fits", "model_dir"):
        folder = getattr(args, name)
        if folder is not None:
            option = f"--{name.replace('_', '-')}"
            check_input(folder, option, "folder")
            inputs.append((option, folder))
            for path in sorted(folder.glob("*.h5")) + sorted(folder.glob("*.onnx")):
                check_input(path, f"{option} file", "file")
    check_output_folder(args.out, "--out", inputs=tuple(inputs))


@command("validate")
def main(argv: list[str]) -> int:
    """Run the command; exit 2 with a one-line error for bad input."""
    args = build_parser().parse_args(argv)
    if args.out is None:
        print("error: give --out DIR (the folder for the tables and figures).", file=sys.stderr)
        return 2
    if args.mitsuba:
        if args.scheduler is not None:
            print("error: --scheduler runs the gate on a cluster; the --mitsuba strips render here.", file=sys.stderr)
            return 2
        check_input(args.decoder, "--decoder", "onnx")
        check_output_folder(args.out, "--out", inputs=(("--decoder", args.decoder),))
        return _mitsuba(args)
    _check_paths(args)
    from training.validate import run as R

    try:
        opts = _options(args)
        args.out.mkdir(parents=True, exist_ok=True)
        with output_lock(args.out, "--out"):
            record = R.run(opts).to_json()
        if args.update_card:
            from training.export.card import update_validation
            from training.validate.record import headline

            update_validation(opts.model_dir / "skin_inversion.json", headline(record))
    except (ValueError, FileExistsError, engine.TaskError) as exc:
        return error_status(exc)
    print(_summary(record))
    print(f"wrote {args.out / 'tables.md'}, tables.json and the figures ({record['run']['timings_s']['total']:.0f} s)")
    return 0
