"""Skin edits in a bake (exporters.skin_edits): one edit for the whole image, or masks that paint it per texel.

A mask (H, W) in [0, 1] weighs its control's edit per texel as a Mix node between the neutral value and the
edit's value would in the live group: control = neutral + mask x (value - neutral).  With edits, a bake's
distinct entries are distinct (colour, edit) pairs: :func:`edited_palette` re-indexes the image by them.
"""

from __future__ import annotations

import numpy as np

from .. import skin_edits
from .targets import BakeError


def texel_edits(edit: skin_edits.SkinEdit, masks: dict[str, np.ndarray] | None,
                shape: tuple[int, int]) -> np.ndarray | None:
    """Edit rows (H * W, 3) float32 of every texel, or None when ``masks`` is empty (one edit everywhere).
    BakeError for a mask of another shape or with NaN."""
    if not masks:
        return None
    unknown = sorted(set(masks) - set(skin_edits.CONTROLS))
    if unknown:
        raise BakeError(f"edit mask(s) {unknown} name no control; use {', '.join(skin_edits.CONTROLS)}")
    value = edit.row()
    neutral = np.array(skin_edits.NEUTRAL)
    rows = np.tile(value.astype(np.float32), (shape[0] * shape[1], 1))
    for j, name in enumerate(skin_edits.CONTROLS):
        if name not in masks:
            continue
        mask = np.asarray(masks[name], np.float64)
        if mask.shape != tuple(shape):
            raise BakeError(f"the {name} mask has shape {mask.shape}, the albedo {tuple(shape)}: give a mask of the "
                            "albedo's size")
        if not np.all(np.isfinite(mask)):
            raise BakeError(f"the {name} mask holds NaN/Inf texels; fix the mask image")
        rows[:, j] = (neutral[j] + np.clip(mask, 0.0, 1.0).ravel() * (value[j] - neutral[j])).astype(np.float32)
    return rows


def edited_palette(palette: np.ndarray, index: np.ndarray, edit: skin_edits.SkinEdit,
                   masks: dict[str, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(palette (M, 3), index (H, W), edits (M, 3)) of the distinct (colour, edit) pairs of the image."""
    rows = texel_edits(edit, masks, index.shape)
    if rows is None:
        return palette, index, np.tile(edit.row(), (len(palette), 1))
    keys = np.column_stack([index.ravel().astype(np.float64), rows.astype(np.float64)])
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    colour_ids = uniq[:, 0].astype(np.int64)
    return palette[colour_ids], inverse.reshape(index.shape).astype(np.int32), uniq[:, 1:]
