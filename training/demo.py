"""``make demo``: the best end-to-end path that exists today, saying what it did.

1. Physics: simulate one representative skin tone with the Monte Carlo simulator at all 376 wavelengths,
   print its reflectance and colour, and plot the swatches of the shipped tones.
2. Artist path (training/demo_render.py): generate a skin albedo texture (light-to-dark, freckles,
   redness), bake it with the Blender add-on's Invert Skin Albedo (the shipped model), apply it to
   Suzanne and render with Cycles (demo/out/preview.png, beside an albedo-only render), and draw a
   contact sheet of the baked maps.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from exporters.colorimetry import spectrum_to_lab, spectrum_to_srgb
from exporters.constants import WAVELENGTHS_NM
from training.skin.swatches import plot_swatches, simulate_spectra
from training.skin.tones import load_tones


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m training demo", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("demo/out"))
    parser.add_argument("--photons", type=int, default=300, help="photons per wavelength (swatches: a fifth)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch CPU threads (1 is fastest for the walker on a busy 2-core machine)")
    parser.add_argument("--render-size", type=int, default=256, help="preview size in pixels")
    parser.add_argument("--samples", type=int, default=64, help="Cycles samples of the preview")
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(max(1, args.threads))
    tones = load_tones()
    name = "R05"
    tone = tones.values[tones.names.index(name)]
    print(f"[demo] 1/2 physics: Monte Carlo of tone {name} (f_mel, f_blood, t_epi cm, so2, b_mel) = {tone.tolist()},\n"
          f"[demo] two-layer skin under a Fresnel boundary, {args.photons} photons x 376 wavelengths.")
    start = time.perf_counter()
    spectrum = simulate_spectra(tone[None], args.photons, args.seed)[0]
    seconds = time.perf_counter() - start
    for nm in (250, 400, 450, 500, 550, 600, 650, 700, 800, 1000):
        print(f"  R_d({nm} nm) = {spectrum[np.searchsorted(WAVELENGTHS_NM, nm)]:.4f}")
    srgb = spectrum_to_srgb(spectrum, "D65")
    lab = spectrum_to_lab(spectrum, "D65")
    print(f"[demo] colour under D65: sRGB {np.round(np.clip(srgb, 0, 1) * 255).astype(int).tolist()}, "
          f"Lab {np.round(lab, 2).tolist()}  ({seconds:.1f} s of simulation)")
    swatches = args.out / "swatches.png"
    spectra = simulate_spectra(tones.values, max(args.photons // 5, 20), args.seed)
    plot_swatches(tones, spectrum_to_srgb(spectra, "D65"), swatches,
                  f"Simulated skin colours (D65), {max(args.photons // 5, 20)} photons per wavelength")
    print(f"[demo] wrote {swatches}: the 10 representative and 10 outlier tones.")
    _artist_path(args)
    return 0


def _artist_path(args) -> None:
    from training import demo_render

    print("[demo] 2/2 artist path: procedural albedo -> Invert Skin Albedo (Blender add-on, shipped model) -> "
          "Cycles render of Suzanne")
    info = demo_render.run(args.out, render_size=args.render_size, samples=args.samples)
    rec = info["record"]
    t = info["timings_s"]
    print(f"[demo] baked {len(rec['files'])} maps (K={rec['K']}, {rec['image_size'][0]}x{rec['image_size'][1]}, "
          f"{rec['stats']['distinct_texels']} distinct texels) in {t['bake']:.1f} s into {args.out / 'maps'}")
    for note in rec["notes"]:
        print(f"[demo]   note: {note}")
    print(f"[demo] rendered {args.out / 'preview.png'} ({args.render_size} px, {args.samples} spp, "
          f"{t['render']:.1f} s); albedo-only vs spectral SSS side by side: {args.out / 'preview_compare.png'}")
    print(f"[demo] contact sheet of the maps: {args.out / 'maps_contact_sheet.png'}")
    print("[demo] The shipped model is an integration model (16 training tones): the preview matches the painted "
          "brightness\n[demo] (Match painted brightness on); its colours are only as good as that model.")
