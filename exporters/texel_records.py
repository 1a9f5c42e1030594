"""What a bake computes per texel (a *record*), by exact evaluation, and the map values made from it.

Everything a bake writes depends on the texel's colour only.  A record holds, for N texels and the
model's K components (arrays in a dict, float64 unless said otherwise):

* ``color`` (N, K, 3) Cycles Subsurface Color, ``radius_m`` (N, K, 3) RANDOM_WALK radius in metres (Blender
  units at unit scale 1; the map is radius_m / unit_scale), ``weight`` (N, K, 3), ``anisotropy`` (N, K)
  — the ``cycles`` target;
* ``alpha`` (N, K, 3) single-scattering albedo, ``sigma_t_cm`` (N, K, 3) in cm^-1 — with ``weight`` and
  ``anisotropy`` the ``physical`` target;
* ``biophysical`` (N, 5) and ``exposure`` (N,) — the ``spectral`` target;
* for the ``openpbr`` target, the single medium made from ``weight``, ``alpha``, ``sigma_t_cm`` and ``anisotropy``
  (:func:`add_single_medium`, exporters.openpbr): ``pbr_base_color``, ``pbr_subsurface_color`` (N, 3),
  ``pbr_radius`` (N,) in scene units, ``pbr_radius_scale`` (N, 3), ``pbr_anisotropy`` and ``pbr_weight`` (N,),
  ``pbr_coat_color`` (N, 3);
* ``max_share`` (N, K): each component's largest share of the rendered colour over the three channels,
  w_kc R_cycles(alpha_kc, g_k) / sum_j w_jc R_cycles(alpha_jc, g_j) (components below a small share
  everywhere are dropped from a bake);
* clamp counts per texel (N,) int: ``n_low`` (channels whose albedo was raised to the collapse's floor),
  ``n_high`` (weights raised above the channel mean), ``n_unreachable`` (colour channels Cycles cannot reach),
  ``n_capped`` (extinctions capped at the smallest mean free path): exporters.collapse;
* with the painted colour, ``spectral_clamped`` (N,) 0/1: the painted spectral media miss the painted colour
  (exporters.painted).

:func:`exact_records` evaluates the model (exporters.inference) and the collapse (exporters.collapse) and
fills only the fields the targets need (``spectral`` alone needs no collapse).  The fast path
(exporters.texel_table) interpolates records instead.  :func:`map_values` turns records into the rows of
one docs/contracts.md §4 map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import collapse, cycles, openpbr, reflectance_tables
from .colorimetry import SRGB_LUMINANCE

MEDIA_TARGETS = ("cycles", "physical", "openpbr")
COUNT_FIELDS = ("n_low", "n_high", "n_unreachable", "n_capped")
#: Stats keys of S_maps.json for each count field (texel x component x channel events, summed over texels).
STAT_NAMES = {"n_low": "alpha_raised_to_floor", "n_high": "weight_raised", "n_unreachable": "unreachable_channels",
              "n_capped": "sigma_t_capped"}
#: Stats counting texels (not channels) whose painted colour was clamped: in Cycles (cycles, physical targets) and
#: in the spectral media (spectral target).
CLAMPED_CYCLES = "texels_colour_unreachable_in_cycles"
CLAMPED_SPECTRAL = "texels_colour_clamped_spectral"
#: What the maps' colour reproduces (CollapseOptions.colour).
COLOURS = ("painted", "model")


@dataclass(frozen=True)
class CollapseOptions:
    """The bake options that change per-texel values (besides the model): ``colour`` ("painted": the albedo as
    painted, exporters.painted; "model": the model's own reflectance), ``ior`` of the Cycles closures,
    ``min_mfp_cm`` (exporters.collapse step 7).  The unit scale is not here: it only divides the radius."""

    colour: str = "painted"
    ior: float = reflectance_tables.CYCLES_IOR
    min_mfp_cm: float = collapse.MIN_MFP_CM

    def __post_init__(self) -> None:
        if self.colour not in COLOURS:
            raise ValueError(f"colour must be one of {COLOURS}, not {self.colour!r}")

    @property
    def painted(self) -> bool:
        return self.colour == "painted"

    def as_dict(self) -> dict:
        return {"colour": self.colour, "ior": round(float(self.ior), 6), "min_mfp_cm": float(self.min_mfp_cm)}


def needs_media(targets: tuple[str, ...]) -> bool:
    """Whether ``targets`` need the collapse (cycles, physical or openpbr maps)."""
    return any(t in MEDIA_TARGETS for t in targets)


def model_luminance(reflectance: np.ndarray) -> np.ndarray:
    """Relative luminance (N,) of the model's reflectance (N, 376) under D65 (linear sRGB, Rec. 709 weights):
    the divisor of the model's exposure, exposure = Y(albedo) / Y(model colour)."""
    return (np.asarray(reflectance, np.float64) @ collapse.channel_matrix().T) @ SRGB_LUMINANCE


def albedo_luminance(rgb: np.ndarray) -> np.ndarray:
    """Y (N,) of albedo rows (N, 3) as the model sees them (clamped to [0, 1])."""
    return np.clip(np.asarray(rgb, np.float64), 0.0, 1.0) @ SRGB_LUMINANCE


def exact_records(model, rgb: np.ndarray, targets: tuple[str, ...], options: CollapseOptions,
                  with_luminance: bool = False) -> dict[str, np.ndarray]:
    """Records (module docstring) of albedo rows ``rgb`` (N, 3), linear sRGB, by the model and the collapse.

    ``model``: an exporters.inference.InversionSession; ``targets``: which fields to fill (spectral alone skips the
    collapse); ``with_luminance`` adds ``y_model`` (N,), the luminance of the model's reflectance.
    """
    out = model.run(rgb)
    painted_rgb = np.asarray(rgb, np.float64) if options.painted else None
    return records_of(out, painted_rgb, targets, options, with_luminance)


def records_of(out: dict[str, np.ndarray], painted_rgb: np.ndarray | None, targets: tuple[str, ...],
               options: CollapseOptions, with_luminance: bool = False) -> dict[str, np.ndarray]:
    """Records of model outputs ``out`` (exporters.inference.OUTPUT_SHAPES, N rows): the collapse reproduces
    ``painted_rgb`` (N, 3) (None: the colour of ``out``'s reflectance)."""
    rec: dict[str, np.ndarray] = {"biophysical": out["biophysical"].astype(np.float64),
                                  "exposure": out["exposure"][:, 0].astype(np.float64)}
    if with_luminance:
        rec["y_model"] = model_luminance(out["reflectance"])
    if not needs_media(targets):
        if painted_rgb is not None and "spectral" in targets:
            rec["spectral_clamped"] = collapse.painted_clamped(out["alpha"], out["g"], out["weight"],
                                                               painted_rgb).astype(np.int64)
        return rec
    media = collapse.collapse(out["reflectance"], out["alpha"], out["sigma_t"], out["g"], out["weight"],
                              painted_rgb=painted_rgb, ior=options.ior, min_mfp_cm=options.min_mfp_cm)
    if media.spectral_clamped is not None:
        rec["spectral_clamped"] = media.spectral_clamped.astype(np.int64)
    cyc = collapse.to_cycles(media, 1.0)
    rec.update(color=cyc.color, radius_m=cyc.radius, weight=media.weight, anisotropy=media.g, alpha=media.alpha,
               sigma_t_cm=media.sigma_t_cm, unreachable=media.unreachable.astype(np.float64),
               n_low=media.low.sum(axis=(1, 2)), n_high=media.high.sum(axis=(1, 2)),
               n_unreachable=media.unreachable.sum(axis=1), n_capped=media.mfp_capped.sum(axis=(1, 2)))
    rec["max_share"] = max_share(cycles_contributions(rec, options.ior))
    return rec


def max_share(contributions: np.ndarray) -> np.ndarray:
    """(N, K): max over channels of each component's share of the channel's colour, from (N, K, 3)
    contributions (:func:`cycles_contributions`); a channel with no light gives every component share 0."""
    total = contributions.sum(axis=1, keepdims=True)
    share = np.where(total > 0.0, contributions / np.where(total > 0.0, total, 1.0), 0.0)
    return share.max(axis=2)


def empty_records(k: int, targets: tuple[str, ...], painted: bool = False) -> dict[str, np.ndarray]:
    """Records of zero texels (the shapes of :func:`exact_records`)."""
    rec = {"biophysical": np.zeros((0, 5)), "exposure": np.zeros(0)}
    if painted and (needs_media(targets) or "spectral" in targets):
        rec["spectral_clamped"] = np.zeros(0, np.int64)
    if needs_media(targets):
        for name in ("color", "radius_m", "weight", "alpha", "sigma_t_cm"):
            rec[name] = np.zeros((0, k, 3))
        rec["anisotropy"] = np.zeros((0, k))
        rec["max_share"] = np.zeros((0, k))
        rec["unreachable"] = np.zeros((0, 3))
        for name in COUNT_FIELDS:
            rec[name] = np.zeros(0, np.int64)
    return rec


def concat_records(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Records of several row blocks, in order (every part must have the same fields)."""
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def take_records(rec: dict[str, np.ndarray], rows) -> dict[str, np.ndarray]:
    """Rows ``rows`` (index array, slice or mask) of every field."""
    return {key: value[rows] for key, value in rec.items()}


def map_values(kind: str, k: int, rec: dict[str, np.ndarray], unit_scale_m: float) -> np.ndarray:
    """Rows (N, channels) float32 of one docs/contracts.md §4 map: ``kind`` as in exporters.bake.UNITS, component ``k``
    (1-based; ignored for "biophysical").  Radii below Cycles' minimum (1e-8 Blender units, which would turn
    the channel into a diffuse BSDF) raise ValueError: use a larger unit scale."""
    i = k - 1
    if kind == "biophysical":
        return np.concatenate([rec["biophysical"], rec["exposure"][:, None]], axis=1).astype(np.float32)
    if kind == "radius":
        radius = rec["radius_m"][:, i] / unit_scale_m
        if radius.size and not radius.min() >= cycles.MIN_RADIUS:
            raise ValueError(f"radius below Cycles' minimum {cycles.MIN_RADIUS} BU at unit scale {unit_scale_m:g} "
                             "m per unit: the channel would become diffuse (use a larger unit scale)")
        return radius.astype(np.float32)
    if kind in ("g", "anisotropy"):
        g = rec["anisotropy"][:, i, None]
        return (np.repeat(g, 3, axis=1) if kind == "g" else g).astype(np.float32)
    if kind in OPENPBR_FIELDS:
        return rec[OPENPBR_FIELDS[kind]].reshape(len(rec[OPENPBR_FIELDS[kind]]), -1).astype(np.float32)
    field = {"color": "color", "weight": "weight", "alpha": "alpha", "sigma_t": "sigma_t_cm"}[kind]
    return rec[field][:, i].astype(np.float32)


#: Record fields of the single medium (``--target openpbr``, :func:`add_single_medium`) per map kind.
OPENPBR_FIELDS = {"openpbr_base_color": "pbr_base_color", "openpbr_subsurface_color": "pbr_subsurface_color",
                  "openpbr_subsurface_radius": "pbr_radius", "openpbr_subsurface_radius_scale": "pbr_radius_scale",
                  "openpbr_subsurface_anisotropy": "pbr_anisotropy", "openpbr_subsurface_weight": "pbr_weight",
                  "openpbr_coat_color": "pbr_coat_color"}


def add_single_medium(rec: dict[str, np.ndarray], ior: float, unit_scale_m: float) -> None:
    """Add the single medium of each texel's media (exporters.openpbr) to ``rec`` (which needs ``weight``,
    ``alpha``, ``sigma_t_cm`` and ``anisotropy``): the fields of OPENPBR_FIELDS, the radius in scene units of
    ``unit_scale_m`` metres (the largest channel's mean free path) and the scale per channel (<= 1)."""
    if "pbr_base_color" in rec:
        return
    medium = openpbr.single_medium(rec["weight"], rec["alpha"], rec["sigma_t_cm"], rec["anisotropy"], ior)
    mfp = medium.mean_free_path(unit_scale_m)
    radius = mfp.max(axis=1) if len(mfp) else np.zeros(0)
    rec.update(pbr_base_color=medium.base_color, pbr_subsurface_color=medium.subsurface_color,
               pbr_radius=radius, pbr_radius_scale=mfp / np.maximum(radius, 1e-300)[:, None],
               pbr_anisotropy=medium.anisotropy, pbr_weight=medium.weight, pbr_coat_color=medium.coat_color)


def count_stats(rec: dict[str, np.ndarray], counts: np.ndarray, targets: tuple[str, ...] = ()) -> dict[str, int]:
    """Clamp statistics of S_maps.json: per-texel counts of ``rec`` weighted by how many texels share the
    colour (``counts`` (N,)); with the painted colour also the texels whose colour was clamped, for the
    ``targets`` they concern (CLAMPED_CYCLES, CLAMPED_SPECTRAL)."""
    out = {STAT_NAMES[name]: int(np.dot(np.rint(rec[name]).astype(np.int64), counts))
           for name in COUNT_FIELDS if name in rec}
    if "spectral_clamped" in rec:  # painted colour
        if needs_media(targets):
            out[CLAMPED_CYCLES] = int(np.dot(rec["n_unreachable"] > 0, counts))
        if "spectral" in targets:
            out[CLAMPED_SPECTRAL] = int(np.dot(np.rint(rec["spectral_clamped"]) > 0, counts))
    return out


def cycles_contributions(rec: dict[str, np.ndarray], ior: float) -> np.ndarray:
    """(N, K, 3): w_kc R_cycles(alpha_kc, g_k), what each component adds to the colour Cycles renders (their sum
    over K is the baked appearance, linear sRGB)."""
    g = rec["anisotropy"][..., None]
    return rec["weight"] * reflectance_tables.reflectance("cycles", rec["alpha"], g, ior)
