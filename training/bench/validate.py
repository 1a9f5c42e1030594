"""Benchmark rows of the validation path: Mitsuba 3 vs our mixture renderer on the network's media.

One row per representative tone (R01 lightest, R05 medium, R10 darkest) at five wavelengths from UV to
NIR (300, 450, 550, 650, 950 nm): total diffuse reflectance of the shipped decoder's K-media mixture
(diffuse illumination, n = 1.4, specular excluded) by Mitsuba 3 (anchor; ``training.validate.mitsuba_scene``, one slab
render per component and wavelength) and by our Monte Carlo (``training.validate.mixture``).  The
acceptance of the Mitsuba issue: agreement within 2 % (or 4 combined standard errors) everywhere.
"""

from __future__ import annotations

import numpy as np

from training.skin.tones import load_tones
from training.validate import mitsuba_scene as em
from training.validate.mixture import mixture_reflectance

WAVELENGTHS = (300.0, 450.0, 550.0, 650.0, 950.0)
TONES = ("R01", "R05", "R10")
#: (Mitsuba paths, our photons) per component and wavelength.
SAMPLES = {True: (65_536, 50_000), False: (524_288, 400_000)}


def agreement_row(name: str, tone: np.ndarray, spp: int, photons: int, variant: str) -> dict:
    """One benchmark row: ours vs Mitsuba at WAVELENGTHS for one tone."""
    mix = em.decode(tone).at(WAVELENGTHS)
    mit = em.mixture_reflectance(mix, spp=spp, variant=variant, batches=16, seed=11)
    ours = mixture_reflectance(mix.alpha, mix.sigma_t, mix.g, mix.weight, photons=photons, seed=11)
    rel = ours.R_d / mit.R_d - 1.0
    se = np.hypot(mit.R_d_stderr, ours.R_d_stderr)
    z = (ours.R_d - mit.R_d) / se
    ok = (np.abs(rel) <= 0.02) | (np.abs(z) <= 4.0)
    fmt = lambda v, s: ", ".join(f"{a:.4g}±{b:.2g}" for a, b in zip(v, s, strict=True))  # noqa: E731
    return {
        "workload": f"mixture R_d, tone {name}, {'/'.join(f'{w:g}' for w in WAVELENGTHS)} nm",
        "ours": fmt(ours.R_d, ours.R_d_stderr),
        "anchor": f"Mitsuba 3 {variant}: " + fmt(mit.R_d, mit.R_d_stderr),
        "ratio": "ours/Mitsuba - 1: " + ", ".join(f"{100 * r:+.2f}%" for r in rel),
        "error": f"max |rel| {100 * np.max(np.abs(rel)):.2f}%, max |z| {np.max(np.abs(z)):.2f}, "
                 f"combined rel. stderr <= {100 * np.max(se / mit.R_d):.2f}%",
        "notes": f"{'PASS' if ok.all() else 'FAIL'} (2 % or 4 sigma); Mitsuba {spp} paths, ours {photons} photons "
                 f"per component and wavelength; {mit.seconds:.0f} s Mitsuba, {ours.seconds:.0f} s ours",
    }


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md (quick: fewer samples, same workloads)."""
    spp, photons = SAMPLES[bool(quick)]
    variant = em.default_variant()
    tones = load_tones().select("representative")
    return [agreement_row(n, tones.values[tones.names.index(n)], spp, photons, variant) for n in TONES]
