"""Architecture boundaries and the command line's contract (docs/contracts.md §2)."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

from training.commands import dispatch
from training.commands.dispatch import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
SPEC_COMMANDS = [
    "simulate-layers", "simulate", "lut", "dataset", "fit", "train", "export", "validate", "report", "bench"
]


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_exporters_import_without_torch_or_bpy():
    code = (
        "import sys; sys.modules['torch'] = None; sys.modules['bpy'] = None; import exporters, pkgutil, importlib\n"
        "for m in pkgutil.iter_modules(exporters.__path__): importlib.import_module('exporters.' + m.name)\n"
        "assert 'torch' not in [k for k, v in sys.modules.items() if v is not None]"
    )
    result = run("-c", code)
    assert result.returncode == 0, result.stderr


def test_help_lists_every_spec_command():
    result = run("-m", "training", "--help")
    assert result.returncode == 0
    for name in SPEC_COMMANDS:
        assert f"  {name} " in result.stdout, name


def test_every_contract_command_is_built():
    """Every command that docs/contracts.md §2 names is dispatched to a module that exists (no stub)."""
    text = (ROOT / "docs" / "contracts.md").read_text(encoding="utf-8")
    section = text.split("## §2.", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"^- `([a-z][a-z-]*)", section, re.M))
    listed = section.split("documented in the research guide")[0].rsplit("\n", 1)[-1]
    named |= set(re.findall(r"`([a-z][a-z-]*)`", listed))
    assert {"simulate-layers", "simulate", "lut", "fit", "report", "bench", "realskin"} <= named, named
    for name in sorted(named):
        assert name in COMMANDS, f"docs/contracts.md §2 names `{name}`, which python -m training does not have"
        assert importlib.util.find_spec(COMMANDS[name][0]) is not None, name


def test_unknown_command_exits_2():
    result = run("-m", "training", "no-such-command")
    assert result.returncode == 2 and "unknown command" in result.stderr


@pytest.mark.parametrize("name", [n for n, (m, _) in COMMANDS.items() if m is not None])
def test_built_commands_have_help(name, capsys):
    """Through the dispatcher that ``python -m training`` runs, in this process (each command's imports once per
    worker, where a process per command imported them again); the subprocess tests above cover the entry point."""
    try:
        code = dispatch.main([name, "--help"])
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    assert code in (0, None), out.err
    assert "usage:" in out.out and name in out.out


def test_no_merge_conflict_markers_in_the_sources_and_docs():
    """A merge resolved in one file and committed with markers in another is caught here."""
    suffixes = {".py", ".md", ".toml", ".txt", ".json", ".osl", ".cfg"}
    files = [p for folder in ("training", "exporters", "blender_addon", "tests", "docs", "bench")
             for p in (ROOT / folder).rglob("*") if p.suffix in suffixes and p.is_file()]
    files += [p for p in ROOT.iterdir() if p.is_file() and (p.suffix in suffixes or p.name == "Makefile")]
    marked = [str(p.relative_to(ROOT)) for p in files
              if any(line.startswith(("<<<<<<< ", ">>>>>>> ")) for line in p.read_text(errors="replace").splitlines())]
    assert len(files) > 100 and not marked, marked
