"""Command dispatcher for ``python -m training`` (docs/contracts.md §2).

Each command is a module of ``training.commands`` (or a study module with its own ``main``) exposing
``main(argv: list[str]) -> int`` and ``build_parser()`` (its parser, an ``exporters.cli_io.OneLineParser``,
which the documentation's CLI reference renders); ``main`` checks its options, inputs and outputs before
computing (``exporters.cli_io``) and is wrapped by ``training.commands.options.command``: whatever it lets
through is answered in one line on stderr: bad input (``InputError``, a file or permission error) exits 2, a task
that failed exits 1 (``training.cluster.engine.TaskError``), Ctrl-C exits 130 saying what was kept and how to
resume; docs/contracts.md §2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: name -> (module implementing ``main(argv)`` or None if not built yet, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate-layers": ("training.commands.simulate_layers", "Monte Carlo of a generic layered medium; prints JSON."),
    "simulate": ("training.commands.simulate", "Monte Carlo of one skin tone at all 376 wavelengths -> .npz."),
    "lut": ("training.commands.lut", "Homogeneous semi-infinite lookup tables R(alpha, g), P(r | alpha, g)."),
    "dataset": ("training.commands.dataset", "Halton training / random validation tones, sharded and resumable."),
    "fit": ("training.commands.fit", "Fit mixtures of K homogeneous media through the LUTs."),
    "train": ("training.commands.train", "Staged training of Enc, Dec_R, Dec_T."),
    "export": ("training.commands.export", "Export the ONNX graphs and the model card."),
    "validate": ("training.commands.validate", "Reproduce the paper's tables and figures."),
    "ablations": ("training.commands.ablations", "The paper's ablations (§5, §8), each trained and gated alike."),
    "report": ("training.commands.report", "Summary report of dataset, fits, model and a validation run."),
    "bench": ("training.bench.collect", "Run the benchmark suite and write bench/results.md."),
    "swatches": ("training.commands.swatches", "Plot the colours of the representative and outlier tones."),
    "mitsuba": ("training.validate.compare", "Mitsuba 3 reflectance of the network's mixture vs ours vs ground truth."),
    "realskin": ("training.commands.realskin", "Fit the skin model to measured human skin reflectance (NIST)."),
    "resampling": ("training.sim.resample_compare", "Radial profile estimators (histogram, KDE, CDF resampling) "
                   "compared at equal photons (paper §3)."),
    "demo": ("training.commands.demo", "What `make demo` runs: the best end-to-end path available today."),
    "texel-table": ("training.commands.texel_table", "Build (or --check) a model's fast-path texel table."),
    "edit-table": ("training.commands.edit_table", "Build (or --check) the table of the skin edits (Melanin, Blood, "
                   "Oxygenation) the live group and the fast bake apply."),
    "reflectance-tables": ("training.commands.reflectance_tables",
                           "Recompute the adding-doubling reflectance tables the bake reads (iadpython)."),
    "channel-matrix": ("training.commands.channel_matrix", "Write the linear-sRGB channel matrix the bake reads."),
}

def _usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: python -m training <command> [options]   (each command has --help)", "", "commands:"]
    for name, (_, text) in COMMANDS.items():
        lines.append(f"  {name:<{width}}  {text}")
    return "\n".join(lines)


def command_parser(name: str) -> argparse.ArgumentParser:
    """The argument parser of command ``name``: its module's ``build_parser()`` (read by the CLI reference)."""
    return importlib.import_module(COMMANDS[name][0]).build_parser()


def main(argv: list[str]) -> int:
    """Dispatch ``argv`` (without the program name) to a command; returns the exit status."""
    if not argv or argv[0] in {"-h", "--help", "help"}:
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"error: unknown command {name!r}.\n\n{_usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    return int(module.main(rest) or 0)
