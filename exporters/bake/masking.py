"""The albedo as a bake reads it: a checked palette of distinct colours with a per-texel index, and the UV
coverage mask (texels no face covers take the most common covered colour, so they are never evaluated)."""

from __future__ import annotations

import numpy as np

from exporters import maps
from exporters.bake.targets import BakeError


def indexed(albedo: maps.AlbedoImage | maps.IndexedAlbedo) -> maps.IndexedAlbedo:
    """An albedo image as an :class:`exporters.maps.IndexedAlbedo`, checked (BakeError for NaN, negative
    texels or a bad shape)."""
    if isinstance(albedo, maps.IndexedAlbedo):
        image = albedo
    else:
        rgb = np.asarray(albedo.rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
            raise BakeError(f"albedo must be an (H, W, 3) image, got shape {rgb.shape}")
        image = maps.IndexedAlbedo.from_dense(albedo)
    if image.index.ndim != 2 or min(image.index.shape) < 1:
        raise BakeError(f"albedo must be an (H, W, 3) image, got an index of shape {image.index.shape}")
    if not np.all(np.isfinite(image.palette)):
        raise BakeError("albedo has NaN/Inf texels; fix the texture")
    if np.any(image.palette < 0):
        raise BakeError("albedo has negative texels; an albedo cannot be negative")
    return image


def apply_mask(image: maps.IndexedAlbedo, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
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
