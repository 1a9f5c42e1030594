"""Benchmarks of the dataset estimators (collected by ``python -m training bench``).

Direct: one absorbing Monte Carlo run per tone.  Reweighted: one baseline walk per split, shared by every
tone of the split, then a reweighting per tone.  Both at the same photons per wavelength on the same
tones; "equal noise" scales the reweighted cost by the measured variance ratio (reweighted / direct
squared standard errors, mean over wavelengths and tones), so the ratio compares the cost of the same
noise.  One torch thread (= one core), uncompiled walks, all 376 wavelengths.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from exporters.colorimetry import SRGB_LUMINANCE, delta_e76, spectrum_to_lab
from exporters.constants import WAVELENGTHS_NM
from training.data.presets import PRESETS
from training.data.reweight import baseline_absorption, reweight, walk
from training.data.sampling import training_tones
from training.sim.tissue import skin_medium
from training.sim.transport import simulate


def _rows(photons: int, n_reweight: int) -> list[dict]:
    tones = training_tones(64, seed=7)[[0, 5, 21, 40]]  # four Halton tones: a spread of melanin and blood
    t0 = time.perf_counter()
    direct = [simulate(skin_medium(t), photons, seed=50 + i) for i, t in enumerate(tones)]
    t_direct = (time.perf_counter() - t0) / len(tones)  # s per tone
    t0 = time.perf_counter()
    traj = walk(photons, seed=3, mua0=baseline_absorption())
    t_walk = time.perf_counter() - t0
    many = training_tones(n_reweight, seed=9)
    t0 = time.perf_counter()
    reweight(traj, many)
    t_rw = (time.perf_counter() - t0) / n_reweight  # s per tone
    rw = reweight(traj, tones)
    d_se = np.stack([d.R_d_stderr for d in direct])
    ok = d_se > 0
    var_ratio = float(np.mean((rw["R_d_stderr"][ok] / d_se[ok]) ** 2))
    de = delta_e76(spectrum_to_lab(rw["R_d"]), spectrum_to_lab(np.stack([d.R_d for d in direct])))
    n_w = 376
    rows = []
    for preset in ("laptop", "paper"):
        p = PRESETS[preset]
        n_tones = p.n_train + p.n_validation
        scale = p.photons / photons
        t_rw_total = 2 * t_walk * scale + n_tones * t_rw * scale  # two walks (train, validation)
        t_direct_total = n_tones * t_direct * scale
        rate_rw = n_tones * n_w / t_rw_total
        rate_direct = n_tones * n_w / t_direct_total
        rows.append({
            "workload": f"dataset `{preset}` ({p.n_train:,} + {p.n_validation:,} tones x 376 wavelengths, "
            f"{p.photons:,} photons), 1 core, projected",
            "ours": f"reweighted {rate_rw:,.0f} tone-wavelengths/s: {t_rw_total / 3600:.2f} h",
            "anchor": f"direct {rate_direct:,.2f} tone-wavelengths/s: {t_direct_total / 3600:,.0f} h",
            "ratio": f"{t_direct_total / t_rw_total:,.0f}x at equal photons, "
            f"{t_direct_total / (t_rw_total * var_ratio):,.0f}x at equal noise",
            "error": f"variance ratio {var_ratio:.2f} (mean over 4 tones x 376 wavelengths); "
            f"dE76 reweighted vs direct at {photons} photons: {', '.join(f'{v:.2f}' for v in de)} (noise)",
            "notes": f"measured at {photons} photons: direct {t_direct:.1f} s per tone, walk {t_walk:.0f} s per "
            f"split, reweighting {t_rw * 1e3:.1f} ms per tone ({n_reweight} tones); linear in photons",
        })
    return rows


def colour_agreement(photons: int, n_tones: int = 3) -> dict:
    """dE76 (D65) between the two estimators at equal photons on ``n_tones`` Halton tones.

    Only the wavelengths the colour integral sees (360-830 nm) are walked; both estimators' noise is in
    the difference (no error propagation: the photon count must make it small).
    """
    vis = np.flatnonzero((np.array(WAVELENGTHS_NM) >= 360) & (np.array(WAVELENGTHS_NM) <= 830))
    tones = training_tones(64, seed=7)[[0, 5, 21, 40, 50][:n_tones]]
    traj = walk(photons, seed=5, mua0=baseline_absorption(), channels=vis, compile=True)
    rw = reweight(traj, tones)
    out = []
    for i, t in enumerate(tones):
        d = simulate(skin_medium(t).select_channels(vis), photons, seed=70 + i, compile=True, r_edges_cm=None)
        specs = []
        for r in (rw["R_d"][i], d.R_d):
            spec = np.zeros(len(WAVELENGTHS_NM))
            spec[vis] = r
            specs.append(spec)
        out.append(float(delta_e76(spectrum_to_lab(specs[0]), spectrum_to_lab(specs[1]))))
    return {"photons": photons, "tones": tones.tolist(), "delta_e76": out, "walk_s": traj.seconds}


def equivalent_photons(dataset: Path, photons: int = 3000, n_tones: int = 6, split: str = "train") -> dict:
    """Direct-simulation photons that give the noise of a built dataset's R_d, on ``n_tones`` of its tones
    (the darkest, the lightest and luminance quantiles between): per tone and wavelength
    N_eq = photons * (se_direct / se_dataset)^2 with a direct run of ``photons``.  Returns the tones,
    the mean variance ratio (dataset photons / N_eq, mean over tones and wavelengths, as in the rows
    above), the equivalent photons of that mean, and per tone the median N_eq over wavelengths and the
    share of wavelengths with N_eq below the dataset's photons."""
    import h5py

    with h5py.File(Path(dataset) / f"{split}.h5", "r") as f:
        rgb, n_data = f["albedo_rgb"][:], int(f.attrs["photons"])
        lum = rgb @ SRGB_LUMINANCE
        order = np.argsort(lum)
        rows = np.sort(order[np.round(np.linspace(0, len(order) - 1, n_tones)).astype(int)])
        tones, se_data = f["tone"][:][rows], f["R_d_stderr"][:][rows]
    se_direct = np.stack([simulate(skin_medium(t), photons, seed=90 + i, compile=True, r_edges_cm=None).R_d_stderr
                          for i, t in enumerate(tones)])
    ok = (se_direct > 0) & (se_data > 0)
    n_eq = np.where(ok, photons * (se_direct / np.where(ok, se_data, 1.0)) ** 2, np.nan)
    ratio = float(np.nanmean(n_data / n_eq))
    return {"dataset": str(dataset), "split": split, "dataset_photons": n_data, "direct_photons": photons,
            "rows": rows.tolist(), "luminance": lum[rows].tolist(), "mean_variance_ratio": ratio,
            "equivalent_photons_of_mean": n_data / ratio,
            "median_n_eq_per_tone": np.nanmedian(n_eq, axis=1).tolist(),
            "share_below_dataset_photons": np.nanmean(n_eq < n_data, axis=1).tolist()}


def preset_variance_ratio(preset: str = "paper", n_tones: int = 12, photons: int = 2_000) -> dict:
    """The R_d variance ratio (reweighted / direct squared standard errors) on the first ``n_tones`` training
    tones of ``preset``: one baseline walk of ``photons`` reweighted to them, against a direct run of each at
    ``photons``.  Per tone its mean, median and largest ratio over the wavelengths, and the mean over tones and
    wavelengths, by which a preset's walked photons are set (``training.data.presets``)."""
    p = PRESETS[preset]
    tones = training_tones(p.n_train, seed=p.train_seed)[:n_tones]
    rw = reweight(walk(photons, seed=5, mua0=baseline_absorption()), tones)
    per_tone = []
    for i, t in enumerate(tones):
        se = simulate(skin_medium(t), photons, seed=100 + i, compile=True, r_edges_cm=None).R_d_stderr
        ok = (se > 0) & (rw["R_d_stderr"][i] > 0)
        ratio = (rw["R_d_stderr"][i][ok] / se[ok]) ** 2
        per_tone.append({"tone": t.tolist(), "mean": float(ratio.mean()), "median": float(np.median(ratio)),
                         "max": float(ratio.max())})
    return {"preset": preset, "photons": photons, "tones": per_tone,
            "mean_variance_ratio": float(np.mean([t["mean"] for t in per_tone]))}


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md (see the module docstring)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        rows = _rows(300 if quick else 3000, 128 if quick else 512)
        if not quick:
            c = colour_agreement(30_000)
            rows.append({
                "workload": f"colour agreement, reweighted vs direct, {c['photons']:,} photons each, 360-830 nm",
                "ours": "dE76 " + ", ".join(f"{v:.2f}" for v in c["delta_e76"]),
                "anchor": "goal dE76 < 0.3", "ratio": "",
                "error": "both estimators' noise included", "notes": "3 Halton tones; compiled walks",
            })
        return rows
    finally:
        torch.set_num_threads(before)


if __name__ == "__main__":
    import json
    import sys

    torch.set_num_threads(1)
    if len(sys.argv) > 2 and sys.argv[1] == "--colour":  # python -m training.bench.data --colour PHOTONS
        print(json.dumps(colour_agreement(int(sys.argv[2]))))
    elif len(sys.argv) > 2 and sys.argv[1] == "--equivalent":  # ... --equivalent DATASET_DIR [PHOTONS]
        print(json.dumps(equivalent_photons(Path(sys.argv[2]), *map(int, sys.argv[3:4])), indent=1))
    elif len(sys.argv) > 1 and sys.argv[1] == "--variance-ratio":  # ... --variance-ratio [PRESET [TONES [PHOTONS]]]
        args = sys.argv[2:]
        print(json.dumps(preset_variance_ratio(*args[:1], *map(int, args[1:3])), indent=1))
    else:
        for row in benchmarks(quick=True):
            print(row)
