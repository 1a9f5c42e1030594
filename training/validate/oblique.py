"""Oblique light: the two-layer skin against the shipped K-media mixture under a collimated beam at a polar angle.

The paper fits each tone's K homogeneous media to the normal-incidence (cosine-lobe) response and names the angular
dependence of the incident light as its first limitation.  This module measures how large it is.  For each tone and
beam angle theta, the Monte Carlo (``training.sim.compiled_transport.simulate_compiled``, numba, torch-free) walks

* the truth: the two-layer skin (``training.skin.model.layer_optics``: epidermis of thickness t_epi over a
  semi-infinite dermis), and
* the mixture: the K components of the shipped decoder (``skin_decoder.onnx``, ``exporters.inference.run_decoder``)
  each walked as a homogeneous semi-infinite medium, combined with the weights w_k (exact by linearity, as
  ``training.validate.mixture`` combines them),

under the same beam (n = 1.4 below air, smooth Fresnel; the beam travels towards +x, so x-z is the plane of
incidence) at a sparse set of wavelengths in the UV, visible and NIR bands.  Per channel it keeps R_d (specular
excluded: the same Fresnel term for both), the median exit radius about the entry point r50 (the profile's width),
and the median and mean exit x (the profile's shift along the plane of incidence).  Colour (CIE Lab under D65,
Delta E76) comes from the visible samples interpolated onto the 2 nm grid, the same interpolation for both sides.

Each (tone, angle) is one cached walk (``--cache``, one .npz each): an interrupted run resumes where it stopped.

    python -m training.validate.oblique --photons 4000 --out docs/validation
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from exporters.colorimetry import spectrum_to_lab
from exporters.constants import N_TISSUE, R_EDGES_CM, WAVELENGTHS_NM
from training.paths import SHIPPED_MODEL_DIR
from training.validate.mixture import combine

#: Beam angles, degrees from the normal.
THETAS_DEG: tuple[float, ...] = (0.0, 45.0, 70.0, 85.0)
#: Wavelengths walked, nm (on the 2 nm grid): UV [250, 400), visible [400, 700), NIR [700, 1000]
#: (``training.validate.metrics.BANDS``); the visible ones every 20 nm for colour.
SAMPLE_NM: tuple[float, ...] = (300.0, 350.0, 380.0, *np.arange(400.0, 700.0, 20.0).tolist(), 700.0, 750.0, 850.0,
                                950.0)
BANDS: dict[str, tuple[float, float]] = {"UV": (250.0, 400.0), "Vis": (400.0, 700.0), "NIR": (700.0, 1000.1)}
#: Signed edges along the plane of incidence, cm: the radial edges mirrored.
X_EDGES_CM: np.ndarray = np.concatenate([-R_EDGES_CM[:0:-1], R_EDGES_CM])
#: Tones named in the figure (light and dark).
FIGURE_TONES: tuple[str, ...] = ("R01", "R09")
DEFAULT_CACHE = Path("build") / "oblique"


def columns(nm: tuple[float, ...] = SAMPLE_NM) -> np.ndarray:
    """Indices (W,) of ``nm`` on the 2 nm grid."""
    cols = np.searchsorted(WAVELENGTHS_NM, np.asarray(nm))
    if not np.allclose(WAVELENGTHS_NM[cols], nm):
        raise ValueError(f"wavelengths {nm} are not all on the 2 nm grid")
    return cols


def tone_media(tone: np.ndarray, decoder: Path, cols: np.ndarray) -> dict[str, np.ndarray]:
    """The truth's two layers (mua, mus, g (2, W), thickness (2,)) and the mixture's K homogeneous media (mua, mus,
    g (1, K * W), component-major) with their weights (K, W), for one tone (5,) at grid columns ``cols``."""
    from exporters.inference import run_decoder
    from training.skin.model import layer_optics

    o = layer_optics(np.asarray(tone, dtype=np.float64)[None])
    pick = lambda t: t[0].numpy()[cols]  # noqa: E731
    mix = run_decoder(np.asarray(tone)[None], decoder, outputs=["alpha", "sigma_t", "g", "weight"])
    a, s, g, w = (mix[k][0][:, cols] for k in ("alpha", "sigma_t", "g", "weight"))
    w = w / w.sum(axis=0, keepdims=True)
    return {"mua": np.stack([pick(o.mua_epi), pick(o.mua_derm)]), "mus": np.stack([pick(o.mus_epi), pick(o.mus_derm)]),
            "g": np.stack([pick(o.g_epi), pick(o.g_derm)]), "thickness": np.array([float(tone[2]), np.inf]),
            "mix_mua": ((1 - a) * s).reshape(1, -1), "mix_mus": (a * s).reshape(1, -1),
            "mix_g": np.clip(g, -0.99, 0.99).reshape(1, -1), "weight": w}


def _walk(mua, mus, g, thickness, photons: int, theta: float, seed: int) -> dict[str, np.ndarray]:
    from training.sim.compiled_transport import simulate_compiled

    return simulate_compiled(mua, mus, g, thickness, photons, n_medium=N_TISSUE, illumination=f"collimated:{theta:g}",
                             seed=seed, r_edges_cm=R_EDGES_CM, x_edges_cm=X_EDGES_CM)


def walk_tone(tone: np.ndarray, theta: float, decoder: Path, photons: int, seed: int) -> dict[str, np.ndarray]:
    """One (tone, angle): the truth's and the mixture's R_d (W,), stderr, and reflected-light histograms over
    radius and over signed x (W, NB) (weight per photon; the mixture's combined with its weights), and the mean
    exit x (W,) cm."""
    m = tone_media(tone, decoder, columns())
    n_w = m["weight"].shape[1]
    truth = _walk(m["mua"], m["mus"], m["g"], m["thickness"], photons, theta, seed)
    comp = _walk(m["mix_mua"], m["mix_mus"], m["mix_g"], np.array([np.inf]), photons, theta, seed + 1)
    w = m["weight"]
    k = w.shape[0]
    per = lambda v: v.reshape(k, n_w, *v.shape[1:])  # noqa: E731
    out = {}
    for name, res in (("truth", truth), ("mix", None)):
        if res is None:
            r_k = per(comp["R_d"])
            r, se = combine(w, r_k, per(comp["R_d_stderr"]))
            hr = np.einsum("kw,kwb->wb", w, per(comp["profile"]) * (np.pi * np.diff(R_EDGES_CM**2)))
            hx = np.einsum("kw,kwb->wb", w, per(comp["profile_plane"]) * np.diff(X_EDGES_CM))
            xm = np.sum(w * r_k * per(comp["shift_cm"]), axis=0) / np.maximum(r, 1e-300)
        else:
            r, se, xm = res["R_d"], res["R_d_stderr"], res["shift_cm"]
            hr = res["profile"] * (np.pi * np.diff(R_EDGES_CM**2))
            hx = res["profile_plane"] * np.diff(X_EDGES_CM)
        out |= {f"{name}_R": r, f"{name}_R_se": se, f"{name}_hist_r": hr.astype(np.float32),
                f"{name}_hist_x": hx.astype(np.float32), f"{name}_x_mean": xm}
    out |= {"mix_R_k": per(comp["R_d"]), "mix_R_k_se": per(comp["R_d_stderr"]), "weight": w,
            "mix_hist_r_k": (per(comp["profile"]) * (np.pi * np.diff(R_EDGES_CM**2))).astype(np.float32)}
    out["seconds"] = np.array(truth["seconds"] + comp["seconds"])
    return out


def median_of_hist(hist: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The median (..., ) of the distribution binned in ``hist`` (..., NB) over ``edges`` (NB + 1,), linear inside
    its bin (NaN where the histogram is empty)."""
    c = np.cumsum(hist, axis=-1)
    total = c[..., -1:]
    half = 0.5 * total
    i = np.clip((c < half).sum(axis=-1), 0, hist.shape[-1] - 1)
    c_lo = np.take_along_axis(np.concatenate([np.zeros_like(total), c], axis=-1), i[..., None], -1)[..., 0]
    h = np.take_along_axis(hist, i[..., None], -1)[..., 0]
    frac = np.where(h > 0, (half[..., 0] - c_lo) / np.where(h > 0, h, 1.0), 0.5)
    med = edges[i] + frac * (edges[i + 1] - edges[i])
    return np.where(total[..., 0] > 0, med, np.nan)


def lab(r_samples: np.ndarray, nm: tuple[float, ...] = SAMPLE_NM) -> np.ndarray:
    """CIE Lab (D65) of R_d sampled at ``nm`` (..., W), interpolated linearly onto the 2 nm grid."""
    r = np.atleast_2d(r_samples)
    full = np.stack([np.interp(WAVELENGTHS_NM, nm, row) for row in r.reshape(-1, r.shape[-1])])
    return spectrum_to_lab(full.reshape(*r.shape[:-1], -1))


def colour_noise(r: dict[str, np.ndarray], base: dict[str, np.ndarray] | None = None, draws: int = 200,
                 seed: int = 0) -> tuple[float, float | None]:
    """Noise floors of Delta E76 (mixture against truth) and (with the normal-incidence run ``base``) of the angle's
    added Delta E76: their mean when only the Monte Carlo's noise separates the spectra (every R_d spectrum
    redrawn ``draws`` times from normals of its standard errors, the Lab differences taken about each spectrum's
    own colour).  A measured value near its floor is no difference the run can see."""
    rng = np.random.default_rng(seed)

    def noise(run: dict[str, np.ndarray], side: str) -> np.ndarray:
        r_d, se = run[f"{side}_R"], run[f"{side}_R_se"]
        return lab(r_d + rng.standard_normal((draws, r_d.size)) * se) - lab(r_d)

    nt, nm = noise(r, "truth"), noise(r, "mix")
    floor = float(np.mean(np.linalg.norm(nt - nm, axis=-1)))
    if base is None:
        return floor, None
    bt, bm = noise(base, "truth"), noise(base, "mix")
    return floor, float(np.mean(np.linalg.norm((nt - bt) - (nm - bm), axis=-1)))


def r50_noise(hist: np.ndarray, r_d: np.ndarray, se: np.ndarray, draws: int = 100, seed: int = 0) -> np.ndarray:
    """Relative standard deviation (W,) of r50 from the Monte Carlo's noise, approximately: each wavelength's
    histogram (W, NB) redrawn as a multinomial of its effective number of exits (R_d / se)^2."""
    rng = np.random.default_rng(seed)
    out = np.full(hist.shape[0], np.nan)
    for i, (h, r, e) in enumerate(zip(hist, r_d, se, strict=True)):
        if h.sum() <= 0 or e <= 0:
            continue
        n = max(int((r / e) ** 2), 1)
        redraw = rng.multinomial(n, h / h.sum(), size=draws).astype(np.float64)
        med = median_of_hist(redraw, R_EDGES_CM)
        out[i] = np.std(med) / np.mean(med)
    return out


def summarise(runs: dict[tuple[str, float], dict[str, np.ndarray]]) -> list[dict]:
    """Table rows, one per (tone, angle): band means of the relative R_d and r50 errors of the mixture, Delta E76
    (visible) with its noise, and the truth's and mixture's median shift x50 (mm) per band.  With the tone's
    normal-incidence run present, also the part of the error the angle adds: ``dE76_angle``, the Delta E76 between
    the truth's and the mixture's colour change from 0 degrees to theta, and ``{band}_r50_rel_angle``, the change
    of the r50 ratio mixture / truth against 0 degrees."""
    nm = np.asarray(SAMPLE_NM)
    rows = []
    for (name, theta), r in runs.items():
        row = {"tone": name, "theta_deg": theta}
        base = runs.get((name, 0.0))
        r50 = {s: median_of_hist(r[f"{s}_hist_r"].astype(np.float64), R_EDGES_CM) for s in ("truth", "mix")}
        x50 = {s: median_of_hist(r[f"{s}_hist_x"].astype(np.float64), X_EDGES_CM) for s in ("truth", "mix")}
        for band, (lo, hi) in BANDS.items():
            b = (nm >= lo) & (nm < hi)
            rel_se = np.hypot(r["mix_R_se"][b], r["truth_R_se"][b]) / r["truth_R"][b]
            row[f"{band}_R_truth"] = float(np.mean(r["truth_R"][b]))
            row[f"{band}_R_rel"] = float(np.mean(r["mix_R"][b] / r["truth_R"][b] - 1))
            row[f"{band}_R_rel_se"] = float(np.sqrt(np.sum(rel_se**2)) / b.sum())
            row[f"{band}_r50_truth_mm"] = float(np.nanmean(r50["truth"][b]) * 10)
            row[f"{band}_r50_rel"] = float(np.nanmean(r50["mix"][b] / r50["truth"][b] - 1))
            var = sum(r50_noise(r[f"{s}_hist_r"][b].astype(np.float64), r[f"{s}_R"][b], r[f"{s}_R_se"][b]) ** 2
                      for s in ("truth", "mix"))
            row[f"{band}_r50_rel_noise"] = float(np.sqrt(np.nansum(var)) / b.sum())
            if base is not None:
                b50 = {s: median_of_hist(base[f"{s}_hist_r"].astype(np.float64), R_EDGES_CM) for s in ("truth", "mix")}
                ratio = (r50["mix"][b] / r50["truth"][b]) / (b50["mix"][b] / b50["truth"][b])
                row[f"{band}_r50_rel_angle"] = float(np.nanmean(ratio - 1))
            row[f"{band}_x50_truth_mm"] = float(np.nanmean(x50["truth"][b]) * 10)
            row[f"{band}_x50_mix_mm"] = float(np.nanmean(x50["mix"][b]) * 10)
            row[f"{band}_xmean_truth_mm"] = float(np.mean(r["truth_x_mean"][b]) * 10)
            row[f"{band}_xmean_mix_mm"] = float(np.mean(r["mix_x_mean"][b]) * 10)
        lt, lm = lab(r["truth_R"])[0], lab(r["mix_R"])[0]
        row["dE76"] = float(np.linalg.norm(lt - lm))
        row["dE76_floor"], row["dE76_angle_floor"] = colour_noise(r, base if theta != 0.0 else None)
        row["L_truth"] = float(lt[0])
        row["dE76_truth_vs_normal"] = row["dE76_angle"] = None
        if base is not None:
            bt, bm = lab(base["truth_R"])[0], lab(base["mix_R"])[0]
            row["dE76_truth_vs_normal"] = float(np.linalg.norm(lt - bt))
            row["dE76_angle"] = float(np.linalg.norm((lt - bt) - (lm - bm)))
        rows.append(row)
    return rows


def run(tones, decoder: Path, photons: int, cache: Path, seed: int = 0,
        thetas: tuple[float, ...] = THETAS_DEG, log=print,
        need: str | None = None) -> dict[tuple[str, float], dict[str, np.ndarray]]:
    """Walk every (tone, angle) not yet in ``cache`` (one ``{tone}_{theta}_{photons}.npz`` each) and return all;
    ``need``: a field a cached walk must hold (walks cached before it was kept are walked again, the same
    packets: the walk is deterministic)."""
    cache.mkdir(parents=True, exist_ok=True)
    runs = {}
    for name, tone in zip(tones.names, tones.values, strict=True):
        for theta in thetas:
            path = cache / f"{name}_{theta:g}_{photons}_s{seed}.npz"
            if path.is_file() and need is not None:
                with np.load(path) as f:
                    if need not in f.files:
                        path.unlink()
            if not path.is_file():
                t0 = time.perf_counter()
                res = walk_tone(tone, theta, decoder, photons, seed)
                tmp = path.with_suffix(".part.npz")
                np.savez_compressed(tmp, **res)
                tmp.replace(path)
                log(f"{name} theta {theta:g}: {time.perf_counter() - t0:.0f} s")
            with np.load(path) as f:
                runs[(name, theta)] = {k: f[k] for k in f.files}
    return runs


def reweighted(r: dict[str, np.ndarray]) -> np.ndarray:
    """Weights (K, W) closest to the shipped ones (least squares, summing to 1) whose mixture R_d equals the
    truth's at each wavelength, clipped to >= 0 and renormalised: what an angle-dependent choice of the component
    weights could reach at this angle, components unchanged."""
    w, r_k = r["weight"], r["mix_R_k"]
    d = r_k - r_k.mean(axis=0)
    c = (r["truth_R"] - np.sum(w * r_k, axis=0)) / np.maximum(np.sum(d * d, axis=0), 1e-300)
    w2 = np.clip(w + c * d, 0.0, None)
    return w2 / w2.sum(axis=0)


def remedy_rows(runs: dict[tuple[str, float], dict[str, np.ndarray]]) -> list[dict]:
    """Per (tone, angle) with components kept: Delta E76 and the visible / NIR r50 error of the mixture with its
    shipped weights and with ``reweighted`` weights."""
    nm = np.asarray(SAMPLE_NM)
    rows = []
    for (name, theta), r in runs.items():
        if "mix_R_k" not in r:
            continue
        w2 = reweighted(r)
        lt = lab(r["truth_R"])[0]
        r50_t = median_of_hist(r["truth_hist_r"].astype(np.float64), R_EDGES_CM)
        row = {"tone": name, "theta_deg": theta}
        for tag, w in (("shipped", r["weight"]), ("reweighted", w2)):
            hist = np.einsum("kw,kwb->wb", w, r["mix_hist_r_k"].astype(np.float64))
            rel = median_of_hist(hist, R_EDGES_CM) / r50_t - 1
            row[f"dE76_{tag}"] = float(np.linalg.norm(lab(np.sum(w * r["mix_R_k"], axis=0))[0] - lt))
            for band in ("Vis", "NIR"):
                lo, hi = BANDS[band]
                row[f"{band}_r50_rel_{tag}"] = float(np.nanmean(rel[(nm >= lo) & (nm < hi)]))
        row["weight_change"] = float(np.abs(w2 - r["weight"]).sum(axis=0).max() / 2)
        rows.append(row)
    return rows


def markdown(rows: list[dict]) -> str:
    """The table of docs/validation/oblique.md."""
    head = ("| tone | θ | ΔE76 mix vs truth (noise floor) | ΔE76 added by the angle (noise floor) | truth's own "
            "colour shift from 0° "
            "| R_d mix/truth − 1: UV / Vis / NIR | r50 mix/truth − 1: UV / Vis / NIR | r50 ratio change from 0°: "
            "UV / Vis / NIR | x50 truth / mix, mm: Vis | x50 truth / mix, mm: NIR |\n"
            "|---|---|---|---|---|---|---|---|---|---|\n")
    pct = lambda v: f"{100 * v:+.1f} %"  # noqa: E731
    opt = lambda v, f: "—" if v is None else f.format(v)  # noqa: E731
    lines = []
    for r in rows:
        lines.append(
            f"| {r['tone']} | {r['theta_deg']:g}° | {r['dE76']:.2f} ({r['dE76_floor']:.2f}) | "
            + ("—" if not r["theta_deg"] or r["dE76_angle"] is None else
               f"{r['dE76_angle']:.2f} ({r['dE76_angle_floor']:.2f})") + " | "
            f"{opt(r['dE76_truth_vs_normal'], '{:.2f}')} | "
            + " / ".join(pct(r[f"{b}_R_rel"]) for b in BANDS) + " | "
            + " / ".join(f"{pct(r[f'{b}_r50_rel'])} (±{100 * r[f'{b}_r50_rel_noise']:.1f})" for b in BANDS) + " | "
            + " / ".join(pct(r[f"{b}_r50_rel_angle"]) if f"{b}_r50_rel_angle" in r else "—" for b in BANDS) + " | "
            + f"{r['Vis_x50_truth_mm']:.3f} / {r['Vis_x50_mix_mm']:.3f} | "
            + f"{r['NIR_x50_truth_mm']:.3f} / {r['NIR_x50_mix_mm']:.3f} |")
    return head + "\n".join(lines) + "\n"


def remedy_markdown(rows: list[dict]) -> str:
    """The remedy table of docs/validation/oblique.md."""
    head = ("| tone | θ | ΔE76 shipped → reweighted | r50 mix/truth − 1, Vis: shipped → reweighted | "
            "NIR: shipped → reweighted | largest weight moved |\n|---|---|---|---|---|---|\n")
    pct = lambda v: f"{100 * v:+.1f} %"  # noqa: E731
    return head + "\n".join(
        f"| {r['tone']} | {r['theta_deg']:g}° | {r['dE76_shipped']:.2f} → {r['dE76_reweighted']:.2f} | "
        f"{pct(r['Vis_r50_rel_shipped'])} → {pct(r['Vis_r50_rel_reweighted'])} | "
        f"{pct(r['NIR_r50_rel_shipped'])} → {pct(r['NIR_r50_rel_reweighted'])} | {r['weight_change']:.2f} |"
        for r in rows) + "\n"


def plot(runs: dict, rows: list[dict], path: Path) -> None:
    """Figure: Delta E76, the angle's added Delta E76 and the visible r50 error against the angle per tone; the
    plane-of-incidence profiles of a light and a dark tone (``FIGURE_TONES``) at 560 nm for each angle (truth
    solid, mixture dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 5, figsize=(22, 4.2))
    names = sorted({r["tone"] for r in rows})
    for name in names:
        rr = [r for r in rows if r["tone"] == name]
        th = [r["theta_deg"] for r in rr]
        ax[0].plot(th, [r["dE76"] for r in rr], "o-", label=name)
        ax[1].plot(th, [r["dE76_angle"] or 0.0 for r in rr], "o-", label=name)
        ax[2].plot(th, [100 * r["Vis_r50_rel"] for r in rr], "o-", label=name)
    ax[0].set(xlabel="beam angle θ (°)", ylabel="ΔE76 mixture vs two-layer (visible)")
    ax[1].set(xlabel="beam angle θ (°)", ylabel="ΔE76 of the colour change from 0°")
    ax[2].set(xlabel="beam angle θ (°)", ylabel="r50 mixture / truth − 1 (%), visible")
    for a in ax[:2]:
        a.axhline(1.0, color="grey", lw=0.8, ls=":")
    ax[2].axhline(10.0, color="grey", lw=0.8, ls=":")
    ax[2].axhline(-10.0, color="grey", lw=0.8, ls=":")
    ax[0].legend(fontsize=7, ncol=2)
    col = int(np.argmin(np.abs(np.asarray(SAMPLE_NM) - 560.0)))
    centres = 0.5 * (X_EDGES_CM[1:] + X_EDGES_CM[:-1]) * 10
    coarse = np.linspace(-1.0, 1.5, 51)
    shown = [n for n in FIGURE_TONES if n in names] or names[:1]
    for a, name in zip(ax[3:], (shown[0], shown[-1]), strict=True):
        for theta, colour in zip(THETAS_DEG, ("k", "C0", "C1", "C3"), strict=True):
            if (name, theta) not in runs:
                continue
            for side, ls in (("truth", "-"), ("mix", "--")):
                h = runs[(name, theta)][f"{side}_hist_x"][col].astype(np.float64)
                binned = np.histogram(centres, bins=coarse, weights=h)[0] / np.diff(coarse)
                a.plot(0.5 * (coarse[1:] + coarse[:-1]), binned, ls=ls, color=colour,
                       label=f"{theta:g}° {'truth' if side == 'truth' else 'mixture'}")
        a.set(xlabel="exit x along the plane of incidence (mm)", ylabel="R_d per mm (560 nm)",
              title=f"{name}: profile in the plane of incidence", yscale="log")
        a.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m training.validate.oblique", description=__doc__.splitlines()[0])
    p.add_argument("--photons", type=int, default=4000, help="photons per wavelength (and per mixture component)")
    p.add_argument("--tones", default="representative", help="tone kind of training/skin/tones.csv, or names a,b,c")
    p.add_argument("--model-dir", type=Path, default=SHIPPED_MODEL_DIR, help="folder with skin_decoder.onnx")
    p.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="folder of the per-(tone, angle) walks")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=None, help="folder for oblique.json and fig_oblique.png")
    p.add_argument("--remedy", action="store_true",
                   help="keep the components' own tallies (walking cached runs without them again) and add what "
                   "angle-dependent component weights could reach")
    args = p.parse_args(argv)
    from training.skin.tones import load_tones

    try:
        if args.photons < 100:
            raise ValueError("--photons must be >= 100")
        tones = load_tones()
        if "," in args.tones or args.tones not in set(tones.kinds):
            want = args.tones.split(",")
            keep = [tones.names.index(n) for n in want if n in tones.names]
            if len(keep) != len(want):
                raise ValueError(f"--tones: unknown tone in {args.tones!r}")
            tones = type(tones)(tuple(tones.names[i] for i in keep), tuple(tones.kinds[i] for i in keep),
                                tones.values[keep], tuple(tones.descriptions[i] for i in keep))
        else:
            tones = tones.select(args.tones)
        runs = run(tones, args.model_dir / "skin_decoder.onnx", args.photons, args.cache, args.seed,
                   log=lambda s: print(s, file=sys.stderr, flush=True), need="mix_R_k" if args.remedy else None)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rows = summarise(runs)
    remedy = remedy_rows(runs)
    print(markdown(rows))
    if remedy:
        print(remedy_markdown(remedy))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        result = {"photons": args.photons, "seed": args.seed, "wavelengths_nm": list(SAMPLE_NM),
                  "thetas_deg": list(THETAS_DEG),
                  "walk_wall_seconds": float(sum(float(r["seconds"]) for r in runs.values())),
                  "rows": rows, "remedy_rows": remedy}
        (args.out / "oblique.json").write_text(json.dumps(result, indent=1))
        plot(runs, rows, args.out / "fig_oblique.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
