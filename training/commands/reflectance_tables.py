"""``python -m training reflectance-tables --build [--out FILE]``: recompute exporters/data/reflectance_tables.npz.

The tables and their builder are ``exporters.reflectance_tables`` (adding-doubling with iadpython, about 10
minutes on one core); without ``--build`` the command prints its help.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from exporters import reflectance_tables
from exporters.cli_io import OneLineParser, atomic_path, check_output_file
from training.commands.options import command


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training reflectance-tables",
                           description=reflectance_tables.__doc__.splitlines()[0])
    parser.add_argument("--build", action="store_true", help="recompute the tables with iadpython")
    parser.add_argument("--out", type=Path, default=reflectance_tables.TABLE_PATH)
    return parser


@command("reflectance-tables")
def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.build:
        parser.print_help()
        return 0
    check_output_file(args.out, "--out", suffixes=(".npz",))
    with atomic_path(args.out) as tmp:
        reflectance_tables.build_tables(tmp)
    print(f"wrote {args.out}")
    return 0
