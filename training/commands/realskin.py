"""``python -m training realskin``: the skin model against measured human skin (docs/contracts.md §2).

    python -m training realskin [--data FILE] [--out DIR] [--json] [--photons 10000] [--seed 1]
                                [--decoder blender_addon/models/skin_decoder.onnx | --no-decoder]
                                [--subjects N] [--cache DIR] [--scattering-scale LO HI]
    python -m training realskin --study [--out DIR] [--photons 3000]

Fits the biophysical parameters of every measured spectrum with the project's Monte Carlo (one walk of
a collimated normal beam, every tone a reweighting of it; ``forward``) and, for comparison, the shipped
decoder, exposure fixed at 1 and free, in the measurement's geometry (``geometry``).  Prints the table
(or the JSON of docs/contracts.md §2 with ``--json``); ``--out DIR`` also writes realskin.json, realskin.md and
fig_realskin.png.  The walk is cached (``--cache``, default DIR/cache or ~/.cache/spectral_skin_sss/realskin):
a rerun with the same skin model, photons and seed fits at once.  ``--scattering-scale LO HI`` also fits a
per-subject factor on both layers' scattering (a diagnostic: the skin model has no such parameter; the
decoder is not compared then).  ``--study`` runs the cause study
instead (``study``: each candidate modelling choice fitted the same way; DIR/study.md and study.json).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from exporters.cli_io import OneLineParser
from exporters.constants import WAVELENGTHS_NM
from training.commands.options import (
    check_input,
    check_output_folder,
    command,
    count,
    error_status,
    finite_float,
    output_lock,
)
from training.paths import SHIPPED_DECODER
from training.realskin import report, study
from training.realskin.fit import fit_subjects
from training.realskin.forward import DecoderForward, MonteCarloForward, cached_walk
from training.realskin.measurements import NIST_FILE, grid_channels, read_measurements

DEFAULT_DECODER = SHIPPED_DECODER


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training realskin", description=__doc__.split("\n\n")[2],
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=NIST_FILE,
                   help="measured spectra (NIST layout); default: the shipped file")
    p.add_argument("--out", type=Path, help="write realskin.json, realskin.md and fig_realskin.png here")
    p.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    p.add_argument("--photons", type=count, help="photons per wavelength of the walk (default 10000; study 3000)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--decoder", type=Path, default=DEFAULT_DECODER, help="skin_decoder.onnx to compare with")
    p.add_argument("--no-decoder", action="store_true", help="fit the Monte Carlo only")
    p.add_argument("--subjects", type=count, help="fit only the first N subjects")
    p.add_argument("--wavelength-stride", type=count, default=1,
                   help="compare at every n-th shared wavelength (default 1: all 126, every 6 nm)")
    p.add_argument("--cache", type=Path, help="folder of cached walks")
    p.add_argument("--scattering-scale", type=finite_float, nargs=2, metavar=("LO", "HI"),
                   help="also fit a per-subject scattering factor in [LO, HI] (a diagnostic; no decoder comparison)")
    p.add_argument("--study", action="store_true",
                   help="run the cause study (every candidate model choice; default 3000 photons)")
    return p


def _cache_dir(args) -> Path:
    if args.cache is not None:
        return args.cache
    if args.out is not None:
        return args.out / "cache"
    return Path(os.environ.get("SPECTRAL_SKIN_SSS_CACHE", Path.home() / ".cache" / "spectral_skin_sss")) / "realskin"


@command("realskin")
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    check_input(args.data, "--data", "file")
    if not args.no_decoder and args.scattering_scale is None:
        check_input(args.decoder, "--decoder", "onnx")
    if args.out is not None:
        check_output_folder(args.out, "--out", inputs=(("--data", args.data), ("--decoder", args.decoder)))
    if args.cache is not None:
        check_output_folder(args.cache, "--cache", inputs=(("--data", args.data),))
    try:
        meas = read_measurements(args.data)
    except ValueError as exc:
        return error_status(exc)
    if args.photons is None:
        args.photons = 3_000 if args.study else 10_000
    if args.photons < 100:
        print("error: --photons must be at least 100 per wavelength.", file=sys.stderr)
        return 2
    scale = args.scattering_scale
    if scale is not None:
        if not 0.1 <= scale[0] < scale[1] <= 10.0:
            print(f"error: --scattering-scale needs 0.1 <= LO < HI <= 10, got {scale[0]:g} {scale[1]:g}.",
                  file=sys.stderr)
            return 2
        args.no_decoder = True  # the decoder has no scattering parameter
    if not args.no_decoder and not args.decoder.is_file():
        print(f"error: decoder {args.decoder} not found (pass --decoder PATH or --no-decoder).", file=sys.stderr)
        return 2
    if args.wavelength_stride < 1:
        print("error: --wavelength-stride must be >= 1.", file=sys.stderr)
        return 2
    channels, measured = grid_channels(meas)
    channels, measured = channels[:: args.wavelength_stride], measured[:, :: args.wavelength_stride]
    names = list(meas.names)
    if args.subjects is not None and args.subjects > len(names):
        print(f"error: --subjects {args.subjects}: {args.data} has {len(names)} subjects.", file=sys.stderr)
        return 2
    if args.subjects is not None:
        names, measured = names[: args.subjects], measured[: args.subjects]
    if args.out is None:
        return _run(args, meas, channels, measured, names)
    args.out.mkdir(parents=True, exist_ok=True)
    with output_lock(args.out, "--out"):
        return _run(args, meas, channels, measured, names)


def _run(args, meas, channels, measured, names: list[str]) -> int:
    """The study or the fits and their report (after every check has passed)."""
    scale = args.scattering_scale
    if args.study:
        print(study.run_study(names, measured, channels, args.photons, args.seed, _cache_dir(args), args.out,
                              args.device))
        return 0
    wl = WAVELENGTHS_NM[channels]
    t0 = time.perf_counter()
    traj = cached_walk(channels, args.photons, args.seed, _cache_dir(args), args.device, progress=not args.json)
    t_walk = time.perf_counter() - t0
    mc = MonteCarloForward(traj)
    fits = {free: fit_subjects(mc, names, measured, wl, mc.specular, free, seed=args.seed,
                               scale_range=None if scale is None else tuple(scale)) for free in (False, True)}
    dec = {False: None, True: None}
    if not args.no_decoder:
        df = DecoderForward(args.decoder, channels, mc.specular)
        dec = {free: fit_subjects(df, names, measured, wl, mc.specular, free, seed=args.seed) for free in (False, True)}
    lightness = report.measured_lightness(meas, mc.specular)[: len(names)]
    settings = {"data": args.data.name, "photons": args.photons, "seed": args.seed, "specular": round(mc.specular, 5),
                "wavelengths": int(channels.size), "skin_model": mc.spec.name,
                "walk_seconds": round(traj.seconds, 1), "seconds": round(time.perf_counter() - t0, 1),
                "walk_cached": t_walk < 0.5 * traj.seconds,
                "scattering_scale_range": None if scale is None else list(scale)}
    rep = report.summary(names, lightness, fits[False], fits[True], dec[False], dec[True], settings)
    md = report.markdown(rep)
    if args.out is not None:
        report.write(args.out, rep, md)
        report.figure(args.out / "fig_realskin.png", wl, measured, names, lightness, fits[False], dec[False])
    print(json.dumps(rep) if args.json else md)
    return 0
