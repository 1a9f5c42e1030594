"""The parts of a validation record from what the run computed: Table 1 (the gate), the check of the renders,
Table 2 (banded fidelity), Table 3 (profile fidelity), the training neighbours and the goals.

The inputs are those of ``training.validate.run``: the ``RunContext`` (gate tones, ground truth ``gt``,
wavelength indices), the configurations' parameters per tone (``rows_per_tone``: row -> ``gate.Params``), their
renders (row -> {"R_d", "R_d_stderr", "profile", "truncated", "seconds"}) and the fits per tone
(``gate.fit_tone``); the outputs are the typed parts of ``training.validate.record``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from exporters.constants import WAVELENGTHS_NM
from training.validate import gate as G
from training.validate import metrics as M
from training.validate import paper
from training.validate.record import (
    BandedRecord,
    GateRecord,
    Goal,
    Goals,
    GroundTruthColour,
    McCheck,
    NetworkTarget,
    NetworkVsK3,
    ProfileFidelity,
    ReductionGoal,
    RowSummary,
    ToneMetrics,
    TrainingNeighbours,
)

if TYPE_CHECKING:
    from training.validate.run import Options, RunContext

#: Per-tone metrics of Table 1 (summarised as means over the representative, outlier and all tones).
METRICS = ("delta_e", "noise_floor", "delta_e_edge", "sam_vis", "shape_vis_lut", "shape_vis_lut_fit_weighting")
#: Radius (in the unit box of ``training.train.balance.unit_box``) within which the fitted training tones of a
#: gate tone are counted: how well stage 3 saw its neighbourhood.
NEIGHBOUR_RADIUS: float = 0.25
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


def _mean(values) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else None


def mc_target(lut, gt: dict, i: int, cols: np.ndarray, photons: float):
    """The fitter's target (``training.fit.loss.Target``) of gate tone ``i``'s ground truth at the validation
    columns ``cols``."""
    return G.mc_target(lut, gt["profile"][i][cols], gt["R_d"][i][cols], gt["profile_stderr"][i][cols], photons)


def _groups(tones) -> dict[str, list[str]]:
    return {"representative": [n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "representative"],
            "outlier": [n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "outlier"],
            "all": list(tones.names)}


# ------------------------------------------------------------------------------------------ Table 1
def gate_tables(ctx: RunContext, rows_per_tone: list[dict], renders: list[dict], fits: dict) -> GateRecord:
    """Table 1 (per tone and summarised): colour ΔE76, edge ΔE76, SAM, LUT shape error, noise floor; the
    network against the K = 3 fits."""
    lut, tones, gt, albedo, cfg = ctx.lut, ctx.tones, ctx.gt, ctx.albedo, ctx.opts.config
    wl_r, col_r = ctx.wl_r, ctx.col_r
    wl = WAVELENGTHS_NM[wl_r]
    vis = M.band_mask(wl, "Vis")
    vis_rows = np.flatnonzero(vis)
    per_row: dict[str, dict[str, ToneMetrics]] = {r: {} for r in G.ROWS}
    nn_vs_k3: dict[str, float] = {}
    gt_rec: dict[str, GroundTruthColour] = {}
    for i, name in enumerate(tones.names):
        g_r, g_se = gt["R_d"][i][col_r], gt["R_d_stderr"][i][col_r]
        g_prof = gt["profile"][i][col_r].astype(np.float64)
        target = mc_target(lut, gt, i, col_r, cfg.gt_photons)
        gt_rec[name] = GroundTruthColour(kind=tones.kinds[i], albedo_rgb=albedo[i].tolist(),
                                         srgb=np.clip(M.linear_srgb(g_r, wl), 0, None).tolist(),
                                         lab=M.lab(g_r, wl).tolist())
        for r in G.ROWS:
            rend = renders[i][r]
            per_row[r][name] = ToneMetrics(
                delta_e=float(M.delta_e(rend["R_d"], g_r, wl)),
                noise_floor=M.noise_floor(g_r, g_se, rend["R_d_stderr"], wl, seed=cfg.seed + i),
                delta_e_edge=M.edge_delta_e(rend["profile"].astype(np.float64), rend["R_d"], g_prof, g_r, wl),
                sam_vis=M.spectral_angle(rend["R_d"], g_r, vis),
                shape_vis_lut=float(np.mean(G.lut_mixture_shape_error(lut, rows_per_tone[i][r], target, vis_rows))),
                shape_vis_lut_fit_weighting=float(np.mean(G.lut_mixture_shape_error(
                    lut, rows_per_tone[i][r], target, vis_rows, "fit"))),
                linear_srgb=M.linear_srgb(rend["R_d"], wl).tolist(),
                truncated_max=float(np.max(rend["truncated"])),
            )
        nn_vs_k3[name] = float(M.delta_e(renders[i]["nn"]["R_d"], renders[i]["k3"]["R_d"], wl))
        per_row["nn_painted"][name].clamped = rows_per_tone[i]["nn_painted"].extra["clamped"]
    kinds = _groups(tones)
    summary = {r: RowSummary(label=G.ROW_LABELS[r], **{
        metric: {kind: _mean(getattr(per_row[r][n], metric) for n in names) if names else None
                 for kind, names in kinds.items()} for metric in METRICS}) for r in G.ROWS}
    k1 = summary["k1"].delta_e["representative"]
    for r in G.ROWS:
        v = summary[r].delta_e["representative"]
        summary[r].vs_k1 = (k1 / v) if (k1 is not None and v) else None
    nn_sum = {kind: _mean(nn_vs_k3[n] for n in names) if names else None for kind, names in kinds.items()}
    diff = {kind: (summary["nn"].delta_e[kind] - summary["k3"].delta_e[kind])
            if summary["nn"].delta_e[kind] is not None else None for kind in kinds}
    return GateRecord(tones=list(tones.names), kinds=list(tones.kinds), groups=kinds, wavelength_nm=wl.tolist(),
                      rows=summary, per_tone=per_row,
                      nn_vs_k3=NetworkVsK3(delta_e=nn_sum, per_tone=nn_vs_k3, difference_of_means=diff),
                      ground_truth=gt_rec)


def mc_check(tones, wl_r: np.ndarray, tables: list[dict], mc: list[dict], seed: int) -> dict[str, McCheck]:
    """The tables' renders against the Monte Carlo ones, per row: mean ΔE76 between the two slab colours over
    all tones, beside the ΔE76 that the Monte Carlo renders' noise alone gives (M.noise_floor)."""
    wl = WAVELENGTHS_NM[wl_r]
    out = {}
    for r in G.ROWS:
        de = [float(M.delta_e(mc[i][r]["R_d"], tables[i][r]["R_d"], wl)) for i in range(len(tones.names))]
        nf = [M.noise_floor(tables[i][r]["R_d"], 0.0 * tables[i][r]["R_d"], mc[i][r]["R_d_stderr"], wl, seed=seed + i)
              for i in range(len(tones.names))]
        out[r] = McCheck(delta_e_mc_vs_lut=float(np.mean(de)), mc_noise_floor=float(np.mean(nf)),
                         max_delta_e_mc_vs_lut=float(np.max(de)))
    return out


def training_neighbours(fits_dir: Path, tones) -> TrainingNeighbours | None:
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
    return TrainingNeighbours(radius=NEIGHBOUR_RADIUS, n_fitted=len(train),
                              count={n: int((d < NEIGHBOUR_RADIUS).sum()) for n, d in
                                     zip(tones.names, dist, strict=True)})


# ------------------------------------------------------------------------------------------ Table 2
def network_shape(lut, tones, gt: dict, wl_val: np.ndarray, nn_val: dict, photons: float) -> dict:
    """The network rows' L_shape through the LUT (rendered weighting) per band at every validation wavelength:
    means over the representative tones and over all tones (the fits' own are in Table 2); row -> group -> band."""
    wl = WAVELENGTHS_NM[wl_val]
    all_cols = np.arange(wl_val.size)
    errs = {r: [] for r in nn_val}
    for i in range(len(tones.names)):
        target = mc_target(lut, gt, i, all_cols, photons)
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


def banded(lut, tones, gt: dict, fits: dict, wl_val: np.ndarray, gate: GateRecord, photons: float) -> BandedRecord:
    """Table 2: per band the fits' mean L_shape (representative tones) for K = 1, 2, 3 and the reductions,
    also of the excess over the ground truth's Monte Carlo noise (``training.fit.loss``: Target.noise,
    shape_excess); the rendered visible SAM of every configuration (representative tones)."""
    from training.fit import loss as fit_loss

    rep = [n for n, k in zip(tones.names, tones.kinds, strict=True) if k == "representative"]
    out = BandedRecord(tones=rep)
    if not rep:
        return out
    wl = WAVELENGTHS_NM[wl_val]
    all_cols = np.arange(wl_val.size)
    noise = np.stack([mc_target(lut, gt, tones.names.index(n), all_cols, photons).noise.numpy() for n in rep])
    shape = {k: np.stack([fits[n][f"k{k}_shape_rmse"] for n in rep]) for k in (1, 2, 3)}  # (T, W) on wl_val
    excess = {k: fit_loss.shape_excess(torch.as_tensor(v), torch.as_tensor(noise)).numpy() for k, v in shape.items()}
    out.noise = {}
    for band in (*M.BANDS, "all"):
        mask = M.band_mask(wl, band) if band != "all" else np.ones(wl.size, bool)
        out.noise[band] = float(np.mean(noise[:, mask])) if mask.any() else None
        for values, data, reductions in ((out.shape, shape, out.reduction), (out.excess, excess, out.excess_reduction)):
            vals = {f"K{k}": float(np.mean(data[k][:, mask])) if mask.any() else None for k in (1, 2, 3)}
            values[band] = vals
            reductions[band] = {a + "_to_" + b: (M.relative_reduction(vals[a], vals[b]) if vals[a] and vals[b]
                                                 is not None else None) for a, b in (("K1", "K2"), ("K2", "K3"))}
    out.sam_vis = {r: gate.rows[r].sam_vis["representative"] for r in G.ROWS}
    sam = [out.sam_vis[f"k{k}"] for k in (1, 2, 3)]
    out.sam_reduction = {"K1_to_K2": M.relative_reduction(sam[0], sam[1]) if sam[0] else None,
                         "K2_to_K3": M.relative_reduction(sam[1], sam[2]) if sam[1] else None}
    out.refl_rel_err = {f"K{k}": float(np.mean(np.stack([fits[n][f"k{k}_refl_rel_err"] for n in rep])))
                        for k in (1, 2, 3)}
    return out


# ------------------------------------------------------------------------------------------ Table 3
def profile_fidelity(opts: Options, lut, files: dict[str, Path]) -> ProfileFidelity:
    """Table 3 from the validation fits (and the network on the validation split) when given."""
    from training.validate import profile_set

    out = ProfileFidelity()
    if opts.fits is not None:
        out.fits = profile_set.fit_profile_fidelity(opts.fits, opts.dataset)
    else:
        out.fits_missing = "no --fits given: Table 3 needs `python -m training fit --dataset DIR --out FITS`."
    if opts.dataset is not None:
        out.network = profile_set.network_profile_fidelity(opts.dataset, lut, files["skin_decoder.onnx"],
                                                           max_tones=opts.nn_profile_tones, progress=opts.progress)
    return out


# ------------------------------------------------------------------------------------------ goals
def network_targets(gate: GateRecord, banded_rec: BandedRecord) -> list[NetworkTarget]:
    """``NETWORK_TARGETS`` checked on the network's rows (``ours`` None where a row or band is missing)."""
    nn = gate.rows["nn"]
    ns = banded_rec.network_shape if isinstance(banded_rec.network_shape, dict) else {}
    shape = ns.get("nn", {}).get("all", {})
    source = {"delta_e": nn.delta_e, "edge": nn.delta_e_edge, "noise_floor": nn.noise_floor,
              "nn_minus_k3": gate.nn_vs_k3.difference_of_means, "shape": shape}
    out = []
    for measure, what, where, target in NETWORK_TARGETS:
        ours = source[measure].get(where)
        out.append(NetworkTarget(measure=measure, where=where, what=what, target=target, ours=ours,
                                 met=None if ours is None else bool(ours <= target)))
    return out


def goals(gate: GateRecord, banded_rec: BandedRecord, fidelity: ProfileFidelity) -> Goals:
    """The goals, checked on our numbers: the network's ΔE76 against the paper's, K = 2's profile-error
    reduction against the paper's (Table 3 where computed, else the gate's representative tones), and
    ``NETWORK_TARGETS``."""
    nn = gate.rows["nn"].delta_e["representative"]
    nn_goal = Goal(ours=nn, paper=paper.TABLE1_DELTA_E["nn"],
                   met=None if nn is None else bool(nn <= paper.TABLE1_DELTA_E["nn"]))
    prof = fidelity.fits
    if prof and "K1_to_K2_reduction" in prof["fits"]:
        red, source = prof["fits"]["K1_to_K2_reduction"]["mean"], "validation split (Table 3)"
    else:
        red, source = banded_rec.reduction.get("all", {}).get("K1_to_K2"), \
            "gate representative tones, all validation wavelengths (Table 3 not available)"
    reduction = ReductionGoal(ours=red, paper=paper.PROFILE_REDUCTION, source=source,
                              met=None if red is None else bool(red >= paper.PROFILE_REDUCTION))
    summ = (prof or {}).get("fitter_summary")
    if not prof and banded_rec.excess_reduction:
        reduction.excess_over_noise = {"reduction": banded_rec.excess_reduction["all"]["K1_to_K2"],
                                       "noise": banded_rec.noise["all"]}
    elif summ:  # the same reduction on the excess over the bins' Monte Carlo noise (training.fit.dataset.summarise)
        ks = {int(k): v for k, v in summ["K"].items()}
        if 1 in ks and 2 in ks and ks[1]["shape_excess"] > 0:
            reduction.excess_over_noise = {"reduction": 1.0 - ks[2]["shape_excess"] / ks[1]["shape_excess"],
                                           "noise": summ["noise"]}
    return Goals(nn_delta_e_at_most_paper=nn_goal, k2_profile_reduction_at_least_paper=reduction,
                 network_targets=network_targets(gate, banded_rec))
