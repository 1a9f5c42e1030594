"""The record of a validation run, typed, and its JSON form (``tables.json``).

``ValidationRecord`` holds what ``python -m training validate`` measured (``training.validate.assemble``
computes its parts, ``training.validate.run`` puts them together).  Every field's name is its key in
tables.json, in the order written; :func:`to_json` turns the record into the plain dicts and lists that
``training.validate.tables`` (tables.md, the notes), ``headline`` (the model card) and the report read, so a
tables.json written before the types existed reads the same.  A field left at ``ABSENT`` is not written: the
keys that only some runs have (the training neighbours without ``--fits``, Table 2 without a representative
tone, the calibration of a given baseline scale).

Groups of tones are "representative", "outlier" and "all" (``ByGroup``); bands "UV", "Vis", "NIR" and, where
stated, "all" (``ByBand``); configurations (rows) are ``training.validate.gate.ROWS``.  ΔE76 is CIE 1976
colour difference, shapes are the fitter's L_shape (``training.fit.loss``), times are seconds.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from exporters.constants import WAVELENGTHS_NM
from training.paths import portable
from training.validate import baselines as bl
from training.validate import gate as G


class Absent:
    """The type of ``ABSENT``: a field that this run does not write to tables.json."""

    def __repr__(self) -> str:
        return "ABSENT"


#: A field's value when its key is not written (:func:`to_json` drops it).
ABSENT = Absent()

#: A value per group of gate tones ("representative", "outlier", "all"); None where the group is empty.
ByGroup = dict[str, float | None]
#: A value per band ("UV", "Vis", "NIR", and "all" where stated); None where the band has no wavelength.
ByBand = dict[str, float | None]


def to_json(value: Any) -> Any:
    """``value`` with every dataclass turned into a dict of its fields (in order, ``ABSENT`` ones left out),
    recursively through dicts, lists and tuples; other values as they are (tables.write_tables makes them
    JSON: NumPy scalars, non-finite floats)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_json(v) for f in dataclasses.fields(value)
                if (v := getattr(value, f.name)) is not ABSENT}
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(to_json(v) for v in value)
    return value


# ------------------------------------------------------------------------------------------ Table 1
@dataclass
class ToneMetrics:
    """One configuration rendered for one gate tone (Table 1 per tone)."""

    delta_e: float  #: ΔE76 of the slab colour against the Monte Carlo ground truth
    noise_floor: float  #: the ΔE76 that Monte Carlo noise alone gives (metrics.noise_floor)
    delta_e_edge: float  #: ΔE76 of the half-plane-lit edge image (metrics.edge_delta_e)
    sam_vis: float  #: visible spectral angle of R_d against the ground truth, rad
    shape_vis_lut: float  #: visible L_shape of the profile through the LUT, as rendered (Σ w_k R_k P_k)
    shape_vis_lut_fit_weighting: float  #: the same with the paper's text weighting (Σ w_k P_k)
    linear_srgb: list[float]  #: (3,) the rendered slab's colour, linear sRGB (D65)
    truncated_max: float  #: largest photon weight still alive at the walk cap (bound on the cut R)
    clamped: bool | Absent = ABSENT  #: painted row only: the painted colour had to be clamped


@dataclass
class RowSummary:
    """One configuration of Table 1: its per-tone metrics averaged over each group of tones."""

    label: str
    delta_e: ByGroup
    noise_floor: ByGroup
    delta_e_edge: ByGroup
    sam_vis: ByGroup
    shape_vis_lut: ByGroup
    shape_vis_lut_fit_weighting: ByGroup
    vs_k1: float | None = None  #: K = 1's representative ΔE76 over this row's


@dataclass
class GroundTruthColour:
    """A gate tone's Monte Carlo ground truth as a colour."""

    kind: str  #: "representative" or "outlier"
    albedo_rgb: list[float]  #: (3,) linear sRGB albedo: the network's input
    srgb: list[float]  #: (3,) linear sRGB of R_d, clipped below at 0
    lab: list[float]  #: (3,) CIE Lab of the unclipped colour


@dataclass
class NetworkVsK3:
    """The network's render against the joint-optimised K = 3 fits' render."""

    delta_e: ByGroup  #: mean ΔE76 between the two renders
    per_tone: dict[str, float]  #: ΔE76 between the two renders, per tone
    difference_of_means: ByGroup  #: mean ΔE76 to the ground truth, network minus K = 3


@dataclass
class TrainingNeighbours:
    """Per gate tone, the fitted training tones within ``radius`` in the unit parameter box."""

    radius: float
    n_fitted: int
    count: dict[str, int]


@dataclass
class McCheck:
    """One configuration: the tables' renders against our Monte Carlo renders, over all tones."""

    delta_e_mc_vs_lut: float
    mc_noise_floor: float
    max_delta_e_mc_vs_lut: float


@dataclass
class GateRecord:
    """Table 1, the rendering gate: rows summarised, every tone, the network against K = 3."""

    tones: list[str]
    kinds: list[str]
    groups: dict[str, list[str]]  #: tone names of each group
    wavelength_nm: list[float]  #: the rendered wavelengths
    rows: dict[str, RowSummary]
    per_tone: dict[str, dict[str, ToneMetrics]]  #: row -> tone -> metrics
    nn_vs_k3: NetworkVsK3
    ground_truth: dict[str, GroundTruthColour]
    training_neighbours: TrainingNeighbours | None | Absent = ABSENT  #: written when --fits is given
    renderer: str = "lut"  #: what rendered the slabs: "lut" (the tables) or "mc"
    mc_check: dict[str, McCheck] | None = None  #: per row; None without Monte Carlo renders


# ------------------------------------------------------------------------------------------ Table 2, 3
@dataclass
class BandedRecord:
    """Table 2, banded fidelity of the joint-optimised fits on the representative tones.  Without a
    representative tone only the empty ``shape`` ... ``excess_reduction`` are written."""

    tones: list[str]
    shape: dict[str, dict[str, float | None]] = field(default_factory=dict)  #: band -> "K1".."K3" -> L_shape
    reduction: dict[str, dict[str, float | None]] = field(default_factory=dict)  #: band -> "K1_to_K2", ...
    excess: dict[str, dict[str, float | None]] = field(default_factory=dict)  #: the same over the MC noise
    excess_reduction: dict[str, dict[str, float | None]] = field(default_factory=dict)
    noise: ByBand | Absent = ABSENT  #: L_shape of the ground truth's noise alone
    sam_vis: dict[str, float | None] | Absent = ABSENT  #: row -> visible SAM, rad
    sam_reduction: dict[str, float | None] | Absent = ABSENT
    refl_rel_err: dict[str, float] | Absent = ABSENT  #: "K1".."K3" -> mean |ΔR| / R of the fits
    network_shape: dict[str, dict[str, ByBand]] | Absent = ABSENT  #: network row -> group -> band -> L_shape


@dataclass
class ProfileFidelity:
    """Table 3 (``training.validate.profile_set``): the validation fits and the network's decoder."""

    fits: dict | None = None
    network: dict | None = None
    fits_missing: str | Absent = ABSENT  #: why ``fits`` is None


# ------------------------------------------------------------------------------------------ goals
@dataclass
class Goal:
    """Ours against the paper's number."""

    ours: float | None
    paper: float
    met: bool | None


@dataclass
class ReductionGoal:
    """K = 2's profile-error reduction against the paper's, and where ours was measured."""

    ours: float | None
    paper: float
    source: str
    met: bool | None
    excess_over_noise: dict | None = None  #: {"reduction", "noise"}: the same on the excess over MC noise


@dataclass
class NetworkTarget:
    """One of ``assemble.NETWORK_TARGETS`` checked: ``ours`` ≤ ``target``."""

    measure: str
    where: str
    what: str
    target: float
    ours: float | None
    met: bool | None


@dataclass
class Goals:
    nn_delta_e_at_most_paper: Goal
    k2_profile_reduction_at_least_paper: ReductionGoal
    network_targets: list[NetworkTarget]


# ------------------------------------------------------------------------------------------ the rest
@dataclass
class Calibration:
    """How the baselines' Subsurface Scale was chosen: "given", or "calibrated" on ``tone``."""

    mode: str
    tone: str | Absent = ABSENT
    scales_m: list[float] | Absent = ABSENT  #: the scales tried, m
    errors: dict[str, list] | Absent = ABSENT  #: method -> visible L_shape per scale


@dataclass
class BaselinesRecord:
    scale_m: dict[str, float]  #: method -> Subsurface Scale, m
    calibration: Calibration
    radius_rgb: list[float]  #: Blender's default Subsurface Radius
    wrenninge_g: float
    published_darkening: dict[str, list]  #: method -> per tone, R / A of the published polynomials


@dataclass
class HeldFits:
    """Fitted albedos moved into the LUT's albedo ``range`` before rendering: ``count`` of ``of``."""

    count: int
    of: int
    range: list[float]


@dataclass
class NetworkAnswers:
    """The inversion's answers per gate tone."""

    exposure: dict[str, float]  #: Y of the input over Y of the network's own reflectance
    biophysical_estimate: dict[str, list[float]]  #: (5,) docs/contracts.md §1
    biophysical_true: dict[str, list[float]]


@dataclass
class WavelengthInfo:
    validation_step_nm: int
    rendered_nm: list[float]  #: first and last rendered wavelength
    n_validation: int
    n_rendered: int


@dataclass
class LutInfo:
    path: str
    sha256: str
    albedo_n: int
    g_n: int
    g_range: list[float]


@dataclass
class ModelInfo:
    dir: str
    sha256: dict[str, str]  #: graph file name -> SHA-256
    card: dict  #: ``card_info``


@dataclass
class GroundTruthInfo:
    estimator: str
    photons: int
    walk_seconds: float


@dataclass
class FitInfo:
    method: str
    steps: Any  #: the fitter's step overrides (``GateConfig.steps()``), None for its defaults
    anchor_every: int
    seconds: float  #: the fits' own compute time, summed over tones


@dataclass
class RunInfo:
    """How the run was made: command, settings, inputs, times, machine."""

    command: str
    quick: bool
    config: dict  #: ``gate.config_record``
    wavelengths: WavelengthInfo
    lut: LutInfo
    model: ModelInfo
    ground_truth: GroundTruthInfo
    fits: FitInfo
    paper_fits: dict
    compute_seconds: dict[str, float]  #: of the cached pieces: ground truth, fits, renders
    timings_s: dict[str, float]  #: of this invocation, by step
    threads: int
    machine: dict[str, str]
    dataset: str | None
    fits_dir: str | None


@dataclass
class ValidationRecord:
    """Everything tables.json holds (module docstring)."""

    gate: GateRecord
    banded: BandedRecord
    profile_fidelity: ProfileFidelity
    goals: Goals
    baselines: BaselinesRecord
    truncated_max: dict[str, float]  #: row -> largest ``ToneMetrics.truncated_max`` over the tones
    fits_held_at_lut_albedo: HeldFits
    network: NetworkAnswers
    run: RunInfo | None = None  #: set once the run's timings are complete
    notes: list[str] = field(default_factory=list)  #: tables.notes

    def to_json(self) -> dict:
        return to_json(self)


# ------------------------------------------------------------------------------------------ building
def card_info(card: Path) -> dict:
    """What the run records of the model card: its path, creation, K, dataset, preset, first note, hashes."""
    if not card.is_file():
        return {"path": portable(card), "missing": True}
    c = json.loads(card.read_text())
    ds = c.get("dataset", {})
    return {"path": portable(card), "created": c.get("created"), "K": c.get("K"),
            "dataset": {k: ds.get(k) for k in ("path", "n_train", "n_validation", "photons")},
            "preset": ds.get("train_attrs", {}).get("preset"), "lut": c.get("lut", {}).get("path"),
            "notes": c.get("notes", [])[:1],
            "sha256": {n: v.get("sha256") for n, v in c.get("files", {}).items()}}


def run_info(opts, cfg: G.GateConfig, lut, lut_sha: str, gt: dict, fits: dict, timings: dict[str, float],
             models: dict, renders: list[dict]) -> RunInfo:
    """``RunInfo`` of a run: ``opts`` (``run.Options``), the LUT, the ground truth, the fits, the timings (s),
    the model hashes and card (``models``) and the renders (their seconds, each walk counted once)."""
    rep_fit_seconds = float(sum(float(f["seconds"]) for f in fits.values()))
    rendered = WAVELENGTHS_NM[G.render_indices(cfg.wavelength_step)]
    return RunInfo(
        command=opts.command, quick=opts.quick, config=G.config_record(cfg),
        wavelengths=WavelengthInfo(validation_step_nm=2 * cfg.wavelength_step,
                                   rendered_nm=[float(rendered[0]), float(rendered[-1])],
                                   n_validation=int(G.validation_indices(cfg.wavelength_step).size),
                                   n_rendered=int(rendered.size)),
        lut=LutInfo(path=portable(opts.lut), sha256=lut_sha, albedo_n=int(lut.albedo.numel()),
                    g_n=int(lut.g.numel()), g_range=list(lut.g_range)),
        model=ModelInfo(dir=portable(opts.model_dir), sha256=models["sha256"], card=models["card"]),
        ground_truth=GroundTruthInfo(estimator="reweighted (training.data.reweight)", photons=int(gt["photons"]),
                                     walk_seconds=float(gt["walk_seconds"])),
        fits=FitInfo(method=cfg.fit_method, steps=cfg.steps(), anchor_every=cfg.anchor_every,
                     seconds=rep_fit_seconds),
        paper_fits={**G.PAPER_FIT, "steps": cfg.steps(), "seconds": timings.get("paper_fits")},
        compute_seconds={"ground_truth": float(gt["seconds"]), "fits": rep_fit_seconds,
                         # rows rendered in one walk share its seconds: count each walk once
                         "renders": float(sum(sum({float(r["seconds"]) for r in t.values()}) for t in renders))},
        timings_s={k: round(v, 2) for k, v in timings.items()},
        threads=opts.threads, machine={"python": platform.python_version(), "torch": torch.__version__,
                                       "cpu": platform.processor() or platform.machine()},
        dataset=portable(opts.dataset), fits_dir=portable(opts.fits),
    )


def headline(record: dict) -> dict:
    """The model card's ``validation`` entry: the headline numbers of the tables (``record``: the JSON form,
    ``ValidationRecord.to_json()`` or a tables.json read back)."""
    rows = record["gate"]["rows"]
    prof = record["profile_fidelity"].get("fits")
    return {
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": record["run"]["command"],
        "gate": {
            "tones": record["gate"]["tones"],
            "nn_delta_e": rows["nn"]["delta_e"],
            "nn_painted_delta_e": rows["nn_painted"]["delta_e"] if "nn_painted" in rows else None,  # a file without it
            "nn_decoder_delta_e": rows["nn_decoder"]["delta_e"],
            "joint_opt_delta_e": {f"K{k}": rows[f"k{k}"]["delta_e"] for k in (1, 2, 3)},
            "baseline_delta_e": {m: rows[m]["delta_e"] for m in bl.METHODS},
            "edge_delta_e": {r: rows[r]["delta_e_edge"] for r in G.ROWS if r in rows},  # rows the file has
            "nn_vs_joint_opt_k3_delta_e": record["gate"]["nn_vs_k3"]["delta_e"],
            "photons": {"ground_truth": record["run"]["ground_truth"]["photons"],
                        "render_per_component": record["run"]["config"]["photons"]},
        },
        "banded": {"shape": record["banded"].get("shape"), "sam_vis": record["banded"].get("sam_vis")},
        "profile_shape": None if not prof else {k: prof["fits"][k]["mean"] for k in ("K1", "K2", "K3")
                                                if k in prof["fits"]}
        | {"K1_to_K2_reduction": prof["fits"].get("K1_to_K2_reduction", {}).get("mean"),
           "n_tones": prof["n_tones"]},
        "goals": record["goals"],
    }
