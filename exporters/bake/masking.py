"""The albedo as a bake reads it: a checked palette of distinct colours with a per-texel index, and the UV
coverage mask (texels no face covers take the most common covered colour, so they are never evaluated)."""

from __future__ import annotations

import numpy as np

from ..image_input import AlbedoImage, IndexedAlbedo, check_texels
from .targets import BakeError


def indexed(albedo: AlbedoImage | IndexedAlbedo) -> IndexedAlbedo:
    """An albedo image as an :class:`exporters.image_input.IndexedAlbedo`, checked: BakeError for a bad shape,
    exporters.image_input.ImageError for NaN/Inf or negative texels (image_input.check_texels, as on reading)."""
    if isinstance(albedo, IndexedAlbedo):
        image = albedo
    else:
        rgb = np.asarray(albedo.rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
            raise BakeError(f"albedo must be an (H, W, 3) image, got shape {rgb.shape}")
        image = IndexedAlbedo.from_dense(albedo)
    if image.index.ndim != 2 or min(image.index.shape) < 1:
        raise BakeError(f"albedo must be an (H, W, 3) image, got an index of shape {image.index.shape}")
    check_texels(image.palette, "albedo", index=image.index)
    return image


def apply_mask(image: IndexedAlbedo, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Palette and index with uncovered texels set to the most common covered colour; returns (palette,
    index, number of uncovered texels).  ``mask`` (H, W) bool: texels the mesh's UVs cover."""
    index = image.index
    covered = index[mask]
    if covered.size == 0:
        raise BakeError("the mesh's UVs cover no texel of the image: check the UV map or bake without the mesh")
    fill = int(np.argmax(np.bincount(covered, minlength=len(image.palette))))
    index = np.where(mask, index, fill)
    used = np.zeros(len(image.palette), bool)
    used[index] = True
    remap = np.cumsum(used) - 1
    return image.palette[used], remap[index].astype(np.int32), int(mask.size - np.count_nonzero(mask))
