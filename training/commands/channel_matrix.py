"""``python -m training channel-matrix [--out FILE]``: write exporters/data/linear_srgb_d65_weights.npy.

M (3, 376), linear sRGB (D65) = M @ R, computed with colour-science (``exporters.collapse.compute_channel_matrix``)
and stored so that the add-on needs no colour-science inside Blender.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from exporters import collapse
from exporters.cli_io import OneLineParser, atomic_file, check_output_file
from training.commands.options import command


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training channel-matrix", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=collapse.CHANNEL_MATRIX_PATH,
                        help="where to write the matrix (default: the one the add-on reads)")
    return parser


@command("channel-matrix")
def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_output_file(args.out, "--out", suffixes=(".npy",))
    matrix = collapse.compute_channel_matrix()
    with atomic_file(args.out) as f:
        np.save(f, matrix)
    print(f"wrote {args.out}")
    return 0
