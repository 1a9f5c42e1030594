"""Spectral coherence of a decoder's mixture along wavelength, and its figure.

    python -m training.validate.coherence [--model blender_addon/models/skin_decoder.onnx | RUN/model.pt]
        [--tones 1000] [--seed 0] [--fitted-stride 4] [--lut LUT.npz] [--json OUT.json] [--figure OUT.png]

On ``n`` tones drawn uniformly in the docs/contracts.md §1 box (``random_tones``), the decoder's mixture (alpha, g,
sigma_t, w: (N, K, 376)) is compared between neighbouring 2 nm steps.  Steps are split into those that
touch a *fitted* wavelength (one of the two ends is a wavelength the fits exist at, every
``fitted_stride``-th from 250 nm) and the others; a decoder supervised only where fits exist shows a
comb: its parameters jump at the fitted wavelengths and interpolate between them.  Per group:

* ``switch_rate``: share of (tone, step) where the dominant component (largest weight) changes;
* ``median_dlog_sigma_t``: median over (tone, step) of max_k |ln sigma_t,k(l + 1) - ln sigma_t,k(l)|
  (the largest change of any component; with this definition the shipped decoder gives the issue's
  0.35 / 0.14).

*Weight jumps*: steps where some component's weight changes by more than ``JUMP_DW`` (0.2); reported
also over 8 nm (``WINDOW_STEPS``), beside the acceptance.  Such a
jump is *explained* when the mixture's rendered radial exitance E(r) = sum_k w_k R_k P_k(r) (through
the LUT: ``training.fit.mixture.radial_profile``) changes by at least ``EXPLAINED_FRACTION`` (1/2) of what
the weight change alone would change it by, E at (media of l, weights of l + 1) against E at l, the
distance being the relative L1 distance d(E_a, E_b) = sum_r |E_a - E_b| A(r) / mean(R_a, R_b) over
the dataset's radial bins (A their areas).  An unexplained jump is the decoder moving light between
components while the rendered mixture stays put: a relabelling of degenerate media, which mixes media
in anything that averages a component over wavelengths (the Cycles collapse, the physical maps).

Acceptance (``acceptance``): switch rates of the two groups within ``SWITCH_TOL`` (absolute),
median |d ln sigma_t| within a factor ``DSIGMA_RATIO_TOL``, no unexplained weight jump.

The LUT is ``--lut``, else $SKIN_SSS_LUT, else the closed-form diffusion-dipole table
(``training.fit.problems.bench_lut``, a stand-in: both sides of the "explained" comparison go through the
same table, so the ratio is meaningful with it, the absolute distances less so).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from exporters.constants import R_EDGES_CM, WAVELENGTH_STEP_NM, WAVELENGTHS_NM
from training.data.sampling import PARAM_HIGH, PARAM_LOW
from training.fit.matching import FIELDS
from training.fit.mixture import Mixture, radial_profile
from training.sim.lut_interp import LookupTables, bin_centres

#: A weight jump: some component's weight changes by more than this between neighbouring wavelengths.
JUMP_DW: float = 0.2
#: A jump is explained when the rendered exitance changes by at least this fraction of the change that
#: the weight change alone makes (module docstring).
EXPLAINED_FRACTION: float = 0.5
#: Reported beside the per-step jumps, not part of the acceptance: the same jumps between wavelengths this many
#: grid steps apart (8 nm).  A decoder whose weights are low-passed along wavelength (``ModelConfig.
#: weight_smoothing_nm``) cannot jump in one step; this shows whether it still moves light between media
#: over a few steps without the rendered mixture changing.
WINDOW_STEPS: int = 4
#: Acceptance: |switch rate (fitted) - switch rate (other)| at most this (absolute share of steps).
SWITCH_TOL: float = 0.01
#: Acceptance: the two groups' median |d ln sigma_t| within this factor of each other.
DSIGMA_RATIO_TOL: float = 1.25
#: The exitance distance uses every n-th of the dataset's radial edges (128 bins of 0-5 cm; the L1 sum is a
#: midpoint rule over log-spaced bins, within a few % of the 512-bin value).
RADIAL_STRIDE: int = 4
#: Fitted wavelengths of the shipped decoder's fits: every 4th of the 376 (``fit --wavelength-stride 4``).
SHIPPED_FITTED_STRIDE: int = 4

Decoded = dict[str, np.ndarray]
DecodeFn = Callable[[np.ndarray], Decoded]


def random_tones(n: int, seed: int = 0) -> np.ndarray:
    """n tones (n, 5) uniform in the docs/contracts.md §1 box (float32, what the decoder takes)."""
    rng = np.random.default_rng(seed)
    return (PARAM_LOW + (PARAM_HIGH - PARAM_LOW) * rng.random((n, PARAM_LOW.size))).astype(np.float32)


def decoder(model) -> DecodeFn:
    """p (N, 5) -> {alpha, g, sigma_t, weight: (N, K, W) float64} of a ``skin_decoder.onnx`` (through
    ``exporters.inference.run_decoder``), a run's ``model.pt``, or a ``SkinChain``."""
    if isinstance(model, str | Path):
        path = Path(model)
        if not path.is_file():
            raise ValueError(f"no such decoder: {path} (a skin_decoder.onnx or a run's model.pt)")
        if path.suffix == ".onnx":
            from exporters.inference import run_decoder

            return lambda p: {f: v for f, v in run_decoder(p, path).items() if f in FIELDS}
        from training.train.run import load_model

        model = load_model(path)

    def run_torch(p: np.ndarray) -> Decoded:
        with torch.no_grad():
            out = model.decode(torch.as_tensor(np.asarray(p, np.float32)))
        return {f: out[f].double().cpu().numpy() for f in FIELDS}

    return run_torch


def decode(fn: DecodeFn, tones: np.ndarray, batch: int = 250) -> Decoded:
    """``fn`` over ``tones`` (N, 5) in batches; fields (N, K, W)."""
    parts = [fn(tones[s : s + batch]) for s in range(0, len(tones), batch)]
    return {f: np.concatenate([p[f] for p in parts]) for f in FIELDS}


def touching(fitted_index: np.ndarray, n_wavelengths: int = WAVELENGTHS_NM.size) -> np.ndarray:
    """(W - 1,) bool: step l -> l + 1 has a fitted wavelength at one of its ends."""
    fitted = np.zeros(n_wavelengths, bool)
    fitted[np.asarray(fitted_index)] = True
    return fitted[:-1] | fitted[1:]


def step_changes(dec: Decoded) -> tuple[np.ndarray, np.ndarray]:
    """(switch (N, W - 1) bool: the dominant component changes; dlog (N, W - 1): max_k |d ln sigma_t,k|)."""
    dom = dec["weight"].argmax(1)
    dlog = np.abs(np.diff(np.log(np.maximum(dec["sigma_t"], 1e-30)), axis=2)).max(1)
    return dom[:, 1:] != dom[:, :-1], dlog


def _exitance_distance(lut: LookupTables, a: Mixture, b: Mixture) -> np.ndarray:
    """Relative L1 distance (module docstring) between the rendered exitances of mixtures a and b (fields
    (J, K)); (J,)."""
    edges = torch.tensor(R_EDGES_CM[::RADIAL_STRIDE])
    r, area = bin_centres(edges), torch.pi * torch.diff(edges**2)
    ea, eb = radial_profile(lut, a, r) * area, radial_profile(lut, b, r) * area
    ref = 0.5 * (ea.sum(-1) + eb.sum(-1))
    return ((ea - eb).abs().sum(-1) / ref.clamp_min(1e-30)).numpy()


def _mixture_at(dec: Decoded, tone: np.ndarray, col: np.ndarray, weight_col: np.ndarray) -> Mixture:
    """The media of tones ``tone`` (J,) at wavelength columns ``col`` (J,) with the weights of ``weight_col``
    (J,): fields (J, K)."""
    media = [torch.as_tensor(dec[f][tone, :, col]) for f in ("alpha", "g", "sigma_t")]
    return Mixture(*media, torch.as_tensor(dec["weight"][tone, :, weight_col]))


def weight_jumps(dec: Decoded, lut: LookupTables, chunk: int = 1024, span: int = 1) -> dict[str, np.ndarray]:
    """The weight jumps of ``dec`` (module docstring) between wavelengths ``span`` grid steps apart: {tone,
    step (J,) int (the first of the two wavelengths); dw (J,): the largest |dw_k|; actual, weight_only (J,):
    the exitance distances; explained (J,) bool}."""
    w = dec["weight"]
    dw = np.abs(w[..., span:] - w[..., :-span]).max(1)  # (N, W - span)
    tone, step = np.nonzero(dw > JUMP_DW)
    actual, alone = np.zeros(len(tone)), np.zeros(len(tone))
    for s in range(0, len(tone), chunk):
        t, c = tone[s : s + chunk], step[s : s + chunk]
        here, there = _mixture_at(dec, t, c, c), _mixture_at(dec, t, c + span, c + span)
        moved = _mixture_at(dec, t, c, c + span)
        actual[s : s + chunk] = _exitance_distance(lut, here, there)
        alone[s : s + chunk] = _exitance_distance(lut, here, moved)
    return {"tone": tone, "step": step, "dw": dw[tone, step], "actual": actual, "weight_only": alone,
            "explained": actual >= EXPLAINED_FRACTION * alone}


def coherence(dec: Decoded, fitted_index: np.ndarray, lut: LookupTables) -> dict:
    """The metrics of the module docstring for decoded tones ``dec``, per group "fitted" / "other", and the
    weight jumps; plus ``acceptance`` (bool per criterion and overall)."""
    touch = touching(fitted_index, dec["weight"].shape[-1])
    switch, dlog = step_changes(dec)
    jumps = weight_jumps(dec, lut)
    out: dict = {"tones": int(dec["weight"].shape[0]), "fitted_wavelengths": int(len(fitted_index))}
    for name, sel in (("fitted", touch), ("other", ~touch)):
        in_group = sel[jumps["step"]]
        out[name] = {"steps": int(sel.sum()), "switch_rate": float(switch[:, sel].mean()),
                     "median_dlog_sigma_t": float(np.median(dlog[:, sel])),
                     "weight_jumps": int(in_group.sum()),
                     "unexplained_jumps": int((in_group & ~jumps["explained"]).sum())}
    f, o = out["fitted"], out["other"]
    hi = max(f["median_dlog_sigma_t"], o["median_dlog_sigma_t"])
    lo = max(min(f["median_dlog_sigma_t"], o["median_dlog_sigma_t"]), 1e-12)
    acc = {"switch_rate": abs(f["switch_rate"] - o["switch_rate"]) <= SWITCH_TOL,
           "dlog_sigma_t": hi / lo <= DSIGMA_RATIO_TOL,
           "no_unexplained_jumps": f["unexplained_jumps"] + o["unexplained_jumps"] == 0}
    slow = weight_jumps(dec, lut, span=WINDOW_STEPS)
    out["window"] = {"span_nm": WAVELENGTH_STEP_NM * WINDOW_STEPS, "weight_jumps": int(slow["tone"].size),
                     "unexplained_jumps": int((~slow["explained"]).sum())}
    out["acceptance"] = {**acc, "all": all(acc.values()),
                         "tolerances": {"switch": SWITCH_TOL, "dlog_ratio": DSIGMA_RATIO_TOL, "jump_dw": JUMP_DW,
                                        "explained_fraction": EXPLAINED_FRACTION}}
    return out


def figure(dec: Decoded, names: list[str], out: Path, fitted_index: np.ndarray | None = None,
           title: str = "") -> Path:
    """alpha, sigma_t, g and w along wavelength (rows) for each tone (columns), one line per component;
    dots at the fitted wavelengths.  Written to ``out`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (("alpha", "α", False), ("sigma_t", "σt (cm⁻¹)", True), ("g", "g", False), ("weight", "w", False))
    n, k = len(names), dec["weight"].shape[1]
    fig, axes = plt.subplots(len(rows), n, figsize=(1.9 * n + 1, 7.5), sharex=True, sharey="row", squeeze=False)
    colours = plt.cm.tab10(np.arange(k))
    wl = WAVELENGTHS_NM
    for j, name in enumerate(names):
        for i, (field, label, log) in enumerate(rows):
            ax = axes[i, j]
            for c in range(k):
                y = dec[field][j, c]
                ax.plot(wl, y, lw=0.8, color=colours[c], label=f"k = {c}")
                if fitted_index is not None:
                    ax.plot(wl[fitted_index], y[fitted_index], ".", ms=1.6, color=colours[c])
            if log:
                ax.set_yscale("log")
            if j == 0:
                ax.set_ylabel(label)
            if i == 0:
                ax.set_title(name, fontsize=9)
            if i == len(rows) - 1:
                ax.set_xlabel("λ (nm)")
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=6, loc="lower right")
    fig.suptitle(title or "Decoder mixture along wavelength (dots: fitted wavelengths)", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _load_lut(path: Path | None) -> tuple[LookupTables, str]:
    """``path``, else $SKIN_SSS_LUT, else the dipole stand-in (module docstring)."""
    if path is None and os.environ.get("SKIN_SSS_LUT"):
        path = Path(os.environ["SKIN_SSS_LUT"])
    if path is not None:
        if not path.is_file():
            raise ValueError(f"no such LUT: {path}")
        return LookupTables.load(path), str(path.name)
    from training.fit.problems import bench_lut

    return bench_lut()


def main(argv: list[str] | None = None) -> int:
    from training.paths import SHIPPED_DECODER

    p = argparse.ArgumentParser(prog="python -m training.validate.coherence", description=__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=SHIPPED_DECODER,
                   help="skin_decoder.onnx or a run's model.pt (default: the shipped decoder)")
    p.add_argument("--tones", type=int, default=1000, help="random tones (uniform in the parameter box)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fitted-stride", type=int, default=SHIPPED_FITTED_STRIDE,
                   help="the fits the decoder learnt from were at every n-th wavelength (default 4)")
    p.add_argument("--lut", type=Path, default=None, help="LUT .npz (default $SKIN_SSS_LUT, else the dipole table)")
    p.add_argument("--json", type=Path, default=None, help="write the metrics here")
    p.add_argument("--figure", type=Path, default=None, help="write the R01-R10 figure here (PNG)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    try:
        if args.tones < 1 or args.fitted_stride < 1:
            raise ValueError("--tones and --fitted-stride must be >= 1")
        lut, lut_note = _load_lut(args.lut)
        fn = decoder(args.model)
        fitted = np.arange(0, WAVELENGTHS_NM.size, args.fitted_stride)
        res = coherence(decode(fn, random_tones(args.tones, args.seed)), fitted, lut)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    res.update({"model": args.model.name, "seed": args.seed, "lut": lut_note})
    print(json.dumps(res, indent=2))
    if args.json is not None:
        args.json.write_text(json.dumps(res, indent=2))
    if args.figure is not None:
        from training.skin.tones import load_tones

        rep = load_tones().select("representative")
        figure(decode(fn, rep.values.astype(np.float32)), list(rep.names), args.figure, fitted,
               f"{args.model.name}: mixture along wavelength, representative tones (dots: fitted wavelengths, "
               f"every {2 * args.fitted_stride} nm)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
