"""One home for each measured number: the benchmark figures the README and ``docs/`` quote are the bench's own.

``bench/results.json`` is the JSON form of ``bench/results.md`` (both written by ``python -m training bench``); a
page quotes a figure with a ``<!-- bench:NAME -->`` marker after the number (training.bench.quotes), and every
such number must be what the results show, rounded as the page rounds it.  CHANGELOG.md quotes no markers: each
entry keeps the numbers it was written with.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from training.bench import collect, quotes

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def test_results_json_is_the_markdown_tables():
    """The committed JSON holds exactly the tables of the committed Markdown file (one writer for both)."""
    md = (ROOT / "bench" / "results.md").read_text()
    assert json.loads((ROOT / "bench" / "results.json").read_text()) == collect.results_record(md)


def test_every_named_figure_is_in_the_results():
    results = quotes.load_results()
    for key in quotes.FIGURES:
        float(quotes.figure_text(results, key).replace(",", ""))


def test_the_pages_quote_the_numbers_the_bench_shows():
    results = quotes.load_results()
    problems = [f"{page.relative_to(ROOT)} {p}" for page in PAGES for p in quotes.stale_quotes(page.read_text(),
                                                                                             results)]
    assert not problems, "\n".join(problems)
    marked = sum(len(quotes.MARKER.findall(page.read_text())) for page in PAGES)
    assert marked >= 20, marked  # the README and the research pages quote the bench through markers


def test_a_stale_or_unknown_quote_is_named():
    results = {"sections": {"training.bench.paper_cost": {"stamp": "", "rows": [
        {"workload": "`paper` build: total (dataset, ...)", "ours": "31 CPU-h (15 h wall on 2 idle cores)"}]}}}
    page = ("fine: 31<!-- bench:paper_total_cpu_h --> CPU-h, rounded 3.1e1 no\n"
            "stale: ~63 CPU-h<!-- bench:paper_total_cpu_h -->\n"
            "unknown: 5<!-- bench:no_such_figure -->\n"
            "missing row: 2.03×<!-- bench:walker_vs_mcml_1_thread -->\n"
            "no number: <!-- bench:paper_total_cpu_h -->\n"
            "an example in code: `63<!-- bench:paper_total_cpu_h -->`")
    problems = quotes.stale_quotes(page, results)
    assert len(problems) == 4, problems
    assert problems[0] == "line 2: quotes 63 for paper_total_cpu_h, the bench shows 31"
    assert "no_such_figure" in problems[1] and "training.bench.walker" in problems[2]
    assert problems[3] == "line 5: bench:paper_total_cpu_h follows no number"



def test_refresh_rewrites_stale_numbers_as_the_page_rounds_them():
    results = {"sections": {"training.bench.paper_cost": {"stamp": "", "rows": [
        {"workload": "`paper` build: total (dataset, ...)", "ours": "31.46 CPU-h (15 h wall on 2 idle cores)"}]}}}
    page = ("stale: ~63 CPU-h<!-- bench:paper_total_cpu_h --> and 63.0<!-- bench:paper_total_cpu_h -->\n"
            "kept: 31<!-- bench:paper_total_cpu_h -->, unknown 5<!-- bench:no_such_figure -->\n"
            "an example in code: `63<!-- bench:paper_total_cpu_h -->`")
    text, changes = quotes.refreshed(page, results)
    assert text == ("stale: ~31 CPU-h<!-- bench:paper_total_cpu_h --> and 31.5<!-- bench:paper_total_cpu_h -->\n"
                    "kept: 31<!-- bench:paper_total_cpu_h -->, unknown 5<!-- bench:no_such_figure -->\n"
                    "an example in code: `63<!-- bench:paper_total_cpu_h -->`")
    assert changes == ["line 1: paper_total_cpu_h 63 -> 31", "line 1: paper_total_cpu_h 63.0 -> 31.5"]
    assert [p for p in quotes.stale_quotes(text, results) if "no_such_figure" not in p] == []

@pytest.mark.parametrize(("quoted", "measured", "same"), [
    ("31", "31", True), ("2.0", "2.03", True), ("2.03", "2.03", True), ("2.1", "2.03", False),
    ("450", "450", True), ("620", "450", False), ("44,299", "44,299", True), ("0.85", "0.849", True),
])
def test_rounding(quoted, measured, same):
    assert quotes.agrees(quoted, measured) is same


def test_the_bench_writes_the_json_beside_the_markdown(tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "bench_mod_q.py").write_text(
        "def benchmarks(quick):\n    return [{'workload': 'w', 'ours': '12.5 CPU-h', 'ratio': '2x'}]\n")
    out = tmp_path / "results.md"
    assert collect.main(["--out", str(out), "--only", "bench_mod_q"]) == 0
    rec = json.loads((tmp_path / "results.json").read_text())
    assert rec == collect.results_record(out.read_text())
    row = rec["sections"]["bench_mod_q"]["rows"][0]
    assert row == {"workload": "w", "ours": "12.5 CPU-h", "anchor": "", "ratio": "2x", "error": "", "notes": ""}


def test_the_benchmark_guide_lists_every_module():
    text = (ROOT / "docs" / "dev" / "benchmarks.md").read_text()
    assert [m for m in collect.BENCH_MODULES if f"| `{m}` |" not in text] == []
