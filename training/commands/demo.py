"""``make demo``: the best end-to-end path that exists today, saying what it did.

1. Physics: simulate one representative skin tone with the Monte Carlo simulator at all 376 wavelengths,
   print its reflectance and colour (the swatches of all 20 shipped tones are ``python -m training swatches``:
   about 3 CPU-minutes, too long for the demo's 3-minute budget).
2. Artist path (training/demo_render.py): generate light, medium and dark skin albedo textures (mottling,
   freckles, redness), put them on a life-sized procedural head with ears and render each with Cycles three
   ways: albedo only, Blender's Principled BSDF Random Walk (Skin) at its default radius, and Spectral Skin
   SSS (the add-on's Invert Skin Albedo with the shipped model, default settings), lit so that translucency
   shows (demo/out/translucency.png); and draw a contact sheet of the baked maps.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from exporters.cli_io import OneLineParser, inside
from exporters.colorimetry import spectrum_to_lab, spectrum_to_srgb
from exporters.constants import WAVELENGTHS_NM
from training import demo_render
from training.commands.options import (
    check_output_file,
    check_output_folder,
    command,
    count,
    in_range,
    output_lock,
    require,
)
from training.commands.swatches import simulate_spectra
from training.export.card import summary
from training.paths import SHIPPED_CARD
from training.skin.tones import load_tones


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser (the CLI reference of the documentation reads it too)."""
    parser = OneLineParser(prog="python -m training demo", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("demo/out"))
    parser.add_argument("--photons", type=count, default=300, help="photons per wavelength of the Monte Carlo tone")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=count, default=1,
                        help="torch CPU threads (1 is fastest for the walker on a busy 2-core machine)")
    parser.add_argument("--render-size", type=in_range(16, 8192, integer=True), default=demo_render.RENDER_SIZE,
                        help="size of each render in pixels")
    parser.add_argument("--samples", type=count, default=demo_render.SAMPLES,
                        help="Cycles samples per pixel of each render (then OpenImageDenoise)")
    parser.add_argument("--figure", type=Path, default=None,
                        help="also write the comparison figure here (.png or .jpg; the README's is "
                             "docs/figures/demo_translucency.jpg)")
    return parser


@command("demo")
def main(argv: list[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_output_folder(args.out, "--out")
    if args.figure is not None:
        check_output_file(args.figure, "--figure", suffixes=(".png", ".jpg", ".jpeg"))
        require(not inside(args.figure, args.out), f"--figure {args.figure}: not inside --out (emptied on each run)")
    import torch

    demo_start = time.perf_counter()
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
    args.out.mkdir(parents=True, exist_ok=True)
    with output_lock(args.out, "--out"):
        _artist_path(args)
    print(f"[demo] done in {time.perf_counter() - demo_start:.0f} s.")
    return 0


def _artist_path(args) -> None:
    card = json.loads(SHIPPED_CARD.read_text())
    print("[demo] 2/2 artist path: light, medium and dark procedural albedos on a life-sized head (Unit Scale 1 m), "
          "each rendered\n[demo] (a) albedo only, (b) Principled BSDF Random Walk (Skin) at Blender's default radius, "
          "(c) Spectral Skin SSS\n[demo] (Invert Skin Albedo, default settings) with the shipped model:\n"
          f"[demo]   {summary(card)}")
    info = demo_render.run(args.out, render_size=args.render_size, samples=args.samples, figure=args.figure)
    t = info["timings_s"]
    for tone, rec in info["records"].items():
        w, h = rec["image_size"]
        print(f"[demo] baked {tone}: {len(rec['files'])} maps (K={rec['K']}, {w}x{h}, "
              f"{rec['stats']['distinct_texels']} distinct texels) in {t['bake_' + tone]:.1f} s "
              f"into {args.out / 'maps' / tone}")
    renders = sum(v for k, v in t.items() if k.startswith("render_"))
    print(f"[demo] rendered 9 views ({args.render_size} px, {args.samples} spp + OpenImageDenoise) in {renders:.1f} s: "
          f"{args.out / 'translucency.png'}" + (f" and {args.figure}" if args.figure else ""))
    ear = info["ear_mean_srgb"]
    for tone in info["records"]:
        means = ", ".join(f"{m} {np.mean(ear[tone + '/' + m]):.2f}" for m, _ in demo_render.METHODS)
        print(f"[demo]   back-lit ear, mean display value ({tone}): {means}")
    print(f"[demo] contact sheet of the maps: {args.out / 'maps_contact_sheet.png'}")
