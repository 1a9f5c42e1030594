"""``python -m training bench``: run every benchmark of the project and write ``bench/results.md``.

Each concept has its benchmarks in one module of this package (``training.bench.sim``, ``.fit``, ...; the
shipped runtime's in ``.runtime`` and the add-on's in ``.addon``, so that the extension zip holds no
benchmark code) exposing ``benchmarks(quick: bool) -> list[dict]`` with keys workload, ours, anchor, ratio,
error, notes (human-readable, units included).  This module only collects them, prints the machine and the
versions, and writes the tables (docs/contracts.md §6): one section per module, headed by the module's name, when it
ran, in which mode and under which load.  ``--only M ...`` re-runs those modules and replaces their sections
in an existing file, keeping the others (each keeps its own stamp).

Beside the Markdown file it writes the same tables as JSON (``bench/results.json``: :func:`results_record`), the
machine-readable home of every measured number the README and ``docs/`` quote (:mod:`training.bench.quotes`).
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import importlib.util
import json
import os
import platform
import re
import sys
import time
import traceback
from importlib import metadata
from pathlib import Path

from exporters.cli_io import (
    RESUME_KEPT,
    InputError,
    OneLineParser,
    atomic_file,
    check_output_file,
    guarded,
)

#: Benchmark modules in pipeline order; a module that does not exist yet is listed as such.
BENCH_MODULES = [
    "training.bench.foundation",
    "training.bench.sim",
    "training.bench.walker",
    "training.bench.data",
    "training.bench.fit",
    "training.bench.train",
    "training.bench.addon",
    "training.bench.live",
    "training.bench.render_cost",
    "training.bench.instructions",
    "training.bench.oblique",
    "training.bench.edit_cost",
    "training.bench.mixture_design",
    "training.bench.eevee",
    "training.bench.memory",
    "training.bench.runtime",
    "training.bench.validate",
    "training.bench.cluster",
    "training.bench.paper_cost",
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


SECTION = re.compile(r"^## `([\w.]+)`$", re.M)


def section(name: str, rows: list[dict], quick: bool, seconds: float) -> str:
    """One module's section: heading, stamp (date, mode, run time, load average) and table."""
    load = " ".join(f"{x:.1f}" for x in os.getloadavg())
    stamp = (f"Measured {dt.datetime.now().isoformat(timespec='seconds')} by `python -m training bench"
             f"{' --quick' if quick else ''} --only {name}` in {seconds:.0f} s; load average before the next "
             f"module: {load}.")
    return f"## `{name}`\n\n{stamp}\n\n{table(rows)}\n"


def read_sections(text: str) -> dict[str, str]:
    """The module sections of an existing results file, by module name, in file order."""
    marks = list(SECTION.finditer(text))
    return {m.group(1): text[m.start(): marks[i + 1].start() if i + 1 < len(marks) else len(text)].rstrip() + "\n"
            for i, m in enumerate(marks)}


_ROW = re.compile(r"^\|(.*)\|\s*$")


def _table_rows(section_text: str) -> list[dict[str, str]]:
    """The rows of the one table of a section, as {column: cell} (cells stripped; the separator line skipped)."""
    lines = [m.group(1) for m in map(_ROW.match, section_text.splitlines()) if m]
    if len(lines) < 2:
        return []
    header = [c.strip() for c in lines[0].split("|")]
    return [dict(zip(header, (c.strip() for c in line.split("|")), strict=True)) for line in lines[2:]]


def results_record(text: str) -> dict:
    """The JSON form of a results file's text: its machine lines and, per module, the stamp and the rows
    (the cells exactly as the Markdown shows them: units and notes included)."""
    head = text.split("\n## ", 1)[0]
    record: dict = {"written_by": "python -m training bench",
                    "machine": [ln[2:] for ln in head.splitlines() if ln.startswith("- ")], "sections": {}}
    for name, body in read_sections(text).items():
        paragraphs = [p.strip() for p in body.split("\n\n")]
        stamp = next((p for p in paragraphs[1:] if p and not p.startswith("|")), "")
        record["sections"][name] = {"stamp": stamp, "rows": _table_rows(body)}
    return record


def json_path(markdown: Path) -> Path:
    """The JSON file written beside a results Markdown file (``bench/results.md`` -> ``bench/results.json``)."""
    return markdown.with_suffix(".json")


def write_results(out: Path, text: str) -> None:
    """Write the Markdown results file and its JSON form beside it, each atomically."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(out, "w") as f:
        f.write(text)
    with atomic_file(json_path(out), "w") as f:
        f.write(json.dumps(results_record(text), indent=1, ensure_ascii=False) + "\n")


def _importable(name: str) -> bool:
    """Whether ``name`` is a module that can be imported (without importing it)."""
    if name in sys.modules:
        return True
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training bench", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results.md"),
                        help="Markdown file to write; its JSON form goes beside it (.json)")
    parser.add_argument("--quick", action="store_true", help="small sizes (about a minute per module)")
    parser.add_argument("--only", nargs="*", default=None,
                        help="module names to run (default: all); their sections replace those in --out")
    parser.add_argument("--seed", type=int, default=0, help="CLI contract only: each benchmark uses a fixed seed")
    return parser


@guarded("python -m training bench", RESUME_KEPT)
def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    unknown = [m for m in args.only or () if not _importable(m)]
    if unknown:
        raise InputError(f"--only: no benchmark module {unknown[0]}; known: {', '.join(BENCH_MODULES)}")
    check_output_file(args.out, "--out", suffixes=(".md",))
    modules = args.only or BENCH_MODULES
    sections = read_sections(args.out.read_text()) if args.only and args.out.is_file() else {}
    for name in modules:
        print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        started = time.perf_counter()
        rows = run_module(name, args.quick)
        sections[name] = section(name, rows, args.quick, time.perf_counter() - started)
    order = [m for m in BENCH_MODULES if m in sections] + [m for m in sections if m not in BENCH_MODULES]
    text = "\n".join(["# Benchmarks", "", "Written by `python -m training bench` (`make bench`); each section says "
                      "when, how and under which load it was measured.", "", *machine_lines(), "",
                      *(sections[m] for m in order)])
    write_results(args.out, text)
    print(text)
    return 0
