"""How paths are written into shipped files (model card, validation tables, figures' records).

Shipped files never record the absolute paths of the machine that built them: a path inside the repository
is recorded relative to its root (``data/laptop``, ``blender_addon/models``); one outside it by its last two
parts (``/scratch/me/lut_paper.npz`` -> ``me/lut_paper.npz``), enough to tell files apart.
"""

from __future__ import annotations

import importlib.util
import os
import re
from pathlib import Path
from types import ModuleType

#: The repository root (the folder holding training/ and exporters/).
REPO_ROOT = Path(__file__).resolve().parents[1]


def _shipped_models() -> ModuleType:
    """The add-on's ``blender_addon/models/__init__.py`` (the paths of the shipped model files), loaded by its
    file: importing it as ``blender_addon.models`` would run the add-on's ``__init__``, which imports bpy."""
    path = REPO_ROOT / "blender_addon" / "models" / "__init__.py"
    spec = importlib.util.spec_from_file_location("_spectral_skin_shipped_models", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_SHIPPED = _shipped_models()
#: The shipped models' folder and files, as the add-on names them (defaults of the training commands).
SHIPPED_MODEL_DIR: Path = _SHIPPED.MODEL_DIR
SHIPPED_MODEL: Path = _SHIPPED.INVERSION_MODEL
SHIPPED_DECODER: Path = _SHIPPED.DECODER_MODEL
SHIPPED_TABLE: Path = _SHIPPED.TEXEL_TABLE
SHIPPED_EDIT_TABLE: Path = _SHIPPED.EDIT_TABLE
SHIPPED_CARD: Path = _SHIPPED.MODEL_CARD


def portable(path: str | Path | None) -> str | None:
    """``path`` as a shipped file records it (module docstring); None stays None."""
    if path is None:
        return None
    # as written first (absolute, ".." removed, links kept): data/ may be a link to a disk outside the checkout
    # (docs/research/rebuilding.md), and data/laptop is what the user typed and means
    for p in (Path(os.path.abspath(Path(path).expanduser())), Path(path).expanduser().resolve()):
        try:
            return p.relative_to(REPO_ROOT).as_posix() or "."
        except ValueError:
            pass
    return Path(*p.parts[-2:]).as_posix() if len(p.parts) > 2 else p.name


def portable_command(program: str, argv: list[str]) -> str:
    """The command line ``program argv...`` as a shipped file records it: every argument that is an absolute
    path (alone or as ``--option=/path``) made ``portable``; the rest kept as typed (shell-quoted)."""
    import shlex

    def one(arg: str) -> str:
        opt, eq, value = arg.partition("=") if arg.startswith("--") else ("", "", arg)
        return f"{opt}{eq}{portable(value)}" if Path(value).is_absolute() else arg

    return " ".join([program, *(shlex.quote(one(a)) for a in argv)])


#: An absolute path inside a text: starts at the text's start or after a space, quote, "=", "(" or "`"; ends
#: before a space, quote, backtick, comma, semicolon or closing parenthesis; two parts at least (" /2" is no path).
_PATH_IN_TEXT = re.compile(r"""(?:(?<=^)|(?<=[\s"'=(`]))(?:/[^\s"'`,;()/]+){2,}""")


def portable_strings(obj):
    """``obj`` (JSON-like: dicts, lists, strings, numbers) with every absolute path, whole or inside a text
    (a command line, a note), made ``portable``."""
    if isinstance(obj, dict):
        return {k: portable_strings(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [portable_strings(v) for v in obj]
    if isinstance(obj, str):
        return _PATH_IN_TEXT.sub(lambda m: portable(m.group(0)), obj)
    return obj
