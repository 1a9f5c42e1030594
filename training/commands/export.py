"""``python -m training export``: ONNX graphs + model card of a trained run (docs/contracts.md §3).

    python -m training export --run RUNDIR --out blender_addon/models/ [--weights auto|float32|float16]
        [--max-mb 25] [--parity-n 10000] [--note TEXT ...] [--overwrite]

Writes ``skin_inversion.onnx``, ``skin_decoder.onnx`` and ``skin_inversion.json``.  Each graph is run
with onnxruntime on --parity-n random inputs and compared with torch (max abs difference <= 1e-4,
relative for sigma_t and exposure); the export fails (exit 1, nothing written) otherwise, and also when
the files together exceed --max-mb.  ``--weights auto`` stores float32 weights unless that exceeds the
size budget, then float16 (with its cost measured and written to the card).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.commands.options import (
    atomic_file,
    check_input,
    check_output_folder,
    command,
    count,
    error_status,
    output_lock,
    positive_float,
)
from training.export.card import build_card, write_card
from training.export.graphs import PARITY_TOL, export_graphs, parity, parity_failures, rounding_cost
from training.paths import portable_command
from training.train.run import load_model

CARD_NAME = "skin_inversion.json"


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training export", description=__doc__.splitlines()[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--run", type=Path, required=True, help="run folder of `python -m training train`")
    p.add_argument("--out", type=Path, required=True, help="folder for the .onnx files and the card")
    p.add_argument("--weights", choices=("auto", "float32", "float16"), default="auto")
    p.add_argument("--max-mb", type=positive_float, default=25.0,
                   help="size budget of the two .onnx files together (MB)")
    p.add_argument("--parity-n", type=count, default=10_000, help="random inputs of the parity check (>= 1)")
    p.add_argument("--note", action="append", default=[], help="free-text note for the card (repeatable)")
    p.add_argument("--overwrite", action="store_true", help="replace existing files in --out")
    p.add_argument("--seed", type=int, default=0, help="seed of the parity inputs")
    p.add_argument("--device", choices=("cpu",), default="cpu", help="export runs on the CPU")
    return p


def _write_atomic(path: Path, data: bytes) -> None:
    with atomic_file(path) as f:
        f.write(data)


def export_run(run_dir: Path, out: Path, *, weights: str = "auto", max_mb: float = 25.0, parity_n: int = 10_000,
               notes: list[str] | None = None, overwrite: bool = False, seed: int = 0, command: str = "") -> dict:
    """Export ``run_dir`` into ``out``; returns the card.  Raises ValueError / RuntimeError on failure."""
    model_path, record_path = run_dir / "model.pt", run_dir / "run.json"
    for p in (model_path, record_path):
        if not p.is_file():
            raise ValueError(f"{p} missing: finish `python -m training train` (all stages) first")
    names = ("skin_inversion.onnx", "skin_decoder.onnx", CARD_NAME)
    existing = [n for n in names if (out / n).exists()]
    if existing and not overwrite:
        raise ValueError(f"{out} already has {existing}; pass --overwrite to replace them")
    model = load_model(model_path)
    budget = max_mb * 1e6
    dtype = "float32" if weights in ("auto", "float32") else "float16"
    graphs = export_graphs(model, dtype)
    if weights == "auto" and sum(map(len, graphs.values())) > budget:
        dtype = "float16"
        graphs = export_graphs(model, dtype)
    total = sum(map(len, graphs.values()))
    if total > budget:
        raise RuntimeError(f"the graphs take {total / 1e6:.1f} MB > --max-mb {max_mb:g} (weights {dtype})")
    errors = parity(model, graphs, dtype, n=parity_n, seed=seed)
    failed = parity_failures(errors)
    if failed:
        raise RuntimeError("torch vs onnxruntime parity failed (tolerance "
                           f"{PARITY_TOL:g}): " + "; ".join(failed))
    cost = rounding_cost(model, n=parity_n, seed=seed) if dtype == "float16" else None
    card = build_card(json.loads(record_path.read_text()), graphs, dtype, errors, cost, command, notes or [])
    out.mkdir(parents=True, exist_ok=True)
    for name, data in graphs.items():
        _write_atomic(out / name, data)
    write_card(out / CARD_NAME, card)
    return card


@command("export")
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    check_input(args.run, "--run", "folder")
    check_input(args.run / "model.pt", "--run", "file")
    check_output_folder(args.out, "--out", inputs=(("--run", args.run),))
    command = portable_command("python -m training export", argv)
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with output_lock(args.out, "--out", inside=False):  # the folder appears only when the export succeeds
            card = export_run(args.run, args.out, weights=args.weights, max_mb=args.max_mb, parity_n=args.parity_n,
                              notes=args.note, overwrite=args.overwrite, seed=args.seed, command=command)
    except ValueError as exc:
        return error_status(exc)
    except RuntimeError as exc:
        print(f"export failed: {exc}", file=sys.stderr)
        return 1
    for name, info in card["files"].items():
        print(f"{args.out / name}: {info['bytes'] / 1e6:.2f} MB, sha256 {info['sha256'][:16]}...")
    worst = {f: max(e.values()) for f, e in card["export"]["parity_torch_vs_onnxruntime"].items()}
    print(f"weights {card['export']['weights_dtype']}; parity max error {worst}")
    print(f"wrote {args.out / CARD_NAME}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
