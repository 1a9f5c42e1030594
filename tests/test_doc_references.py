"""Every reference to the project's documents resolves inside the repository.

Code, tests, the README and the docs cite the contracts and the research as ``docs/contracts.md §3`` or
``docs/research/blender_cycles.md §2d``.  Each such path must exist, and where a section label is given the
file must have a Markdown heading carrying it (``## §3. ...``, ``### §2d. ...``).  References to documents
that live outside the repository (the old "SPEC §N" and ``notes/*.md``) must not come back.  Relative links
in the Markdown files must resolve too.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: What is scanned: the packages, the tests, the README and the docs, text files only.
SCANNED = ["exporters", "training", "blender_addon", "tests", "docs", "README.md", "__init__.py"]
TEXT_SUFFIXES = {".py", ".md", ".csv", ".toml", ".txt", ".json", ".osl", ".cfg", ".ini", ".yaml", ".yml"}

#: ``docs/<path>`` optionally followed by `` §<label>``.
DOC_REF = re.compile(r"(?<![\w./-])(docs/[\w./-]*[\w/])(?:\s*§\s*(\w+))?")
#: References to documents outside the repository.
STALE = [re.compile(r"\bSPEC\b"), re.compile(r"\bnotes/"), re.compile(r"\.\./shared\b")]
#: Matches of STALE that mean something else: the --scheduler option's metavar.
ALLOWED_STALE = {'metavar="SPEC"'}
#: Relative Markdown links ``[text](target)``.
MD_LINK = re.compile(r"\]\(([^)\s]+)\)")


def scanned_files() -> list[Path]:
    out = []
    for name in SCANNED:
        path = ROOT / name
        paths = [path] if path.is_file() else sorted(path.rglob("*"))
        out += [p for p in paths if p.is_file() and p.suffix in TEXT_SUFFIXES and "__pycache__" not in p.parts]
    return out


def section_labels(md: Path) -> set[str]:
    """Labels ``§X`` carried by the Markdown headings of ``md``."""
    heads = [line for line in md.read_text(encoding="utf-8").splitlines() if line.startswith("#")]
    return {label for line in heads for label in re.findall(r"§(\w+)", line)}


def problems(text: str, where: str, root: Path = ROOT) -> list[str]:
    """One line per reference in ``text`` that does not resolve inside ``root`` (``where`` names the file)."""
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        for m in DOC_REF.finditer(line):
            path, label = m.group(1).rstrip("."), m.group(2)
            target = root / path
            if not target.exists():
                out.append(f"{where}:{n}: {path} does not exist")
            elif label and not (target.suffix == ".md" and label in section_labels(target)):
                out.append(f"{where}:{n}: {path} has no heading §{label}")
        rest = line
        for ok in ALLOWED_STALE:
            rest = rest.replace(ok, "")
        out += [f"{where}:{n}: reference outside the repository: {line.strip()}" for pat in STALE if pat.search(rest)]
    return out


def test_every_document_reference_resolves():
    found, bad = 0, []
    for path in scanned_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        found += len(DOC_REF.findall(text))
        if path.resolve() != Path(__file__).resolve():  # this file's examples are broken on purpose
            bad += problems(text, str(path.relative_to(ROOT)))
    assert found > 100, f"only {found} docs/ references found: is the scan looking at the right files?"
    assert not bad, "\n".join(bad)


def test_markdown_links_resolve():
    bad = []
    for md in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for target in MD_LINK.findall(md.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue  # a URL or an anchor in the same file
            if not (md.parent / target.split("#")[0]).exists():
                bad.append(f"{md.relative_to(ROOT)}: link to {target} does not resolve")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("text, expected", [
    ("see docs/contracts.md §3", 0),
    ("see docs/contracts.md §99", 1),                       # no such section
    ("see docs/research/blender_cycles.md §2d", 0),
    ("see docs/research/blender_cycles.md §2z", 1),
    ("see docs/research/nowhere.md", 1),                    # no such file
    ("as SPEC §4 says", 1),                                  # a document outside the repository
    ("notes/mitsuba.md has the facts", 1),
    ('metavar="SPEC"', 0),
])
def test_the_check_catches_broken_references(text, expected):
    assert len(problems(text, "example")) == expected
