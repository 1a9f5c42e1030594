"""Which fast-path table a bake uses: the one shipped beside the model, or one built for other options and
cached per user.  A table made from another model is refused with a warning (the bake then evaluates exactly)."""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path

from .. import inference, texel_table
from ..texel_records import CollapseOptions


def default_table_path(model_path: str | os.PathLike) -> Path:
    """Where a model's shipped table lives: ``<model stem>_table.npz`` beside the model."""
    p = Path(model_path)
    return p.with_name(f"{p.stem}_table.npz")


def table_cache_dir() -> Path:
    """Per-user folder of tables built for option sets no shipped table covers: $SPECTRAL_SKIN_SSS_CACHE, else
    $XDG_CACHE_HOME/spectral_skin_sss, else ~/.cache/spectral_skin_sss."""
    env = os.environ.get("SPECTRAL_SKIN_SSS_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "spectral_skin_sss"


def cached_table_path(model_sha256: str, options: CollapseOptions, step: float = texel_table.DEFAULT_STEP) -> Path:
    """The user-cache file of the table for a model, collapse options and grid step."""
    opts = hashlib.sha256(json.dumps(options.as_dict(), sort_keys=True).encode()).hexdigest()[:12]
    return table_cache_dir() / f"table_{model_sha256[:16]}_{opts}_step{step:g}.npz"


def find_table(model: inference.ModelFile, options: CollapseOptions, table_path=None,
               notes: list[str] | None = None, cache_step: float = texel_table.DEFAULT_STEP
               ) -> texel_table.TexelTable | None:
    """The fast-path table for ``model`` and ``options``: ``table_path`` (or the one beside the model), else
    the user cache.  A table made from another model (SHA-256 differs) is refused with a warning in
    ``notes`` (and Python's warnings): the bake then evaluates exactly."""
    notes = notes if notes is not None else []
    first = Path(table_path) if table_path else default_table_path(model.path)
    for path in dict.fromkeys([first, cached_table_path(model.sha256, options, cache_step)]):
        if not path.is_file():
            continue
        try:
            table = texel_table.load(path)
        except texel_table.TableError as exc:
            warn(notes, f"{exc}; every texel is evaluated exactly")
            continue
        if table.model_sha256 != model.sha256:
            warn(notes, f"fast-path table {path.name} was made from model {table.model_sha256[:12]}, not from "
                        f"{model.path.name} ({model.sha256[:12]}): refused, every texel is evaluated exactly; "
                        f"rebuild it: python -m training texel-table --model {model.path} --out {path} --overwrite")
            continue
        if table.options == options:
            return table
    return None


def warn(notes: list[str], text: str) -> None:
    """A warning for the user: in the bake's notes (stderr, S_maps.json) and Python's warnings."""
    notes.append(f"warning: {text}")
    warnings.warn(text, stacklevel=3)
