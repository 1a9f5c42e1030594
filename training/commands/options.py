"""argparse types shared by the commands of ``python -m training``; the checks of options, inputs and outputs
they share with ``blender_addon/bake.py`` are ``exporters.cli_io`` (re-exported here)."""

from __future__ import annotations

import argparse
import re
import sys

from exporters.cli_io import (  # noqa: F401 - the commands' shared front
    EXIT_BAD_INPUT,
    NOTHING_KEPT,
    RESUME_KEPT,
    InputError,
    OneLineParser,
    atomic_file,
    atomic_path,
    check_biophysical,
    check_input,
    check_output_file,
    check_output_folder,
    count,
    finite_float,
    fraction,
    guarded,
    in_range,
    non_negative_float,
    non_negative_int,
    output_lock,
    positive_float,
    require,
)
from training.cluster.engine import TaskError


def parse_shard(text: str) -> tuple[int, int]:
    """argparse type of ``--shard I/N`` (0 <= I < N): this process's share of a shardable command."""
    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--shard must look like I/N (e.g. 0/4), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise argparse.ArgumentTypeError(f"--shard I/N needs 0 <= I < N, got {text!r}")
    return i, n


def torch_device(text: str) -> str:
    """argparse type of ``--device``: "cpu", "cuda" or "cuda:N" (the devices the walk and torch's code here run
    on), checked without importing torch; whether a CUDA device is present is ``check_cuda``'s to say."""
    if re.fullmatch(r"cpu|cuda(:\d+)?", text) is None:
        raise argparse.ArgumentTypeError(f"must be cpu, cuda or cuda:N, got {text!r}")
    return text


def check_cuda(device: str) -> None:
    """ValueError naming the fix when ``device`` is a CUDA device and torch sees none."""
    if device.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise ValueError(f"--device {device}: torch sees no CUDA device here; use --device cpu")
        index = int(device.split(":")[1]) if ":" in device else 0
        if index >= torch.cuda.device_count():
            raise ValueError(f"--device {device}: torch sees {torch.cuda.device_count()} CUDA device(s) "
                             "(cuda:0 ...); pick one of them")


def triple(text: str, kind: type) -> list:
    """argparse type of an option taking one value for all three training stages or three comma-separated ones."""
    try:
        vals = [kind(v) for v in text.split(",")]
    except (ValueError, argparse.ArgumentTypeError) as exc:
        raise argparse.ArgumentTypeError(f"{exc} in {text!r}") from None
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"give one value or three comma-separated values, got {text!r}")
    return vals


#: Commands whose interrupted runs keep finished pieces (rerun to resume); the others write atomically.
RESUMABLE = frozenset({"lut", "dataset", "fit", "train", "validate", "ablations", "realskin", "demo"})


def command(name: str):
    """Decorator of a command's ``main``: the one-line answers of ``exporters.cli_io.guarded`` (bad input exit 2,
    a failed ``TaskError`` exit 1, Ctrl-C exit 130 saying what was kept)."""
    return guarded(f"python -m training {name}", RESUME_KEPT if name in RESUMABLE else NOTHING_KEPT, (TaskError,))


def shard_part(shard: tuple[int, int]) -> str:
    """The lock part of ``--shard I/N`` (exporters.cli_io.output_lock): shards of one output run together."""
    return "" if shard == (0, 1) else f"shard{shard[0]}of{shard[1]}"


def error_status(exc: Exception) -> int:
    """Print ``error: <exc>`` to stderr and return the command's exit status.

    2 for bad input (anything but a failed task: the user can fix the command), 1 for a task that failed
    while running (``training.cluster.engine.TaskError``).
    """
    print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
    return 1 if isinstance(exc, TaskError) else 2
