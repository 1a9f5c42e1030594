"""``python -m training mitsuba``: Mitsuba 3 vs our mixture renderer vs the biophysical ground truth.

For one tone and a few wavelengths, three total diffuse reflectances (specular excluded, diffuse
cosine-weighted illumination, n = 1.4; docs/contracts.md §1), each with its standard error:

* ``mitsuba``: the network's K-media mixture (``skin_decoder.onnx``) rendered by Mitsuba 3
  (``training.validate.mitsuba_scene``: one semi-infinite slab render per component and wavelength, sum_k w_k R_k);
* ``ours``: the same mixture, same parameters, by our Monte Carlo (``training.validate.mixture``);
* ``ground_truth``: the two-layer skin model of the tone itself (``training.sim.tissue.skin_medium``),
  simulated by ``training.sim``, i.e. what the network's mixture is meant to reproduce.

``network`` is the decoder's own reflectance output.  Mitsuba vs ours checks the renderers (they must
agree within noise); ground truth vs either measures the model.

Example::

    python -m training mitsuba --tone 0.001 0.010 0.008 0.75 0.72 --wavelengths 300,450,550,650,950 --json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from exporters.cli_io import NOTHING_KEPT, OneLineParser, check_biophysical, check_input, count, finite_float, guarded
from exporters.constants import WAVELENGTHS_NM
from training.sim.medium import LayeredMedium
from training.sim.tissue import skin_medium
from training.sim.transport import simulate
from training.validate import mitsuba_scene as em
from training.validate.mixture import mixture_reflectance, photons_for_precision


def ground_truth(tone, wavelengths_nm, photons: int, seed: int = 0, device: str = "cpu") -> tuple[np.ndarray, ...]:
    """R_d and its stderr (W,) of the biophysical two-layer model at the given wavelengths (nm).

    Optical coefficients are linearly interpolated between grid wavelengths (exact on the 2 nm grid).
    """
    wl = em.check_wavelengths(wavelengths_nm)
    full = skin_medium(np.asarray(tone, dtype=np.float64))
    lerp = lambda t: torch.as_tensor(np.stack([np.interp(wl, WAVELENGTHS_NM, row) for row in t.numpy()]))  # noqa: E731
    medium = LayeredMedium(lerp(full.mua), lerp(full.mus), lerp(full.g), full.thickness, full.n_medium)
    res = simulate(medium, int(photons), illumination="diffuse", seed=seed, device=device, r_edges_cm=None)
    return res.R_d, res.R_d_stderr


def compare(tone, wavelengths_nm, *, spp: int, photons: int, gt_photons: int | None = None,
            variant: str | None = None, batches: int = 8, seed: int = 0, decoder=em.DEFAULT_DECODER,
            device: str = "cpu", progress: bool = False, rel_stderr: float | None = None) -> dict:
    """The JSON record of the command (see the module docstring); every list has one value per wavelength.

    ``rel_stderr``: when given, Mitsuba's paths and our photons per component and wavelength are allocated from a
    pilot run of ``spp`` paths and ``photons`` photons per component (em.paths_for_precision,
    photons_for_precision) for that relative standard error of R_d at every wavelength; ``samples`` in the record
    says how many each component got."""
    tone = np.asarray(tone, dtype=np.float64)
    variant = variant or em.default_variant()
    mix = em.decode(tone, decoder).at(wavelengths_nm)
    mit_paths, our_photons = spp, photons
    t_pilot = time.perf_counter()
    if rel_stderr is not None:
        mit_paths = em.paths_for_precision(mix, rel_stderr, variant=variant, batches=batches, pilot_spp=spp,
                                           seed=seed + 1)
        our_photons = photons_for_precision(mix.alpha, mix.sigma_t, mix.g, mix.weight, rel_stderr,
                                            pilot_photons=photons, seed=seed + 1)
    t_pilot = time.perf_counter() - t_pilot
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=mix.k * mix.wavelength_nm.size, desc="mitsuba renders", file=sys.stderr)
    t0 = time.perf_counter()
    mit = em.mixture_reflectance(mix, spp=mit_paths, variant=variant, batches=batches, seed=seed,
                                 progress=(lambda done, total: bar.update(1)) if bar else None)
    if bar:
        bar.close()
    t1 = time.perf_counter()
    ours = mixture_reflectance(mix.alpha, mix.sigma_t, mix.g, mix.weight, photons=our_photons, seed=seed,
                               device=device, progress=progress)
    t2 = time.perf_counter()
    gt, gt_se = ground_truth(tone, mix.wavelength_nm, gt_photons or photons, seed=seed, device=device)
    t3 = time.perf_counter()
    se = np.hypot(mit.R_d_stderr, ours.R_d_stderr)
    lst = lambda a: [float(x) for x in np.asarray(a)]  # noqa: E731
    return {
        "wavelength_nm": lst(mix.wavelength_nm),
        "mitsuba": lst(mit.R_d),
        "ours": lst(ours.R_d),
        "ground_truth": lst(gt),
        "network": lst(mix.reflectance),
        "stderr": {"mitsuba": lst(mit.R_d_stderr), "ours": lst(ours.R_d_stderr), "ground_truth": lst(gt_se)},
        "agreement": {"relative_difference": lst(mit.R_d / ours.R_d - 1.0), "z": lst((mit.R_d - ours.R_d) / se)},
        "components": {"mitsuba": mit.R_k.tolist(), "ours": ours.R_k.tolist(), "weight": mix.weight.tolist(),
                       "alpha": mix.alpha.tolist(), "g": mix.g.tolist(), "sigma_t_cm": mix.sigma_t.tolist()},
        "tone": lst(tone),
        "illumination": "diffuse (cosine-weighted), n = 1.4, specular excluded",
        "variant": variant, "spp": int(spp), "batches": int(batches), "photons": int(photons),
        "rel_stderr": rel_stderr,
        "samples": {"mitsuba_paths": mit.spp.tolist(),
                    "our_photons": np.broadcast_to(np.asarray(ours.photons), mix.alpha.shape).tolist()},
        "ground_truth_photons": int(gt_photons or photons),
        "seconds": {"pilots": t_pilot, "mitsuba": t1 - t0, "ours": t2 - t1, "ground_truth": t3 - t2},
    }


def _wavelengths(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"wavelengths must be comma-separated numbers in nm, got {text!r}") from exc
    if not values or not all(250.0 <= v <= 1000.0 for v in values):
        raise argparse.ArgumentTypeError(f"wavelengths must lie in 250-1000 nm, got {text!r}")
    return values


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training mitsuba",
                      description="Mitsuba 3 reflectance of the network's mixture vs ours vs ground truth.")
    p.add_argument("--tone", nargs=5, type=finite_float, required=True,
                   metavar=("F_MEL", "F_BLOOD", "T_EPI", "SO2", "B_MEL"), help="biophysical vector (t_epi in cm)")
    p.add_argument("--wavelengths", type=_wavelengths, default=[300.0, 450.0, 550.0, 650.0, 950.0],
                   help="comma-separated, nm, within 250-1000 (default 300,450,550,650,950)")
    p.add_argument("--spp", type=count, default=65536,
                   help="Mitsuba paths per component and wavelength (with --rel-stderr: the pilot's)")
    p.add_argument("--batches", type=count, default=8, help="independent Mitsuba renders for the standard error")
    p.add_argument("--photons", type=count, default=100_000,
                   help="our photons per component and wavelength (with --rel-stderr: the pilot's)")
    p.add_argument("--rel-stderr", type=finite_float, default=None, metavar="R",
                   help="sample each component and wavelength for a relative standard error R of R_d at every "
                        "wavelength (e.g. 0.005), from a pilot run of --spp paths and --photons photons")
    p.add_argument("--gt-photons", type=count, default=None,
                   help="ground-truth photons per wavelength (default --photons)")
    p.add_argument("--variant", default="auto",
                   help="Mitsuba variant (auto: llvm_ad_rgb if libLLVM 19 is installed, else scalar_rgb)")
    p.add_argument("--decoder", type=Path, default=em.DEFAULT_DECODER, help="skin_decoder.onnx")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--threads", type=count, default=1, help="torch threads (1 is fastest on a busy 2-core machine)")
    p.add_argument("--json", action="store_true", help="print the JSON record (otherwise a table)")
    p.add_argument("--no-progress", action="store_true")
    return p


def _table(rec: dict) -> str:
    paths, photons = (int(np.sum(rec["samples"][k])) for k in ("mitsuba_paths", "our_photons"))
    lines = [f"tone {rec['tone']}  variant {rec['variant']}  Mitsuba {paths:,} paths  ours {photons:,} photons",
             f"{'nm':>6} {'mitsuba':>16} {'ours':>16} {'ground truth':>16} {'network':>8} {'rel diff':>9} {'z':>6}"]
    se = rec["stderr"]
    for i, wl in enumerate(rec["wavelength_nm"]):
        cell = lambda key, i=i: f"{rec[key][i]:.5f}±{se[key][i]:.5f}"  # noqa: E731
        lines.append(f"{wl:6.1f} {cell('mitsuba'):>16} {cell('ours'):>16} {cell('ground_truth'):>16} "
                     f"{rec['network'][i]:8.5f} {100 * rec['agreement']['relative_difference'][i]:8.2f}% "
                     f"{rec['agreement']['z'][i]:6.2f}")
    return "\n".join(lines)


@guarded("python -m training mitsuba", NOTHING_KEPT)
def main(argv: list[str]) -> int:
    """Run the command; exit 2 with a one-line error for bad input or a missing Mitsuba."""
    args = build_parser().parse_args(argv)
    check_biophysical(args.tone, "--tone")
    check_input(args.decoder, "--decoder", "onnx")
    try:
        for name in ("spp", "photons", "batches"):
            if getattr(args, name) < 2:
                raise ValueError(f"--{name} must be >= 2.")
        if args.threads < 1:
            raise ValueError("--threads must be >= 1.")
        if args.rel_stderr is not None and not 0 < args.rel_stderr < 1:
            raise ValueError(f"--rel-stderr must lie in (0, 1), e.g. 0.005; got {args.rel_stderr:g}.")
        torch.set_num_threads(args.threads)
        variant = None if args.variant == "auto" else args.variant
        rec = compare(args.tone, args.wavelengths, spp=args.spp, photons=args.photons, gt_photons=args.gt_photons,
                      variant=variant, batches=args.batches, seed=args.seed, decoder=args.decoder,
                      device=args.device, progress=not args.no_progress, rel_stderr=args.rel_stderr)
    except (ValueError, em.MitsubaUnavailable) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(rec) if args.json else _table(rec))
    return 0
