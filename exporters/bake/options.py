"""How a bake is asked for: :class:`BakeOptions`, their defaults and their checks."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .. import collapse, inference, maps, reflectance_tables, skin_edits, texel_table
from ..texel_records import CollapseOptions
from .targets import BakeError, parse_targets

#: Default texels per band: bands bound the memory of the expanded maps (about 0.3 KB per texel).
DEFAULT_BAND_TEXELS = 1 << 19
#: A component is dropped when its share of the rendered colour stays below this for every texel and
#: channel: the colour then changes by less than 0.2 % (at most about 0.1 ΔE76).
DEFAULT_PRUNE_SHARE = 0.002
#: Mantissa bits of fast-path maps (BakeOptions.mantissa_bits).
FAST_MANTISSA_BITS = 16


@dataclass
class BakeOptions:
    """``targets``: docs/contracts.md §4; ``unit_scale_m`` m per Blender unit; ``threads`` for onnxruntime, the table
    lookups and OpenEXR (0 = all cores); ``memory_mb`` budget (MiB) of the bake's working
    arrays, shared by the map rows held, one table step, one inference chunk and the decoded image
    (exporters.bake.job.WORK_SHARES); ``chunk`` caps distinct
    texels per exact step (None: from the budget); ``model_colour``: the maps render the model's own reflectance
    (the colour of the biophysical skin the network found) instead of the painted albedo (the default,
    exporters.painted); ``ior``: the IOR the node group's closures use (its IOR input; it sets how view rays
    enter the medium, see exporters.reflectance_tables); ``min_mfp_m``: smallest mean free path given to
    Cycles, metres (exporters.collapse step 7); ``overwrite`` replaces existing files.

    Fast path and skipping: ``exact`` evaluates every distinct colour with the model (no table);
    ``table_path``: the fast-path table (None: ``<model stem>_table.npz`` beside the model, then the user
    cache); ``cache_tables``: build and cache a table for option sets no shipped table covers when the image
    has enough distinct colours to pay for it; ``prune_share``: components below this share of the colour
    everywhere are dropped (0 keeps all); ``texel_mask`` (H, W) bool: texels the mesh's UVs cover (others
    take the maps of the most common covered colour); ``force`` re-bakes an up-to-date folder;
    ``compression`` of the EXR maps (exporters.maps.COMPRESSIONS); ``mantissa_bits``: float32 mantissa bits the
    maps keep (None: 16 when the table is used — relative 7.6e-6, far below its interpolation error, and 25 %
    faster to compress — and all 23 for exact bakes); ``half_maps``: the maps of ``HALF_KINDS`` stored as
    half floats, and the radius maps too when every radius lies in half's normal range (None: on the fast
    path, not with ``exact``); ``cache_min_colours``: distinct colours from which a
    bake without a usable table builds one (grid step ``cache_step``) into the user cache.

    ``--target openpbr``: ``material_stem`` names its material files (``<stem>_openpbr.mtlx`` / ``.usda``; None: the
    image's stem) and ``material_maps_stem`` the maps they read (None: this bake's; a UDIM set's last tile passes the
    set's ``skin.<UDIM>`` so that one material reads every tile); ``write_material`` False leaves them out (the
    other tiles of a UDIM set).

    Skin edits (exporters.skin_edits): ``edit`` the Melanin, Blood and Oxygenation controls for every texel;
    ``edit_masks`` {control name: (H, W) mask in [0, 1]} paint a control's edit per texel (exporters.bake.edits).
    Edited texels come from the edit table beside the model (``<model stem>_edits.npz``, exporters.edit_table, as
    the live group renders them) on the fast path, from the network and the decoder (``skin_decoder.onnx`` beside
    the model) with ``exact``."""

    targets: tuple[str, ...] = ("cycles",)
    unit_scale_m: float = 1.0
    threads: int = 0
    memory_mb: float = inference.DEFAULT_MEMORY_MB
    chunk: int | None = None
    band_texels: int = DEFAULT_BAND_TEXELS
    model_colour: bool = False
    ior: float = reflectance_tables.CYCLES_IOR
    min_mfp_m: float = collapse.MIN_MFP_CM / 100.0
    overwrite: bool = False
    exact: bool = False
    table_path: str | os.PathLike | None = None
    cache_tables: bool = True
    prune_share: float = DEFAULT_PRUNE_SHARE
    texel_mask: np.ndarray | None = field(default=None, repr=False)
    force: bool = False
    compression: str = maps.DEFAULT_COMPRESSION
    mantissa_bits: int | None = None
    half_maps: bool | None = None
    cache_min_colours: int = 50_000  # building evaluates ~34,000 grid nodes: it pays off from ~1.5x that
    cache_step: float = texel_table.DEFAULT_STEP
    write_material: bool = True
    material_stem: str | None = None
    material_maps_stem: str | None = None
    edit: skin_edits.SkinEdit = field(default_factory=skin_edits.SkinEdit)
    edit_masks: dict[str, np.ndarray] | None = field(default=None, repr=False)

    @property
    def edited(self) -> bool:
        """Whether any texel's tone is edited."""
        return not self.edit.neutral

    def collapse_options(self) -> CollapseOptions:
        return CollapseOptions(colour="model" if self.model_colour else "painted", ior=float(self.ior),
                               min_mfp_cm=float(self.min_mfp_m) * 100.0)

    def check(self) -> tuple[str, ...]:
        """BakeError for a bad option (naming it and its range); returns the parsed targets."""
        targets = parse_targets(self.targets)
        if not (np.isfinite(self.memory_mb) and self.memory_mb > 0):
            raise BakeError(f"memory budget must be a positive number of MiB, got {self.memory_mb}")
        if not (np.isfinite(self.unit_scale_m) and self.unit_scale_m > 0):
            raise BakeError(f"unit scale must be a positive number of metres per Blender unit, got {self.unit_scale_m}")
        if not reflectance_tables.IOR_MIN <= self.ior <= reflectance_tables.IOR_MAX:
            raise BakeError(f"IOR must lie in [{reflectance_tables.IOR_MIN}, {reflectance_tables.IOR_MAX}] "
                            f"(Cycles' range), got {self.ior}")
        if not (np.isfinite(self.min_mfp_m) and self.min_mfp_m >= 0):
            raise BakeError(f"smallest mean free path must be >= 0 m, got {self.min_mfp_m}")
        if not (np.isfinite(self.prune_share) and 0.0 <= self.prune_share < 1.0):
            raise BakeError(f"prune share must lie in [0, 1), got {self.prune_share}")
        if self.mantissa_bits is not None and not 1 <= self.mantissa_bits <= 23:
            raise BakeError(f"mantissa bits must lie in 1..23, got {self.mantissa_bits}")
        if self.compression not in maps.COMPRESSIONS:
            raise BakeError(f"EXR compression must be one of {', '.join(maps.COMPRESSIONS)}, not {self.compression!r}")
        for name in skin_edits.CONTROLS:
            lo, hi = skin_edits.CONTROL_RANGES[name]
            value = getattr(self.edit, name)
            if not lo <= value <= hi:
                raise BakeError(f"{name} must lie in [{lo:g}, {hi:g}], got {value:g}")
        if self.edit_masks and any(getattr(self.edit, n) == v for n, v in zip(skin_edits.CONTROLS, skin_edits.NEUTRAL,
                                                                                strict=True) if n in self.edit_masks):
            raise BakeError("an edit mask weighs its control's edit: give the control's value too (e.g. --melanin 1.5 "
                            "with --melanin-map)")
        return targets
