"""The computing stages of a validation run, each cached in the run's ``cache`` folder where it is expensive:
the joint-optimised fits per tone, the Monte Carlo renders per tone, the network's answers and the baselines'
Subsurface Scale.  ``training.validate.run`` calls them in order; ``training.validate.assemble`` turns their
results into the tables.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from exporters.constants import WAVELENGTHS_NM
from training.validate import baselines as bl
from training.validate import gate as G
from training.validate.assemble import mc_target
from training.validate.record import Calibration

if TYPE_CHECKING:
    from training.validate.run import Options, RunContext


def log(opts: Options, text: str) -> None:
    """``text`` on stderr unless the run is quiet (``opts.progress`` False)."""
    if opts.progress:
        print(text, file=sys.stderr, flush=True)


def progress_bar(opts: Options, total: int, desc: str, job=None):
    """A stage's bar (off under a cluster ``job``: its own bar counts the tasks)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=not opts.progress or job is not None, file=sys.stderr)


def fits(ctx: RunContext, paper: bool = False) -> dict[str, dict]:
    """Joint-optimised fits per tone (cached): all validation wavelengths for the representative tones,
    the render wavelengths for the others.  ``paper``: the paper's method as written (``G.PAPER_FIT``), at the
    render wavelengths only.  ``ctx.job``: the missing ones as its tasks."""
    opts, lut, lut_sha, tones, gt, cache, job = ctx.opts, ctx.lut, ctx.lut_sha, ctx.tones, ctx.gt, ctx.cache, ctx.job
    wl_val, wl_r = ctx.wl_val, ctx.wl_r
    cfg = opts.config
    t0 = time.perf_counter()
    out = {}
    bar = progress_bar(opts, len(tones.names),
                       "paper-as-written fits K=1,2,3" if paper else "joint-optimised fits K=1,2,3", job)
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
                           on_done=lambda f, name=name: out.__setitem__(name, f))
                continue
            fit = how(lut, *args)
            G.Cache.save(path, **fit)
        out[name] = fit
        bar.update(1)
    if job is not None:
        job.wait()
        out = {name: out[name] for name in tones.names}  # in the tones' order
    bar.close()
    ctx.timings["paper_fits" if paper else "fits"] = time.perf_counter() - t0
    return out


def mc_renders(opts: Options, cache: G.Cache, tones, rows_per_tone: list[dict], job) -> list[dict]:
    """Every configuration of every tone rendered by our Monte Carlo mixture renderer (cached per tone)."""
    cfg = opts.config
    renders = [None] * len(tones.names)
    bar = progress_bar(opts, len(tones.names), "gate renders (Monte Carlo)", job)
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


def network(opts: Options, files: dict[str, Path], albedo: np.ndarray, tones: np.ndarray, wl_idx: np.ndarray):
    """The network's mixtures at the grid indices ``wl_idx`` (inversion on the albedo (T, 3), as it is and with
    the painted colour of the albedo; decoder on the true p (T, 5)), and the decoder's full outputs (T, K, 376)
    for the figures (the paper's Fig. spectral_params): (inv, painted, dec, full)."""
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


def baseline_scales(opts: Options, lut, tones, gt: dict, albedo: np.ndarray,
                    wl_val: np.ndarray) -> tuple[dict[str, float], Calibration]:
    """Each baseline's Subsurface Scale (m): given, or calibrated on the calibration tone (see baselines)."""
    cfg = opts.config
    if cfg.baseline_scale_m is not None:
        return {m: cfg.baseline_scale_m for m in bl.METHODS}, Calibration(mode="given")
    name = cfg.calibration_tone if cfg.calibration_tone in tones.names else next(
        n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "representative")
    i = tones.names.index(name)
    scales = {}
    calib = Calibration(mode="calibrated", tone=name, scales_m=list(cfg.calibration_scales_m), errors={})
    for m in bl.METHODS:
        target = mc_target(lut, gt, i, np.arange(wl_val.size), cfg.gt_photons)
        best, errs = bl.calibrate_scale(m, lut, albedo[i], WAVELENGTHS_NM[wl_val], target,
                                        np.asarray(cfg.calibration_scales_m))
        scales[m] = best
        calib.errors[m] = errs
    return scales, calib
