"""``python -m training validate --out DIR``: run the gate, compute the tables, write them with the figures.

Stages (each cached in ``DIR/cache`` so that a rerun of the same command continues): ground truth,
joint-optimised fits per tone, baseline calibration, renders per tone; then the metrics (seconds),
Table 3 from the validation fits (if given) and the figures.  The output files are ``tables.md``,
``tables.json`` and ``fig_*.png``; existing ones are replaced only with ``overwrite``.

This module runs the steps in order; the work is elsewhere: ``stages`` computes (fits, renders, the network,
the baselines' scale), ``assemble`` turns the results into the tables' parts, ``record`` types them
(``ValidationRecord``, whose JSON form is tables.json), ``run_figures`` draws the figures and ``tables``
writes tables.md and tables.json.
"""

from __future__ import annotations

import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from exporters.constants import WAVELENGTHS_NM
from exporters.maps import sha256_file
from training.validate import assemble, stages
from training.validate import baselines as bl
from training.validate import gate as G
from training.validate.record import BaselinesRecord, HeldFits, NetworkAnswers, ValidationRecord, card_info, run_info
from training.validate.run_figures import write_figures
from training.validate.stages import log
from training.validate.tables import notes, write_tables

#: The paper's full gate: 10 representative and 10 outlier tones of tones.csv.
FULL_TONES: tuple[str, ...] = tuple(f"R{i:02d}" for i in range(1, 11)) + tuple(f"O{i:02d}" for i in range(1, 11))
#: --quick: three representative tones and one outlier, every 20 nm, few photons, few fitter iterations.
QUICK_TONES: tuple[str, ...] = ("R01", "R05", "R10", "O01")
QUICK_STEPS: tuple[tuple[str, int], ...] = (("k1_shape", 3), ("k1_joint", 3), ("k2", 3), ("k3", 3))
QUICK = dict(wavelength_step=10, gt_photons=400, photons=150, fit_steps=QUICK_STEPS, max_steps=2_000,
             calibration_scales_m=tuple(np.geomspace(1e-4, 0.3, 8).tolist()))
#: Tiny MC LUT built for --quick when none is given (about 10 s): albedos x g nodes, photons per node.
QUICK_LUT = dict(albedo_n=24, g_n=5, photons=400, max_steps=20_000)
OUTPUTS = ("tables.md", "tables.json", "fig_k_progression.png", "fig_spectral_parameters.png",
           "fig_cross_sections.png", "fig_reflectance_profiles.png")


@dataclass
class Options:
    """What the command was asked to do (``config``: the gate's numbers-determining settings)."""

    out: Path
    config: G.GateConfig
    lut: Path
    model_dir: Path
    dataset: Path | None = None
    fits: Path | None = None
    threads: int = 1
    overwrite: bool = False
    progress: bool = True
    quick: bool = False
    nn_profile_tones: int | None = None
    command: str = ""
    scheduler: object = None  # training.cluster.engine.Scheduler: ground-truth walk, fits and renders on Dask


@dataclass
class RunContext:
    """What the steps of one validation run share, set up by ``_run`` once the ground truth is known: the
    options, model files (``model_files``), the LUT and its SHA-256, the cache, the timings (s, by step), the
    cluster job (a ``training.cluster.engine.Job`` or None), the gate tones with their ground truth (``gt``:
    ``gate.ground_truth``), the validation and render wavelength indices (``wl_val``, ``wl_r``; ``col_r``:
    the render wavelengths' columns in ``wl_val``) and the tones' albedo colours (T, 3) linear sRGB."""

    opts: Options
    files: dict[str, Path]
    lut: object  # training.sim.lut_interp.LookupTables
    lut_sha: str
    cache: G.Cache
    timings: dict[str, float]
    job: object
    tones: object  # training.skin.tones.ToneSet
    gt: dict[str, np.ndarray]
    wl_val: np.ndarray
    wl_r: np.ndarray
    col_r: np.ndarray
    albedo: np.ndarray


def check_outputs(out: Path, overwrite: bool) -> None:
    """Refuse to replace the outputs of an earlier run unless ``overwrite``."""
    existing = [str(out / n) for n in OUTPUTS if (out / n).exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{', '.join(existing)} exist; pass --overwrite to replace them.")


def model_files(model_dir: Path) -> dict[str, Path]:
    """The two ONNX graphs and the card of ``model_dir`` (ValueError naming a missing one)."""
    files = {n: Path(model_dir) / n for n in ("skin_inversion.onnx", "skin_decoder.onnx")}
    missing = [str(p) for p in files.values() if not p.is_file()]
    if missing:
        raise ValueError(f"model file(s) {missing} not found: pass --model-dir with the exported model "
                         "(python -m training export).")
    files["card"] = Path(model_dir) / "skin_inversion.json"
    return files


def run(opts: Options) -> ValidationRecord:
    """Run the whole validation (module docstring); returns the tables' record (its JSON form is tables.json)."""
    t_start = time.perf_counter()
    cfg = opts.config
    check_outputs(opts.out, opts.overwrite)
    files = model_files(opts.model_dir)
    torch.set_num_threads(opts.threads)
    from training.fit.mixture import PROFILE_WEIGHTING
    from training.sim.lut_extend import extension_record
    from training.sim.lut_interp import LookupTables

    log(opts, f"loading LUT {opts.lut}")
    t0 = time.perf_counter()
    lut_sha = sha256_file(opts.lut)
    try:
        lut = LookupTables.load(opts.lut)
    except (OSError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise ValueError(f"cannot read the LUT {opts.lut}: {exc or type(exc).__name__}") from None
    timings = {"lut_load": time.perf_counter() - t0}
    # the model is not in the manifest: a new model re-renders only its own rows (gate.render_tone)
    models = {"sha256": {n: sha256_file(p) for n, p in files.items() if n != "card"}, "card": card_info(files["card"])}
    manifest = {"config": G.config_record(cfg), "lut_sha256": lut_sha, "fit_profile_weighting": PROFILE_WEIGHTING,
                "lut_albedo_extension": extension_record(opts.lut)}
    cache = G.Cache(opts.out.resolve() / "cache", manifest)  # absolute: cluster workers write there too
    cache.open(reset=opts.overwrite)
    from training.cluster import engine

    with engine.job(opts.scheduler, "validate", shared=[cache.folder, opts.lut.resolve()], threads=opts.threads,
                    progress=opts.progress) as job:
        return _run(opts, files, lut, lut_sha, cache, models, timings, t_start, job)


def _run(opts: Options, files: dict[str, Path], lut, lut_sha: str, cache: G.Cache, models: dict,
         timings: dict[str, float], t_start: float, job) -> ValidationRecord:
    """``run`` after the LUT and the cache are open; ``job``: a ``training.cluster.engine.Job`` or None."""
    cfg = opts.config
    tones = G.gate_tones(cfg.tones)
    wl_val = G.validation_indices(cfg.wavelength_step)
    wl_r = G.render_indices(cfg.wavelength_step)
    col_r = np.searchsorted(wl_val, wl_r)

    t0 = time.perf_counter()
    gt = G.ground_truth(tones.values, wl_val, cfg.gt_photons, cfg.seed, cache, lambda s: log(opts, s), job)
    timings["ground_truth"] = time.perf_counter() - t0
    albedo = G.albedo_rgb_of(gt["R_d"], wl_val)
    ctx = RunContext(opts, files, lut, lut_sha, cache, timings, job, tones, gt, wl_val, wl_r, col_r, albedo)

    fits = stages.fits(ctx)
    paper_fits = stages.fits(ctx, paper=True)
    t0 = time.perf_counter()
    inv, painted, dec, dec_full = stages.network(opts, files, albedo, tones.values, wl_val)
    nn_val = {"nn": inv, "nn_painted": painted, "nn_decoder": dec}  # at every validation wavelength
    inv, painted, dec = ([p.cols(col_r) for p in ps] for ps in (inv, painted, dec))
    scales, calib = stages.baseline_scales(opts, lut, tones, gt, albedo, wl_val)
    timings["network_and_calibration"] = time.perf_counter() - t0

    rows_per_tone, held = _configurations(ctx, fits, paper_fits, {"nn": inv, "nn_painted": painted,
                                                                  "nn_decoder": dec}, scales)
    t0 = time.perf_counter()
    mc = stages.mc_renders(opts, cache, tones, rows_per_tone, job) if cfg.photons > 0 else None
    timings["mc_renders"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    tables = [{r: G.lut_render(lut, p) for r, p in rows.items()} for rows in rows_per_tone]
    timings["lut_renders"] = time.perf_counter() - t0
    renders = tables if cfg.renderer == "lut" else mc

    t0 = time.perf_counter()
    record = _assemble(ctx, rows_per_tone, renders, tables, mc, fits, nn_val, (scales, calib), held)
    timings["metrics"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    opts.out.mkdir(parents=True, exist_ok=True)
    write_figures(ctx, renders, fits, dec_full, record.gate)
    timings["figures"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    if {n: sha256_file(p) for n, p in files.items() if n != "card"} != models["sha256"]:
        raise ValueError(f"the model in {opts.model_dir} changed during the run: run the command again.")
    record.run = run_info(opts, cfg, lut, lut_sha, gt, fits, timings, models, mc or renders)
    record.notes = notes(record.to_json())
    write_tables(opts.out, record.to_json())
    return record


def _configurations(ctx: RunContext, fits: dict, paper_fits: dict, network: dict[str, list], scales: dict[str, float]
                    ) -> tuple[list[dict], dict[str, bool]]:
    """Every configuration's media per gate tone at the render wavelengths (row -> ``gate.Params``): the fits
    with their albedo held in the LUT's range, the paper-as-written fits, the network's rows (``network``: row ->
    one Params per tone) and the baselines; and which fits were held (``"<tone>_k<K>"`` -> bool)."""
    lut, tones, albedo, wl_r = ctx.lut, ctx.tones, ctx.albedo, ctx.wl_r
    rows_per_tone, held = [], {}
    for i, name in enumerate(tones.names):
        rows = {}
        for k in (1, 2, 3):
            rows[f"k{k}"], held[f"{name}_k{k}"] = G.hold_lut_albedo(G.fit_params(fits[name], k, wl_r), lut)
        for r, key in zip(G.PAPER_ROWS, ("1s", 1, 2, 3), strict=True):
            rows[r] = G.hold_lut_albedo(G.fit_params(paper_fits[name], key, wl_r), lut)[0]
        rows |= {r: params[i] for r, params in network.items()}
        rows |= {m: G.baseline_params(m, albedo[i], scales[m], wl_r) for m in bl.METHODS}
        rows_per_tone.append(rows)
    return rows_per_tone, held


def _assemble(ctx: RunContext, rows_per_tone: list[dict], renders: list[dict], tables: list[dict],
              mc: list[dict] | None, fits: dict, nn_val: dict[str, list], baseline_scales: tuple,
              held: dict[str, bool]) -> ValidationRecord:
    """The record's parts from the run's results (``run`` and ``notes`` are added once the run is timed):
    Table 1 from ``renders``, the check of ``tables`` (the LUT renders) against ``mc``, Tables 2 and 3, the
    goals, the baselines (``baseline_scales``: scales and calibration), the held fits, the network's answers."""
    opts, lut, tones, gt, albedo, wl_val, wl_r = ctx.opts, ctx.lut, ctx.tones, ctx.gt, ctx.albedo, ctx.wl_val, ctx.wl_r
    cfg = opts.config
    scales, calib = baseline_scales
    inv = [rows["nn"] for rows in rows_per_tone]  # the network from RGB, with its exposure and p
    gate = assemble.gate_tables(ctx, rows_per_tone, renders, fits)
    if opts.fits is not None:
        gate.training_neighbours = assemble.training_neighbours(opts.fits, tones)
    gate.renderer = cfg.renderer
    gate.mc_check = None if mc is None else assemble.mc_check(tones, wl_r, tables, mc, cfg.seed)
    banded = assemble.banded(lut, tones, gt, fits, wl_val, gate, cfg.gt_photons)
    banded.network_shape = assemble.network_shape(lut, tones, gt, wl_val, nn_val, cfg.gt_photons)
    fidelity = assemble.profile_fidelity(opts, lut, ctx.files)
    goals = assemble.goals(gate, banded, fidelity)
    return ValidationRecord(
        gate=gate, banded=banded, profile_fidelity=fidelity, goals=goals,
        baselines=BaselinesRecord(scale_m=scales, calibration=calib, radius_rgb=list(bl.BLENDER_RADIUS),
                                  wrenninge_g=bl.WRENNINGE_G,
                                  published_darkening={m: [bl.published_darkening(m, a, WAVELENGTHS_NM[wl_r])
                                                           for a in albedo] for m in bl.METHODS}),
        truncated_max={r: max(gate.per_tone[r][n].truncated_max for n in tones.names) for r in G.ROWS},
        fits_held_at_lut_albedo=HeldFits(count=int(sum(held.values())),
                                         of=int(sum(3 * 2 * wl_r.size for _ in tones.names)),
                                         range=list(G.params_lut_range(lut))),
        network=NetworkAnswers(
            exposure={n: inv[i].extra["exposure"] for i, n in enumerate(tones.names)},
            biophysical_estimate={n: inv[i].extra["biophysical"] for i, n in enumerate(tones.names)},
            biophysical_true={n: tones.values[i].tolist() for i, n in enumerate(tones.names)}))
