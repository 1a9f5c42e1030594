"""``python -m training edit-table``: build the skin-edit table (exporters.edit_table), or check it.

    python -m training edit-table [--model M] [--decoder D] [--table T]
        [--out blender_addon/models/skin_inversion_edits.npz] [--step 0.03] [--threads N] [--overwrite] [--check]

``--check`` measures the live group's answer (the tables) against the exact one (the network, the decoder and the
collapse) on the colours of the representative tones R01-R09 (training/skin/tones.csv, through the decoder) under
single-control edits spanning each control's range and under combined edits (the presets and a few more), and
prints ΔE76 of the colour and the relative error of the effective radius per channel.  ``--monte-carlo PHOTONS``
checks the reference itself: the decoder's colour of edited tones (R02, R05 and R08, as inverted and under each
preset) against the two-layer Monte Carlo of the same tones (training.sim, PHOTONS packets per visible wavelength,
diffuse illumination as the dataset's).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from exporters import edit_table, inference, skin_edits, texel_table
from exporters.cli_io import OneLineParser, check_input, check_output_file, in_range, non_negative_int
from exporters.constants import N_WAVELENGTHS
from training.commands.options import command
from training.paths import SHIPPED_DECODER, SHIPPED_EDIT_TABLE, SHIPPED_MODEL, SHIPPED_TABLE
from training.skin.tones import load_tones

#: Single-control edits of the check: each control across its range (levels and between them).
SINGLE_EDITS = ([(v, 1.0, 0.0) for v in (0.25, 0.35, 0.5, 0.7, 1.5, 2.0, 3.0, 4.0)]
                + [(1.0, v, 0.0) for v in (0.25, 0.35, 0.5, 0.7, 1.5, 2.0, 3.0, 4.0)]
                + [(1.0, 1.0, v) for v in (-0.5, -0.35, -0.2, -0.1, 0.1, 0.2, 0.35, 0.5)])
#: Combined edits of the check: the presets and a few more.
COMBINED_EDITS = ([tuple(p.row()) for p in skin_edits.PRESETS.values()]
                  + [(1.5, 2.0, -0.2), (0.5, 2.0, 0.0), (2.0, 0.5, 0.2), (0.7, 1.5, -0.1)])


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="python -m training edit-table", description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=SHIPPED_MODEL, help="skin_inversion.onnx")
    parser.add_argument("--decoder", type=Path, default=SHIPPED_DECODER, help="skin_decoder.onnx")
    parser.add_argument("--table", type=Path, default=SHIPPED_TABLE, help="the model's texel table (.npz)")
    parser.add_argument("--out", type=Path, default=SHIPPED_EDIT_TABLE, help="edit table file (.npz)")
    parser.add_argument("--step", type=in_range(0.005, 0.5), default=edit_table.DEFAULT_STEP,
                        help="grid step in skin space")
    parser.add_argument("--threads", type=non_negative_int, default=0, help="onnxruntime threads (0 = all cores)")
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--check", action="store_true", help="measure --out against the exact answer")
    parser.add_argument("--monte-carlo", type=non_negative_int, default=0, metavar="PHOTONS",
                        help="compare the decoder's colour of edited tones with the Monte Carlo of those tones")
    return parser


def check_colours(decoder: Path) -> np.ndarray:
    """Linear sRGB (9, 3) of the representative tones R01-R09 (R10 is near black)."""
    rows = load_tones().select("representative").values[:9]
    return skin_edits.model_colour(inference.run_decoder(rows, decoder)["reflectance"])


def monte_carlo_rows(decoder: Path, photons: int) -> list[str]:
    """One line per (tone, edit): ΔE76 between the decoder's and the Monte Carlo's colour of the edited tone."""
    from exporters.colorimetry import delta_e76, linear_srgb_to_lab
    from training.sim.tissue import skin_medium
    from training.sim.transport import simulate

    matrix = skin_edits.model_colour(np.eye(N_WAVELENGTHS)).T  # (3, 376)
    support = np.flatnonzero(np.abs(matrix).sum(axis=0) > 0)
    tones = load_tones().select("representative")
    rows = []
    for name, tone in zip(tones.names, tones.values, strict=True):
        if name not in ("R02", "R05", "R08"):
            continue
        for edit_name, edit in (("as painted", skin_edits.SkinEdit()), *skin_edits.PRESETS.items()):
            edited = skin_edits.apply_edit(tone[None], edit.row())
            result = simulate(skin_medium(edited[0]).select_channels(support), photons, illumination="diffuse",
                              seed=1, r_edges_cm=None)
            mc = np.zeros(376)
            mc[support] = result.R_d
            ours = skin_edits.model_colour(inference.run_decoder(edited, decoder)["reflectance"])
            de = delta_e76(linear_srgb_to_lab(ours), linear_srgb_to_lab(skin_edits.model_colour(mc[None])))[0]
            rows.append(f"{name} {edit_name}: f_mel {edited[0, 0]:.3f} f_blood {edited[0, 1]:.3f} so2 "
                        f"{edited[0, 3]:.2f}  decoder vs Monte Carlo ΔE76 {de:.2f}")
    return rows


@command("edit-table")
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    for option, path, kind in (("--model", args.model, "onnx"), ("--decoder", args.decoder, "onnx"),
                               ("--table", args.table, "npz")):
        check_input(path, option, kind)
    model = inference.load_model(args.model, threads=args.threads)
    texels = texel_table.load(args.table)
    if args.monte_carlo:
        for line in monte_carlo_rows(args.decoder, args.monte_carlo):
            print(line)
        return 0
    if args.check:
        check_input(args.out, "--out", "npz")
        table = edit_table.load(args.out)
        rgb = check_colours(args.decoder)
        for name, edits in (("single-control", SINGLE_EDITS), ("combined", COMBINED_EDITS)):
            result = edit_table.check(model, texels, table, rgb, np.array(edits), args.decoder)
            print(f"{name} edits: " + json.dumps({k: round(v, 4) for k, v in result.items()}))
        return 0
    check_output_file(args.out, "--out", suffixes=(".npz",), overwrite=args.overwrite,
                      inputs=(("--model", args.model), ("--table", args.table)))
    table = edit_table.build(model, texels, args.decoder, args.step)
    edit_table.save(table, args.out, overwrite=args.overwrite)
    m = table.meta
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB): {m['shape']} grid, {m['valid_nodes']} nodes "
          f"x {3 * len(edit_table.LEVELS['melanin'])} edits evaluated in {m['build_seconds']:.1f} s")
    return 0
