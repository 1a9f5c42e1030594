"""UDIM (tiled) albedo images for Invert Skin Albedo: one bake per tile, read back as UDIM images.

A tiled image ``skin.<UDIM>.png`` is baked tile by tile, each exactly as ``bake.py`` bakes that tile's file
(docs/contracts.md §4): tile 1002 gives ``skin.1002_k1_color.exr`` ..., so every map kind is itself a UDIM set
(``skin.<UDIM>_k1_color.exr``) that Blender loads as one tiled image.  Every tile keeps all K components (no
pruning), so every map exists for every tile and no tile of a map renders missing.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import bpy

from .core import bake, image_input


@dataclass(frozen=True)
class TiledAlbedo:
    """The tiles of a UDIM albedo: ``pattern`` (absolute, with ``<UDIM>``), (tile number, file) by tile, and the
    colour space to read them in."""

    pattern: str
    tiles: tuple[tuple[int, str], ...]
    colorspace: str

    @property
    def stem(self) -> str:
        """The maps' stem without the tile: ``skin.<UDIM>.png`` -> ``skin``."""
        return Path(self.pattern).name.split(image_input.UDIM_TOKEN)[0].rstrip("._-") or "albedo"


def tiled_albedo(image: bpy.types.Image, colorspace: str) -> TiledAlbedo:
    """The files of a tiled image's tiles; ValueError (one line, what to do) when it has none on disk or one is
    missing."""
    if image.packed_file is not None or not image.filepath:
        raise ValueError(f"UDIM image '{image.name}' has no files on disk: save its tiles (Image > Save All Images) "
                         "and invert again")
    pattern = bpy.path.abspath(image.filepath, library=image.library)
    if image_input.UDIM_TOKEN not in os.path.basename(pattern):
        raise ValueError(f"UDIM image '{image.name}' has no {image_input.UDIM_TOKEN} in its file name ({pattern})")
    tiles = []
    for tile in image.tiles:
        path = pattern.replace(image_input.UDIM_TOKEN, f"{tile.number:04d}")
        if not os.path.isfile(path):
            raise ValueError(f"tile {tile.number} of UDIM image '{image.name}' is missing: {path}")
        tiles.append((tile.number, path))
    return TiledAlbedo(pattern, tuple(sorted(tiles)), colorspace)


class TiledJob:
    """One exporters.bake.BakeJob per tile, driven as one job (the interface AddonBake uses of a BakeJob)."""

    def __init__(self, albedo: TiledAlbedo, out_dir: Path, model, options, read: Callable | None = None) -> None:
        """``read(path, colorspace)``: how a tile's file is read (default exporters.image_input.read_albedo_indexed)."""
        read = read or (lambda path, colorspace: image_input.read_albedo_indexed(path, colorspace=colorspace))
        self.jobs = []
        for i, (number, path) in enumerate(albedo.tiles):
            image = read(path, albedo.colorspace)
            stem = image_input.udim_tile_stem(albedo.pattern, number)
            tile_options = bake.udim_tile_options(options, albedo.pattern, last=i == len(albedo.tiles) - 1)
            self.jobs.append(bake.BakeJob(image, out_dir, stem, model, tile_options, input_image=path,
                                          image_id=bake.file_id(path, albedo.colorspace)))
        self.key = hashlib.sha256(" ".join(job.key for job in self.jobs).encode()).hexdigest()

    @property
    def specs(self) -> list:
        """The maps of the first tile (``skin.1001_k1_color.exr`` ...): Blender finds the other tiles of each."""
        return self.jobs[0].specs

    def steps(self) -> Iterator[float]:
        for i, job in enumerate(self.jobs):
            for fraction in job.steps():
                yield (i + fraction) / len(self.jobs)

    def cancel(self) -> None:
        for job in self.jobs:
            job.cancel()

    def finish(self):
        """Publish every tile's maps: the exporters.bake.BakeResult of the first tile, whose ``files`` lists every
        tile's maps and the other tiles' records (what undoing the bake removes)."""
        results = []
        try:
            for job in self.jobs:
                results.append(job.finish())
        except BaseException:
            for result in results:
                if not result.reused:
                    for path in [*result.files, result.json_path]:
                        Path(path).unlink(missing_ok=True)
            raise
        ks = {r.k for r in results}
        if len(ks) != 1:
            raise RuntimeError(f"the tiles were baked with different numbers of components ({sorted(ks)})")
        first = results[0]
        first.files = [f for r in results for f in r.files] + [r.json_path for r in results[1:]]
        first.notes = sorted({note for r in results for note in r.notes})
        first.reused = all(r.reused for r in results)
        return first


def load_tiled(path: str) -> bpy.types.Image:
    """The UDIM image whose first tile is the file ``path`` (Blender finds the other tiles beside it)."""
    image = bpy.data.images.load(path, check_existing=False)
    image.source = "TILED"
    return image
