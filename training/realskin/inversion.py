"""The inversion on measured skin colours: which exposure it answers them with.

An artist paints skin's colour. The measured NIST spectra without their specular part (the rough n = 1.4
surface of ``training.realskin.geometry``) are such colours: D65, linear sRGB, CIE 1931 2 degrees
(``exporters.colorimetry``).  ``skin_inversion.onnx`` answers each with a biophysical tone and an exposure:
Y(input) / Y(the tone's reflectance), so 1 means the encoder found a tone as bright as the skin, and a
factor far from 1 means the skin model (or the network) cannot make skin that bright or that dark.

Geometry: the measurements are collimated at 8 degrees, the network's albedo is the diffuse-light R_d of
the dataset.  The two differ by a few per cent for skin; no correction is applied (an artist's photograph
is lit neither way exactly).

    python -m training.realskin.inversion [--model-dir DIR] [--json]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from exporters.colorimetry import linear_srgb_to_lab, spectrum_to_linear_srgb
from training.realskin.measurements import Measurements, diffuse_on_grid, read_measurements

#: The band the issue asks the exposure of measured skin to fall in.
EXPOSURE_BAND: tuple[float, float] = (0.9, 1.1)


def measured_albedo_rgb(meas: Measurements, specular: float) -> np.ndarray:
    """Linear sRGB (S, 3) under D65 of each measured spectrum without its specular part, clipped to [0, 1]."""
    return np.clip(spectrum_to_linear_srgb(diffuse_on_grid(meas, specular), "D65"), 0.0, 1.0)


def inversion_exposure(model_path: Path, meas: Measurements | None = None, specular: float | None = None) -> dict:
    """The exposure ``skin_inversion.onnx`` at ``model_path`` gives each measured skin colour.

    Returns a JSON-able record: per subject ``name``, ``L_star`` (of the colour without the specular part)
    and ``exposure``; and ``summary`` (min, median, max, the count inside ``EXPOSURE_BAND``, the count).
    """
    from exporters.inference import load_model
    from training.realskin.geometry import rough_specular

    meas = read_measurements() if meas is None else meas
    specular = rough_specular() if specular is None else float(specular)
    rgb = measured_albedo_rgb(meas, specular)
    session = load_model(model_path, threads=1)
    exposure = session.run(rgb)["exposure"][:, 0].astype(np.float64)
    lightness = linear_srgb_to_lab(rgb)[:, 0]
    lo, hi = EXPOSURE_BAND
    return {
        "model_sha256": session.sha256,
        "specular": round(specular, 5),
        "subjects": [{"name": n, "L_star": round(float(v), 2), "exposure": round(float(e), 4)}
                     for n, v, e in zip(meas.names, lightness, exposure, strict=True)],
        "summary": {"n": int(exposure.size), "min": float(exposure.min()), "median": float(np.median(exposure)),
                    "max": float(exposure.max()), "band": list(EXPOSURE_BAND),
                    "inside_band": int(((exposure >= lo) & (exposure <= hi)).sum())},
    }


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json
    import sys

    from training.paths import SHIPPED_MODEL_DIR

    ap = argparse.ArgumentParser(prog="python -m training.realskin.inversion", description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=Path, default=SHIPPED_MODEL_DIR,
                    help="folder with skin_inversion.onnx (default: the shipped model)")
    ap.add_argument("--json", action="store_true", help="print the whole record as JSON")
    args = ap.parse_args(argv)
    path = args.model_dir / "skin_inversion.onnx"
    if not path.is_file():
        print(f"error: {path}: no such file (give --model-dir with skin_inversion.onnx)", file=sys.stderr)
        return 2
    rec = inversion_exposure(path)
    if args.json:
        print(json.dumps(rec, indent=1))
    else:
        s = rec["summary"]
        print(f"exposure on {s['n']} measured skin colours: {s['min']:.2f}-{s['max']:.2f} (median {s['median']:.2f}); "
              f"{s['inside_band']} of {s['n']} in {s['band'][0]}-{s['band'][1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
