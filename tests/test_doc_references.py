"""Every reference to the project's documents resolves inside the repository.

Code, tests, the README and the docs cite the contracts and the research as ``docs/contracts.md §3`` or
``docs/research/blender_cycles.md §2d``.  Each such path must exist, and where a section label is given the
file must have a Markdown heading carrying it (``## §3. ...``, ``### §2d. ...``).  References to documents
that live outside the repository (the old "SPEC §N" and ``notes/*.md``) must not come back.  Relative links
in the Markdown files must resolve too, down to the heading a ``#anchor`` names; the README stays a front door
(at most 200 lines), and the documentation site's CLI reference renders every command.
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
#: The README is the front door; everything longer belongs in docs/ (docs/dev/documentation.md).
README_MAX_LINES = 200


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


def markdown_files() -> list[Path]:
    return [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]


def heading_anchors(md: Path) -> set[str]:
    """The anchors of ``md``'s headings as GitHub and MyST make them (lower case, punctuation dropped, spaces
    to hyphens), outside fenced code blocks."""
    anchors, fenced = set(), False
    for line in md.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(r"#{1,6} ", line):
            title = re.sub(r"[`*]", "", line.lstrip("#").strip()).lower()
            anchors.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return anchors


def link_problems(md: Path) -> list[str]:
    """One line per relative link of ``md`` that does not resolve: a missing file, or a missing heading."""
    bad = []
    for target in MD_LINK.findall(md.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target):
            continue  # a URL
        path, _, anchor = target.partition("#")
        linked = (md.parent / path).resolve() if path else md
        if not linked.exists():
            bad.append(f"{md.relative_to(ROOT)}: link to {target} does not resolve")
        elif anchor and linked.suffix == ".md" and anchor not in heading_anchors(linked):
            bad.append(f"{md.relative_to(ROOT)}: link to {target}: {linked.name} has no heading #{anchor}")
    return bad


def test_markdown_links_resolve():
    bad = [line for md in markdown_files() for line in link_problems(md)]
    assert not bad, "\n".join(bad)


def test_docs_link_markdown_only_inside_docs():
    """The site is built from docs/ alone: a page there cannot link another Markdown file outside it (it would
    be a broken link on the site); it includes the file in a page of its own instead (docs/changelog.md)."""
    docs = (ROOT / "docs").resolve()
    bad = []
    for md in sorted(docs.rglob("*.md")):
        for target in MD_LINK.findall(md.read_text(encoding="utf-8")):
            path = target.partition("#")[0]
            if path.endswith(".md") and not re.match(r"[a-z]+:", path):
                if docs not in (md.parent / path).resolve().parents:
                    bad.append(f"{md.relative_to(ROOT)}: links {target}, outside docs/")
    assert not bad, "\n".join(bad)


def test_the_link_check_catches_broken_links(tmp_path):
    page = ROOT / "docs" / "index.md"
    assert "dev" in {p.name for p in (ROOT / "docs").iterdir()}
    anchors = heading_anchors(ROOT / "docs" / "dev" / "documentation.md")
    assert anchors >= {"the-site", "warnings-are-errors-links-are-checked"}
    assert not link_problems(page)
    broken = tmp_path / "broken.md"
    broken.write_text("[a](nowhere.md) [b](#no-such-heading)\n# Real heading\n[c](#real-heading)\n", encoding="utf-8")
    problems_found = [line for line in _problems_outside_root(broken)]
    assert len(problems_found) == 2, problems_found


def _problems_outside_root(md: Path) -> list[str]:
    """link_problems for a file outside the repository (the test's own examples)."""
    global ROOT
    saved, ROOT = ROOT, md.parent
    try:
        return link_problems(md)
    finally:
        ROOT = saved


def test_readme_is_a_front_door():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines (at most {README_MAX_LINES}): move the detail to docs/ and link it")
    first_screen = "\n".join(lines[:40])
    assert "make demo" in first_screen and "make test" in first_screen, "the two set-up commands left the first screen"


def test_cli_reference_renders_every_command():
    """docs/reference/cli.md has a sphinx-argparse directive for every command of the dispatcher, reading the
    module's build_parser(), whose prog is the command line a user types."""
    from training.commands.dispatch import COMMANDS, command_parser

    text = (ROOT / "docs" / "reference" / "cli.md").read_text(encoding="utf-8")
    for name, (module, _) in COMMANDS.items():
        directive = f"```{{argparse}}\n:module: {module}\n:func: build_parser\n:prog: python -m training {name}\n```"
        assert directive in text, f"docs/reference/cli.md does not render `{name}`"
        assert command_parser(name).prog == f"python -m training {name}", name


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
