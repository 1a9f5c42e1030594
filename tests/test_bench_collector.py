"""`python -m training bench` collects each module's rows into its own section of the results file; `--only`
re-runs some modules and keeps the other sections as they were."""

from __future__ import annotations

import sys

from training.bench import collect as bench


def _module(folder, name: str, workload: str) -> None:
    (folder / f"{name}.py").write_text(
        "def benchmarks(quick):\n"
        f"    return [{{'workload': {workload!r}, 'ours': '1 s', 'notes': 'quick' if quick else 'full'}}]\n")
    sys.modules.pop(name, None)


def test_only_replaces_its_sections_and_keeps_the_others(tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "results.md"
    _module(tmp_path, "bench_mod_a", "first a")
    _module(tmp_path, "bench_mod_b", "first b")
    assert bench.main(["--out", str(out), "--quick", "--only", "bench_mod_a", "bench_mod_b"]) == 0
    _module(tmp_path, "bench_mod_a", "second a")
    assert bench.main(["--out", str(out), "--only", "bench_mod_a"]) == 0
    text = out.read_text()
    sections = bench.read_sections(text)
    assert list(sections) == ["bench_mod_a", "bench_mod_b"]
    assert "second a" in sections["bench_mod_a"] and "first a" not in text
    assert "| first b | 1 s |" in sections["bench_mod_b"] and "--quick --only bench_mod_b" in sections["bench_mod_b"]
    assert "--quick" not in sections["bench_mod_a"].splitlines()[2]
    assert text.count("- machine:") == 1 and text.startswith("# Benchmarks")


def test_a_failing_module_becomes_an_honest_row(tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "bench_mod_broken.py").write_text("def benchmarks(quick):\n    raise RuntimeError('no LUT')\n")
    rows = bench.run_module("bench_mod_broken", True)
    assert rows == [{"workload": "bench_mod_broken", "notes": "FAILED: RuntimeError: no LUT"}]
    assert bench.run_module("training.no_such_bench", True)[0]["notes"] == "not built yet"
