"""``python -m training resampling``: profile estimators compared at equal photons (paper §3).

The paper reports its CDF-based conservative resampling at 4x lower RMSR than uniform binning and 2x
lower than a kernel density estimate at 10^5 photons.  Here, for a few homogeneous media (sigma_t =
100 cm^-1) and one skin tone at two wavelengths (the two-layer model, direct estimator), one walk of
``repeats`` x ``photons`` photons is split by photon id into ``repeats`` independent runs of
``photons`` each.  Every run's exits give four estimates of the profile on the 512 log bins of docs/contracts.md §1:

* ``histogram``: the plain tally in the 512 log bins (what the simulator writes by default);
* ``uniform``: a histogram in 512 bins uniform in r over [0, 5 cm], remapped conservatively onto the
  log bins (density constant in area within a uniform bin) - "uniform binning" read literally;
* ``kde``: a weighted Gaussian KDE of log r (scipy, Scott's bandwidth), integrated over each bin;
* ``cdf``: ``training.sim.resample.cdf_resample`` at several ``min_count`` (the default marked).

Reference: for run i, the pooled histogram of the other runs ((repeats - 1) x photons: independent of
run i).  RMSR (root-mean-square relative residual) of an estimate p against the reference q over the
bins S where the pooled reference of all runs has a relative standard error below 10 % (also below 30 %,
"with tails", reported beside it; ``SUPPORTS``):
    RMSR^2 = mean_S ((p - q) / q)^2 - mean_S (se_q / q)^2,
the second term removing the reference's own noise (its per-bin standard error), clipped at 0.  Mean
over the runs.  Everything is deterministic for a seed.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

from exporters.cli_io import NOTHING_KEPT, OneLineParser, check_output_folder, count, guarded
from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.sim.medium import LayeredMedium
from training.sim.resample import MAX_SPAN, MIN_COUNT, cdf_resample, histogram_profile, kde_profile
from training.sim.transport import simulate_records

#: RMSR supports: bins where the pooled reference's relative standard error is below 10 % ("resolved")
#: and below 30 % ("with tails": most of the sparse tail too); ``--quick``, its reference being small, 30 / 50 %.
SUPPORTS = {"resolved": 0.1, "with_tails": 0.3}
SUPPORTS_QUICK = {"resolved": 0.3, "with_tails": 0.5}
#: min_count values of the CDF resampler compared (MIN_COUNT is the default).
MIN_COUNTS = (200, 400, 800, 1600)
#: Representative tone R05 of training/skin/tones.csv (medium skin) and the wavelengths used (nm).
SKIN_TONE = ("R05", (0.035, 0.02, 0.01, 0.75, 0.8))
SKIN_WAVELENGTHS_NM = (450, 650)
SIGMA_T = 100.0  #: cm^-1, extinction of the homogeneous media
HOMOGENEOUS = ((0.9, 0.8), (0.99, 0.8), (0.998, 0.85))  #: (albedo, g)


def _cases(quick: bool) -> list[dict]:
    from training.sim.tissue import skin_medium

    media = HOMOGENEOUS[:1] if quick else HOMOGENEOUS
    cases = [{"name": f"homogeneous a={a} g={g}", "kind": "homogeneous", "albedo": a, "g": g, "sigma_t": SIGMA_T,
              "medium": LayeredMedium.homogeneous(SIGMA_T * (1 - a), SIGMA_T * a, g, n_medium=1.4)}
             for a, g in media]
    wls = SKIN_WAVELENGTHS_NM[:1] if quick else SKIN_WAVELENGTHS_NM
    idx = [int(np.argmin(np.abs(np.asarray(WAVELENGTHS_NM) - w))) for w in wls]
    skin = skin_medium(np.array(SKIN_TONE[1])).select_channels(idx)
    for c, w in enumerate(wls):
        cases.append({"name": f"skin {SKIN_TONE[0]} {w} nm", "kind": "skin", "tone": list(SKIN_TONE[1]),
                      "wavelength_nm": w, "medium": skin.select_channels([c])})
    return cases


def uniform_profile(r: np.ndarray, w: np.ndarray, photons: int, r_edges: np.ndarray, n_bins: int) -> np.ndarray:
    """Histogram in ``n_bins`` bins uniform in r over [0, r_edges[-1]], remapped onto ``r_edges`` (cm^-2).

    The cumulative energy is linear in r^2 inside a uniform bin (constant density per area), so the
    remap is conservative: np.interp of the cumulative energy at the target edges' r^2.
    """
    lin = np.linspace(0.0, r_edges[-1], n_bins + 1)
    e = np.histogram(r, bins=lin, weights=w)[0] / photons
    cum = np.concatenate([[0.0], np.cumsum(e)])
    return histogram_profile(np.diff(np.interp(r_edges**2, lin**2, cum)), r_edges)


def _tally(r: np.ndarray, w: np.ndarray, r_edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sums of exit weights and of their squares per bin of ``r_edges`` (exits beyond the last edge dropped)."""
    return np.histogram(r, bins=r_edges, weights=w)[0], np.histogram(r, bins=r_edges, weights=w * w)[0]


def _mean_se(s1: np.ndarray, s2: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-photon mean and its standard error from sums of weights and squared weights over n photons."""
    mean = s1 / n
    return mean, np.sqrt(np.maximum(s2 / n - mean**2, 0.0) / n)


def _rmsr(p: np.ndarray, q: np.ndarray, se_q: np.ndarray, support: np.ndarray) -> float:
    rel = (p[support] - q[support]) / q[support]
    return float(math.sqrt(max(np.mean(rel**2) - np.mean((se_q[support] / q[support]) ** 2), 0.0)))


def compare_case(medium: LayeredMedium, photons: int, repeats: int, seed: int,
                 supports: dict[str, float] = SUPPORTS, r_edges: np.ndarray = R_EDGES_CM) -> dict:
    """RMSR of every estimator for one single-channel medium (module docstring) on each support (the
    first is the headline ``rmsr``, the others ``rmsr_<name>``); per-run curves of run 0."""
    rec = simulate_records(medium, photons * repeats, seed=seed, compile=False)
    refl = rec.kind == 1
    r, w, run = rec.r_cm[refl], rec.w[refl], rec.pid[refl] % repeats
    tallies = [_tally(r[run == i], w[run == i], r_edges) for i in range(repeats)]
    s1, s2 = np.sum([t[0] for t in tallies], axis=0), np.sum([t[1] for t in tallies], axis=0)
    mean_all, se_all = _mean_se(s1, s2, photons * repeats)
    masks = {}
    every_ref = np.all([s1 - t[0] > 0 for t in tallies], axis=0)  # every leave-one-out reference has light
    for name, rel_se in supports.items():
        masks[name] = every_ref & (se_all < rel_se * mean_all)
        if masks[name].sum() < 10:
            raise ValueError(f"only {int(masks[name].sum())} bins of the pooled reference are resolved to "
                             f"{rel_se:.0%}: raise --photons or --repeats")
    rmsr: dict[str, dict[str, list[float]]] = {name: {} for name in supports}
    curves = {}
    for i in range(repeats):
        e_ref, se_ref = _mean_se(s1 - tallies[i][0], s2 - tallies[i][1], photons * (repeats - 1))
        q, se_q = histogram_profile(e_ref, r_edges), histogram_profile(se_ref, r_edges)
        sel = run == i
        e, e2 = tallies[i][0] / photons, tallies[i][1] / photons
        est = {
            "histogram": histogram_profile(e, r_edges),
            "uniform": uniform_profile(r[sel], w[sel], photons, r_edges, r_edges.size - 1),
            "kde": kde_profile(r[sel & (r < r_edges[-1])], w[sel & (r < r_edges[-1])], photons, r_edges),
        }
        for m in MIN_COUNTS:
            est["cdf" if m == MIN_COUNT else f"cdf_m{m}"] = cdf_resample(e, e2, r_edges, photons, min_count=m)
        for name, mask in masks.items():
            for k, p in est.items():
                rmsr[name].setdefault(k, []).append(_rmsr(p, q, se_q, mask))
        if i == 0:
            curves = {"reference": q, **{k: est[k] for k in ("histogram", "uniform", "kde", "cdf")}}
    first = next(iter(supports))
    out = {"walk_seconds": rec.seconds, "_curves": curves, "_support": masks[first]}
    for name in supports:
        mean = {k: float(np.mean(v)) for k, v in rmsr[name].items()}
        tag = "" if name == first else f"_{name}"
        out |= {f"rmsr{tag}": mean, f"support_bins{tag}": int(masks[name].sum()),
                **{f"ratio_{k}_over_cdf{tag}": mean[k] / mean["cdf"] for k in ("histogram", "uniform", "kde")}}
    out["rmsr_runs"] = rmsr[first]
    return out


def _figure(results: list[dict], path: Path, photons: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    centres = np.sqrt(R_EDGES_CM[1:-1] * R_EDGES_CM[2:])
    colours = {"histogram": "0.55", "uniform": "tab:green", "kde": "tab:orange", "cdf": "tab:blue"}
    n = len(results)
    cols = min(n + 1, 3)
    rows = math.ceil((n + 1) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.3 * rows), squeeze=False)
    axes = axes.ravel()
    for ax in axes[n + 1:]:
        ax.axis("off")
    for ax, res in zip(axes[:n], results, strict=True):
        cv, sup = res["_curves"], res["_support"][1:]
        q = cv["reference"][1:]
        for k in ("histogram", "kde", "cdf"):
            rel = np.where(sup, cv[k][1:] / np.where(q > 0, q, 1.0) - 1.0, np.nan)
            ax.plot(centres, rel, color=colours[k], lw=0.8, label=k)
        ax.set_xscale("log")
        ax.set_ylim(-1.0, 1.0)
        ax.set_title(res["name"], fontsize=8)
        ax.set_xlabel("r (cm)")
        ax.set_ylabel("estimate / reference - 1", fontsize=8)
    axes[0].legend(fontsize=7, title=f"one run, {photons:,} photons", title_fontsize=7)
    bar_ax = axes[n]
    x = np.arange(n)
    for j, k in enumerate(colours):
        bar_ax.bar(x + (j - 1.5) * 0.2, [r["rmsr"][k] for r in results], 0.2, label=k, color=colours[k])
    bar_ax.set_xticks(x, [r["name"].replace("homogeneous ", "") for r in results], rotation=30, fontsize=6,
                      ha="right")
    bar_ax.set_yscale("log")
    bar_ax.set_title("RMSR (mean over runs)", fontsize=8)
    bar_ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(out: Path, photons: int, repeats: int, seed: int, quick: bool, log=print) -> dict:
    """Compare the estimators on every case; write resampling.json, resampling.md, fig_resampling.png."""
    t0 = time.perf_counter()
    results = []
    supports = SUPPORTS_QUICK if quick else SUPPORTS
    for c, case in enumerate(_cases(quick)):
        res = compare_case(case.pop("medium"), photons, repeats, seed + c, supports)
        results.append({**case, **res})
        log(f"{case['name']}: RMSR " + ", ".join(f"{k} {v:.3f}" for k, v in res["rmsr"].items()))
    out.mkdir(parents=True, exist_ok=True)
    _figure(results, out / "fig_resampling.png", photons)
    keys = ("histogram", "uniform", "kde", "cdf")
    tags = [""] + [f"_{n}" for n in list(supports)[1:]]
    means = {t: {k: float(np.mean([r[f"rmsr{t}"][k] for r in results])) for k in results[0]["rmsr"]} for t in tags}
    summary = {
        "command": "python -m training resampling" + (" --quick" if quick else "")
        + f" --photons {photons} --repeats {repeats} --seed {seed}",
        "photons": photons, "repeats": repeats, "reference_photons": photons * (repeats - 1),
        "supports_rel_se": supports, "default_min_count": MIN_COUNT, "default_max_span": MAX_SPAN,
        "cases": [{k: v for k, v in r.items() if not k.startswith("_")} for r in results],
        "paper": {"ratio_uniform_over_cdf": 4.0, "ratio_kde_over_cdf": 2.0, "photons": 100_000},
    }
    for t in tags:
        summary[f"mean_rmsr{t}"] = means[t]
        summary |= {f"ratio_{k}_over_cdf{t}": means[t][k] / means[t]["cdf"] for k in ("histogram", "uniform", "kde")}
    summary["seconds"] = time.perf_counter() - t0
    (out / "resampling.json").write_text(json.dumps(summary, indent=1))
    lines = [f"# Profile estimators at {photons:,} photons (`{summary['command']}`)", "",
             f"RMSR against a leave-one-out reference of {photons * (repeats - 1):,} photons, mean over "
             f"{repeats} runs (the reference's own noise removed; `training/sim/resample_compare.py`), over "
             "the bins where the pooled reference's relative standard error is below "
             + " / ".join(f"{v:.0%} ({k.replace('_', ' ')})" for k, v in supports.items()) + ".", ""]
    for t, (name, rel_se) in zip(tags, supports.items(), strict=True):
        lines += [f"**{name.replace('_', ' ')}** (reference resolved to {rel_se:.0%})", "",
                  "| case | bins | " + " | ".join(keys) + " | histogram / cdf | uniform / cdf | kde / cdf |",
                  "|---|---|" + "---|" * (len(keys) + 3)]
        for r in results:
            lines.append(f"| {r['name']} | {r[f'support_bins{t}']} | "
                         + " | ".join(f"{r[f'rmsr{t}'][k]:.3f}" for k in keys) + " | "
                         + " | ".join(f"{r[f'ratio_{k}_over_cdf{t}']:.2f}" for k in ("histogram", "uniform", "kde"))
                         + " |")
        lines.append("| mean | | " + " | ".join(f"{means[t][k]:.3f}" for k in keys) + " | "
                     + " | ".join(f"{summary[f'ratio_{k}_over_cdf{t}']:.2f}" for k in ("histogram", "uniform", "kde"))
                     + " |")
        lines += ["", f"CDF resampling at other `min_count` (max span {MAX_SPAN} bins; mean RMSR): "
                  + ", ".join(f"{m}: {means[t]['cdf' if m == MIN_COUNT else f'cdf_m{m}']:.3f}" for m in MIN_COUNTS)
                  + f" (default {MIN_COUNT}).", ""]
    lines += ["Paper (§3, 10^5 photons): CDF resampling 4x lower RMSR than uniform binning, 2x lower than a KDE.", ""]
    (out / "resampling.md").write_text("\n".join(lines))
    return summary


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training resampling",
                      description="Radial profile estimators (histogram, uniform bins, KDE, CDF "
                      "resampling) against a high-photon reference at equal photons.")
    p.add_argument("--out", type=Path, required=True, help="folder for resampling.json/.md, fig_resampling.png")
    p.add_argument("--photons", type=count, default=None, help="photons per run (default 100000; --quick 10000)")
    p.add_argument("--repeats", type=count, default=None, help="independent runs per case (default 4; --quick 3)")
    p.add_argument("--quick", action="store_true", help="one medium, one skin wavelength, few photons (seconds)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu",), default="cpu", help="the comparison runs on the CPU")
    p.add_argument("--threads", type=count, default=1)
    return p


@guarded("python -m training resampling", NOTHING_KEPT)
def main(argv: list[str]) -> int:
    """Run the command; returns the exit status (2 for bad input)."""
    args = build_parser().parse_args(argv)
    check_output_folder(args.out, "--out")
    photons = args.photons or (10_000 if args.quick else 100_000)
    repeats = args.repeats or (3 if args.quick else 4)
    if photons < 10 or repeats < 2:
        print("error: --photons must be >= 10 and --repeats >= 2 (the reference is the other runs)", file=sys.stderr)
        return 2
    torch.set_num_threads(args.threads)
    try:
        s = run(args.out, photons, repeats, args.seed, args.quick)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print("mean RMSR: " + ", ".join(f"{k} {v:.3f}" for k, v in s["mean_rmsr"].items())
          + f" -> {args.out / 'resampling.md'}")
    return 0
