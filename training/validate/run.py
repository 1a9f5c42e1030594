"""``python -m training validate --out DIR``: run the gate, compute the tables, write them with the figures.

Stages (each cached in ``DIR/cache`` so that a rerun of the same command continues): ground truth,
joint-optimised fits per tone, baseline calibration, renders per tone; then the metrics (seconds),
Table 3 from the validation fits (if given) and the figures.  The output files are ``tables.md``,
``tables.json`` and ``fig_*.png``; existing ones are replaced only with ``overwrite``.
"""

from __future__ import annotations

import json
import platform
import sys
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from exporters.maps import sha256_file
from training.paths import portable
from training.validate import baselines as bl
from training.validate import figures, paper
from training.validate import gate as G
from training.validate import metrics as M

#: The paper's full gate: 10 representative and 10 outlier tones of tones.csv.
FULL_TONES: tuple[str, ...] = tuple(f"R{i:02d}" for i in range(1, 11)) + tuple(f"O{i:02d}" for i in range(1, 11))
#: --quick: three representative tones and one outlier, every 20 nm, few photons, few fitter iterations.
QUICK_TONES: tuple[str, ...] = ("R01", "R05", "R10", "O01")
QUICK_STEPS: tuple[tuple[str, int], ...] = (("k1_shape", 3), ("k1_joint", 3), ("k2", 3), ("k3", 3))
QUICK = dict(wavelength_step=10, gt_photons=400, photons=150, fit_steps=QUICK_STEPS, max_steps=2_000,
             calibration_scales_m=tuple(np.geomspace(1e-4, 0.3, 8).tolist()))
#: Tiny MC LUT built for --quick when none is given (about 10 s): albedos x g nodes, photons per node.
QUICK_LUT = dict(albedo_n=24, g_n=5, photons=400, max_steps=20_000)
#: Wavelengths of the cross-section figure (nm; the nearest validation wavelength is shown).
CROSS_SECTION_NM = (250, 350, 450, 550, 650, 750, 850, 1000)
#: Per-tone metrics of Table 1 (summarised as means over the representative, outlier and all tones).
METRICS = ("delta_e", "noise_floor", "delta_e_edge", "sam_vis", "shape_vis_lut", "shape_vis_lut_fit_weighting")
#: Tones of the profile heat maps (those present are used).
HEAT_TONES = ("R01", "R05", "R09", "R10")
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


def _log(opts: Options, text: str) -> None:
    if opts.progress:
        print(text, file=sys.stderr, flush=True)


def _bar(opts: Options, total: int, desc: str, job=None):
    """A stage's bar (off under a cluster ``job``: its own bar counts the tasks)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=not opts.progress or job is not None, file=sys.stderr)


def _mean(values) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else None


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


# ------------------------------------------------------------------------------------------ the run
def run(opts: Options) -> dict:
    """Run the whole validation (module docstring); returns the tables' record (also in tables.json)."""
    t_start = time.perf_counter()
    cfg = opts.config
    check_outputs(opts.out, opts.overwrite)
    files = model_files(opts.model_dir)
    torch.set_num_threads(opts.threads)
    from training.fit.mixture import PROFILE_WEIGHTING
    from training.sim.lut_extend import extension_record
    from training.sim.lut_interp import LookupTables

    _log(opts, f"loading LUT {opts.lut}")
    t0 = time.perf_counter()
    lut_sha = sha256_file(opts.lut)
    try:
        lut = LookupTables.load(opts.lut)
    except (OSError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise ValueError(f"cannot read the LUT {opts.lut}: {exc or type(exc).__name__}") from None
    timings = {"lut_load": time.perf_counter() - t0}
    # the model is not in the manifest: a new model re-renders only its own rows (gate.render_tone)
    models = {"sha256": {n: sha256_file(p) for n, p in files.items() if n != "card"}, "card": _card_info(files["card"])}
    manifest = {"config": G.config_record(cfg), "lut_sha256": lut_sha, "fit_profile_weighting": PROFILE_WEIGHTING,
                "lut_albedo_extension": extension_record(opts.lut)}
    cache = G.Cache(opts.out.resolve() / "cache", manifest)  # absolute: cluster workers write there too
    cache.open(reset=opts.overwrite)
    from training.cluster import engine

    with engine.job(opts.scheduler, "validate", shared=[cache.folder, opts.lut.resolve()], threads=opts.threads,
                    progress=opts.progress) as job:
        return _run(opts, files, lut, lut_sha, cache, models, timings, t_start, job)


def _run(opts, files, lut, lut_sha, cache, models, timings, t_start, job) -> dict:
    """``run`` after the LUT and the cache are open; ``job``: a ``training.cluster.engine.Job`` or None."""
    cfg = opts.config
    tones = G.gate_tones(cfg.tones)
    wl_val = G.validation_indices(cfg.wavelength_step)
    wl_r = G.render_indices(cfg.wavelength_step)
    col_r = np.searchsorted(wl_val, wl_r)

    t0 = time.perf_counter()
    gt = G.ground_truth(tones.values, wl_val, cfg.gt_photons, cfg.seed, cache, lambda s: _log(opts, s), job)
    timings["ground_truth"] = time.perf_counter() - t0
    albedo = G.albedo_rgb_of(gt["R_d"], wl_val)
    ctx = RunContext(opts, files, lut, lut_sha, cache, timings, job, tones, gt, wl_val, wl_r, col_r, albedo)

    fits = _fits(ctx)
    paper_fits = _fits(ctx, paper=True)
    t0 = time.perf_counter()
    inv, painted, dec, dec_full = _network(opts, files, albedo, tones.values, wl_val)
    nn_val = {"nn": inv, "nn_painted": painted, "nn_decoder": dec}  # at every validation wavelength
    inv, painted, dec = ([p.cols(col_r) for p in ps] for ps in (inv, painted, dec))
    scales, calib = _baseline_scales(opts, lut, tones, gt, albedo, wl_val)
    timings["network_and_calibration"] = time.perf_counter() - t0

    rows_per_tone, held = [], {}
    for i, name in enumerate(tones.names):
        rows = {}
        for k in (1, 2, 3):
            rows[f"k{k}"], held[f"{name}_k{k}"] = G.hold_lut_albedo(G.fit_params(fits[name], k, wl_r), lut)
        for r, key in zip(G.PAPER_ROWS, ("1s", 1, 2, 3), strict=True):
            rows[r] = G.hold_lut_albedo(G.fit_params(paper_fits[name], key, wl_r), lut)[0]
        rows |= {"nn": inv[i], "nn_painted": painted[i], "nn_decoder": dec[i]}
        rows |= {m: G.baseline_params(m, albedo[i], scales[m], wl_r) for m in bl.METHODS}
        rows_per_tone.append(rows)
    t0 = time.perf_counter()
    mc = _mc_renders(opts, cache, tones, rows_per_tone, job) if cfg.photons > 0 else None
    timings["mc_renders"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    tables = [{r: G.lut_render(lut, p) for r, p in rows.items()} for rows in rows_per_tone]
    timings["lut_renders"] = time.perf_counter() - t0
    renders = tables if cfg.renderer == "lut" else mc

    t0 = time.perf_counter()
    record = _gate_tables(ctx, rows_per_tone, renders, fits)
    if opts.fits is not None:
        record["gate"]["training_neighbours"] = _training_neighbours(opts.fits, tones)
    record["gate"]["renderer"] = cfg.renderer
    record["gate"]["mc_check"] = None if mc is None else _mc_check(tones, wl_r, tables, mc, cfg.seed)
    record["banded"] = _banded(lut, tones, gt, fits, wl_val, record, cfg.gt_photons)
    record["banded"]["network_shape"] = _network_shape(lut, tones, gt, wl_val, nn_val, cfg.gt_photons)
    record["profile_fidelity"] = _profile_fidelity(opts, lut, files, record)
    record["goals"] = _goals(record)
    timings["metrics"] = time.perf_counter() - t0
    record["baselines"] = {"scale_m": scales, "calibration": calib, "radius_rgb": list(bl.BLENDER_RADIUS),
                           "wrenninge_g": bl.WRENNINGE_G,
                           "published_darkening": {m: [bl.published_darkening(m, a, WAVELENGTHS_NM[wl_r])
                                                       for a in albedo] for m in bl.METHODS}}
    record["truncated_max"] = {r: max(record["gate"]["per_tone"][r][n]["truncated_max"] for n in tones.names)
                               for r in G.ROWS}
    record["fits_held_at_lut_albedo"] = {"count": int(sum(held.values())),
                                         "of": int(sum(3 * 2 * wl_r.size for _ in tones.names)),
                                         "range": list(G.params_lut_range(lut))}
    record["network"] = {"exposure": {n: inv[i].extra["exposure"] for i, n in enumerate(tones.names)},
                         "biophysical_estimate": {n: inv[i].extra["biophysical"] for i, n in enumerate(tones.names)},
                         "biophysical_true": {n: tones.values[i].tolist() for i, n in enumerate(tones.names)}}
    t0 = time.perf_counter()
    opts.out.mkdir(parents=True, exist_ok=True)
    _figures(ctx, rows_per_tone, renders, fits, dec_full, record)
    timings["figures"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    if {n: sha256_file(p) for n, p in files.items() if n != "card"} != models["sha256"]:
        raise ValueError(f"the model in {opts.model_dir} changed during the run: run the command again.")
    record["run"] = _run_record(opts, cfg, lut, lut_sha, gt, fits, timings, models, mc or renders)
    from training.validate.tables import notes, write_tables

    record["notes"] = notes(record)
    write_tables(opts.out, record)
    return record


def _fits(ctx: RunContext, paper: bool = False) -> dict[str, dict]:
    """Joint-optimised fits per tone (cached): all validation wavelengths for the representative tones,
    the render wavelengths for the others.  ``paper``: the paper's method as written (``G.PAPER_FIT``), at the
    render wavelengths only.  ``ctx.job``: the missing ones as its tasks."""
    opts, lut, lut_sha, tones, gt, cache, job = ctx.opts, ctx.lut, ctx.lut_sha, ctx.tones, ctx.gt, ctx.cache, ctx.job
    wl_val, wl_r = ctx.wl_val, ctx.wl_r
    cfg = opts.config
    t0 = time.perf_counter()
    fits = {}
    bar = _bar(opts, len(tones.names), "paper-as-written fits K=1,2,3" if paper else "joint-optimised fits K=1,2,3",
               job)
    for i, name in enumerate(tones.names):
        idx = wl_val if tones.kinds[i] == "representative" and not paper else wl_r
        cols = np.searchsorted(wl_val, idx)
        path = cache.path(f"fit_paper_{name}.npz" if paper else f"fit_{name}.npz")
        fit = G.Cache.load(path)
        if fit is None or not np.array_equal(fit["wl_idx"], idx):
            args = (gt["profile"][i][cols], gt["R_d"][i][cols], gt["profile_stderr"][i][cols], idx, cfg.gt_photons)
            args, how = (args + (cfg.steps(),), G.fit_tone_paper) if paper else \
                (args + (cfg.fit_method, cfg.steps(), cfg.anchor_every), G.fit_tone)
            if job is not None:
                job.submit(f"fit {name}", G.fit_tone_into, path, opts.lut.resolve(), lut_sha, how, *args,
                           on_done=lambda f, name=name: fits.__setitem__(name, f))
                continue
            fit = how(lut, *args)
            G.Cache.save(path, **fit)
        fits[name] = fit
        bar.update(1)
    if job is not None:
        job.wait()
        fits = {name: fits[name] for name in tones.names}  # in the tones' order
    bar.close()
    ctx.timings["paper_fits" if paper else "fits"] = time.perf_counter() - t0
    return fits


def _mc_renders(opts, cache, tones, rows_per_tone, job) -> list[dict]:
    """Every configuration of every tone rendered by our Monte Carlo mixture renderer (cached per tone)."""
    cfg = opts.config
    renders = [None] * len(tones.names)
    bar = _bar(opts, len(tones.names), "gate renders (Monte Carlo)", job)
    for i, name in enumerate(tones.names):
        args = (cache, name, rows_per_tone[i], cfg.photons, cfg.seed * 1000 + i, cfg.max_steps)
        if job is not None:
            job.submit(f"render {name}", G.render_tone, *args, on_done=lambda r, i=i: renders.__setitem__(i, r))
            continue
        renders[i] = G.render_tone(*args)
        bar.update(1)
    if job is not None:
        job.wait()
    bar.close()
    return renders


def _mc_check(tones, wl_r, tables, mc, seed: int) -> dict:
    """The tables' renders against the Monte Carlo ones, per row: mean ΔE76 between the two slab colours over
    all tones, beside the ΔE76 that the Monte Carlo renders' noise alone gives (M.noise_floor)."""
    wl = WAVELENGTHS_NM[wl_r]
    out = {}
    for r in G.ROWS:
        de = [float(M.delta_e(mc[i][r]["R_d"], tables[i][r]["R_d"], wl)) for i in range(len(tones.names))]
        nf = [M.noise_floor(tables[i][r]["R_d"], 0.0 * tables[i][r]["R_d"], mc[i][r]["R_d_stderr"], wl, seed=seed + i)
              for i in range(len(tones.names))]
        out[r] = {"delta_e_mc_vs_lut": float(np.mean(de)), "mc_noise_floor": float(np.mean(nf)),
                  "max_delta_e_mc_vs_lut": float(np.max(de))}
    return out


def _network_shape(lut, tones, gt, wl_val, nn_val, photons) -> dict:
    """The network rows' L_shape through the LUT (rendered weighting) per band at every validation wavelength:
    means over the representative tones and over all tones (the fits' own are in Table 2)."""
    wl = WAVELENGTHS_NM[wl_val]
    all_cols = np.arange(wl_val.size)
    errs = {r: [] for r in nn_val}
    for i in range(len(tones.names)):
        target = _target(lut, gt, i, all_cols, photons)
        for r, params in nn_val.items():
            errs[r].append(G.lut_mixture_shape_error(lut, params[i], target, all_cols))
    groups = {"representative": [i for i, k in enumerate(tones.kinds) if k == "representative"],
              "all": list(range(len(tones.names)))}
    out = {}
    for r, e in errs.items():
        e = np.stack(e)  # (T, W)
        out[r] = {kind: {band: (float(np.mean(e[idx][:, M.band_mask(wl, band)])) if idx and M.band_mask(wl, band).any()
                                else None) for band in M.BANDS} for kind, idx in groups.items()}
    return out


def _network(opts, files, albedo, tones, wl_idx):
    """The network's mixtures at the grid indices ``wl_idx`` (inversion on the albedo, as it is and with the
    painted colour of the albedo; decoder on the true p), and the decoder's full outputs (T, K, 376) for the
    figures (the paper's Fig. spectral_params)."""
    from exporters import inference
    from exporters.painted import paint_mixture
    from training.validate.mitsuba_scene import decode

    model = inference.load_model(files["skin_inversion.onnx"], threads=opts.threads)
    out = model.run(np.asarray(albedo, dtype=np.float32))
    inv = [G.Params(out["alpha"][i][:, wl_idx], out["sigma_t"][i][:, wl_idx], out["g"][i][:, wl_idx],
                    out["weight"][i][:, wl_idx],
                    extra={"exposure": float(out["exposure"][i, 0]), "biophysical": out["biophysical"][i].tolist()})
           for i in range(len(albedo))]
    p = paint_mixture(out["alpha"], out["sigma_t"], out["g"], out["weight"], albedo)
    painted = [G.Params(p.alpha[i][:, wl_idx], p.sigma_t[i][:, wl_idx], out["g"][i][:, wl_idx],
                        out["weight"][i][:, wl_idx], extra={"clamped": bool(p.clamped[i])}) for i in range(len(albedo))]
    dec, full = [], {"alpha": [], "sigma_t": [], "weight": []}
    for tone in tones:
        m = decode(tone, files["skin_decoder.onnx"])
        dec.append(G.Params(m.alpha[:, wl_idx], m.sigma_t[:, wl_idx], m.g[:, wl_idx], m.weight[:, wl_idx]))
        for key in full:
            full[key].append(getattr(m, key))
    return inv, painted, dec, {k: np.stack(v) for k, v in full.items()}


def _baseline_scales(opts, lut, tones, gt, albedo, wl_val) -> tuple[dict[str, float], dict]:
    """Each baseline's Subsurface Scale: given, or calibrated on the calibration tone (see baselines)."""
    cfg = opts.config
    if cfg.baseline_scale_m is not None:
        return {m: cfg.baseline_scale_m for m in bl.METHODS}, {"mode": "given"}
    name = cfg.calibration_tone if cfg.calibration_tone in tones.names else next(
        n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "representative")
    i = tones.names.index(name)
    scales, calib = {}, {"mode": "calibrated", "tone": name, "scales_m": list(cfg.calibration_scales_m), "errors": {}}
    for m in bl.METHODS:
        target = _target(lut, gt, i, np.arange(wl_val.size), cfg.gt_photons)
        best, errs = bl.calibrate_scale(m, lut, albedo[i], WAVELENGTHS_NM[wl_val], target,
                                        np.asarray(cfg.calibration_scales_m))
        scales[m] = best
        calib["errors"][m] = errs
    return scales, calib


# ------------------------------------------------------------------------------------------ metrics
def _target(lut, gt, i, cols, photons):
    return G.mc_target(lut, gt["profile"][i][cols], gt["R_d"][i][cols], gt["profile_stderr"][i][cols], photons)


def _gate_tables(ctx: RunContext, rows_per_tone, renders, fits) -> dict:
    """Table 1 (per tone and summarised): colour Delta E, edge Delta E, SAM, LUT shape error, noise floor."""
    lut, tones, gt, albedo, cfg = ctx.lut, ctx.tones, ctx.gt, ctx.albedo, ctx.opts.config
    wl_r, col_r = ctx.wl_r, ctx.col_r
    wl = WAVELENGTHS_NM[wl_r]
    vis = M.band_mask(wl, "Vis")
    vis_rows = np.flatnonzero(vis)
    per_row: dict[str, dict[str, dict]] = {r: {} for r in G.ROWS}
    nn_vs_k3 = {}
    gt_rec = {}
    for i, name in enumerate(tones.names):
        g_r, g_se = gt["R_d"][i][col_r], gt["R_d_stderr"][i][col_r]
        g_prof = gt["profile"][i][col_r].astype(np.float64)
        target = _target(lut, gt, i, col_r, cfg.gt_photons)
        gt_rec[name] = {"kind": tones.kinds[i], "albedo_rgb": albedo[i].tolist(),
                        "srgb": np.clip(M.linear_srgb(g_r, wl), 0, None).tolist(),
                        "lab": M.lab(g_r, wl).tolist()}
        for r in G.ROWS:
            rend = renders[i][r]
            rec = {
                "delta_e": float(M.delta_e(rend["R_d"], g_r, wl)),
                "noise_floor": M.noise_floor(g_r, g_se, rend["R_d_stderr"], wl, seed=cfg.seed + i),
                "delta_e_edge": M.edge_delta_e(rend["profile"].astype(np.float64), rend["R_d"], g_prof, g_r, wl),
                "sam_vis": M.spectral_angle(rend["R_d"], g_r, vis),
                "shape_vis_lut": float(np.mean(G.lut_mixture_shape_error(lut, rows_per_tone[i][r], target, vis_rows))),
                "shape_vis_lut_fit_weighting": float(np.mean(G.lut_mixture_shape_error(
                    lut, rows_per_tone[i][r], target, vis_rows, "fit"))),
                "linear_srgb": M.linear_srgb(rend["R_d"], wl).tolist(),
                "truncated_max": float(np.max(rend["truncated"])),
            }
            per_row[r][name] = rec
        nn_vs_k3[name] = float(M.delta_e(renders[i]["nn"]["R_d"], renders[i]["k3"]["R_d"], wl))
        per_row["nn_painted"][name]["clamped"] = rows_per_tone[i]["nn_painted"].extra["clamped"]
    kinds = {"representative": [n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "representative"],
             "outlier": [n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "outlier"],
             "all": list(tones.names)}
    summary = {}
    for r in G.ROWS:
        summary[r] = {"label": G.ROW_LABELS[r]}
        for metric in METRICS:
            summary[r][metric] = {kind: _mean(per_row[r][n][metric] for n in names) if names else None
                                  for kind, names in kinds.items()}
    k1 = summary["k1"]["delta_e"]["representative"]
    for r in G.ROWS:
        v = summary[r]["delta_e"]["representative"]
        summary[r]["vs_k1"] = (k1 / v) if (k1 is not None and v) else None
    nn_sum = {kind: _mean(nn_vs_k3[n] for n in names) if names else None for kind, names in kinds.items()}
    diff = {kind: (summary["nn"]["delta_e"][kind] - summary["k3"]["delta_e"][kind])
            if summary["nn"]["delta_e"][kind] is not None else None for kind in kinds}
    return {"gate": {"tones": list(tones.names), "kinds": list(tones.kinds), "groups": kinds,
                     "wavelength_nm": wl.tolist(), "rows": summary, "per_tone": per_row,
                     "nn_vs_k3": {"delta_e": nn_sum, "per_tone": nn_vs_k3, "difference_of_means": diff},
                     "ground_truth": gt_rec}}


#: Radius (in the unit box of ``training.train.balance.unit_box``) within which the fitted training tones of a
#: gate tone are counted: how well stage 3 saw its neighbourhood.
NEIGHBOUR_RADIUS: float = 0.25


def _training_neighbours(fits_dir: Path, tones) -> dict | None:
    """Per gate tone, the fitted training tones (done rows of the train fits) within ``NEIGHBOUR_RADIUS``
    of it in the unit box; None without training fits."""
    import h5py

    from training.train.balance import unit_box
    from training.train.data import fits_files

    paths = fits_files(fits_dir, "train")
    if not paths:
        return None
    parts = []
    for path in paths:
        with h5py.File(path, "r") as f:
            parts.append(np.asarray(f["tone"][:], np.float64)[np.asarray(f["done"][:], bool)])
    train = unit_box(np.concatenate(parts))
    gate = unit_box(np.asarray(tones.values, np.float64))
    dist = np.sqrt(((gate[:, None, :] - train[None, :, :]) ** 2).sum(-1))
    return {"radius": NEIGHBOUR_RADIUS, "n_fitted": len(train),
            "count": {n: int((d < NEIGHBOUR_RADIUS).sum()) for n, d in zip(tones.names, dist, strict=True)}}


def _banded(lut, tones, gt, fits, wl_val, record, photons) -> dict:
    """Table 2: per band the fits' mean L_shape (representative tones) for K = 1, 2, 3 and the reductions,
    also of the excess over the ground truth's Monte Carlo noise (``training.fit.loss``: Target.noise,
    shape_excess); the rendered visible SAM of every configuration (representative tones)."""
    from training.fit import loss as fit_loss

    rep = [n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "representative"]
    out: dict = {"tones": rep, "shape": {}, "reduction": {}, "excess": {}, "excess_reduction": {}}
    if not rep:
        return out
    wl = WAVELENGTHS_NM[wl_val]
    all_cols = np.arange(wl_val.size)
    noise = np.stack([_target(lut, gt, tones.names.index(n), all_cols, photons).noise.numpy() for n in rep])
    shape = {k: np.stack([fits[n][f"k{k}_shape_rmse"] for n in rep]) for k in (1, 2, 3)}  # (T, W) on wl_val
    excess = {k: fit_loss.shape_excess(torch.as_tensor(v), torch.as_tensor(noise)).numpy() for k, v in shape.items()}
    out["noise"] = {}
    for band in (*M.BANDS, "all"):
        mask = M.band_mask(wl, band) if band != "all" else np.ones(wl.size, bool)
        out["noise"][band] = float(np.mean(noise[:, mask])) if mask.any() else None
        for key, data, red in (("shape", shape, "reduction"), ("excess", excess, "excess_reduction")):
            vals = {f"K{k}": float(np.mean(data[k][:, mask])) if mask.any() else None for k in (1, 2, 3)}
            out[key][band] = vals
            out[red][band] = {a + "_to_" + b: (M.relative_reduction(vals[a], vals[b]) if vals[a] and vals[b]
                                               is not None else None) for a, b in (("K1", "K2"), ("K2", "K3"))}
    rows = record["gate"]["rows"]
    out["sam_vis"] = {r: rows[r]["sam_vis"]["representative"] for r in G.ROWS}
    sam = [out["sam_vis"][f"k{k}"] for k in (1, 2, 3)]
    out["sam_reduction"] = {"K1_to_K2": M.relative_reduction(sam[0], sam[1]) if sam[0] else None,
                            "K2_to_K3": M.relative_reduction(sam[1], sam[2]) if sam[1] else None}
    out["refl_rel_err"] = {f"K{k}": float(np.mean(np.stack([fits[n][f"k{k}_refl_rel_err"] for n in rep])))
                           for k in (1, 2, 3)}
    return out


def _profile_fidelity(opts, lut, files, record) -> dict:
    """Table 3 from the validation fits (and the network on the validation split) when given."""
    from training.validate import profile_set

    out: dict = {"fits": None, "network": None}
    if opts.fits is not None:
        out["fits"] = profile_set.fit_profile_fidelity(opts.fits, opts.dataset)
    else:
        out["fits_missing"] = "no --fits given: Table 3 needs `python -m training fit --dataset DIR --out FITS`."
    if opts.dataset is not None:
        out["network"] = profile_set.network_profile_fidelity(opts.dataset, lut, files["skin_decoder.onnx"],
                                                              max_tones=opts.nn_profile_tones, progress=opts.progress)
    return out


#: The rebuilt network's acceptance targets: (measure, what, group or band, target).
#: "nn_minus_k3" is the difference of the mean ΔE76 to the ground truth, the paper's "vs. joint-opt"; "shape"
#: the network's profile shape as rendered at every validation wavelength of the band, over all gate tones.
NETWORK_TARGETS: tuple[tuple[str, str, str, float], ...] = (
    ("delta_e", "network from RGB, gate ΔE76, representative tones", "representative", 1.5),
    ("delta_e", "network from RGB, gate ΔE76, all tones", "all", 2.5),
    ("nn_minus_k3", "network minus the joint K = 3 fits, representative tones", "representative", 0.5),
    ("nn_minus_k3", "network minus the joint K = 3 fits, all tones", "all", 0.5),
    ("edge", "network from RGB, edge ΔE76, representative tones", "representative", 1.0),
    ("shape", "network from RGB, profile shape as rendered, UV", "UV", 0.3),
    ("shape", "network from RGB, profile shape as rendered, Vis", "Vis", 0.25),
    ("shape", "network from RGB, profile shape as rendered, NIR", "NIR", 0.3),
    ("noise_floor", "the gate's Monte Carlo noise floor (ΔE76, representative tones)", "representative", 0.1),
)


def _network_targets(record) -> list[dict]:
    """``NETWORK_TARGETS`` checked on the network's rows (``ours`` None where a row or band is missing)."""
    nn = record["gate"]["rows"]["nn"]
    source = {"delta_e": nn["delta_e"], "edge": nn["delta_e_edge"], "noise_floor": nn["noise_floor"],
              "nn_minus_k3": record["gate"].get("nn_vs_k3", {}).get("difference_of_means", {}),
              "shape": record.get("banded", {}).get("network_shape", {}).get("nn", {}).get("all", {})}
    out = []
    for measure, what, where, target in NETWORK_TARGETS:
        ours = source[measure].get(where)
        out.append({"measure": measure, "where": where, "what": what, "target": target, "ours": ours,
                    "met": None if ours is None else bool(ours <= target)})
    return out


def _goals(record) -> dict:
    """The issue's goals, checked on our numbers."""
    nn = record["gate"]["rows"]["nn"]["delta_e"]["representative"]
    goals = {"nn_delta_e_at_most_paper": {"ours": nn, "paper": paper.TABLE1_DELTA_E["nn"],
                                           "met": None if nn is None else bool(nn <= paper.TABLE1_DELTA_E["nn"])}}
    prof = record.get("profile_fidelity", {}).get("fits")
    if prof and "K1_to_K2_reduction" in prof["fits"]:
        red, source = prof["fits"]["K1_to_K2_reduction"]["mean"], "validation split (Table 3)"
    else:
        red, source = record["banded"]["reduction"].get("all", {}).get("K1_to_K2"), \
            "gate representative tones, all validation wavelengths (Table 3 not available)"
    met = None if red is None else bool(red >= paper.PROFILE_REDUCTION)
    goals["k2_profile_reduction_at_least_paper"] = {"ours": red, "paper": paper.PROFILE_REDUCTION, "source": source,
                                                    "met": met, "excess_over_noise": None}
    summ = (prof or {}).get("fitter_summary")
    if not prof and record["banded"].get("excess_reduction"):
        b = record["banded"]
        goals["k2_profile_reduction_at_least_paper"]["excess_over_noise"] = {
            "reduction": b["excess_reduction"]["all"]["K1_to_K2"], "noise": b["noise"]["all"]}
    elif summ:  # the same reduction on the excess over the bins' Monte Carlo noise (training.fit.dataset.summarise)
        ks = {int(k): v for k, v in summ["K"].items()}
        if 1 in ks and 2 in ks and ks[1]["shape_excess"] > 0:
            goals["k2_profile_reduction_at_least_paper"]["excess_over_noise"] = {
                "reduction": 1.0 - ks[2]["shape_excess"] / ks[1]["shape_excess"], "noise": summ["noise"]}
    goals["network_targets"] = _network_targets(record)
    return goals


# ------------------------------------------------------------------------------------------ figures
def _figures(ctx: RunContext, rows_per_tone, renders, fits, dec_full, record) -> None:
    """The four figures of the run (``OUTPUTS``) into ``ctx.opts.out``."""
    opts, lut, tones, gt = ctx.opts, ctx.lut, ctx.tones, ctx.gt
    wl_val, wl_r, col_r = ctx.wl_val, ctx.wl_r, ctx.col_r
    wl = WAVELENGTHS_NM[wl_r]
    rep = [i for i, k in enumerate(tones.kinds) if k == "representative"] or list(range(len(tones.names)))
    x = M.edge_positions_cm()
    edge = []
    for i in rep:
        g_r = gt["R_d"][i][col_r]
        cells = [M.linear_srgb(M.edge_exitance(gt["profile"][i][col_r].astype(np.float64), g_r, x), wl)]
        for r in G.ROWS:
            rend = renders[i][r]
            cells.append(M.linear_srgb(M.edge_exitance(rend["profile"].astype(np.float64), rend["R_d"], x), wl))
        edge.append(np.stack(cells))  # (rows, P, 3)
    edge_rgb = np.stack(edge, axis=1)  # (rows, tones, P, 3)
    de, de_edge = np.zeros(edge_rgb.shape[:2]), np.zeros(edge_rgb.shape[:2])
    per_tone = record["gate"]["per_tone"]
    for j, i in enumerate(rep):
        for r_i, r in enumerate(G.ROWS):
            de[r_i + 1, j] = per_tone[r][tones.names[i]]["delta_e"]
            de_edge[r_i + 1, j] = per_tone[r][tones.names[i]]["delta_e_edge"]
    names = [tones.names[i] for i in rep]
    figures.k_progression(opts.out / "fig_k_progression.png", names, ["MC ground truth"] +
                          [G.ROW_LABELS[r].replace(" (", "\n(") for r in G.ROWS], edge_rgb, de, de_edge)
    figures.spectral_parameters(opts.out / "fig_spectral_parameters.png", WAVELENGTHS_NM, dec_full["alpha"],
                                dec_full["sigma_t"], dec_full["weight"],
                                f"skin_decoder.onnx on the true p of the {len(tones.names)} gate tones: median and IQR")
    cols = [int(np.argmin(np.abs(WAVELENGTHS_NM[wl_val] - w))) for w in CROSS_SECTION_NM]
    cols = list(dict.fromkeys(cols))
    figures.cross_sections(opts.out / "fig_cross_sections.png", names, WAVELENGTHS_NM[wl_val][cols],
                           gt["profile"][rep][:, cols].astype(np.float64))
    heat = [i for i in rep if tones.names[i] in HEAT_TONES] or rep[:1]
    fit_prof = {}
    for k in (1, 3):
        arr = np.zeros((len(tones.names), wl_val.size, R_EDGES_CM.size - 1))
        for i in heat:
            arr[i] = _lut_profile(lut, G.fit_params(fits[tones.names[i]], k, wl_val))
        fit_prof[f"K={k}"] = arr
    srgb = np.array([record["gate"]["ground_truth"][n]["srgb"] for n in names])
    used = np.zeros((len(rep), wl_val.size, R_EDGES_CM.size - 1), bool)  # the bins the fitter's loss uses
    for j, i in enumerate(rep):
        if i in heat:
            used[j] = _target(lut, gt, i, np.arange(wl_val.size), opts.config.gt_photons).mask.numpy() > 0
    from exporters.colorimetry import srgb_encode

    figures.reflectance_and_profiles(opts.out / "fig_reflectance_profiles.png", WAVELENGTHS_NM[wl_val], names,
                                     gt["R_d"][rep], srgb_encode(srgb), [rep.index(i) for i in heat],
                                     gt["profile"][rep].astype(np.float64), used,
                                     {k: v[rep] for k, v in fit_prof.items()})


def _lut_profile(lut, params: G.Params) -> np.ndarray:
    """Absolute profile sum_k w_k R_k P_k (W, 512) cm^-2 of a mixture through the LUT (paper eq. mixture)."""
    from training.sim.lut_interp import bin_centres

    dt = lut.P.dtype
    r = torch.as_tensor(bin_centres(R_EDGES_CM), dtype=dt)
    a, s, g, w = (torch.as_tensor(v.T, dtype=dt) for v in (params.alpha, params.sigma_t, params.g, params.weight))
    p = lut.profile(r, a, g, s)  # (W, K, M)
    return ((w * lut.reflectance(a, g))[..., None] * p).sum(1).numpy()


# ------------------------------------------------------------------------------------------ record
def _card_info(card: Path) -> dict:
    if not card.is_file():
        return {"path": portable(card), "missing": True}
    c = json.loads(card.read_text())
    ds = c.get("dataset", {})
    return {"path": portable(card), "created": c.get("created"), "K": c.get("K"),
            "dataset": {k: ds.get(k) for k in ("path", "n_train", "n_validation", "photons")},
            "preset": ds.get("train_attrs", {}).get("preset"), "lut": c.get("lut", {}).get("path"),
            "notes": c.get("notes", [])[:1],
            "sha256": {n: v.get("sha256") for n, v in c.get("files", {}).items()}}


def _run_record(opts, cfg, lut, lut_sha, gt, fits, timings, models, renders) -> dict:
    rep_fit_seconds = float(sum(float(f["seconds"]) for f in fits.values()))
    return {
        "command": opts.command, "quick": opts.quick, "config": G.config_record(cfg),
        "wavelengths": {"validation_step_nm": 2 * cfg.wavelength_step,
                        "rendered_nm": [float(WAVELENGTHS_NM[G.render_indices(cfg.wavelength_step)][0]),
                                        float(WAVELENGTHS_NM[G.render_indices(cfg.wavelength_step)][-1])],
                        "n_validation": int(G.validation_indices(cfg.wavelength_step).size),
                        "n_rendered": int(G.render_indices(cfg.wavelength_step).size)},
        "lut": {"path": portable(opts.lut), "sha256": lut_sha, "albedo_n": int(lut.albedo.numel()),
                "g_n": int(lut.g.numel()), "g_range": list(lut.g_range)},
        "model": {"dir": portable(opts.model_dir), "sha256": models["sha256"], "card": models["card"]},
        "ground_truth": {"estimator": "reweighted (training.data.reweight)", "photons": int(gt["photons"]),
                         "walk_seconds": float(gt["walk_seconds"])},
        "fits": {"method": cfg.fit_method, "steps": cfg.steps(), "anchor_every": cfg.anchor_every,
                 "seconds": rep_fit_seconds},
        "paper_fits": {**G.PAPER_FIT, "steps": cfg.steps(), "seconds": timings.get("paper_fits")},
        "compute_seconds": {"ground_truth": float(gt["seconds"]), "fits": rep_fit_seconds,
                            # rows rendered in one walk share its seconds: count each walk once
                            "renders": float(sum(sum({float(r["seconds"]) for r in t.values()}) for t in renders))},
        "timings_s": {k: round(v, 2) for k, v in timings.items()},
        "threads": opts.threads, "machine": {"python": platform.python_version(), "torch": torch.__version__,
                                             "cpu": platform.processor() or platform.machine()},
        "dataset": portable(opts.dataset), "fits_dir": portable(opts.fits),
    }


def headline(record: dict) -> dict:
    """The model card's ``validation`` entry: the headline numbers of the tables."""
    rows = record["gate"]["rows"]
    prof = record["profile_fidelity"].get("fits")
    return {
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": record["run"]["command"],
        "gate": {
            "tones": record["gate"]["tones"],
            "nn_delta_e": rows["nn"]["delta_e"],
            "nn_painted_delta_e": rows["nn_painted"]["delta_e"] if "nn_painted" in rows else None,  # older runs
            "nn_decoder_delta_e": rows["nn_decoder"]["delta_e"],
            "joint_opt_delta_e": {f"K{k}": rows[f"k{k}"]["delta_e"] for k in (1, 2, 3)},
            "baseline_delta_e": {m: rows[m]["delta_e"] for m in bl.METHODS},
            "edge_delta_e": {r: rows[r]["delta_e_edge"] for r in G.ROWS if r in rows},  # rows added since: absent
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
