"""``tables.md`` and ``tables.json`` of ``python -m training validate``: our numbers beside the paper's.

The Markdown holds Table 1 (rendering gate), its per-tone breakdown, Table 2 (banded fidelity), Table 3
(profile fidelity on the validation split), the goals of the issue and a Notes section whose every line
is filled from the run's record (photons, wavelengths, LUT, model card, dataset, baselines, gaps).
"""

from __future__ import annotations

import json
import re
import time
from functools import cache
from importlib import resources
from pathlib import Path
from string import Template

import numpy as np

from training.paths import portable_strings
from training.validate import gate as G
from training.validate import metrics as M
from training.validate import paper
from training.validate.baselines import BLENDER_DEFAULT_SCALE_M, METHODS
from training.validate.metrics import BANDS, EDGE_HALF_WIDTH_CM, EDGE_STEP_CM


def _f(x, digits: int = 2, pct: bool = False) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "—"
    return f"{100 * x:.1f} %" if pct else f"{x:.{digits}f}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|",
            *("| " + " | ".join(r) + " |" for r in rows)]


def table1(record: dict) -> list[str]:
    rows = record["gate"]["rows"]
    groups = record["gate"]["groups"]
    out = ["## Table 1 — rendering gate", "",
           "ΔE76 between the D65 colour of the rendered slab and the Monte Carlo ground truth (mean over tones; "
           f"{len(groups['representative'])} representative, {len(groups['outlier'])} outlier tones). "
           "*Edge ΔE76*: the same slab lit on one half-plane (±2 mm image, mean over pixels) — sees translucency. "
           "*Shape Vis*: L_shape (log-profile RMSE, 400–700 nm) of the configuration's profile through the LUT, "
           "as rendered (Σ w_k R_k P_k / Σ w_k R_k: a path picks medium k with probability w_k; the fitter's "
           "loss) and as the paper's §4 text writes it (Σ w_k P_k). "
           "*Noise floor*: the ΔE76 that Monte Carlo noise alone gives.", ""]
    body = []
    for r in G.ROWS:
        s = rows[r]
        pap = paper.TABLE1_DELTA_E.get(r)
        body.append([s["label"], _f(s["delta_e"]["representative"]), _f(s.get("vs_k1"), 1) + "×" if s.get("vs_k1")
                     else "—", _f(s["delta_e"]["outlier"]), _f(s["delta_e"]["all"]), _f(pap),
                     _f(s["noise_floor"]["representative"]), _f(s["delta_e_edge"]["representative"]),
                     _f(s["sam_vis"]["representative"], 3), _f(s["shape_vis_lut"]["representative"], 3),
                     _f(s["shape_vis_lut_fit_weighting"]["representative"], 3)])
    out += _table(["Configuration", "ΔE76 rep.", "vs K=1", "ΔE76 outliers", "ΔE76 all", "paper rep.",
                   "noise floor rep.", "edge ΔE76 rep.", "SAM Vis rep. (rad)", "shape Vis rep. (rendered)",
                   "shape Vis rep. (Σ w_k P_k)"], body)
    nv = record["gate"]["nn_vs_k3"]
    out += ["", f"Network vs the joint-optimised K = 3 reference (ΔE76 between the two renders): representative "
            f"{_f(nv['delta_e']['representative'])}, outliers {_f(nv['delta_e']['outlier'])}, all "
            f"{_f(nv['delta_e']['all'])}. Difference of the means vs ground truth (NN − K=3): representative "
            f"{_f(nv['difference_of_means']['representative'])} (paper {paper.NN_MINUS_JOINT_OPT:+.2f}), all "
            f"{_f(nv['difference_of_means']['all'])}; paper's NN on all 20 tones: {paper.NN_ALL_TONES}.", ""]
    return out


def table1_per_tone(record: dict) -> list[str]:
    g = record["gate"]
    out = ["### Table 1 per tone (ΔE76, slab colour)", ""]
    body = []
    for n in g["tones"]:
        srgb = np.clip(np.array(g["ground_truth"][n]["srgb"]), 0, 1)
        from exporters.colorimetry import srgb_encode

        hexc = "#" + "".join(f"{int(round(255 * v)):02x}" for v in np.clip(srgb_encode(srgb), 0, 1))
        body.append([n, g["ground_truth"][n]["kind"][:3], hexc] +
                     [_f(g["per_tone"][r][n]["delta_e"]) for r in G.ROWS] + [_f(g["nn_vs_k3"]["per_tone"][n])])
    out += _table(["Tone", "kind", "GT sRGB", *[r for r in G.ROWS], "NN vs K=3"], body)
    return out + [""]


def table2(record: dict) -> list[str]:
    b = record["banded"]
    out = ["## Table 2 — banded fidelity (joint-optimised fits, representative tones)", "",
           "Shape: the fits' L_shape (RMSE of log normalised profiles, the fitter's own loss term) averaged over the "
           "band's validation wavelengths and the representative tones; paper values in brackets. SAM: visible "
           "spectral angle of the rendered R_d vs the ground truth.", ""]
    if not b.get("shape"):
        return out + ["(no representative tone in this run)", ""]
    body = []
    for band in (*BANDS, "all"):
        v = b["shape"][band]
        red = b["reduction"][band]
        pap = paper.TABLE2_SHAPE.get(band)
        label = band if band != "all" else "all wavelengths"
        body.append([label] + [f"{_f(v[f'K{k}'], 3)}" + (f" ({pap[k - 1]})" if pap else "") for k in (1, 2, 3)]
                    + [_f(red["K1_to_K2"], pct=True), _f(red["K2_to_K3"], pct=True)])
    sam = b["sam_vis"]
    body.append(["SAM Vis (rad)"] + [f"{_f(sam[f'k{k}'], 3)} ({paper.TABLE2_SAM_VIS[k - 1]})" for k in (1, 2, 3)]
                + [_f(b["sam_reduction"]["K1_to_K2"], pct=True), _f(b["sam_reduction"]["K2_to_K3"], pct=True)])
    out += _table(["Band", "Shape K=1", "K=2", "K=3", "K=1→2", "K=2→3"], body)
    ex, exr, nz = b["excess"], b["excess_reduction"], b["noise"]
    out += ["", "The same with the ground truth's Monte Carlo noise taken out (excess sqrt(L² − noise²), "
            "`training.fit.loss.shape_excess`; noise = the L_shape that the bins' noise alone gives):", ""]
    out += _table(["Band", "noise", "excess K=1", "K=2", "K=3", "K=1→2", "K=2→3"],
                  [[band if band != "all" else "all wavelengths", _f(nz[band], 3)]
                   + [_f(ex[band][f"K{k}"], 3) for k in (1, 2, 3)]
                   + [_f(exr[band]["K1_to_K2"], pct=True), _f(exr[band]["K2_to_K3"], pct=True)]
                   for band in (*BANDS, "all")])
    ns = b.get("network_shape")
    if ns:
        out += ["", "The network's L_shape through the LUT, as rendered, at every validation wavelength (the fits' "
                "own are above; representative tones / all tones):", ""]
        out += _table(["Band", *(G.ROW_LABELS[r] for r in ns)],
                      [[band] + [f"{_f(ns[r]['representative'][band], 3)} / {_f(ns[r]['all'][band], 3)}" for r in ns]
                       for band in BANDS])
    out += ["", "Visible SAM of the other configurations (rep.): " + ", ".join(
        f"{G.ROW_LABELS[r]} {_f(sam[r], 3)}" for r in G.ROWS if not r.startswith("k")) + ".",
        "Mean relative reflectance error of the fits (LUT, rep.): " + ", ".join(
            f"K={k} {_f(b['refl_rel_err'][f'K{k}'], pct=True)}" for k in (1, 2, 3)) + ".", ""]
    return out


def table3(record: dict) -> list[str]:
    pf = record["profile_fidelity"]
    out = ["## Table 3 — profile fidelity on the validation split", ""]
    fits = pf.get("fits")
    if not fits:
        out += [f"Not computed: {pf.get('fits_missing', 'no fits')} (paper: K = 1 {paper.PROFILE_K1} → K = 2 "
                f"{paper.PROFILE_K2}, −{100 * paper.PROFILE_REDUCTION:.1f} %).", ""]
    else:
        t = fits["fits"]
        out += [f"Mean L_shape over {fits['n_tones']} validation tones × {fits['n_wavelengths']} wavelengths "
                f"(files: {', '.join(Path(p).name for p in fits['files'])}).", ""]
        body = []
        for key in ("mean", *BANDS):
            body.append([key if key != "mean" else "all"] + [_f(t.get(f"K{k}", {}).get(key), 4) for k in (1, 2, 3)]
                        + [_f(t.get("K1_to_K2_reduction", {}).get(key), pct=True),
                           _f(t.get("K2_to_K3_reduction", {}).get(key), pct=True)]
                        + ([f"{paper.PROFILE_K1} → {paper.PROFILE_K2} (−{100 * paper.PROFILE_REDUCTION:.1f} %)"]
                           if key == "mean" else ["—"]))
        out += _table(["Wavelengths", "K=1", "K=2", "K=3", "K=1→2", "K=2→3", "paper"], body) + [""]
        summ = fits.get("fitter_summary")
        if summ:
            ks = {int(k): v for k, v in summ["K"].items()}
            ex = [ks[k]["shape_excess"] for k in sorted(ks)]
            red = M.relative_reduction(ex[0], ex[1]) if len(ex) > 1 and ex[0] > 0 else None
            out += [f"The fitter's summary (`training.fit.dataset.summarise`): the Monte Carlo noise of the bins "
                    f"alone gives L_shape ≈ {summ['noise']:.4f}; the excess over it, sqrt(L² − noise²), is "
                    + ", ".join(f"K={k} {_f(ks[k]['shape_excess'], 4)}" for k in sorted(ks))
                    + f" (K = 1 → 2: {_f(red, pct=True)}); mean |ΔR|/R "
                    + ", ".join(f"K={k} {_f(ks[k]['refl_rel_err'], pct=True)}" for k in sorted(ks)) + ".", ""]
    net = pf.get("network")
    if net:
        n = net["nn_decoder"]
        out += [f"The network's decoder (true p of {net['n_tones']} validation tones) through the LUT: L_shape "
                f"{_f(n['fit']['mean'], 4)} with the paper's text weighting Σ w_k P_k, "
                f"{_f(n['rendered']['mean'], 4)} with "
                "the rendered weighting Σ w_k R_k P_k (per band, paper's text weighting: " + ", ".join(
                    f"{b} {_f(n['fit'][b], 4)}" for b in BANDS) + ").", ""]
    return out


def goals_md(record: dict) -> list[str]:
    g = record["goals"]
    a, b = g["nn_delta_e_at_most_paper"], g["k2_profile_reduction_at_least_paper"]
    met = lambda m: "—" if m is None else ("met" if m else "NOT met")  # noqa: E731
    ex = b.get("excess_over_noise")
    extra = (f" On the excess over the bins' Monte Carlo noise (L_shape ≈ {ex['noise']:.3f} from noise alone) the "
             f"reduction is {_f(ex['reduction'], pct=True)}." if ex else "")
    return ["## Goals of the issue", "",
            f"- Network rendering ΔE76 on the representative gate tones ≤ the paper's {a['paper']}: ours "
            f"{_f(a['ours'])} — {met(a['met'])}.",
            f"- K = 2 reduces the profile error by ≥ {100 * b['paper']:.1f} %: ours {_f(b['ours'], pct=True)} on the "
            f"{b['source']} — {met(b['met'])}.{extra}", ""] + network_targets_md(g.get("network_targets", [])) \
        + nn_minus_k3_causes_md(record)


def network_targets_md(targets: list[dict]) -> list[str]:
    """The rebuilt network's targets (``assemble.NETWORK_TARGETS``), each with ours and, where missed, by how much."""
    if not targets:
        return []
    out = ["The network's targets:", "", "| target | ours | goal | |", "|---|---|---|---|"]
    for t in targets:
        if t["met"] is None:
            verdict = "not measured"
        else:
            verdict = "met" if t["met"] else f"NOT met, by {_f(t['ours'] - t['target'])}"
        out.append(f"| {t['what']} | {_f(t['ours'])} | ≤ {t['target']} | {verdict} |")
    return out + ["", "Which tones: the `nn` and `NN vs K=3` columns of Table 1 per tone.", ""]


def nn_minus_k3_causes_md(record: dict) -> list[str]:
    """Where a "network minus K = 3" target is missed: the tones above it, their gap split into what the encoder
    adds (RGB in against the true p in) and what the decoder leaves (true p in against the K = 3 fits), and how
    many fitted training tones stage 3 saw near each (``assemble.training_neighbours``)."""
    missed = [t for t in record["goals"].get("network_targets", [])
              if t["measure"] == "nn_minus_k3" and t["met"] is False]
    if not missed:
        return []
    g = record["gate"]
    rows, groups = g["per_tone"], g["groups"]
    limit = min(t["target"] for t in missed)
    names = sorted({n for t in missed for n in groups[t["where"]]
                    if rows["nn"][n]["delta_e"] - rows["k3"][n]["delta_e"] > limit},
                   key=lambda n: rows["k3"][n]["delta_e"] - rows["nn"][n]["delta_e"])
    near = g.get("training_neighbours")
    head = "| tone | NN − K3 | encoder (RGB in − true p in) | decoder (true p in − K3) |"
    sep = "|---|---|---|---|"
    if near:
        head += f" fitted training tones within {near['radius']} |"
        sep += "---|"
    out = [f"Why, measured: the tones whose network error exceeds the K = 3 fits' by more than {limit}, split into "
           "the encoder's and the decoder's share (Table 1's `nn`, `nn_decoder` and `k3` columns)"
           + (f", with the fitted training tones stage 3 saw within {near['radius']} of each in the unit parameter "
              f"box (f_mel, f_blood, t_epi on a log scale; median over all gate tones "
              f"{int(np.median(list(near['count'].values())))} of {near['n_fitted']:,})" if near else "") + ":",
           "", head, sep]
    for n in names:
        nn, dec, k3 = (rows[r][n]["delta_e"] for r in ("nn", "nn_decoder", "k3"))
        line = f"| {n} | {_f(nn - k3)} | {_f(nn - dec)} | {_f(dec - k3)} |"
        out.append(line + (f" {near['count'][n]} |" if near else ""))
    return out + [""]


#: The Notes section's prose: ``string.Template`` sections of ``templates/notes.md`` (``note_templates``).
NOTES_TEMPLATE: str = "templates/notes.md"


@cache
def note_templates() -> dict[str, Template]:
    """The sections of ``NOTES_TEMPLATE`` by name: each "## name" heading starts one, its lines joined with
    single spaces (the leading HTML comment describes the file)."""
    text = resources.files("training.validate").joinpath(NOTES_TEMPLATE).read_text(encoding="utf-8")
    sections: dict[str, list[str]] = {}
    lines: list[str] = []
    for line in re.sub(r"<!--.*?-->", "", text, flags=re.S).splitlines():
        if line.startswith("## "):
            lines = sections.setdefault(line[3:].strip(), [])
        elif line.strip():
            lines.append(line.strip())
    return {name: Template(" ".join(body)) for name, body in sections.items()}


def _note(name: str, **values) -> str:
    """Section ``name`` of the notes template with its placeholders filled (KeyError naming a missing one)."""
    return note_templates()[name].substitute(values)


def _names(names: list[str]) -> str:
    return ", ".join(names) if names else "none"


def notes(record: dict) -> list[str]:
    """Facts of the run, and the gaps to the paper with what explains them (one string per note): the prose of
    ``NOTES_TEMPLATE`` filled with the numbers of ``record`` (the form of tables.json)."""
    run, g, rows = record["run"], record["gate"], record["gate"]["rows"]
    cfg, out = run["config"], []
    if run["quick"]:
        out.append(_note("quick"))
    renderer = _note("renderer_lut" if cfg.get("renderer", "lut") == "lut" else "renderer_mc")
    out.append(_note("photons", gt_photons=f"{run['ground_truth']['photons']:,}",
                     paper_photons=f"{paper.GATE_PHOTONS:,}", renderer=renderer,
                     noise_floors=", ".join(f"{r} {_f(rows[r]['noise_floor']['representative'])}" for r in G.ROWS)))
    mc = g.get("mc_check")
    if mc:
        out.append(_note("mc_check", photons=f"{cfg['photons']:,}", mc_vs_tables=", ".join(
            f"{r} {_f(v['delta_e_mc_vs_lut'])} ({_f(v['mc_noise_floor'])})" for r, v in mc.items())))
    tr = record["truncated_max"]
    out.append(_note("walk_cap", max_steps=f"{cfg['max_steps']:,}",
                     truncated=", ".join(f"{r} {tr[r]:.1e}" for r in G.ROWS)))
    wl = run["wavelengths"]
    out.append(_note("wavelengths", step_nm=wl["validation_step_nm"], n_validation=wl["n_validation"],
                     n_rendered=wl["n_rendered"], first_nm=f"{wl['rendered_nm'][0]:.0f}",
                     last_nm=f"{wl['rendered_nm'][1]:.0f}"))
    oog = [n for n in g["tones"] if np.any(np.array(g["ground_truth"][n]["srgb"]) > 1.0)]
    neg = [n for n in g["tones"] if any(v < 0 for v in record["gate"]["per_tone"]["k1"][n]["linear_srgb"])]
    out.append(_note("edge", half_width_mm=f"{10 * EDGE_HALF_WIDTH_CM:.0f}", step_um=f"{1e4 * EDGE_STEP_CM:.0f}",
                     out_of_gamut=_names(oog), negative_channel=_names(neg)))
    lut, fits = run["lut"], run["fits"]
    schedule = (_note("fit_schedule_given", method=fits["method"], steps=str(fits["steps"])) if fits["steps"]
                else _note("fit_schedule_default", method=fits["method"]))
    out.append(_note("lut", path=lut["path"], albedo_n=lut["albedo_n"], g_n=lut["g_n"],
                     g_lo=f"{lut['g_range'][0]:.2f}", g_hi=f"{lut['g_range'][1]:.2f}", sha256=lut["sha256"][:16],
                     fit_schedule=schedule, fit_seconds=f"{fits['seconds']:.0f}"))
    held = record["fits_held_at_lut_albedo"]
    out.append(_note("held_albedo", lo=f"{held['range'][0]:g}", hi=f"{held['range'][1]:g}", count=held["count"],
                     of=held["of"]))
    out.append(_model_note(run["model"]))
    pf = record["profile_fidelity"]
    if pf.get("fits"):
        at = pf["fits"]["attrs"]
        out.append(_note("table3", fits_dir=run["fits_dir"], n_tones=pf["fits"]["n_tones"],
                         n_tones_in_files=pf["fits"]["n_tones_in_files"], method=at.get("method"),
                         preset=at.get("dataset_preset"), photons=at.get("dataset_photons")))
    else:
        out.append(_note("table3_missing"))
    out.append(_baselines_note(record["baselines"]))
    exp = list(record["network"]["exposure"].values())
    clamped = [n for n, v in g["per_tone"]["nn_painted"].items() if v.get("clamped")]
    out.append(_note("network", lo=f"{min(exp):.3f}", hi=f"{max(exp):.3f}", nn_label=G.ROW_LABELS["nn"],
                     painted_label=G.ROW_LABELS["nn_painted"], clamped=_names(clamped)))
    k1 = rows["k1"]["delta_e"]["representative"]
    if k1 is not None:
        out.append(_note("gap_k1", ours=_f(k1), paper=paper.TABLE1_DELTA_E["k1"], paper_figure=paper.FIGURE_K1_DELTA_E,
                         refl_rel_err=_f(record["banded"].get("refl_rel_err", {}).get("K1"), pct=True)))
    if record["banded"].get("shape"):
        out.append(_note("gap_table2", paper_k1=paper.PROFILE_K1, paper_k2=paper.PROFILE_K2,
                         paper_train_k2=paper.TRAIN_SHAPE_K2, paper_train_k3=paper.TRAIN_SHAPE_K3))
    sv = {r: (rows[r]["shape_vis_lut"]["representative"], rows[r]["shape_vis_lut_fit_weighting"]["representative"])
          for r in ("k1", "k2", "k3")}
    out.append(_note("weighting", shapes=", ".join(f"K={r[1]} {_f(sv[r][0], 3)} / {_f(sv[r][1], 3)}" for r in sv)))
    t, c = run["timings_s"], run["compute_seconds"]
    out.append(_note("compute", pieces=", ".join(f"{k} {v:.0f} s" for k, v in c.items()),
                     invocation=", ".join(f"{k} {v:.0f}" for k, v in t.items()), threads=run["threads"]))
    return out


def _model_note(m: dict) -> str:
    """The model note: the graph's SHA-256 against its card and what the card says it was trained on."""
    card = m["card"]
    if card.get("missing"):
        return _note("model_without_card", dir=m["dir"])
    same = card.get("sha256", {}).get("skin_inversion.onnx") == m["sha256"]["skin_inversion.onnx"]
    ds = card.get("dataset", {})
    return _note("model", dir=m["dir"], sha256=m["sha256"]["skin_inversion.onnx"][:16],
                 card_match=_note("card_matches" if same else "card_differs"), created=card.get("created"),
                 n_train=ds.get("n_train"), photons=ds.get("photons"), preset=card.get("preset"), k=card.get("K"),
                 card_note=(card.get("notes") or ["—"])[0][:300])


def _baselines_note(bl: dict) -> str:
    """The baselines note: each method's Subsurface Scale, how it was chosen, and the published polynomials'
    darkening under the gate's boundary."""
    cal = bl["calibration"]
    how = (_note("scale_calibrated", tone=cal["tone"], n_scales=len(cal["scales_m"]), lo=f"{cal['scales_m'][0]:g}",
                 hi=f"{cal['scales_m'][-1]:g}") if cal["mode"] == "calibrated" else _note("scale_given"))
    dark = {mth: float(np.mean(v)) for mth, v in bl["published_darkening"].items()}
    return _note("baselines", radius_rgb=str(tuple(bl["radius_rgb"])),
                 scales=", ".join(f"{mth} {bl['scale_m'][mth]:.3g} m" for mth in METHODS), scale_source=how,
                 blender_scale=BLENDER_DEFAULT_SCALE_M, wrenninge_g=bl["wrenninge_g"],
                 darkening=", ".join(f"{mth} {dark[mth]:.2f}" for mth in METHODS))


def markdown(record: dict, stamp: str | None = None) -> str:
    """tables.md of ``record`` (the form of tables.json); ``stamp``: the time in its header line (default: now,
    "YYYY-MM-DD HH:MM UTC")."""
    run = record["run"]
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()) if stamp is None else stamp
    head = ["# Validation tables", "",
            f"`{run['command']}` — {stamp}."
            + (" **Quick mode: not the validation.**" if run["quick"] else ""), ""]
    body = table1(record) + table1_per_tone(record) + table2(record) + table3(record) + goals_md(record)
    body += ["## Notes", "", *(f"- {n}" for n in record["notes"]), ""]
    return "\n".join(head + body)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def write_tables(out: Path, record: dict) -> None:
    """Write ``tables.json`` and ``tables.md`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    record = portable_strings(_jsonable(record))  # shipped: no absolute paths of the building machine
    (out / "tables.json").write_text(json.dumps(record, indent=1) + "\n")
    (out / "tables.md").write_text(markdown(record))
