"""The K = 3 physical decomposition of paper §8 and its Figs. 7-9, computed from the shipped model.

    python -m training.validate.decomposition --out docs/validation [--quick] [--model-dir DIR] [--overwrite]

writes ``decomposition.json``, ``decomposition.md`` and the figures ``fig_sss_reconstruction.png`` (Fig. 7),
``fig_component_maps.png`` (its weight and g), ``fig_sigma_t_distribution.png`` (Fig. 8) and
``fig_g_bimodality.png`` (Fig. 9).  Everything comes from ``skin_inversion.onnx`` and ``skin_decoder.onnx``
(onnxruntime, no Monte Carlo): about 20 CPU-seconds, ``--quick`` a few.

**Tone sets** (the statistics are computed on each; the verdicts on ``validation``):

* ``validation``: ``VALIDATION_TONES`` validation-like tones (``training.data.sampling.validation_tones``,
  seed ``VALIDATION_SEED``, the dataset's skin-weighted sampling) through ``skin_decoder.onnx``;
* ``representative``: R01-R10 of ``training/skin/tones.csv`` through ``skin_decoder.onnx``;
* ``measured``: the colours (D65, linear sRGB) of the 50 measured NIST skin spectra
  (``training.realskin.measurements``, specular reflection included) through ``skin_inversion.onnx``;
* ``subjects``: ``SUBJECT_SAMPLES`` texels of each of the three demo albedo textures (light, medium, dark:
  ``training.demo_subject.skin_albedo_texture``) through ``skin_inversion.onnx``.

**Definitions** (ours where the paper gives none, marked *choice*):

* Component identity: the network's K outputs keep their identity across tones and wavelengths (trained on
  fits matched along wavelength and sorted by sigma_t at 600 nm, ``training.fit.matching``); they are
  named C1..C3 in order of their median albedo over a set's tones and wavelengths, decreasing (*choice*),
  C3 the lowest.  The maps of Fig. 7 use the order of the ``validation`` set.  "The two high-alpha
  components' median alpha" is the median of C1's and C2's alpha pooled over tones and wavelengths; the
  low component's alpha and weight are medians likewise.  As a check of that choice, ``lowest_per_sample``
  takes at every (tone, wavelength) the component of lowest albedo there (the most favourable reading
  for a low-albedo component).
* Mass: a sample (tone, wavelength) of C3 counts with its mixture weight w_3 (the caption's "mass").
  Energy: with w_3 R(alpha_3, g_3), the light it reflects (``exporters.reflectance_tables``, the model's
  boundary): the text's "mixture-weighted energy".  The boundary share is the mass (energy) at
  sigma_t < 10 cm^-1 over all of C3's, over all wavelengths or within a band.
* Bands: UV [250, 400), blue [400, 500) (*choice*), NIR [700, 1000] nm (``training.validate.metrics``).
  Concentration = mean(UV share, blue share) / NIR share: the reading that gives the paper's own 2.7 from
  its 30.7 %, 16.3 % and 8.8 %; the pooled reading (UV and blue samples together) is reported beside it.
* Modes of g: a Gaussian kernel density of C3's g (unweighted, the figure's histogram; and mass-weighted),
  binned every ``G_BIN`` with bandwidth max(Silverman's rule, ``G_MIN_BANDWIDTH``); a mode is a peak of
  prominence >= ``MODE_PROMINENCE`` x the highest density (``scipy.signal.find_peaks``).  Bimodal: >= 2 modes.
  Sarle's bimodality coefficient (skew^2 + 1) / kurtosis (> 5/9 suggests bimodality) is given beside it.

**Verdicts** (``comparison``): a share or ratio agrees within a factor ``AGREE_FACTOR`` of the paper's,
is "partly" within ``PARTLY_FACTOR`` (for the concentration: whenever UV/blue exceed NIR, the paper's
direction); an albedo is judged by its absorbed fraction 1 - alpha with the same factors (0.92 against 0.96
absorbs twice as much); a weight agrees within ``WEIGHT_TOLERANCE``; g agrees if
bimodal with modes within ``MODE_TOLERANCE`` of 0 and 0.87 (partly: bimodal elsewhere).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exporters.constants import WAVELENGTHS_NM
from training.paths import SHIPPED_MODEL_DIR as DEFAULT_MODEL_DIR
from training.validate import paper
from training.validate.metrics import BANDS as METRIC_BANDS

#: Mixture fields of the model's outputs, each (N, K, W).
FIELDS: tuple[str, ...] = ("alpha", "sigma_t", "g", "weight")
#: Bands of the boundary shares: name -> (low nm, high nm, include low, include high).  Blue is our choice.
BANDS: dict[str, tuple[float, float, bool, bool]] = {
    "UV": METRIC_BANDS["UV"], "blue": (400.0, 500.0, True, False), "NIR": METRIC_BANDS["NIR"]}
#: Wavelength of the per-component maps (nm): the haemoglobin band of Fig. 7's middle column (541 nm in the
#: paper; 542 nm is on the 2 nm grid) and the three reflectance columns of Fig. 7.
MAP_NM: float = 542.0
REFLECTANCE_NM: tuple[float, ...] = (250.0, 542.0, 940.0)
#: Tone sets (module docstring).
VALIDATION_TONES, QUICK_VALIDATION_TONES = 2000, 64
VALIDATION_SEED = 2024
SUBJECT_SAMPLES, QUICK_SUBJECT_SAMPLES = 300, 16
#: Demo textures: edge length (texels) of the maps.
TEXTURE_SIZE, QUICK_TEXTURE_SIZE = 128, 16
#: Mode finding on g: bin width, smallest kernel bandwidth, relative prominence of a mode.
G_BIN: float = 0.0025
G_MIN_BANDWIDTH: float = 0.02
MODE_PROMINENCE: float = 0.1
#: Verdict tolerances (module docstring).
AGREE_FACTOR, PARTLY_FACTOR = 1.5, 3.0
WEIGHT_TOLERANCE, MODE_TOLERANCE = 0.1, 0.1
FILES = {"json": "decomposition.json", "md": "decomposition.md", "fig7": "fig_sss_reconstruction.png",
         "fig7b": "fig_component_maps.png", "fig8": "fig_sigma_t_distribution.png", "fig9": "fig_g_bimodality.png"}


def check_mixture(mix: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``mix`` as float64 arrays (N, K, W) of one shape; ValueError naming the field that is wrong."""
    out = {f: np.asarray(mix[f], dtype=np.float64) for f in FIELDS}
    shape = out["alpha"].shape
    for f, v in out.items():
        if v.ndim != 3 or v.shape != shape:
            raise ValueError(f"mixture field {f!r} has shape {v.shape}; every field must be (N, K, W) like "
                             f"alpha {shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"mixture field {f!r} contains NaN/Inf")
    return out


def albedo_rank(mix: dict[str, np.ndarray]) -> np.ndarray:
    """The model's components (K,) in order of their median albedo over all tones and wavelengths, decreasing."""
    alpha = check_mixture(mix)["alpha"]
    return np.argsort(-np.median(alpha.transpose(1, 0, 2).reshape(alpha.shape[1], -1), axis=1), kind="stable")


def reorder(mix: dict[str, np.ndarray], order: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The mixture's fields with their components in ``order`` (K,) (default ``albedo_rank(mix)``)."""
    m = check_mixture(mix)
    order = albedo_rank(m) if order is None else np.asarray(order)
    return {f: m[f][:, order] for f in FIELDS}


def band_mask(wavelength_nm: np.ndarray, band: str) -> np.ndarray:
    """Boolean (W,) mask of ``band`` (a key of ``BANDS``)."""
    lo, hi, inc_lo, inc_hi = BANDS[band]
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    return ((wl >= lo) if inc_lo else (wl > lo)) & ((wl <= hi) if inc_hi else (wl < hi))


def _share(below: np.ndarray, mass: np.ndarray) -> float | None:
    total = float(mass.sum())
    return float((mass * below).sum() / total) if total > 0 else None


def _ratio(num: float | None, den: float | None) -> float | None:
    """num / den, None where undefined (no NaN/Inf leaves this module)."""
    if num is None or den is None or den <= 0:
        return None
    return num / den


def boundary_shares(sigma_t: np.ndarray, mass: np.ndarray, wavelength_nm: np.ndarray = WAVELENGTHS_NM,
                    threshold_cm: float = paper.K3_SIGMA_T_BOUNDARY_CM) -> dict:
    """Share of ``mass`` (N, W) at ``sigma_t`` (N, W) [cm^-1] < ``threshold_cm``: over all wavelengths
    (``all``), per band (``bands``), the concentration mean(UV, blue) / NIR and the pooled (UV + blue) / NIR."""
    below = np.asarray(sigma_t) < threshold_cm
    masks = {b: band_mask(wavelength_nm, b) for b in BANDS}
    bands = {b: _share(below[:, k], mass[:, k]) for b, k in masks.items()}
    short = masks["UV"] | masks["blue"]
    mean_short = None if bands["UV"] is None or bands["blue"] is None else 0.5 * (bands["UV"] + bands["blue"])
    return {"all": _share(below, mass), "bands": bands, "concentration": _ratio(mean_short, bands["NIR"]),
            "concentration_pooled": _ratio(_share(below[:, short], mass[:, short]), bands["NIR"])}


@dataclass
class Modes:
    """Modes of a 1-D distribution: ``modes`` (ascending), ``bandwidth``, the density ``density`` on ``grid``."""

    modes: list[float]
    bandwidth: float
    grid: np.ndarray
    density: np.ndarray

    @property
    def bimodal(self) -> bool:
        return len(self.modes) >= 2


def _weighted_quantiles(x: np.ndarray, w: np.ndarray, q: tuple[float, ...]) -> np.ndarray:
    """Quantiles ``q`` of ``x`` weighted by ``w`` (inverted CDF; numpy < 2 has no weights in np.quantile)."""
    order = np.argsort(x, kind="stable")
    cdf = np.cumsum(w[order]) / w.sum()
    return x[order][np.minimum(np.searchsorted(cdf, q), x.size - 1)]


def find_modes(values: np.ndarray, weights: np.ndarray | None = None, lo: float = -1.0, hi: float = 1.0) -> Modes:
    """Modes of ``values`` (weighted by ``weights``) on [lo, hi]: a binned Gaussian kernel density (bins of
    ``G_BIN``, bandwidth max(Silverman's rule, ``G_MIN_BANDWIDTH``)) and its peaks of prominence at least
    ``MODE_PROMINENCE`` of its maximum (``scipy.signal.find_peaks``)."""
    from scipy.ndimage import gaussian_filter1d
    from scipy.signal import find_peaks

    x = np.asarray(values, dtype=np.float64).ravel()
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if x.size < 2 or w.shape != x.shape or not (np.all(np.isfinite(x)) and np.all(np.isfinite(w))) or w.sum() <= 0:
        raise ValueError("find_modes needs >= 2 finite values with finite weights of positive sum, one per value")
    mean = np.average(x, weights=w)
    sd = math.sqrt(np.average((x - mean) ** 2, weights=w))
    q1, q3 = _weighted_quantiles(x, w, (0.25, 0.75))
    spread = min(sd, (q3 - q1) / 1.34) or sd
    n_eff = w.sum() ** 2 / (w**2).sum()
    bandwidth = max(0.9 * spread * n_eff ** -0.2, G_MIN_BANDWIDTH)
    edges = np.arange(lo, hi + G_BIN / 2, G_BIN)
    hist, _ = np.histogram(np.clip(x, lo, hi), bins=edges, weights=w)
    density = gaussian_filter1d(hist / (w.sum() * G_BIN), bandwidth / G_BIN, mode="constant")
    grid = 0.5 * (edges[:-1] + edges[1:])
    peaks, _ = find_peaks(np.pad(density, 1), prominence=MODE_PROMINENCE * density.max())
    return Modes([float(grid[p - 1]) for p in peaks], float(bandwidth), grid, density)


def bimodality_coefficient(values: np.ndarray) -> float:
    """Sarle's bimodality coefficient of a sample, (skew^2 + 1) / (excess kurtosis + 3 (n-1)^2 / ((n-2)(n-3)))
    with the bias-corrected moments of ``scipy.stats``; > 5/9 (a uniform's) suggests bimodality."""
    from scipy.stats import kurtosis, skew

    x = np.asarray(values, dtype=np.float64).ravel()
    n = x.size
    if n < 4 or np.ptp(x) == 0:
        raise ValueError("the bimodality coefficient needs >= 4 values that are not all equal")
    return float((skew(x, bias=False) ** 2 + 1) / (kurtosis(x, bias=False) + 3 * (n - 1) ** 2 / ((n - 2) * (n - 3))))


def component_reflectance(alpha: np.ndarray, g: np.ndarray) -> np.ndarray:
    """R(alpha, g) of each component at the model's boundary (``exporters.reflectance_tables``, "model")."""
    from exporters.reflectance_tables import reflectance

    return reflectance("model", alpha, np.clip(g, 0.0, None))


def decomposition_stats(mix: dict[str, np.ndarray], wavelength_nm: np.ndarray = WAVELENGTHS_NM) -> dict:
    """The §8 statistics (module docstring) of mixtures (N, K, W) on ``wavelength_nm`` (W,)."""
    rank = albedo_rank(mix)
    m = reorder(mix, rank)
    n, k, _ = m["alpha"].shape
    if k < 2:
        raise ValueError(f"the decomposition needs K >= 2 components, got K = {k}")
    comps = [{name: float(np.median(m[f][:, c])) for name, f in (("median_alpha", "alpha"), ("median_weight", "weight"),
                                                                  ("median_sigma_t_cm", "sigma_t"), ("median_g", "g"))}
             | {"mean_weight": float(m["weight"][:, c].mean()), "output": int(rank[c])} for c in range(k)]
    low = {f: m[f][:, -1] for f in FIELDS}
    energy = low["weight"] * component_reflectance(low["alpha"], low["g"])
    lowest = np.argmin(m["alpha"], axis=1)[:, None]  # per (tone, wavelength): the sensitivity check
    per_sample = {f: np.take_along_axis(m[f], lowest, axis=1)[:, 0] for f in ("alpha", "weight")}
    g_modes = find_modes(low["g"])
    g_modes_mass = find_modes(low["g"], low["weight"])
    return {
        "tones": n, "k": k, "components": comps,
        "high_median_alpha": float(np.median(m["alpha"][:, :-1])),
        "low_median_alpha": comps[-1]["median_alpha"], "low_median_weight": comps[-1]["median_weight"],
        "lowest_per_sample": {"median_alpha": float(np.median(per_sample["alpha"])),
                              "median_weight": float(np.median(per_sample["weight"]))},
        "boundary_mass": boundary_shares(low["sigma_t"], low["weight"], wavelength_nm),
        "boundary_energy": boundary_shares(low["sigma_t"], energy, wavelength_nm),
        "g_low": {"modes": g_modes.modes, "bimodal": g_modes.bimodal, "bandwidth": g_modes.bandwidth,
                  "modes_mass_weighted": g_modes_mass.modes, "bimodal_mass_weighted": g_modes_mass.bimodal,
                  "bimodality_coefficient": bimodality_coefficient(low["g"])},
    }


# ------------------------------------------------------------------------------------------- verdicts

def _factor_verdict(ours: float | None, ref: float) -> str:
    if ours is None or ours <= 0:
        return "disagree"
    f = max(ours / ref, ref / ours)
    return "agree" if f <= AGREE_FACTOR else "partly" if f <= PARTLY_FACTOR else "disagree"


def _concentration_verdict(s: dict) -> str:
    c, short, nir = s["concentration"], s["bands"]["UV"], s["bands"]["NIR"]
    if c is None:  # no NIR mass below the threshold: the direction holds if UV has some, the size is unbounded
        return "partly" if (short or 0) > 0 and nir == 0 else "disagree"
    if c <= 1:
        return "disagree"
    return "agree" if max(c, paper.K3_CONCENTRATION) / min(c, paper.K3_CONCENTRATION) <= AGREE_FACTOR else "partly"


def _g_verdict(g: dict) -> str:
    if not g["bimodal"]:
        return "disagree"
    near = all(min(abs(m - p) for m in g["modes"]) <= MODE_TOLERANCE for p in paper.K3_G_MODES)
    return "agree" if near else "partly"


def comparison(stats: dict) -> list[dict]:
    """Rows (claim, paper, ours, verdict) of the paper's §8 numbers against ``stats`` of one tone set."""
    b = stats["boundary_mass"]
    absorbed = lambda ours, ref: _factor_verdict(1.0 - ours, 1.0 - ref)  # noqa: E731
    rows = [
        ("high-alpha components (C1, C2): median alpha", paper.K3_HIGH_ALPHA, stats["high_median_alpha"],
         absorbed(stats["high_median_alpha"], paper.K3_HIGH_ALPHA)),
        ("low-alpha component (C3): median alpha", paper.K3_LOW_ALPHA, stats["low_median_alpha"],
         absorbed(stats["low_median_alpha"], paper.K3_LOW_ALPHA)),
        ("C3: median weight", paper.K3_LOW_WEIGHT, stats["low_median_weight"],
         "agree" if abs(stats["low_median_weight"] - paper.K3_LOW_WEIGHT) <= WEIGHT_TOLERANCE else "disagree"),
        ("C3: share of mass at sigma_t < 10 cm^-1, all wavelengths", paper.K3_BOUNDARY_SHARE, b["all"],
         _factor_verdict(b["all"], paper.K3_BOUNDARY_SHARE)),
        *((f"C3: share of mass at sigma_t < 10 cm^-1, {band}", ref, b["bands"][band],
           _factor_verdict(b["bands"][band], ref)) for band, ref in paper.K3_BOUNDARY_BANDS.items()),
        ("C3: concentration mean(UV, blue) / NIR", paper.K3_CONCENTRATION, b["concentration"],
         _concentration_verdict(b)),
        ("C3: g bimodal, modes", list(paper.K3_G_MODES), stats["g_low"]["modes"], _g_verdict(stats["g_low"])),
    ]
    return [{"claim": c, "paper": p, "ours": o, "verdict": v} for c, p, o, v in rows]


# ------------------------------------------------------------------------------------------- the model

def _decoder_mixture(decoder: Path, tones: np.ndarray) -> dict[str, np.ndarray]:
    """``skin_decoder.onnx`` on biophysical rows (N, 5): its mixture (checked) and reflectance, float64."""
    from exporters.inference import run_decoder

    out = run_decoder(tones, decoder)
    return check_mixture(out) | {"reflectance": out["reflectance"]}


def measured_colours() -> np.ndarray:
    """Linear sRGB (S, 3) under D65 of the measured NIST skin spectra, interpolated onto the 2 nm grid."""
    from exporters.colorimetry import spectrum_to_linear_srgb
    from training.realskin.measurements import read_measurements

    meas = read_measurements()
    spectra = np.stack([np.interp(WAVELENGTHS_NM, meas.wavelength_nm, r) for r in meas.reflectance])
    return np.clip(spectrum_to_linear_srgb(spectra), 0.0, 1.0)


def subject_textures(size: int) -> dict[str, np.ndarray]:
    """The demo's light, medium and dark albedo textures: name -> (size, size, 3) linear sRGB."""
    from exporters.colorimetry import srgb_decode
    from training.demo_subject import TONES, skin_albedo_texture

    return {name: srgb_decode(skin_albedo_texture(size, seed=0, base=base) / 255.0) for name, base in TONES.items()}


def _columns(nm: tuple[float, ...]) -> np.ndarray:
    return np.array([int(np.abs(WAVELENGTHS_NM - x).argmin()) for x in nm])


def subject_maps(model, linear: np.ndarray, order: np.ndarray) -> dict[str, np.ndarray]:
    """Per-texel maps of one texture (H, W, 3) linear sRGB through the inversion ``model``: ``input`` and
    ``reconstructed`` (the model's reflectance times its exposure, D65) linear sRGB, ``alpha``, ``sigma_t``,
    ``weight``, ``g`` (H, W, K) at ``MAP_NM`` (components in ``order`` (K,)) and ``reflectance``
    (H, W, len(REFLECTANCE_NM))."""
    from exporters.colorimetry import spectrum_to_linear_srgb
    from exporters.inference import unique_rows

    h, w, _ = linear.shape
    uniq, inverse = unique_rows(linear.reshape(-1, 3).astype(np.float32))
    col, rcols = _columns((MAP_NM,))[0], _columns(REFLECTANCE_NM)
    parts: dict[str, list[np.ndarray]] = {}
    for _, out in model.run_chunks(uniq, 2048):
        mix = reorder(out, order)
        refl = out["reflectance"].astype(np.float64)
        got = {f: mix[f][..., col] for f in FIELDS} | {
            "reconstructed": spectrum_to_linear_srgb(refl * out["exposure"].astype(np.float64)),
            "reflectance": refl[:, rcols]}
        for key, v in got.items():
            parts.setdefault(key, []).append(v)
    maps = {key: np.concatenate(v)[inverse].reshape(h, w, -1) for key, v in parts.items()}
    return maps | {"input": linear}


def _inversion_mixture(model, rgb: np.ndarray) -> dict[str, np.ndarray]:
    out = model.run(np.asarray(rgb, dtype=np.float32))
    return check_mixture(out)


def tone_sets(model_dir: Path, quick: bool, model) -> dict[str, dict]:
    """name -> {"description", "mixture"} of the four tone sets (module docstring)."""
    from training.data.sampling import validation_tones
    from training.skin.tones import load_tones

    decoder = model_dir / "skin_decoder.onnx"
    n_val = QUICK_VALIDATION_TONES if quick else VALIDATION_TONES
    n_sub = QUICK_SUBJECT_SAMPLES if quick else SUBJECT_SAMPLES
    rng = np.random.default_rng(VALIDATION_SEED)
    texels = np.concatenate([t.reshape(-1, 3)[rng.choice(t.shape[0] * t.shape[1], n_sub, replace=False)]
                             for t in subject_textures(QUICK_TEXTURE_SIZE if quick else TEXTURE_SIZE).values()])
    colours = measured_colours()
    return {
        "validation": {"description": f"{n_val} validation-like tones (seed {VALIDATION_SEED}), skin_decoder.onnx",
                       "mixture": _decoder_mixture(decoder, validation_tones(n_val, VALIDATION_SEED))},
        "representative": {"description": "R01-R10 (training/skin/tones.csv), skin_decoder.onnx",
                           "mixture": _decoder_mixture(decoder, load_tones().select("representative").values)},
        "measured": {"description": f"colours of the {len(colours)} measured NIST skin spectra (D65), "
                                    "skin_inversion.onnx", "mixture": _inversion_mixture(model, colours)},
        "subjects": {"description": f"{n_sub} texels of each demo texture (light, medium, dark), skin_inversion.onnx",
                     "mixture": _inversion_mixture(model, texels)},
    }


# ------------------------------------------------------------------------------------------- outputs

def _fmt(v) -> str:
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, list):
        return "[" + ", ".join(f"{x:.2f}" for x in v) + "]"
    return f"{v:.3g}"


def markdown(result: dict) -> str:
    """decomposition.md: the paper beside ours per tone set, the components, the subjects."""
    sets = list(result["sets"])
    lines = [
        "# The K = 3 physical decomposition (paper §8, Figs. 7-9), from the shipped model", "",
        f"Written by `{result['command']}` from the model of {result['model']['card_created']} "
        f"(skin_inversion.onnx sha256 {result['model']['sha256'][:12]}…). These are the numbers of the model "
        "shipped at that time: rerun the command after a rebuild. Definitions: the docstring of "
        "`training/validate/decomposition.py` (the network's components named by median albedo; C3 the lowest; "
        "shares weighted by the mixture weight; blue = 400–500 nm; concentration = mean(UV, blue share) / NIR share).",
        "", "Tone sets: " + "; ".join(f"**{s}**: {result['sets'][s]['description']}" for s in sets) + ".", "",
        "| claim | paper | " + " | ".join(f"ours, {s}" for s in sets) + " | verdict (validation) |",
        "|---|---|" + "---|" * len(sets) + "---|",
    ]
    rows = {s: result["sets"][s]["comparison"] for s in sets}
    for i, row in enumerate(rows["validation"]):
        lines.append(f"| {row['claim']} | {_fmt(row['paper'])} | "
                     + " | ".join(_fmt(rows[s][i]["ours"]) for s in sets) + f" | {row['verdict']} |")
    lines += ["", "Energy reading (C3's reflected light w·R(α, g) instead of its weight) and the pooled "
              "concentration:", "",
              "| set | energy share < 10 cm⁻¹ | UV | blue | NIR | concentration | pooled concentration (mass) | "
              "g modes, mass-weighted | bimodality coefficient of g | lowest α per (tone, λ): median α / its weight |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for s in sets:
        st = result["sets"][s]["stats"]
        e = st["boundary_energy"]
        lines.append(f"| {s} | {_fmt(e['all'])} | " + " | ".join(_fmt(e["bands"][b]) for b in BANDS)
                     + f" | {_fmt(e['concentration'])} | {_fmt(st['boundary_mass']['concentration_pooled'])} | "
                     f"{_fmt(st['g_low']['modes_mass_weighted'])} | {_fmt(st['g_low']['bimodality_coefficient'])} | "
                     f"{_fmt(st['lowest_per_sample']['median_alpha'])} / "
                     f"{_fmt(st['lowest_per_sample']['median_weight'])} |")
    lines += ["", "Components (named by median albedo; `output` is the network's index), median over tones and "
              "wavelengths:", "", "| set | component | output | α | weight (median / mean) | σt (cm⁻¹) | g |",
              "|---|---|---|---|---|---|---|"]
    for s in sets:
        for c, comp in enumerate(result["sets"][s]["stats"]["components"]):
            lines.append(f"| {s} | C{c + 1} | {comp['output']} | {comp['median_alpha']:.3f} | "
                         f"{comp['median_weight']:.3f} / "
                         f"{comp['mean_weight']:.3f} | {comp['median_sigma_t_cm']:.1f} | {comp['median_g']:.3f} |")
    lines += ["", f"Fig. 7 subjects (the demo textures, {result['texture_size']}² texels; maps at {MAP_NM:g} nm; "
              "paper's σt colour ranges C1 [80, 901], C2 [73, 3555], C3 [86, 5147] cm⁻¹):", "",
              "| subject | ΔE76 input → reconstructed (mean / max) | σt range at 542 nm, C1 / C2 / C3 (cm⁻¹) |",
              "|---|---|---|"]
    for name, sub in result["subjects"].items():
        lines.append(f"| {name} | {sub['delta_e_mean']:.2f} / {sub['delta_e_max']:.2f} | "
                     + " / ".join(f"[{lo:.0f}, {hi:.0f}]" for lo, hi in sub["sigma_t_range_cm"]) + " |")
    lines += ["", "Figures: " + ", ".join(f"`{FILES[k]}`" for k in ("fig7", "fig7b", "fig8", "fig9")), ""]
    return "\n".join(lines)


def _subject_summary(maps: dict[str, np.ndarray]) -> dict:
    from exporters.colorimetry import delta_e76, linear_srgb_to_lab

    de = delta_e76(linear_srgb_to_lab(maps["input"]), linear_srgb_to_lab(maps["reconstructed"]))
    s = maps["sigma_t"]
    return {"delta_e_mean": float(de.mean()), "delta_e_max": float(de.max()),
            "sigma_t_range_cm": [[float(s[..., c].min()), float(s[..., c].max())] for c in range(s.shape[-1])]}


def _plot(out: Path, subjects: dict[str, dict], validation: dict[str, np.ndarray], stats: dict) -> None:
    from training.validate import figures

    names = list(subjects)
    stack = {key: np.stack([subjects[n][key] for n in names]) for key in subjects[names[0]]}
    figures.sss_reconstruction(out / FILES["fig7"], names, stack, MAP_NM, REFLECTANCE_NM)
    figures.component_maps(out / FILES["fig7b"], names, stack, MAP_NM)
    low = {f: reorder(validation)[f][:, -1] for f in FIELDS}
    figures.sigma_t_distribution(out / FILES["fig8"], WAVELENGTHS_NM, low["sigma_t"], low["weight"],
                                 paper.K3_SIGMA_T_BOUNDARY_CM, stats["boundary_mass"]["bands"], paper.K3_BOUNDARY_BANDS)
    figures.g_bimodality(out / FILES["fig9"], find_modes(low["g"]), find_modes(low["g"], low["weight"]),
                         paper.K3_G_MODES)


def run(out: Path, model_dir: Path = DEFAULT_MODEL_DIR, quick: bool = False, command: str = "") -> dict:
    """Compute everything of the module docstring and write it into ``out``; returns the JSON's content."""
    from exporters.inference import load_model

    model = load_model(model_dir / "skin_inversion.onnx", threads=1)
    card = json.loads((model_dir / "skin_inversion.json").read_text())
    size = QUICK_TEXTURE_SIZE if quick else TEXTURE_SIZE
    sets = tone_sets(model_dir, quick, model)
    order = albedo_rank(sets["validation"]["mixture"])
    subjects = {name: subject_maps(model, tex, order) for name, tex in subject_textures(size).items()}
    result = {"command": command, "quick": quick, "texture_size": size,
              "model": {"sha256": model.sha256, "card_created": card.get("created", "unknown")},
              "map_nm": MAP_NM, "reflectance_nm": list(REFLECTANCE_NM),
              "sets": {}, "subjects": {n: _subject_summary(m) for n, m in subjects.items()}}
    for name, s in sets.items():
        st = decomposition_stats(s["mixture"])
        result["sets"][name] = {"description": s["description"], "stats": st, "comparison": comparison(st)}
    out.mkdir(parents=True, exist_ok=True)
    _plot(out, subjects, sets["validation"]["mixture"], result["sets"]["validation"]["stats"])
    (out / FILES["json"]).write_text(json.dumps(result, indent=2) + "\n")
    (out / FILES["md"]).write_text(markdown(result))
    return result


def main(argv: list[str]) -> int:
    from training.paths import portable_command

    p = argparse.ArgumentParser(prog="python -m training.validate.decomposition", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="folder for decomposition.{json,md} and the figures")
    p.add_argument("--model-dir", type=Path, default=DEFAULT_MODEL_DIR,
                   help="folder with skin_inversion.onnx, skin_decoder.onnx and skin_inversion.json")
    p.add_argument("--quick", action="store_true", help=f"{QUICK_VALIDATION_TONES} validation tones, "
                   f"{QUICK_TEXTURE_SIZE}² textures (a test runs it)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier run in --out")
    args = p.parse_args(argv)
    existing = [f for f in FILES.values() if (args.out / f).exists()]
    if existing and not args.overwrite:
        print(f"error: {args.out} already holds {', '.join(existing)}; pass --overwrite to replace them",
              file=sys.stderr)
        return 2
    try:
        result = run(args.out, args.model_dir, args.quick,
                     portable_command("python -m training.validate.decomposition", argv))
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
