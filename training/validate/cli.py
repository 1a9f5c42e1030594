"""``python -m training validate``: the paper's validation (SPEC §6).

Built so far: ``--mitsuba --out DIR`` writes the teaser-like Mitsuba strips (``training.validate.strips``).
The tables (rendering Delta E76 for K = 1, 2, 3 and the network, banded shape error, spectral angle,
profile error) come with the validation issue; until then any other use says so and exits 2.

Example::

    python -m training validate --mitsuba --out docs/figures --overwrite
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from exporters import mitsuba as em


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training validate", description="Reproduce the paper's validation.")
    p.add_argument("--mitsuba", action="store_true", help="render the teaser-like Mitsuba 3 strips (PNG) into --out")
    p.add_argument("--out", type=Path, help="output folder")
    p.add_argument("--size", type=int, default=64, help="pixels per tone (square)")
    p.add_argument("--spp", type=int, default=48, help="samples per pixel per wavelength (split over components)")
    p.add_argument("--variant", default="auto",
                   help="Mitsuba variant (auto: llvm_ad_rgb if libLLVM 19 is installed, else scalar_rgb)")
    p.add_argument("--decoder", type=Path, default=em.DEFAULT_DECODER, help="skin_decoder.onnx")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--overwrite", action="store_true", help="replace existing strips in --out")
    p.add_argument("--no-progress", action="store_true")
    return p


def main(argv: list[str]) -> int:
    """Run the command; exit 2 with a one-line error for bad input."""
    args = _parser().parse_args(argv)
    if not args.mitsuba:
        print("error: only `validate --mitsuba --out DIR` is built yet (the validation tables are not); "
              "see the README's status table.", file=sys.stderr)
        return 2
    if args.out is None:
        print("error: --mitsuba needs --out DIR (the folder for the PNG strips).", file=sys.stderr)
        return 2
    if args.size < 8 or args.spp < 1:
        print("error: --size must be >= 8 pixels and --spp >= 1.", file=sys.stderr)
        return 2
    from training.validate.strips import StripConfig, render_strips

    config = StripConfig(size=args.size, spp=args.spp, variant=None if args.variant == "auto" else args.variant,
                         seed=args.seed, decoder=str(args.decoder))
    try:
        rec = render_strips(args.out, config, overwrite=args.overwrite, progress=not args.no_progress)
    except (ValueError, FileExistsError, em.MitsubaUnavailable) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for band, values in rec["translucency"].items():
        print(f"{band:6s} translucency " + " ".join(f"{n}={v:.4f}" for n, v in zip(rec["tones"], values, strict=True)))
    print(f"wrote {args.out} ({rec['config']['variant']}, {rec['seconds']:.0f} s)")
    return 0
