"""What a bake writes: the targets of docs/contracts.md §4, their files (:class:`MapSpec`) and their units."""

from __future__ import annotations

from dataclasses import dataclass

from .. import maps

TARGETS: tuple[str, ...] = ("cycles", "physical", "spectral", "openpbr")
#: Units strings stored in each EXR header and in S_maps.json.
UNITS = {
    "color": "1 (Cycles Subsurface Color, RANDOM_WALK)",
    "radius": "Blender units (Subsurface Radius with Scale = 1)",
    "weight": "1 (mixture weight per channel)",
    "anisotropy": "1 (Henyey-Greenstein g)",
    "alpha": "1 (single-scattering albedo)",
    "sigma_t": "cm^-1",
    "g": "1 (Henyey-Greenstein g)",
    "biophysical": "f_mel 1, f_blood 1, t_epi cm, so2 1, b_mel 1, exposure 1",
    "openpbr_base_color": "1 (OpenPBR base_color: the colour the mixture renders, linear Rec.709)",
    "openpbr_subsurface_color": "1 (OpenPBR subsurface_color, linear Rec.709)",
    "openpbr_subsurface_radius": "scene units (OpenPBR subsurface_radius: the largest channel's mean free path)",
    "openpbr_subsurface_radius_scale": "1 (OpenPBR subsurface_radius_scale: mean free path / subsurface_radius)",
    "openpbr_subsurface_anisotropy": "1 (OpenPBR subsurface_scatter_anisotropy, Henyey-Greenstein g)",
    "openpbr_subsurface_weight": "1 (OpenPBR subsurface_weight)",
    "openpbr_coat_color": "1 (OpenPBR coat_color: the share of the light the mixture absorbs, linear Rec.709)",
}
#: The maps of ``--target openpbr`` (one medium per texel, exporters.openpbr): kind -> channels.
OPENPBR_KINDS: dict[str, tuple[str, ...]] = {
    "openpbr_base_color": maps.RGB_CHANNELS,
    "openpbr_subsurface_color": maps.RGB_CHANNELS,
    "openpbr_subsurface_radius": maps.SINGLE_CHANNEL,
    "openpbr_subsurface_radius_scale": maps.RGB_CHANNELS,
    "openpbr_subsurface_anisotropy": maps.SINGLE_CHANNEL,
    "openpbr_subsurface_weight": maps.SINGLE_CHANNEL,
    "openpbr_coat_color": maps.RGB_CHANNELS,
}
#: Cycles map kinds bounded to [-1, 1] (colour, weights, anisotropy): the fast path stores them as half floats
#: (BakeOptions.half_maps).  Their rounding (<= 2.4e-4 below 1) is a tenth of the table's interpolation error in
#: the rendered colour, and halves what PIZ compresses.  Radius maps are half too when every radius of the bake
#: lies in half's normal range (exporters.bake.job; skin's radii, >= 4 pi x 10 um, do at unit scales up to ~1):
#: relative rounding 4.9e-4, 1/70 of the table's radius error.  The physical and biophysical maps stay float32:
#: 1 - alpha of a physical albedo near 1 needs float's precision.
HALF_KINDS = frozenset({"color", "weight", "anisotropy"})


class BakeError(ValueError):
    """Bad input for a bake (targets, output folder, existing files); the message says what to do."""


@dataclass(frozen=True)
class MapSpec:
    """One output file: its name, kind (key of UNITS), component k (1-based in the files, 0 for spectral),
    channels, target, and ``source_k``: the model's component it holds (differs from k when components
    were dropped)."""

    name: str
    kind: str
    k: int
    channels: tuple[str, ...]
    target: str
    source_k: int = 0


def parse_targets(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """'cycles,physical' -> ('cycles', 'physical'); BakeError naming unknown targets."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    bad = [t for t in items if t not in TARGETS]
    if bad or not items:
        raise BakeError(f"unknown target(s) {bad or items!r}; use a comma-separated subset of {','.join(TARGETS)}")
    return tuple(dict.fromkeys(items))


def map_specs(stem: str, k_count: int, targets: tuple[str, ...],
              components: tuple[int, ...] | list[int] | None = None) -> list[MapSpec]:
    """Every file a bake writes (docs/contracts.md §4 names), in a fixed order; the weight map is shared by the cycles
    and physical targets (it is the same array).  ``components``: the model's components to write (1-based,
    default all ``k_count``); they are numbered k1, k2, ... in the file names."""
    rgb, one = maps.RGB_CHANNELS, maps.SINGLE_CHANNEL
    kept = list(components) if components is not None else list(range(1, k_count + 1))
    specs: dict[str, MapSpec] = {}
    for target in targets:
        if target == "spectral":
            specs[f"{stem}_biophysical.exr"] = MapSpec(f"{stem}_biophysical.exr", "biophysical", 0,
                                                       maps.BIOPHYSICAL_CHANNELS, target)
            continue
        if target == "openpbr":
            for kind, channels in OPENPBR_KINDS.items():
                specs[f"{stem}_{kind}.exr"] = MapSpec(f"{stem}_{kind}.exr", kind, 0, channels, target)
            continue
        kinds = (("color", rgb), ("radius", rgb), ("weight", rgb), ("anisotropy", one)) if target == "cycles" else \
            (("alpha", rgb), ("sigma_t", rgb), ("g", rgb), ("weight", rgb))
        for k, source in enumerate(kept, start=1):
            for kind, channels in kinds:
                name = f"{stem}_k{k}_{kind}.exr"
                specs.setdefault(name, MapSpec(name, kind, k, channels, target, source))
    return list(specs.values())


def units_of(spec: MapSpec, unit_scale_m: float) -> str:
    """The units string of a map (radii name the Blender unit's length)."""
    if spec.kind == "radius":
        return f"{UNITS['radius']}; 1 BU = {unit_scale_m:g} m"
    if spec.kind == "openpbr_subsurface_radius":
        return f"{UNITS[spec.kind]}; 1 unit = {unit_scale_m:g} m"
    return UNITS[spec.kind]
