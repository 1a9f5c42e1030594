"""``python -m training texel-table``: build (or check) the fast-path texel table of a model.

    python -m training texel-table [--model blender_addon/models/skin_inversion.onnx]
        [--out blender_addon/models/skin_inversion_table.npz] [--step 0.015] [--model-colour] [--ior N]
        [--min-mfp-m M] [--threads N] [--overwrite] [--check]

The table and its builder are ``exporters.texel_table`` (a bake reads the table); this command only parses
the options.  Defaults: the model and table shipped with the add-on (``training.paths.SHIPPED_MODEL``,
``SHIPPED_TABLE``).  ``--check`` exits 0 when --out was made from --model, 1 otherwise.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from exporters import inference, texel_table
from exporters.cli_io import (
    OneLineParser,
    check_input,
    check_output_file,
    in_range,
    non_negative_float,
    non_negative_int,
)
from exporters.maps import sha256_file
from exporters.reflectance_tables import IOR_MAX, IOR_MIN
from exporters.texel_records import CollapseOptions
from training.commands.options import command
from training.paths import SHIPPED_MODEL, SHIPPED_TABLE


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training texel-table",
                           description=texel_table.__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=SHIPPED_MODEL, help="skin_inversion.onnx")
    parser.add_argument("--out", type=Path, default=SHIPPED_TABLE, help="table file (.npz)")
    parser.add_argument("--step", type=in_range(1e-3, 0.5), default=texel_table.DEFAULT_STEP,
                        help="grid step in skin space, in [0.001, 0.5]")
    parser.add_argument("--model-colour", action="store_true", help="table for bakes with --model-colour")
    parser.add_argument("--ior", type=in_range(IOR_MIN, IOR_MAX), default=CollapseOptions().ior,
                        help=f"IOR of the Cycles closures, in [{IOR_MIN}, {IOR_MAX}]")
    parser.add_argument("--min-mfp-m", type=non_negative_float, default=CollapseOptions().min_mfp_cm / 100,
                        help="smallest mean free path given to Cycles, metres")
    parser.add_argument("--threads", type=non_negative_int, default=0, help="onnxruntime threads (0 = all cores)")
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--check", action="store_true", help="only check that --out was made from --model")
    return parser


@command("texel-table")
def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_input(args.model, "--model", "onnx")
    if args.check:
        check_input(args.out, "--out", "npz")
        table = texel_table.load(args.out)
        sha = sha256_file(args.model)
        same = table.model_sha256 == sha
        print(f"{args.out}: made from model {table.model_sha256[:12]}, {args.model.name} is {sha[:12]}: "
              f"{'matches' if same else 'DOES NOT MATCH (rebuild the table)'}")
        return 0 if same else 1
    check_output_file(args.out, "--out", suffixes=(".npz",), overwrite=args.overwrite,
                      inputs=(("--model", args.model),))
    model = inference.load_model(args.model, threads=args.threads)
    options = CollapseOptions(colour="model" if args.model_colour else "painted", ior=args.ior,
                              min_mfp_cm=args.min_mfp_m * 100)
    table = texel_table.build(model, options, args.step)
    texel_table.save(table, args.out, overwrite=args.overwrite)
    m = table.meta
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB): {m['shape']} grid, {m['valid_nodes']} nodes "
          f"evaluated in {m['build_seconds']:.1f} s, model {table.model_sha256[:12]}, K = {table.k}")
    return 0
