"""The grazing-light correction (exporters.oblique_correction) fitted to the oblique Monte Carlo, and its effect.

The walks are those of ``training.validate.oblique`` (its cache: the truth and the shipped mixture per tone and
beam angle).  Per tone, in linear sRGB (D65) as a renderer's channels: the weight factor that brings the mixture's
reflectance to the truth's, q_c = RGB_truth / RGB_mix, and the radius factor that brings its profile's width to the
truth's, the mean of r50_truth / r50_mix over the channel's wavelengths (``CHANNEL_NM``).  Each is fitted by least
squares over the oblique angles as 1 + slope x h(mu), h(mu) = smoothstep(e0, e1, 1 - mu) (the ramp shared by every
tone, the best on a grid), so that normal incidence is untouched; the slopes are kept per tone, at the tone's
luminance.

The effect is measured as the table of docs/validation/oblique.md measures the mixture: Delta E76 of the corrected
mixture's colour (its linear sRGB times f_c) against the truth's, and the visible r50 error (each wavelength's r50
times s_c of its channel).  ``--check-seed`` measures the correction fitted on one seed on walks of another.

    python -m training.validate.oblique_fit --out exporters/data/oblique_correction.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from exporters import oblique_correction as oc
from exporters.colorimetry import linear_srgb_to_lab, spectrum_to_linear_srgb
from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.paths import SHIPPED_MODEL_DIR
from training.validate import oblique

#: Wavelength ranges (nm) whose r50 stand for the renderer's channels R, G, B.
CHANNEL_NM: tuple[tuple[float, float], ...] = ((590.0, 700.0), (490.0, 590.0), (400.0, 490.0))
#: Ramps (e0, e1) of h(mu) = smoothstep(e0, e1, 1 - mu) tried (1 - mu: 0.29 at 45 degrees, 0.66 at 70, 0.91 at 85).
RAMPS: tuple[tuple[float, float], ...] = tuple((e0, e1) for e0 in np.arange(0.0, 0.75, 0.05).round(2)
                                               for e1 in np.arange(0.2, 1.01, 0.05).round(2) if e1 >= e0 + 0.1)
#: Tones whose width (r50, mean of the channels) is off by more than this at normal incidence do not choose the
#: radius ramp: their width error is the K-media fit's, not the angle's (their slopes are fitted all the same).
NORMAL_WIDTH_OFF = 0.2
#: Smallest radius slope (s stays >= 1 + this at grazing: positive).
RADIUS_SLOPE_MIN = -0.8


def cached_runs(cache: Path, names, thetas, photons: int = 10000, seed: int = 0) -> dict:
    """The walks of ``names`` x ``thetas`` already in ``cache`` ((tone, theta) -> walk); the others are left out."""
    out = {}
    for n in names:
        for t in thetas:
            path = cache / f"{n}_{t:g}_{photons}_s{seed}.npz"
            if path.is_file():
                with np.load(path) as f:
                    out[(n, float(t))] = {k: f[k] for k in f.files}
    return out


def bodies(render: dict) -> dict[tuple[str, float], dict[str, np.ndarray]]:
    """(tone, view angle) -> the block's rendered body reflectance (render less coat: training.oblique_render.slab),
    per variant rendered ("shipped", "corrected")."""
    coat = np.asarray(render["coat"])
    out = {}
    for name, r in render.items():
        if not isinstance(r, dict):
            continue
        for i, theta in enumerate(render["views_deg"]):
            out[(name, float(theta))] = {k: np.asarray(r[k])[i] - coat[i] for k in ("shipped", "corrected") if k in r}
    return out


def tone_colours(tones, decoder: Path) -> np.ndarray:
    """Painted colours (N, 3) of ``tones``: the decoder's reflectance in linear sRGB under D65, clamped to [0, 1]."""
    from exporters.inference import run_decoder

    refl = run_decoder(tones.values, decoder, ["reflectance"])["reflectance"]
    return np.clip(spectrum_to_linear_srgb(refl), 0.0, 1.0)


def rgb(r_samples: np.ndarray) -> np.ndarray:
    """Linear sRGB (D65) (3,) of R_d sampled at ``oblique.SAMPLE_NM``, interpolated on the 2 nm grid (as
    ``oblique.lab``)."""
    return spectrum_to_linear_srgb(np.interp(WAVELENGTHS_NM, oblique.SAMPLE_NM, r_samples))


def channel_of_samples() -> np.ndarray:
    """Channel index (W,) of each walked wavelength (0 R, 1 G, 2 B; -1 outside the visible)."""
    nm = np.asarray(oblique.SAMPLE_NM)
    out = np.full(nm.size, -1)
    for c, (lo, hi) in enumerate(CHANNEL_NM):
        out[(nm >= lo) & (nm < hi)] = c
    return out


def r50_ratio(r: dict[str, np.ndarray]) -> np.ndarray:
    """r50 of the truth over r50 of the mixture (W,) of one walk."""
    t = oblique.median_of_hist(r["truth_hist_r"].astype(np.float64), R_EDGES_CM)
    m = oblique.median_of_hist(r["mix_hist_r"].astype(np.float64), R_EDGES_CM)
    return t / m


def targets(r: dict[str, np.ndarray], body: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weight and radius factors (3,) that make the mixture's channels match the truth's in one walk: the weights
    bring ``body`` (the live group's rendered body colour at that angle; None: the walked mixture's colour) to the
    truth's colour, the radii the mixture's r50 to the truth's."""
    ratio = r50_ratio(r)
    ch = channel_of_samples()
    base = rgb(r["mix_R"]) if body is None else body
    return rgb(r["truth_R"]) / base, np.array([np.nanmean(ratio[ch == c]) for c in range(3)])


def _slopes(h: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Least-squares slopes (3,) of target - 1 (A, 3) on h (A,)."""
    return (h @ (target - 1.0)) / max(float(h @ h), 1e-300)


def fit(runs: dict, names: list[str], colours: np.ndarray, rendered: dict | None = None) -> oc.ObliqueCorrection:
    """The correction fitted to ``runs`` ((tone, theta) -> walk) of the tones ``names`` with painted ``colours``.
    Per tone, the slopes are least squares over its oblique angles walked (theta > 0); the ramps shared by the
    tones are the grid's best: the weights' by the summed Delta E76 of the corrected colours against the truth's
    (what the weights are for), the radii's by the summed squared relative r50 errors of the tones whose width is
    right at normal incidence (within ``NORMAL_WIDTH_OFF``)."""
    per_tone = {}
    for n in names:
        thetas = sorted(t for (m, t) in runs if m == n and t > 0.0 and (rendered is None or (n, t) in rendered))
        walks = [runs[(n, t)] for t in thetas]
        base = [_base(runs[(n, t)], rendered, (n, t)) for t in thetas]
        per_tone[n] = {"mu": np.cos(np.radians(thetas)),
                       "q": np.array([targets(r, b) for r, b in zip(walks, base, strict=True)]),  # (A, 2, 3)
                       "mix": np.array(base), "lab": linear_srgb_to_lab(np.array([rgb(r["truth_R"]) for r in walks]))}

    def slopes(t: dict, ramp, which: int) -> np.ndarray:
        return _slopes(oc.angle_shape(t["mu"], ramp), t["q"][:, which])

    def colour_error(ramp) -> float:
        total = 0.0
        for t in per_tone.values():
            f = 1 + np.outer(oc.angle_shape(t["mu"], ramp), slopes(t, ramp, 0))
            total += float(np.sum(np.linalg.norm(linear_srgb_to_lab(t["mix"] * f) - t["lab"], axis=-1)))
        return total

    def width_error(ramp) -> float:
        return sum(float(np.sum((1 + np.outer(oc.angle_shape(t["mu"], ramp), slopes(t, ramp, 1)) - t["q"][:, 1]) ** 2
                                / t["q"][:, 1] ** 2)) for n, t in per_tone.items() if n not in off_at_normal)

    off_at_normal = {n for n in names if (n, 0.0) in runs and abs(np.mean(targets(runs[(n, 0.0)])[1]) - 1.0)
                     > NORMAL_WIDTH_OFF}

    ramp_w, ramp_r = min(RAMPS, key=colour_error), min(RAMPS, key=width_error)
    a = np.array([slopes(per_tone[n], ramp_w, 0) for n in names])
    b = np.array([slopes(per_tone[n], ramp_r, 1) for n in names])
    y = np.clip(colours, 0.0, 1.0) @ oc.SRGB_LUMINANCE
    order = np.argsort(y)
    walked = sorted({t for (_, t) in runs if t > 0.0})
    src = (f"training.validate.oblique_fit on {len(names)} tones ({', '.join(names)}) at "
           f"{', '.join(f'{t:g}' for t in walked)} degrees; the weights bring "
           + ("the live group's Cycles render (block under a white world, training.oblique_render)"
              if rendered is not None else "the walked mixture")
           + " to the two-layer truth, the radii the mixture's r50")
    return oc.ObliqueCorrection(y[order], a[order], np.maximum(b[order], RADIUS_SLOPE_MIN), ramp_w, ramp_r, src)


def _base(walk: dict, rendered: dict | None, key: tuple[str, float]) -> np.ndarray:
    """The colour the weights act on: the rendered body's (``rendered[key]``) or the walked mixture's."""
    return rgb(walk["mix_R"]) if rendered is None else rendered[key]


def evaluate(runs: dict, names: list[str], colours: np.ndarray, corr: oc.ObliqueCorrection,
             rendered: dict | None = None) -> list[dict]:
    """Per (tone, theta): Delta E76 and visible / NIR r50 error of the mixture as shipped and corrected (the colour:
    of the rendered body times f where ``rendered`` holds it, else of the walked mixture times f)."""
    nm = np.asarray(oblique.SAMPLE_NM)
    vis = (nm >= 400.0) & (nm < 700.0)
    nir = nm >= 700.0
    ch = channel_of_samples()
    rows = []
    for n, colour in zip(names, colours, strict=True):
        for theta in sorted(t for (m, t) in runs if m == n and (rendered is None or (n, t) in rendered)):
            r = runs[(n, theta)]
            f, s = oc.factors(corr, colour, np.cos(np.radians(theta)))
            lab_t = linear_srgb_to_lab(rgb(r["truth_R"]))
            mix = _base(r, rendered, (n, theta))
            rel = 1.0 / r50_ratio(r)
            rel_corr = rel * np.where(ch >= 0, s[np.maximum(ch, 0)], 1.0)
            rows.append({"tone": n, "theta_deg": theta,
                         "dE76_shipped": float(np.linalg.norm(linear_srgb_to_lab(mix) - lab_t)),
                         "dE76_corrected": float(np.linalg.norm(linear_srgb_to_lab(mix * f) - lab_t)),
                         "Vis_r50_rel_shipped": float(np.nanmean(rel[vis]) - 1),
                         "Vis_r50_rel_corrected": float(np.nanmean(rel_corr[vis]) - 1),
                         "NIR_r50_rel": float(np.nanmean(rel[nir]) - 1),
                         "weight_factor": f.tolist(), "radius_factor": s.tolist()})
    return rows


def markdown(rows: list[dict]) -> str:
    """The correction's table of docs/validation/oblique.md."""
    pct = lambda v: f"{100 * v:+.1f} %"  # noqa: E731
    head = ("| tone | θ | ΔE76 shipped → corrected | r50 mix/truth − 1, Vis: shipped → corrected | "
            "weight factor R / G / B | radius factor R / G / B |\n|---|---|---|---|---|---|\n")
    return head + "\n".join(
        f"| {r['tone']} | {r['theta_deg']:g}° | {r['dE76_shipped']:.2f} → {r['dE76_corrected']:.2f} | "
        f"{pct(r['Vis_r50_rel_shipped'])} → {pct(r['Vis_r50_rel_corrected'])} | "
        + " / ".join(f"{v:.3f}" for v in r["weight_factor"]) + " | "
        + " / ".join(f"{v:.3f}" for v in r["radius_factor"]) + " |" for r in rows) + "\n"


def _tones(spec: str):
    from training.skin.tones import load_tones

    tones = load_tones()
    want = spec.split(",")
    keep = [tones.names.index(n) for n in want if n in tones.names]
    if len(keep) != len(want):
        raise ValueError(f"--tones: unknown tone in {spec!r}")
    return type(tones)(tuple(tones.names[i] for i in keep), tuple(tones.kinds[i] for i in keep),
                       tones.values[keep], tuple(tones.descriptions[i] for i in keep))


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m training.validate.oblique_fit", description=__doc__.splitlines()[0])
    p.add_argument("--photons", type=int, default=10000, help="photons of the cached walks")
    p.add_argument("--tones", default=",".join(f"R{i:02d}" for i in range(1, 11)), help="tone names a,b,c")
    p.add_argument("--seed", type=int, default=0, help="seed of the walks fitted")
    p.add_argument("--check-seed", type=int, default=None, help="also measure on the walks of this seed")
    p.add_argument("--check-tones", default="R01,R07,R08,R09", help="tones walked with --check-seed")
    p.add_argument("--extra-thetas", default="30,55,60,65,75,80",
                   help="more beam angles (degrees) walked for --extra-tones, for the correction's angular shape")
    p.add_argument("--extra-tones", default="R07,R08,R09,R10")
    p.add_argument("--cache", type=Path, default=oblique.DEFAULT_CACHE)
    p.add_argument("--model-dir", type=Path, default=SHIPPED_MODEL_DIR, help="folder with skin_decoder.onnx")
    p.add_argument("--out", type=Path, default=None, help="write the fitted correction here (JSON)")
    p.add_argument("--render", type=Path, default=None,
                   help="fit the weights to the live group's rendered body colour in this JSON of "
                   "training.oblique_render --shipped-only (default: to the walked mixture's colour)")
    args = p.parse_args(argv)
    decoder = args.model_dir / "skin_decoder.onnx"
    log = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    try:
        tones = _tones(args.tones)
        runs = oblique.run(tones, decoder, args.photons, args.cache, args.seed, log=log, need="mix_R_k")
        if args.extra_thetas:
            extra = tuple(float(t) for t in args.extra_thetas.split(","))
            runs |= oblique.run(_tones(args.extra_tones), decoder, args.photons, args.cache, args.seed, extra, log)
        colours = tone_colours(tones, decoder)
        rendered = None
        if args.render is not None:
            rendered = {k: v["shipped"] for k, v in bodies(json.loads(args.render.read_text())["render"]).items()}
        corr = fit(runs, list(tones.names), colours, rendered)
        rows = evaluate(runs, list(tones.names), colours, corr, rendered)
        print(f"weight ramp {corr.weight_ramp}, radius ramp {corr.radius_ramp}\n")
        print(markdown(rows))
        if args.check_seed is not None:
            check = _tones(args.check_tones)
            held = oblique.run(check, decoder, args.photons, args.cache, args.check_seed, log=log)
            print(f"seed {args.check_seed} (not fitted):\n")
            print(markdown(evaluate(held, list(check.names), tone_colours(check, decoder), corr, rendered)))
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.out is not None:
        args.out.write_text(corr.to_json() + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
