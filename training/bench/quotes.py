"""The measured numbers the README and ``docs/`` quote, read from the bench's own results (``bench/results.json``).

A page quotes a benchmark number by following it with a marker naming the figure::

    the projected `paper` build is 31<!-- bench:paper_total_cpu_h --> CPU-hours

The marker is an HTML comment, so it shows neither on a code host nor in the built site.  :data:`FIGURES` says
where each named figure lives: the module's section, a piece of its row's workload, the column, and a pattern
whose group is the number as the table prints it.  :func:`stale_quotes` lists every marker whose number is not
the bench's (rounded to as many decimals as the page gives); ``tests/test_doc_numbers.py`` runs it on the README
and every page of ``docs/``, and ``docs/conf.py`` turns each finding into a warning, so ``make docs`` (warnings
are errors) fails on a stale number.  When a benchmark is re-run and a number moves, the pages that quote it fail
until they say the new number: ``python -m training.bench.quotes --refresh README.md docs/...`` rewrites the
marked numbers (:func:`refreshed`); the sentences around them still need a reader.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS_JSON = ROOT / "bench" / "results.json"


@dataclass(frozen=True)
class Figure:
    """Where one quoted number lives in the results: ``module``'s section, the first row whose workload contains
    ``row`` (and ``also``, when given), the cell of ``column``, and ``pattern`` (its first group is the number)."""

    module: str
    row: str
    column: str
    pattern: str
    also: str = ""


_WALK = "simulate-layers end to end"
_HEAD = "render cost, demo head "
_PAPER = "`paper` build: "
#: Every benchmark figure a page may quote, by name.
FIGURES: dict[str, Figure] = {
    "paper_total_cpu_h": Figure("paper_cost", _PAPER + "total", "ours", r"([\d.]+) CPU-h"),
    "paper_total_wall_h": Figure("paper_cost", _PAPER + "total", "ours", r"\(([\d.]+) h wall"),
    "paper_goal_cpu_h": Figure("paper_cost", _PAPER + "total", "error", r"<= ([\d.]+) CPU-h"),
    "paper_walks_cpu_h": Figure("paper_cost", _PAPER + "dataset walks", "ours", r"([\d.]+) CPU-h"),
    "paper_reweighting_cpu_h": Figure("paper_cost", _PAPER + "reweighting", "ours", r"([\d.]+) CPU-h"),
    "paper_fits_cpu_h": Figure("paper_cost", _PAPER + "fits", "ours", r"([\d.]+) CPU-h"),
    "paper_training_cpu_h": Figure("paper_cost", _PAPER + "training", "ours", r"([\d.]+) CPU-h"),
    "paper_validation_cpu_h": Figure("paper_cost", _PAPER + "validation", "ours", r"([\d.]+) CPU-h"),
    "paper_memory_gb": Figure("paper_cost", _PAPER + "walk records", "ours", r"([\d.]+) GB"),
    "paper_disk_gb": Figure("paper_cost", _PAPER + "disk", "ours", r"([\d.]+) GB"),
    "fit_cpu_s_per_tone": Figure("paper_cost", _PAPER + "fits", "notes", r"([\d.]+) CPU-s per tone in chunks of 64"),
    "walker_vs_mcml_1_thread": Figure("walker", _WALK, "ratio", r"([\d.]+)x wall"),
    "walker_vs_mcml_2_threads": Figure("walker", "the same, 2 threads", "ratio", r"([\d.]+)x MCML's 1-core rate"),
    "walker_photons_per_s": Figure("walker", _WALK, "ours", r"([\d,]+) photons/s wall"),
    "mcml_photons_per_s": Figure("walker", _WALK, "anchor", r"([\d,]+) photons/s wall"),
    "reweighted_vs_direct_time": Figure("walker", "simulate one tone", "ratio", r"([\d.]+)x the direct time"),
    "fit_schedule_speedup": Figure("fit", "fit K=1,2,3 schedule", "ratio", r"([\d.]+)x"),
    "bake_4k_peak_mib": Figure("memory", "bake.py peak RSS", "ours", r"([\d,]+) MiB peak RSS"),
    "bake_4k_fast_s": Figure("runtime", "bake 4096x4096 8-bit sRGB PNG", "ours", r"([\d.]+) s wall"),
    "live_memory_vs_principled": Figure("live", "live group (default)", "ratio", r"process memory ([\d.]+)x"),
    "baked_memory_vs_principled": Figure("live", "baked maps", "ratio", r"process memory ([\d.]+)x"),
    **{f"{name}_{part}_peak_mb": Figure("live", row, column, rf"{what} ([\d,]+) MB")
       for name, row in (("live", "live group (default)"), ("baked", "baked maps"))
       for part, column, what in (("process", "ours", "process peak"), ("cycles", "ours", "Cycles' own peak"),
                                  ("principled_cycles", "anchor", "Cycles' own peak"))},
    **{f"appended_{name}cycles_peak_mb": Figure("live", "skins appended from a file each", column, pattern)
       for name, column, pattern in (("", "ours", r"^Cycles' own peak ([\d,]+) MB"),
                                     ("copies_", "ours", r"without the merge: Cycles' own peak ([\d,]+) MB"),
                                     ("principled_", "anchor", r"Cycles' own peak ([\d,]+) MB"))},
    "live_operator_s": Figure("live", "live group (default)", "ours", r"operator ([\d.]+) s"),
    "live_operator_thread_s": Figure("live", "live group (default)", "ours", r"CPU ([\d.]+) s on the calling thread"),
    "live_operator_cpu_s": Figure("live", "live group (default)", "ours", r"calling thread, ([\d.]+) s in all"),
    "live_render_time_vs_principled": Figure("live", "live group (default)", "ratio", r"time ([\d.]+)x"),
    "live_noise_time_vs_principled": Figure("render_cost", "live group (default) vs Principled", "ratio",
                                            r"time to equal noise ([\d.]+)x", _HEAD),
    "live_noise_vs_principled": Figure("render_cost", "live group (default) vs Principled", "ratio",
                                       r"noise at equal samples ([\d.]+)x", _HEAD),
    "live_relative_noise_time_vs_principled": Figure("render_cost", "live group (default) vs Principled", "ratio",
                                                     r"time to equal noise relative to the image mean ([\d.]+)x",
                                                     _HEAD),
    **{f"{scene}_nested_vs_per_channel_noise_time": Figure("render_cost", "live group (default) vs the live group "
                                                          "with single-channel closures", "ratio",
                                                          r"time to equal noise ([\d.]+)x", also)
       for scene, also in (("head", _HEAD), ("backlit_head", "back-lit head scene"),
                           ("backlit_plate", "back-lit plate scene"))},
    "live_time_per_sample_vs_principled": Figure("render_cost", "live group (default) vs Principled", "ratio",
                                                 r"time per sample ([\d.]+)x", _HEAD),
    **{f"{scene}_paired_{what}": Figure("render_cost", "time per sample paired in one process", "ratio", pattern,
                                         also)
       for scene, also in (("head", _HEAD), ("backlit_head", "back-lit head scene"),
                           ("backlit_plate", "back-lit plate scene"))
       for what, pattern in (("time_per_sample", r"paired time per sample ([\d.]+)x"),
                             ("time_per_sample_low", r"interval ([\d.]+)-"),
                             ("time_per_sample_high", r"interval [\d.]+-([\d.]+)\)"),
                             ("noise", r"noise at equal samples ([\d.]+)x"),
                             ("noise_time", r"time to equal noise ([\d.]+)x"),
                             ("noise_time_low", r"time to equal noise [\d.]+x \(([\d.]+)-"),
                             ("noise_time_high", r"time to equal noise [\d.]+x \([\d.]+-([\d.]+)\)"))},
    "baked_time_per_sample_vs_principled": Figure("render_cost", "baked maps (Bake, packed) vs Principled", "ratio",
                                                  r"time per sample ([\d.]+)x", _HEAD),
    "per_channel_noise_time_vs_principled": Figure("render_cost", "single-channel closures (the earlier design; "
                                                   "diagnostic) vs Principled", "ratio",
                                                   r"time to equal noise ([\d.]+)x", _HEAD),
    "per_channel_noise_vs_principled": Figure("render_cost", "single-channel closures (the earlier design; "
                                              "diagnostic) vs Principled", "ratio",
                                              r"noise at equal samples ([\d.]+)x", _HEAD),
    **{f"{scene}_{what}": Figure("render_cost", f"{design} vs Principled", "ratio", pattern, scene.replace("_", " ")
                                 .replace("backlit", "back-lit") + " scene")
       for scene in ("backlit_head", "backlit_plate")
       for design, prefix in (("live group (default)", ""), ("single-channel closures (the earlier design; diagnostic)",
                                                              "per_channel_"), ("K RGB closures (OSL; diagnostic of "
                                                                                "the noise)", "osl_"))
       for what, pattern in ((prefix + "noise_time", r"time to equal noise ([\d.]+)x"),
                             (prefix + "noise", r"noise at equal samples ([\d.]+)x"),
                             (prefix + "relative_noise", r"relative to the image mean ([\d.]+)x"),
                             (prefix + "relative_noise_time", r"time to equal noise relative to the image mean "
                                                              r"([\d.]+)x"),
                             (prefix + "time_per_sample", r"time per sample ([\d.]+)x"))},
    **{f"edits_{mode}_time_equal_samples": Figure("edit_cost", label, "ratio", r"time at equal samples ([\d.]+)x")
       for mode, label in (("neutral", "at neutral"), ("tan", "at preset tan"), ("flush", "at preset flush"),
                           ("pallor", "at preset pallor"), ("three", "between two levels, from its cache"),
                           ("three_table", "read from the table (not cached)"),
                           ("three_spare", "from a spare cache"),
                           ("flush_mask", "painted by the Edit Mask"), ("flush_linked", "fed to each control"),
                           ("blood_linked", "Blood alone painted by a mask"),
                           ("flush_frame", "from the mask cache's line"),
                           ("flush_frame_table", "the same frame with the mask cache holding no edit"))},
    "edit_images_mb": Figure("edit_cost", "edit table in Blender", "ours", r"images ([\d.]+) MB"),
    "edit_operator_s": Figure("edit_cost", "edit table in Blender", "ours", r"operator ([\d.]+) s"),
    "edit_operator_cpu_s": Figure("edit_cost", "edit table in Blender", "ours", r"\(([\d.]+) CPU-s\)"),
    **{f"counted_{name}_{part}": Figure("instructions", row, "ratio", rf"{label} ([\d.]+)x")
       for name, row in (("live", "live group (default) vs Principled"), ("bake", "baked maps"),
                         ("tan", "tan preset"), ("flush", "flush preset"), ("pallor", "pallor preset"),
                         ("three", "between two levels, from its cache"),
                         ("three_table", "read from the table (not cached)"),
                         ("three_spare", "from a spare cache"),
                         ("flush_mask", "painted by the Edit Mask"), ("flush_linked", "fed to each control"),
                         ("blood_linked", "Blood alone painted by a mask"),
                         ("flush_frame", "from the mask cache's line"),
                         ("flush_frame_table", "the same frame with the mask cache holding no edit"))
       for part, label in (("instructions", "instructions"), ("shading", "shading"), ("walks", "walks"))},
    **{f"counted_{name}_dispatches": Figure("instructions", row, column, r"([\d.]+) SVM dispatches")
       for name, row, column in (("live", "live group (default) vs Principled", "ours"),
                                 ("principled", "live group (default) vs Principled", "anchor"),
                                 ("bake", "baked maps", "ours"), ("tan", "tan preset", "ours"),
                                 ("flush", "flush preset", "ours"), ("pallor", "pallor preset", "ours"),
                                 ("three", "between two levels, from its cache", "ours"),
                                 ("three_table", "read from the table (not cached)", "ours"),
                                 ("three_spare", "from a spare cache", "ours"),
                                 ("flush_mask", "painted by the Edit Mask", "ours"),
                                 ("flush_linked", "fed to each control", "ours"),
                                 ("blood_linked", "Blood alone painted by a mask", "ours"))},
    "grazing_cost": Figure("oblique", "grazing-light correction vs without", "ratio", r"time ([\d.]+)x"),
    "eevee_first_render_vs_principled": Figure("eevee", "EEVEE first render", "ratio", r"first render ([\d.]+)x"),
    "onnx_vs_torch_inference": Figure("train", "skin_inversion.onnx inference", "ratio", r"([\d.]+)x"),
}

#: A quoted number followed (within a few characters: a unit, a sign) by its marker.
MARKER = re.compile(r"(?P<value>\d[\d,]*(?:\.\d+)?)(?P<between>[^\d<\n]{0,16}?)<!--\s*bench:(?P<key>\w+)\s*-->")
#: A marker with no number before it (a typo in the page).
_ANY_MARKER = re.compile(r"<!--\s*bench:(?P<key>\w+)\s*-->")


def load_results(path: Path = RESULTS_JSON) -> dict:
    """The bench's results as written by ``python -m training bench`` (training.bench.collect.results_record)."""
    return json.loads(Path(path).read_text())


def figure_text(results: dict, key: str) -> str:
    """The number named ``key`` as the results table prints it (``"31"``, ``"2.03"``, ``"450"``).

    Raises KeyError naming what is missing: the figure, the module's section, the row or the pattern."""
    fig = FIGURES[key]
    module = f"training.bench.{fig.module}"
    section = results["sections"].get(module)
    if section is None:
        raise KeyError(f"{key}: no section {module} in the results")
    row = next((r for r in section["rows"] if fig.row in r.get("workload", "") and fig.also in r.get("workload", "")),
               None)
    if row is None:
        raise KeyError(f"{key}: no row with {fig.row!r} in {module}")
    found = re.search(fig.pattern, row.get(fig.column, ""))
    if found is None:
        raise KeyError(f"{key}: {fig.pattern!r} not in the {fig.column} cell of {fig.row!r} ({module})")
    return found.group(1)


def _number(text: str) -> float:
    return float(text.replace(",", ""))


def _decimals(text: str) -> int:
    return len(text.split(".", 1)[1]) if "." in text else 0


def agrees(quoted: str, measured: str) -> bool:
    """Whether a page's ``quoted`` number is the bench's ``measured`` one, rounded as the page rounds it."""
    digits = _decimals(quoted)
    return abs(round(_number(measured), digits) - _number(quoted)) < 0.5 * 10.0 ** -digits


#: Code: fenced blocks and inline spans, where a marker is an example of the syntax, not a quote.
_CODE = re.compile(r"```.*?```|`[^`\n]+`", re.S)


def stale_quotes(text: str, results: dict) -> list[str]:
    """Each marker of a page whose number differs from the bench's (or names no figure), as one line each:
    ``line N: quotes X for KEY, the bench shows Y``.  Markers inside code (spans, fenced blocks) are examples and
    are not read."""
    text = _CODE.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)
    problems = []
    quoted_at = {m.end(): m for m in MARKER.finditer(text)}
    for marker in _ANY_MARKER.finditer(text):
        line = text.count("\n", 0, marker.start()) + 1
        key = marker.group("key")
        match = quoted_at.get(marker.end())
        if key not in FIGURES:
            problems.append(f"line {line}: bench:{key} names no figure of training.bench.quotes.FIGURES")
            continue
        if match is None:
            problems.append(f"line {line}: bench:{key} follows no number")
            continue
        try:
            measured = figure_text(results, key)
        except KeyError as exc:
            problems.append(f"line {line}: {exc.args[0]}")
            continue
        if not agrees(match.group("value"), measured):
            problems.append(f"line {line}: quotes {match.group('value')} for {key}, the bench shows {measured}")
    return problems


def refreshed(text: str, results: dict) -> tuple[str, list[str]]:
    """``text`` with every marked number replaced by the bench's, rounded as the page rounds it, and one line per
    change (``line N: KEY X -> Y``).  Markers inside code, and markers the bench cannot answer, are left as they are
    (:func:`stale_quotes` names those)."""
    masked = _CODE.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)
    pieces, changes, last = [], [], 0
    for match in MARKER.finditer(masked):
        key, quoted = match.group("key"), match.group("value")
        try:
            measured = figure_text(results, key) if key in FIGURES else None
        except KeyError:
            measured = None
        if measured is None or agrees(quoted, measured):
            continue
        digits = _decimals(quoted)
        value = f"{round(_number(measured), digits):,.{digits}f}" if "," in quoted else \
            f"{round(_number(measured), digits):.{digits}f}"
        pieces += [text[last:match.start("value")], value]
        last = match.end("value")
        changes.append(f"line {text.count(chr(10), 0, match.start()) + 1}: {key} {quoted} -> {value}")
    return "".join(pieces) + text[last:], changes


def main(argv: list[str] | None = None) -> int:
    """``python -m training.bench.quotes [--refresh] PAGE ...``: name the stale quotes of the pages, or rewrite
    them to the numbers of bench/results.json (after a bench run)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m training.bench.quotes", description=main.__doc__)
    parser.add_argument("pages", nargs="+", type=Path)
    parser.add_argument("--refresh", action="store_true", help="rewrite the quoted numbers in place")
    args = parser.parse_args(argv)
    results, stale = load_results(), 0
    for page in args.pages:
        text, changes = page.read_text(), []
        if args.refresh:
            text, changes = refreshed(text, results)
            if changes:
                page.write_text(text)
        problems = stale_quotes(text, results)
        for line in changes + problems:
            print(f"{page}: {line}")
        stale += len(problems)
    return 1 if stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
