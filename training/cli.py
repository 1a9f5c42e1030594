"""Command dispatcher for ``python -m training`` (docs/contracts.md §2).

Each command lives in the module that owns its concept and exposes ``main(argv: list[str]) -> int``
with its own argparse parser.  Commands whose module is ``None`` are not built yet: they say so and
exit 2 rather than pretend.
"""

from __future__ import annotations

import importlib
import sys

#: name -> (module implementing ``main(argv)`` or None if not built yet, one-line help)
COMMANDS: dict[str, tuple[str | None, str]] = {
    "simulate-layers": ("training.sim.cli_layers", "Monte Carlo of a generic layered medium; prints JSON."),
    "simulate": ("training.sim.cli_tone", "Monte Carlo of one skin tone at all 376 wavelengths -> .npz."),
    "lut": ("training.sim.cli_lut", "Homogeneous semi-infinite lookup tables R(alpha, g), P(r | alpha, g)."),
    "dataset": ("training.data.cli", "Halton training / random validation tones, sharded and resumable."),
    "fit": ("training.fit.cli", "Fit mixtures of K homogeneous media through the LUTs."),
    "train": ("training.train.cli", "Staged training of Enc, Dec_R, Dec_T."),
    "export": ("training.export.cli", "Export the ONNX graphs and the model card."),
    "validate": ("training.validate.cli", "Reproduce the paper's tables and figures."),
    "ablations": ("training.ablations.cli", "The paper's ablations (§5, §8), each trained and gated alike."),
    "report": (None, "Summary report of dataset, fits and model."),
    "bench": ("training.bench", "Run the benchmark suite and write bench/results.md."),
    "swatches": ("training.skin.swatches", "Plot the colours of the representative and outlier tones."),
    "mitsuba": ("training.validate.compare", "Mitsuba 3 reflectance of the network's mixture vs ours vs ground truth."),
    "realskin": ("training.realskin.cli", "Fit the skin model to measured human skin reflectance (NIST)."),
    "resampling": ("training.sim.resample_compare", "Radial profile estimators (histogram, KDE, CDF resampling) "
                   "compared at equal photons (paper §3)."),
    "demo": ("training.demo", "What `make demo` runs: the best end-to-end path available today."),
}


def parse_shard(text: str) -> tuple[int, int]:
    """argparse type of ``--shard I/N`` (0 <= I < N): this process's share of a shardable command."""
    import argparse

    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--shard must look like I/N (e.g. 0/4), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise argparse.ArgumentTypeError(f"--shard I/N needs 0 <= I < N, got {text!r}")
    return i, n


def _usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: python -m training <command> [options]   (each command has --help)", "", "commands:"]
    for name, (module, text) in COMMANDS.items():
        mark = "" if module else "  [not implemented yet]"
        lines.append(f"  {name:<{width}}  {text}{mark}")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    """Dispatch ``argv`` (without the program name) to a command; returns the exit status."""
    if not argv or argv[0] in {"-h", "--help", "help"}:
        print(_usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"error: unknown command {name!r}.\n\n{_usage()}", file=sys.stderr)
        return 2
    module_name, _ = COMMANDS[name]
    if module_name is None:
        print(f"error: `{name}` is not implemented yet (see the README's status table).", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            print(f"error: `{name}` is not implemented yet ({module_name} is missing).", file=sys.stderr)
            return 2
        raise
    return int(module.main(rest) or 0)
