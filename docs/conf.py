"""Sphinx configuration of the documentation site (``make docs``; docs/dev/documentation.md)."""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")


def _import_script(name: str, path: Path) -> None:
    """Import a script that lives outside the packages under ``name``, for sphinx-argparse's ``:module:``."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules[name] = module


# blender_addon/bake.py is a script (its package imports bpy); the bake.py reference reads its parser.
_import_script("bake_script", ROOT / "blender_addon" / "bake.py")

project = "Spectral Skin SSS"
author = "Spectral Skin SSS contributors"
copyright = "the Spectral Skin SSS contributors, GPL-3.0-or-later"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = ["_build", "**/.ipynb_checkpoints"]
# The real-skin reports (docs/validation/realskin*/) are tables written by `python -m training realskin`, with no
# title of their own; the research guide's toctree gives them one, so Sphinx's "no title" notice is not a defect.
suppress_warnings = ["toc.no_title"]

# Markdown through MyST; headings get anchors so that `page.md#section` links resolve and are checked.
myst_enable_extensions = ["dollarmath", "deflist"]
myst_heading_anchors = 4

# The API reference: one page per module of `exporters` and `training`, generated at build time into
# the _generated/ folder beside reference/api.md (ignored by git).
autosummary_generate = True
# `make docs` empties the folder before the html build; the linkcheck build after it reuses those pages, and
# with them the html build's parsed environment (-d), instead of reading every module again.
autosummary_generate_overwrite = False
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_mock_imports: list[str] = []
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# Link checking without a network: `make docs` runs the linkcheck builder after the HTML one.  Internal links
# and references are resolved by Sphinx/MyST themselves (a missing one is a warning, hence an error under -W);
# external URLs are listed in DOCS_OUT/linkcheck/output.json as "ignored", never fetched.
linkcheck_ignore = [r"https?://.*", r"mailto:.*"]

html_theme = "alabaster"
html_title = "Spectral Skin SSS"
html_static_path: list[str] = []



#: Inline literals and interpreted text (roles), where a bar means itself already.
_LITERAL = re.compile(r"(``.+?``|`[^`]+`)")
#: The first line of a list item, a field, a directive or a comment: blocks whose indented lines are theirs.
_STRUCTURE = re.compile(r"^(\*|-|\+|\d+\.|#\.)\s|^:|^\.\.\s")
_LIST_ITEM = re.compile(r"^(\*|-|\+|\d+\.)\s")


#: A name ending in an underscore, which reStructuredText reads as a link.
_TRAILING_UNDERSCORE = re.compile(r"(?<=\w)_(?![\w])")


#: An asterisk that opens emphasis nothing on its line closes (``w *= albedo``): plain text, not markup.
_LONE_ASTERISK = re.compile(r"(?<!\S)\*(?=[^\s*])(?!.*\*)")


#: ``file:output`` is a file name and an output name, not a ``file:`` URI.
_FILE_SCHEME = re.compile(r"\bfile:(?!//)")


def _escape_text(text: str) -> str:
    text = _TRAILING_UNDERSCORE.sub(r"\\_", text.replace("|", "\\|"))
    text = _FILE_SCHEME.sub(r"file\\:", text)
    return _LONE_ASTERISK.sub(r"\\*", text)


def _escape(line: str) -> str:
    parts = _LITERAL.split(line)
    return "".join(part if i % 2 else _escape_text(part) for i, part in enumerate(parts))


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _blocks(lines: list[str]) -> list[list[str]]:
    """Runs of non-blank lines; a literal block (after a line ending in ``::``) stays one run, blanks included."""
    blocks: list[list[str]] = []
    current: list[str] = []
    literal_indent: int | None = None
    for line in lines:
        if literal_indent is not None:
            if not line.strip() or _indent(line) > literal_indent:
                current.append(line)
                continue
            literal_indent = None
            blocks.append(current)
            current = []
        if not line.strip():
            if current:
                blocks.append(current)
            current = []
            continue
        current.append(line)
        if line.rstrip().endswith("::"):
            literal_indent = _indent(line)
    if current:
        blocks.append(current)
    return blocks


def _split_lists(block: list[str]) -> list[list[str]]:
    """Split a block where a list starts under a sentence, or a sentence follows a list, without a blank line."""
    out = [[block[0]]]
    for line in block[1:]:
        first = out[-1][0]
        starts_list = _LIST_ITEM.match(line.lstrip()) and not _STRUCTURE.match(first.lstrip())
        ends_list = (_LIST_ITEM.match(first.lstrip()) and _indent(line) <= _indent(first)
                     and not _LIST_ITEM.match(line.lstrip()))
        items = [_indent(text) for text in out[-1] if _LIST_ITEM.match(text.lstrip())]
        nested_list = bool(_LIST_ITEM.match(line.lstrip()) and items and _indent(line) > items[-1])
        if starts_list and _indent(line) == _indent(first) or ends_list:
            out.append([line])
        elif nested_list:
            out[-1] += ["", line]
        else:
            out[-1].append(line)
    return out


def _literal(block: list[str]) -> list[str]:
    base = min(_indent(line) for line in block if line.strip())
    return [" " * base + "::", ""] + ["    " + line for line in block]


def plain_docstring_to_rst(app, what, name, obj, options, lines: list[str]) -> None:
    """Read the project's plain-text docstrings as reStructuredText the way they read as text.

    The docstrings are written to read well in ``help()`` and in the editor, with Sphinx roles where they link.
    A few habits of plain text mean something else in reStructuredText, so they are translated here rather
    than rewritten in every docstring:

    - ``|x|`` is an absolute value or a norm (``|Δw|``, ``|z| < 4``), not a substitution; a name ending in
      ``_`` (``MALLOC_TRIM_THRESHOLD_``) is not a link; ``w *= albedo`` opens no emphasis; ``file:output`` is
      no URI: outside inline literals, roles and literal blocks these are escaped (no docstring uses
      substitutions, line blocks, tables or named links);
    - an indented block after a paragraph (a usage line, an aligned list of options) and a paragraph with
      hanging indents (``name: text`` with its continuation lines indented, a formula under its sentence)
      are shown as written, as literal blocks;
    - a list that starts on the line after its introducing sentence (``Conventions:`` then ``* ...``), a
      list nested without a blank line, and a paragraph that follows a list without one, get the blank line
      reStructuredText wants.
    """
    out: list[str] = []
    previous: list[str] | None = None
    for raw in _blocks(lines):
        for block in (_split_lists(raw) if not raw[0].rstrip().endswith("::") else [raw]):
            if out:
                out.append("")
            first = block[0]
            structured = bool(_STRUCTURE.match(first.lstrip()))
            opens_literal = previous is not None and previous[-1].rstrip().endswith("::")
            if opens_literal and _indent(first) > _indent(previous[-1]):
                out += block  # the literal block the previous paragraph announced
            elif (previous is not None and not structured and _indent(first) > _indent(previous[0])
                  and not _STRUCTURE.match(previous[0].lstrip())):
                out += [" " * _indent(previous[0]) + "::", ""] + block  # an indented block under a paragraph
            elif not structured and any(_indent(line) > _indent(first) for line in block[1:]):
                head = [line for line in block if not line.rstrip().endswith("::")]
                out += _literal(block) if head == block else [_escape(line) for line in block]
            else:
                out += [_escape(line) for line in block]
            previous = block
    lines[:] = out


def _escape_help(data):
    """The parser data sphinx-argparse renders, with the help texts escaped as plain text (``|ln exposure|``)."""
    if isinstance(data, dict):
        return {key: _escape_text(value) if key == "help" and isinstance(value, str) else _escape_help(value)
                for key, value in data.items()}
    if isinstance(data, list):
        return [_escape_help(item) for item in data]
    return data


def _parse_parser_escaped(*args, **kwargs):
    return _escape_help(_parse_parser(*args, **kwargs))


import sphinxarg.ext  # noqa: E402  (after the helpers it is patched with)

_parse_parser = sphinxarg.ext.parse_parser
sphinxarg.ext.parse_parser = _parse_parser_escaped


def check_bench_numbers(app, docname: str, source: list[str]) -> None:
    """Warn (an error under ``make docs``'s -W) for every benchmark number a page quotes that the bench's own
    results (bench/results.json) no longer show (training.bench.quotes)."""
    from sphinx.util import logging

    from training.bench import quotes

    for problem in quotes.stale_quotes(source[0], quotes.load_results()):
        logging.getLogger(__name__).warning(f"stale benchmark number: {problem}", location=docname)


def setup(app) -> None:
    app.connect("source-read", check_bench_numbers)
    # After napoleon (priority 500), which turns the few Google-style sections into fields first.
    app.connect("autodoc-process-docstring", plain_docstring_to_rst, priority=600)
