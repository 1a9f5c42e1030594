"""What a bake tells its user: :class:`BakeResult`, the notes (special inputs, clamped colours) and the
``S_maps.json`` record (files, units, options, how texels were evaluated, statistics, timings)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import collapse, maps, openpbr, painted
from ..cli_io import one_line  # noqa: F401 - re-exported (exporters.bake.one_line)
from ..image_input import AlbedoImage, IndexedAlbedo
from ..texel_records import CLAMPED_CYCLES, CLAMPED_SPECTRAL, needs_media
from . import material_files
from .targets import units_of

if TYPE_CHECKING:
    from .job import BakeJob

#: How the maps' colour is defined, per mode (S_maps.json "colour").
COLOUR_TARGETS = {
    "painted": "the painted albedo: linear sRGB (D65) of the texel, per channel (exporters.painted)",
    "model": "the model's reflectance: linear sRGB (D65) of the spectrum of the skin the network found "
             "(--model-colour)",
}


@dataclass
class BakeResult:
    """What a finished bake wrote: ``files`` (paths in order), ``json_path``, K (components written), notes for
    the user, the counts of collapse clamps (texels x components x channels) and of how texels were
    evaluated, timings in seconds, and ``reused`` (True when an up-to-date bake was found and kept)."""

    out_dir: Path
    stem: str
    files: list[Path]
    json_path: Path
    k: int
    notes: list[str]
    stats: dict[str, int]
    timings_s: dict[str, float] = field(default_factory=dict)
    reused: bool = False
    components: list[int] = field(default_factory=list)


def input_notes(albedo: AlbedoImage | IndexedAlbedo) -> list[str]:
    """Remarks on valid but special inputs (shown to the user and stored in S_maps.json)."""
    notes = []
    if albedo.n_channels in (1, 2):
        notes.append("grayscale image: its gray value is used for R, G and B")
    has_alpha = albedo.has_alpha if isinstance(albedo, IndexedAlbedo) else albedo.alpha is not None
    if has_alpha:
        notes.append("alpha channel ignored: the albedo is taken from the colour channels")
    if albedo.n_clamped:
        notes.append(f"{albedo.n_clamped} texel(s) with negative values clamped to 0")
    if isinstance(albedo, IndexedAlbedo):
        above = int(albedo.counts[(albedo.palette > 1.0).any(axis=1)].sum())
        h, w = albedo.shape
    else:
        above = int(np.count_nonzero((albedo.rgb > 1.0).any(axis=-1)))
        h, w = albedo.rgb.shape[:2]
    if above:
        notes.append(f"{above} texel(s) above 1 (not a valid albedo) are treated as 1")
    if h * w == 1:
        notes.append("1 x 1 image: the maps are uniform")
    return notes


def clamp_warnings(stats: dict[str, int], texels: int) -> list[str]:
    """Warnings (prefixed "warning: ") for painted colours a medium cannot produce, from the bake's stats, after a
    note (no prefix) on the texels that are not skin colours of the fast-path table."""
    out = []
    n = int(stats.get("texels_outside_table", 0))
    if n:
        out.append(f"{n:,} of {texels:,} texel(s) lie outside the fast-path table's skin colours (make-up, ink, "
                   "paint): their maps render the painted colour with the translucency of the nearest skin colour, "
                   "as the live group renders them (--exact runs the network on them)")
    n = int(stats.get(CLAMPED_CYCLES, 0))
    if n:
        out.append(f"warning: {n:,} of {texels:,} texel(s) are painted brighter than Cycles' walk can render "
                   "(a channel above what K closures of weight 1 and albedo ~1 reflect): clamped to the brightest "
                   "it renders")
    n = int(stats.get(CLAMPED_SPECTRAL, 0))
    if n:
        out.append(f"warning: {n:,} of {texels:,} texel(s) have a painted colour that no bounded correction of "
                   f"their skin's spectrum reaches (within a factor {painted.C_MAX:g} per wavelength, albedo <= "
                   f"{painted.ALPHA_MAX}; e.g. saturated non-skin colours): their spectral media get the nearest "
                   "colour")
    return out


def write_record(job: BakeJob, timings: dict[str, float], files: list[Path], file_states: dict) -> Path:
    """Write ``S_maps.json`` for a finished ``job`` (docs/contracts.md §4 keys via exporters.maps.write_maps_json, plus
    what this bake did)."""
    opts, table = job.options, job.evaluator.table
    colour = opts.collapse_options().colour
    listed = {s.name: {"units": units_of(s, opts.unit_scale_m), "channels": list(s.channels), "target": s.target,
                       "component": s.k or None, "kind": s.kind, "colorspace": "Non-Color"} for s in job.specs}
    for name in job.material_names:
        listed[name] = {"target": "openpbr", "kind": "materialx" if name.endswith(".mtlx") else "usd",
                        "units": f"scene units of {opts.unit_scale_m:g} m", "channels": [],
                        "reads": "the openpbr maps by relative paths"}
    extra = {
        "image_size": [job.width, job.height],
        "targets": list(job.targets),
        "colour": _colour_record(colour, job.targets),
        "model": {"path": str(job.model.path), "K": job.model_k},
        "evaluation": {"mode": "exact" if table is None else "table",
                       "table": None if table is None else {
                           "path": str(table.path), "sha256": table.sha256, "step": table.meta.get("step"),
                           "model_sha256": table.model_sha256, "command": table.meta.get("command")},
                       "exr_compression": opts.compression,
                       "mantissa_bits": job.mantissa_bits,
                       "half_kinds": sorted({s.kind for s in job.specs if job.pixel_types.get(s.name) == "half"})},
        "components": {"model_K": job.model_k, "kept": list(job.components),
                       "dropped": [k for k in range(1, job.model_k + 1) if k not in job.components],
                       "prune_share": float(opts.prune_share),
                       "max_share": [round(float(s), 6) for s in job.evaluator.max_share]},
        "notes": job.notes,
        "stats": job.stats,
        "bake": {"key": job.key, "files": file_states},
    }
    extra["collapse"] = {"method": "exporters.collapse (per channel: Cycles reflectance share, diffusion length)",
                         "used": needs_media(job.targets), "colour": colour, "target": COLOUR_TARGETS[colour],
                         "g_max": collapse.G_MAX, "alpha_star_soft_max": collapse.ALPHA_STAR_SOFT_MAX,
                         "alpha_min": "face-on albedo alpha*(g) (exporters.collapse.face_on_albedo)"
                         if colour == "painted" else collapse.ALPHA_MIN,
                         "ior": float(opts.ior), "min_mean_free_path_m": float(opts.min_mfp_m)}
    if "openpbr" in job.targets:
        extra["openpbr"] = {"method": "exporters.openpbr (one medium per texel at the mixture's albedo, under a clear "
                                      "coat tinted by the share the mixture absorbs: the mixture's colour face-on, "
                                      "its bleed-matched diffusion length per channel)",
                            "specular_ior": float(opts.ior), "cycles_subsurface_scale": openpbr.CYCLES_RADIUS_SCALE,
                            "coat": material_files.coat_values(float(opts.ior), material_files.SPECULAR_ROUGHNESS),
                            "material_files": job.material_names}
    sha = {job.model.path.name: job.model.sha256}
    return maps.write_maps_json(job.json_path, listed, job.k, sha, job.input_image, job.albedo_colorspace, timings,
                                unit_scale_m=opts.unit_scale_m, overwrite=opts.overwrite, extra=extra)


def _colour_record(colour: str, targets: tuple[str, ...]) -> dict:
    """S_maps.json "colour": what the maps render, and how a consumer of the spectral target gets the same."""
    rec = {"mode": colour, "target": COLOUR_TARGETS[colour]}
    if "spectral" in targets:
        rec["spectral"] = (
            "biophysical + exposure as docs/contracts.md §4 (the skin the network found); skin_decoder.onnx: media. "
            "Painted colour: exporters.painted.paint_mixture(alpha, sigma_t, g, weight of the decoder, the albedo "
            "texel in linear sRGB) gives the media that render the painted colour (a smooth correction of the "
            f"visible within a factor {painted.C_MAX:g}; UV and NIR unchanged); the albedo is the input image "
            "(its colour space above)" if colour == "painted" else
            "biophysical + exposure as docs/contracts.md §4; skin_decoder.onnx: the media of the model's own colour")
    return rec
