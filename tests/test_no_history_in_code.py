"""Comments and docstrings explain the code as it is: no issue numbers and no dates in them.

Every ``.py`` file of ``exporters``, ``training``, ``blender_addon``, ``tests`` and the root ``__init__.py`` is
tokenized (``tokenize``); its comments and its docstrings (every string that stands alone as a statement, as
``ast`` finds them: module, class and function docstrings and the attribute docstrings after an assignment) are
searched for ``HISTORY``.  Strings that are data (a value written into a report, a model card, a fixture) are not
searched.  History belongs in commit messages; a hit is reported as ``file:line: match | line``.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("exporters", "training", "blender_addon", "tests")

_MONTH = r"(?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\.?"
#: What narrates history: "issue", "issues", "stop", "PR" or "pull request" followed by a number, a "#" followed
#: by digits (not a hex colour, not the ``#:`` of an attribute comment), an ISO date (YYYY-MM-DD), or a date
#: written with a month's name (month day, year or day month year).
HISTORY = re.compile(
    r"\b(?:issues?|stops?|PR|pull request)\s*#?\d+\b"
    r"|(?<![\w&])#\d+\b"
    r"|\b(?:19|20)\d\d-[01]\d-[0-3]\d\b"
    rf"|\b{_MONTH} \d{{1,2}},? (?:19|20)\d\d\b"
    rf"|\b\d{{1,2}} {_MONTH} (?:19|20)\d\d\b",
    re.IGNORECASE,
)


def python_files() -> list[Path]:
    return [ROOT / "__init__.py"] + [p for top in TOPS for p in sorted((ROOT / top).rglob("*.py"))]


def docstring_starts(source: str) -> set[tuple[int, int]]:
    """(line, column) of every string that stands alone as a statement (a docstring of any kind)."""
    return {(node.lineno, node.col_offset) for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)}


def history_in(source: str) -> list[tuple[int, str, str]]:
    """(line number, match, stripped line) of each ``HISTORY`` match in the comments and docstrings of
    ``source``."""
    docs = docstring_starts(source)
    hits = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT or (tok.type == tokenize.STRING and tok.start in docs):
            for offset, line in enumerate(tok.string.splitlines()):
                hits += [(tok.start[0] + offset, m.group(0), line.strip()) for m in HISTORY.finditer(line)]
    return hits


def test_scanner_finds_history_in_comments_and_docstrings_only():
    """The scanner itself, on a made-up module: it flags comments and docstrings, not data strings."""
    source = '\n'.join([
        '"""Module doc, see issue 12."""',
        'X = 1  # fixed in #7',
        'Y = 2',
        '"""Attribute doc written 2025-01-31."""',
        'STAMP = "2025-01-31"  # a measured value: data',
        'COLOUR = "#123456"',
        'def f():',
        '    """Made on 3 March 2025, see stop 4."""',
        '    return "issue 9"',
        '# a hex colour #a0b1c2 and the #: marker are fine',
        '',
    ])
    assert [(line, match) for line, match, _ in history_in(source)] == [
        (1, "issue 12"), (2, "#7"), (4, "2025-01-31"), (8, "3 March 2025"), (8, "stop 4")]


def test_no_issue_numbers_or_dates_in_comments_or_docstrings():
    found = [f"{path.relative_to(ROOT)}:{line}: {match!r} | {text[:100]}"
             for path in python_files() for line, match, text in history_in(path.read_text())]
    assert not found, ("history in comments or docstrings (say what the code does; history goes in commit "
                       "messages):\n" + "\n".join(found))
