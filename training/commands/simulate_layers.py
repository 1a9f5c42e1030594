"""``python -m training simulate-layers``: Monte Carlo of a generic layered medium, JSON out (docs/contracts.md §2).

Example (the van de Hulst / MCML slab check)::

    python -m training simulate-layers --layer 10 90 0.75 0.02 --n-medium 1.0 \\
        --illumination normal --photons 100000 --json
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from exporters.cli_io import OneLineParser
from exporters.constants import R_EDGES_CM
from training.commands.options import command, count, error_status, in_range
from training.sim.illumination import parse_illumination
from training.sim.medium_check import check_layer_values
from training.sim.walk_constants import ENGINES


def _illumination(text: str) -> str:
    """argparse type of ``--illumination`` (``training.sim.illumination.parse_illumination``)."""
    try:
        parse_illumination(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("illumination ")) from None
    return text


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="python -m training simulate-layers",
        description="Monte Carlo diffuse reflectance / transmittance of a layered medium (top layer first).",
    )
    p.add_argument("--layer", nargs=4, action="append", required=True,
                   metavar=("MUA", "MUS", "G", "THICKNESS"),
                   help="one layer: mua, mus (cm^-1), HG g, thickness (cm; the last may be 'inf')")
    p.add_argument("--n-medium", type=in_range(1.0, 3.0), default=1.4,
                   help="refractive index of all layers (air above), in [1, 3]")
    p.add_argument("--n-below", type=in_range(1.0, 3.0), default=1.0, help="index below a finite stack (default air)")
    p.add_argument("--illumination", type=_illumination, default="diffuse", metavar="{diffuse,normal,collimated:THETA}",
                   help="diffuse (cosine-weighted lobe), normal (collimated beam) or collimated:THETA (a collimated "
                   "beam at THETA degrees from the normal, in the x-z plane; the JSON then adds the specular "
                   "(Fresnel) part and, on the numba engine, shift_cm, the reflected light's mean exit x along the "
                   "plane of incidence)")
    p.add_argument("--photons", type=count, required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--engine", choices=ENGINES, default="auto",
                   help="walk engine: numba (compiled per-packet loop, all CPU cores), torch (vectorised step, "
                   "CPU or CUDA); auto: numba on the CPU, torch on CUDA")
    p.add_argument("--threads", type=count, default=None,
                   help="threads of the numba engine (default: every CPU this process may run on)")
    p.add_argument("--compile", choices=("auto", "on", "off"), default="auto",
                   help="torch.compile the torch engine's step (auto: only for large runs)")
    p.add_argument("--json", action="store_true", help="print one JSON object (the only output format)")
    p.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    return p


def _layers(args: argparse.Namespace) -> tuple[np.ndarray, ...]:
    """mua, mus, g (L, 1) and thickness (L,) float64 from the --layer options, checked."""
    rows = []
    for layer in args.layer:
        try:
            rows.append([float(v) for v in layer])
        except ValueError as exc:
            raise ValueError(f"--layer values must be numbers: {' '.join(layer)}") from exc
    t = np.array(rows, dtype=np.float64)
    if np.isnan(t).any() or np.isinf(t[:, :3]).any():
        raise ValueError("--layer MUA MUS G must be finite numbers")
    if (t[:, :2] < 0).any() or (np.abs(t[:, 2]) >= 1).any() or (t[:, 3] <= 0).any():
        raise ValueError("--layer needs MUA >= 0, MUS >= 0, -1 < G < 1 and THICKNESS > 0 (cm)")
    if np.isinf(t[:-1, 3]).any():
        raise ValueError("--layer: only the last layer may be infinitely thick")
    mua, mus, g, thickness = t[:, 0:1].copy(), t[:, 1:2].copy(), t[:, 2:3].copy(), t[:, 3].copy()
    check_layer_values(mua, mus, g, thickness, args.n_medium, args.n_below)
    return mua, mus, g, thickness


def _walk(args: argparse.Namespace, layers: tuple[np.ndarray, ...]) -> dict:
    """R_d, R_d_stderr, T_d (arrays over the one channel), photons and seconds of the asked engine and device.

    The numba engine on the CPU runs torch-free (``training.sim.compiled_transport``); the torch engine, CUDA and
    numba-cuda go through ``training.sim.transport.simulate``, which gives the numba engine the same numbers.
    """
    if args.device == "cpu" and args.engine in ("auto", "numba"):
        from training.sim.compiled_transport import simulate_compiled

        mua, mus, g, thickness = layers
        oblique = parse_illumination(args.illumination).cos_in < 1.0
        return simulate_compiled(mua, mus, g, thickness, args.photons, n_medium=args.n_medium,
                                 n_below=args.n_below, illumination=args.illumination, seed=args.seed,
                                 threads=args.threads, progress=args.progress,
                                 r_edges_cm=R_EDGES_CM if oblique else None)
    from training.sim.medium import LayeredMedium
    from training.sim.transport import simulate

    medium = LayeredMedium(*layers, n_medium=args.n_medium, n_below=args.n_below)
    res = simulate(
        medium, args.photons, illumination=args.illumination, seed=args.seed, device=args.device,
        r_edges_cm=None, progress=args.progress, compile={"auto": "auto", "on": True, "off": False}[args.compile],
        engine=args.engine, threads=args.threads,
    )
    out = {"R_d": res.R_d, "R_d_stderr": res.R_d_stderr, "T_d": res.T_d, "photons": res.photons,
           "seconds": res.seconds}
    if parse_illumination(args.illumination).cos_in < 1.0:
        out["specular"] = res.specular
    return out


@command("simulate-layers")
def main(argv: list[str]) -> int:
    """Run the command; returns the exit status (2 for bad input)."""
    args = build_parser().parse_args(argv)
    try:
        layers = _layers(args)
        if args.photons < 1:
            raise ValueError("--photons must be >= 1")
        res = _walk(args, layers)
    except ValueError as exc:
        return error_status(exc)
    out = {
        "R_d": float(res["R_d"][0]),
        "R_d_stderr": float(res["R_d_stderr"][0]),
        "T_d": 0.0 if math.isinf(float(layers[3][-1])) else float(res["T_d"][0]),
        "photons": int(res["photons"]),
        "seconds": round(float(res["seconds"]), 4),
    }
    out.update({k: float(res[k][0]) for k in ("specular", "shift_cm") if k in res})
    print(json.dumps(out))
    return 0
