"""``python -m training bench``: run every benchmark of the project and write ``bench/results.md``.

Each concept owns its benchmarks in a ``bench`` module exposing ``benchmarks(quick: bool) -> list[dict]``
with keys workload, ours, anchor, ratio, error, notes (human-readable, units included).  This module only
collects them, prints the machine and the versions, and writes the table (SPEC §6).
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import os
import platform
import sys
import time
import traceback
from importlib import metadata
from pathlib import Path

#: Benchmark modules in pipeline order; a module that does not exist yet is listed as such.
BENCH_MODULES = [
    "training.bench_foundation",
    "training.sim.bench",
    "training.data.bench",
    "training.fit.bench",
    "training.train.bench",
    "blender_addon.bench",
    "exporters.bench",
    "training.validate.bench",
]
COLUMNS = ["workload", "ours", "anchor", "ratio", "error", "notes"]
PACKAGES = ["torch", "numpy", "onnxruntime", "OpenImageIO", "colour-science", "bpy", "iadpython", "mitsuba"]


def machine_lines() -> list[str]:
    """Machine and package versions, one Markdown bullet each."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    lines = [f"- machine: {cpu}, {os.cpu_count()} logical cores, Python {platform.python_version()}"]
    versions = []
    for name in PACKAGES:
        try:
            versions.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{name} (not installed)")
    lines.append("- versions: " + ", ".join(versions))
    return lines


def run_module(name: str, quick: bool) -> list[dict]:
    """The rows of one benchmark module; a missing module or a failure becomes an honest row."""
    try:
        module = importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name and name.startswith(exc.name):
            return [{"workload": name, "notes": "not built yet"}]
        raise
    try:
        return list(module.benchmarks(quick))
    except Exception as exc:  # a broken benchmark must not hide the others
        traceback.print_exc()
        return [{"workload": name, "notes": f"FAILED: {type(exc).__name__}: {exc}"}]


def table(rows: list[dict]) -> str:
    """Markdown table of the rows (missing cells are empty)."""
    out = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        out.append("| " + " | ".join(str(row.get(c, "")).replace("|", "/") for c in COLUMNS) + " |")
    return "\n".join(out)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m training bench", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results.md"), help="Markdown file to write")
    parser.add_argument("--quick", action="store_true", help="small sizes (about a minute per module)")
    parser.add_argument("--only", nargs="*", default=None, help="module names to run (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="CLI contract only: each benchmark uses a fixed seed")
    args = parser.parse_args(argv)
    modules = args.only or BENCH_MODULES
    rows, started = [], time.perf_counter()
    for name in modules:
        print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        rows.extend(run_module(name, args.quick))
    text = "\n".join(
        [
            "# Benchmarks",
            "",
            f"Written by `python -m training bench{' --quick' if args.quick else ''}` on "
            f"{dt.datetime.now().isoformat(timespec='seconds')} in {time.perf_counter() - started:.0f} s.",
            "",
            *machine_lines(),
            "",
            table(rows),
            "",
        ]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    return 0
