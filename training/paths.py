"""How paths are written into shipped files (model card, validation tables, figures' records).

Shipped files never record the absolute paths of the machine that built them: a path inside the repository
is recorded relative to its root (``data/laptop``, ``blender_addon/models``); one outside it by its last two
parts (``/scratch/me/lut_paper.npz`` -> ``me/lut_paper.npz``), enough to tell files apart.
"""

from __future__ import annotations

from pathlib import Path

#: The repository root (the folder holding training/ and exporters/).
REPO_ROOT = Path(__file__).resolve().parents[1]


def portable(path: str | Path | None) -> str | None:
    """``path`` as a shipped file records it (module docstring); None stays None."""
    if path is None:
        return None
    p = Path(path).expanduser().resolve()
    try:
        return p.relative_to(REPO_ROOT).as_posix() or "."
    except ValueError:
        return Path(*p.parts[-2:]).as_posix() if len(p.parts) > 2 else p.name
