"""argparse types shared by the commands of ``python -m training``."""

from __future__ import annotations

import argparse
import sys

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


def triple(text: str, kind: type) -> list:
    """argparse type of an option taking one value for all three training stages or three comma-separated ones."""
    vals = [kind(v) for v in text.split(",")]
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"give one value or three comma-separated values, got {text!r}")
    return vals


def error_status(exc: Exception) -> int:
    """Print ``error: <exc>`` to stderr and return the command's exit status.

    2 for bad input (anything but a failed task: the user can fix the command), 1 for a task that failed
    while running (``training.cluster.engine.TaskError``).
    """
    print(f"error: {exc}", file=sys.stderr)
    return 1 if isinstance(exc, TaskError) else 2
